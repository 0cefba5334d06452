// The distributed backend (`--set backend=mpi`, `--ranks N`: runtime/src/mpi/ behind
// runtime/include/hybgen/rt/core/backend.hpp) against the one-process runner: every method
// on 1 and 2 ranks, on shipped models of 2, 3 and 5 dimensions, with one mode and two.
//
// The reference is the OpenMP runner's output. For the transfer operator and the spectrum
// it comes from other code (Eigen's CSR and Spectra against PETSc and SLEPc), so they are
// compared to rounding and to the eigen-solvers' tolerance. For the particles and the
// characteristics the backend claims more, and the test holds it to that: the same bits
// (the particles' deposit is summed in integers across ranks; a characteristic does not
// depend on which rank traces it).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::kMpiEnv;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;

#ifdef HYBGEN_WITH_MPI

/// A finished run: its directory and summary.
struct RunDir {
  fs::path dir;
  nlohmann::json summary;
};

/// `hybgen run MODEL SETS` into a fresh directory named `name`, on `ranks` MPI ranks (0: the
/// OpenMP runner), writing `outputs`; the run must succeed.
RunDir run_model(const std::string& model, const std::string& sets, const std::string& name,
                 int ranks, const std::string& outputs = "npy") {
  const fs::path dir = hybgen::testing::own_dir(e2e_dir("mpi")) / name;
  fs::remove_all(dir);
  const std::string args = "run " + model + " " + sets + " --set outputs=" + outputs +
                           " -q --out '" + dir.string() + "'" +
                           (ranks > 0 ? " --ranks " + std::to_string(ranks) : std::string());
  const auto r = run_hybgen(args, e2e_dir("mpi") / "cache", kMpiEnv);
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << args << "\n" << r.out;
  return {dir, fs::exists(dir / "summary.json") ? read_json_file(dir / "summary.json")
                                                : nlohmann::json::object()};
}

/// The frames a run wrote (summary "files", or invariant.npy).
std::vector<std::vector<double>> frames(const RunDir& run) {
  std::vector<std::vector<double>> out;
  std::vector<std::string> names;
  if (run.summary.contains("files") && !run.summary.at("files").empty())
    names = run.summary.at("files").get<std::vector<std::string>>();
  else
    names = {"invariant.npy"};
  for (const auto& n : names) out.push_back(hybgen::rt::read_npy((run.dir / n).string()).data);
  return out;
}

/// max |a − b| over every frame, over max |a|.
double relative_difference(const std::vector<std::vector<double>>& a,
                           const std::vector<std::vector<double>>& b) {
  double diff = 0.0, scale = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    for (std::size_t i = 0; i < a[k].size(); ++i) {
      diff = std::max(diff, std::fabs(a[k][i] - b[k][i]));
      scale = std::max(scale, std::fabs(a[k][i]));
    }
  }
  return diff / std::max(scale, 1e-300);
}

/// x as printf's %.17g: every digit, never rounded to 0 (std::to_string prints 1e-12 as 0.000000).
std::string repr(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%.17g", x);
  return b;
}

/// What tests/e2e/compare_run_nc.py says of two run.nc files ("ok" when they hold the same
/// run: to the bit, or to `rtol` of each variable's largest magnitude).
std::string compare_run_nc(const fs::path& a, const fs::path& b, double rtol = 0.0) {
  const std::string python = hybgen::testing::python_with("netCDF4, numpy");
  if (python.empty()) return "no python3 with netCDF4 and numpy (scripts/setup.sh --tests)";
  const auto r = hybgen::testing::run_shell(
      python + " '" + HYBGEN_SOURCE_DIR + "/tests/e2e/compare_run_nc.py' '" + a.string() + "' '" +
      b.string() + "'" + (rtol > 0 ? " --rtol " + repr(rtol) : std::string()) + " 2>&1");
  return r.out;
}

/// Values per frame of the grid: modes × nodes.
std::size_t frame_values(const nlohmann::json& summary) {
  std::size_t n = summary.at("modes").size();
  for (const auto& a : summary.at("grid").at("axes")) n *= a.at("n").get<std::size_t>();
  return n;
}

/// max_k |a[key][k] − b[key][k]| for a budget series.
double series_difference(const nlohmann::json& a, const nlohmann::json& b, const char* key) {
  const auto x = a.at(key).get<std::vector<double>>(), y = b.at(key).get<std::vector<double>>();
  EXPECT_EQ(x.size(), y.size()) << key;
  double d = 0.0;
  for (std::size_t k = 0; k < std::min(x.size(), y.size()); ++k)
    d = std::max(d, std::fabs(x[k] - y[k]));
  return d;
}

/// A model and the settings that keep its runs short.
struct Case {
  const char* name;   ///< Test label.
  const char* model;  ///< Path from the source directory.
  const char* sets;   ///< --set arguments.
};

/// gtest prints a case by its name.
void PrintTo(const Case& c, std::ostream* os) {
  *os << c.name;
}

const Case kCases[] = {
    // 2-D, one mode, |J| = e² ≠ 1 at every impact.
    {"ball", "models/bouncing_ball.model",
     "--set e=0.8 --set grid=61x61 --set t_end=2 --set dt=0.5"},
    // 2-D, two modes, switching across x y = 0.
    {"filippov", "models/filippov.model", "--set grid=41x41 --set t_end=0.5 --set dt=0.25"},
    // 3-D, resets with |J| = 1 − f.
    {"sir3d", "models/sir_3d.model", "--set grid=13x13x13 --set t_end=1 --set dt=0.5"},
    // 5-D, the reduced GL2 system.
    {"gl2", "models/gl2.model", "--set grid=7x7x7x7x7 --set t_end=0.5 --set dt=0.5"},
};

class MpiAgreement : public ::testing::TestWithParam<Case> {};

TEST_P(MpiAgreement, ParticlesAreTheSameBitsOnOneAndTwoRanks) {
  const Case& c = GetParam();
  const std::string sets = std::string(c.sets) + " --set method=particles --set particles=30000";
  // run.nc too: on 2 ranks every rank writes its part of each frame (parallel NetCDF), and
  // the file must be the one-process file, to the bit.
  const RunDir ref =
      run_model(c.model, sets, std::string(c.name) + "_particles_omp", 0, "npy+netcdf");
  for (int ranks : {1, 2}) {
    const RunDir r =
        run_model(c.model, sets, std::string(c.name) + "_particles_" + std::to_string(ranks), ranks,
                  "npy+netcdf");
    EXPECT_EQ(compare_run_nc(ref.dir / "run.nc", r.dir / "run.nc"), "ok\n") << c.name;
    // Each mode's arrays, written in parts by the ranks that hold them.
    if (ref.summary.contains("mode_files")) {
      for (const auto& [mode, files] : ref.summary.at("mode_files").items()) {
        for (const auto& f : files) {
          EXPECT_EQ(hybgen::rt::read_npy((ref.dir / f.get<std::string>()).string()).data,
                    hybgen::rt::read_npy((r.dir / f.get<std::string>()).string()).data)
              << c.name << " " << f;
        }
      }
    }
    // No rank received a frame of the grid: the deposit is summed onto each rank's block.
    if (ranks == 2) {
      EXPECT_LT(r.summary.at("gathered_values_per_rank").get<std::size_t>(),
                frame_values(r.summary))
          << c.name;
    }
    EXPECT_EQ(r.summary.at("ranks").get<int>(), ranks);
    EXPECT_EQ(r.summary.at("backend").get<std::string>(), "mpi");
    const auto a = frames(ref), b = frames(r);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t k = 0; k < a.size(); ++k) EXPECT_EQ(a[k], b[k]) << c.name << " frame " << k;
    for (const char* key : {"mass", "outflow", "atom", "atom_error"})
      EXPECT_EQ(ref.summary[key], r.summary[key]) << c.name << " " << key;
    EXPECT_EQ(ref.summary.at("initial_mass"), r.summary.at("initial_mass"));
    EXPECT_EQ(ref.summary.at("mass_error"), r.summary.at("mass_error"));
  }
}

TEST_P(MpiAgreement, CharacteristicsAreTheSameBitsAndTheBudgetAgrees) {
  const Case& c = GetParam();
  // An observable too: under cell averages its slots ride in the cubature beside the masses.
  const std::string sets = std::string(c.sets) +
                           " --set method=characteristics --set 'observe.first=" +
                           (std::string(c.name) == "gl2"     ? "zeta1"
                            : std::string(c.name) == "sir3d" ? "S"
                                                             : "x") +
                           "'";
  const RunDir ref = run_model(c.model, sets, std::string(c.name) + "_char_omp", 0);
  const double mass0 = ref.summary.at("initial_mass").get<double>();
  for (int ranks : {1, 2}) {
    const RunDir r =
        run_model(c.model, sets, std::string(c.name) + "_char_" + std::to_string(ranks), ranks);
    const auto a = frames(ref), b = frames(r);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t k = 0; k < a.size(); ++k) EXPECT_EQ(a[k], b[k]) << c.name << " frame " << k;
    // The budget's cubature takes the same decisions on the same values; its sums may run
    // over other thread counts (one per rank): rounding.
    for (const char* key : {"mass", "outflow", "atom"})
      EXPECT_LE(series_difference(ref.summary, r.summary, key), 1e-12 * mass0)
          << c.name << " " << key;
    // filippov's focus concentrates the density below its 41² grid's spacing by t = 0.5: its
    // frames are cell averages (values=auto), traced by the ranks together, and every rank
    // keeps its part of the same bits (the frames above); their error estimates too.
    EXPECT_EQ(ref.summary.at("values").at("kind"), r.summary.at("values").at("kind")) << c.name;
    if (std::string(c.name) == "filippov") {
      EXPECT_EQ(r.summary.at("values").at("kind"), "cells");
      EXPECT_EQ(ref.summary.at("values").at("error"), r.summary.at("values").at("error"));
    }
    // The observable's mean: the same bits under cell averages (every rank integrates the
    // whole); from node values a sum over the ranks' parts, so rounding.
    for (const char* key : {"values", "errors"}) {
      const auto x = ref.summary.at("observables").at("first").at(key).get<std::vector<double>>();
      const auto y = r.summary.at("observables").at("first").at(key).get<std::vector<double>>();
      ASSERT_EQ(x.size(), y.size()) << c.name;
      for (std::size_t k = 0; k < x.size(); ++k)
        EXPECT_NEAR(x[k], y[k], 1e-12 * (1.0 + std::fabs(x[k])))
            << c.name << " " << key << " " << k;
    }
  }
}

TEST_P(MpiAgreement, TheTransferOperatorOnPetscMarchesAsTheCsrMatrix) {
  const Case& c = GetParam();
  const std::string sets = std::string(c.sets) + " --set method=transfer";
  const RunDir ref =
      run_model(c.model, sets, std::string(c.name) + "_transfer_omp", 0, "npy+netcdf");
  const double mass0 = ref.summary.at("initial_mass").get<double>();
  for (int ranks : {1, 2}) {
    const RunDir r =
        run_model(c.model, sets, std::string(c.name) + "_transfer_" + std::to_string(ranks), ranks,
                  "npy+netcdf");
    EXPECT_EQ(compare_run_nc(ref.dir / "run.nc", r.dir / "run.nc", 1e-12), "ok\n") << c.name;
    // The frames stay on the ranks that marched them.
    if (ranks == 2) {
      EXPECT_LT(r.summary.at("gathered_values_per_rank").get<std::size_t>(),
                frame_values(r.summary))
          << c.name;
    }
    // The same entries (the same columns, assembled by the same code), summed in another
    // order by another mat-vec: rounding.
    EXPECT_EQ(ref.summary.at("transfer").at("nonzeros"), r.summary.at("transfer").at("nonzeros"));
    EXPECT_LE(relative_difference(frames(ref), frames(r)), 1e-12) << c.name;
    for (const char* key : {"mass", "outflow", "atom"})
      EXPECT_LE(series_difference(ref.summary, r.summary, key), 1e-12 * mass0)
          << c.name << " " << key;
    EXPECT_LE(r.summary.at("transfer").at("budget_defect").get<double>(), 1e-12);
  }
}

TEST_P(MpiAgreement, SlepcFindsTheInvariantDensityThatSpectraFinds) {
  const Case& c = GetParam();
  // The sampled operator (scheme=hat): SLEPc against Spectra on the same matrix.
  const std::string sets = std::string(c.sets) + " --set method=invariant --set scheme=hat";
  const RunDir ref = run_model(c.model, sets, std::string(c.name) + "_inv_omp", 0);
  const auto& a = ref.summary.at("invariant");
  for (int ranks : {1, 2}) {
    const RunDir r =
        run_model(c.model, sets, std::string(c.name) + "_inv_" + std::to_string(ranks), ranks);
    const auto& b = r.summary.at("invariant");
    if (ranks == 2) {
      EXPECT_NE(b.at("solver").get<std::string>().find("slepc"), std::string::npos);
    }
    EXPECT_TRUE(b.at("converged").get<bool>()) << c.name;
    // The Perron root is the spectral radius: both solvers must find it, to their
    // tolerance (1e-10 on the Ritz values).
    const double l1 = a.at("eigenvalues").at(0).at("re").get<double>();
    EXPECT_NEAR(b.at("eigenvalues").at(0).at("re").get<double>(), l1, 1e-9) << c.name;
    // Its eigenvector is the density only when λ₁ is simple; with a multiple λ₁ (a
    // conservative flow has one invariant density per conserved quantity) any non-negative
    // vector of its eigenspace is one, and the solvers may pick different ones: then each
    // must be an eigenvector (residual) and a density (≥ 0, unit mass by construction).
    const double gap = a.at("spectral_gap").get<double>();
    if (gap > 1e-3) {
      EXPECT_LE(relative_difference(frames(ref), frames(r)), 1e-7) << c.name << " gap " << gap;
    } else {
      EXPECT_LE(b.at("residual").get<double>(), 1e-8) << c.name;
      const auto u = frames(r).front();
      const double top = *std::max_element(u.begin(), u.end());
      EXPECT_GE(b.at("min_value").get<double>(), -1e-6 * top) << c.name;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Models, MpiAgreement, ::testing::ValuesIn(kCases),
                         [](const ::testing::TestParamInfo<Case>& p) {
                           return std::string(p.param.name);
                         });

TEST(Mpi, AFailureIsFoundOnceWhicheverRankHitIt) {
  // An event cap of 1 fails the ball's characteristics at many nodes, on both ranks; the
  // run names the one of the smallest index, as the one-process runner does, exit 3, once.
  const std::string sets = "--set method=characteristics --set max_events=1 --set t_end=4";
  std::string messages[2];
  for (int ranks : {0, 2}) {
    const fs::path dir = e2e_dir("mpi") / ("fail_" + std::to_string(ranks));
    const auto r = run_hybgen("run models/bouncing_ball.model " + sets + " -q --out '" +
                                  dir.string() + "'" + (ranks ? " --ranks 2" : ""),
                              e2e_dir("mpi") / "cache", kMpiEnv);
    EXPECT_EQ(r.code, exit_status(ExitCode::Numerical)) << r.out;
    const auto at = r.out.find("hybgen: numerical failure:");
    ASSERT_NE(at, std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("hybgen: numerical failure:", at + 1), std::string::npos) << r.out;
    messages[ranks ? 1 : 0] = r.out.substr(at, r.out.find('\n', at) - at);
    EXPECT_FALSE(fs::exists(dir)) << "a failed run left " << dir;
  }
  EXPECT_EQ(messages[0], messages[1]);
}

TEST(Mpi, TwoRanksDrawThePicturesOfTheOneProcessRun) {
  // The pictures of a distributed run come from the 2-D marginals of the figure pairs, each
  // summed from every rank's part; the guards from every rank's nodes. The same files as
  // one process, every frame's picture the same size, and a report that links them.
  for (const Case& c : {kCases[1], kCases[3]}) {
    const std::string sets = std::string(c.sets) + " --set method=particles --set particles=20000";
    const RunDir ref =
        run_model(c.model, sets, std::string(c.name) + "_pictures_omp", 0, "png+html");
    const RunDir r = run_model(c.model, sets, std::string(c.name) + "_pictures_2", 2, "png+html");
    ASSERT_EQ(ref.summary.at("outputs"), r.summary.at("outputs")) << c.name;
    for (const auto& f : ref.summary.at("outputs").at("figures")) {
      const fs::path a = ref.dir / f.get<std::string>(), b = r.dir / f.get<std::string>();
      ASSERT_TRUE(fs::exists(b)) << b;
      // Frames and the budget: a PNG of the same width and height (bytes 16-23 of IHDR).
      std::ifstream fa(a, std::ios::binary), fb(b, std::ios::binary);
      std::string ha(24, '\0'), hb(24, '\0');
      fa.read(ha.data(), 24);
      fb.read(hb.data(), 24);
      EXPECT_EQ(ha, hb) << f;
    }
    EXPECT_TRUE(fs::exists(r.dir / "report.html")) << c.name;
  }
}

TEST(Mpi, TwoRanksDepositTheSameMarginalBits) {
  // density=marginals (the particles keep the marginal of every pair of axes and the moments,
  // not the grid: how models/gl3.model's ten dimensions run) on the 5-D GL2 system: each of
  // the ten pairs' marginals, the mean and the covariance are the one-process bits on two ranks.
  const std::string sets =
      "--set method=particles --set density=marginals --set particles=20000 --set t_end=0.5 "
      "--set dt=0.25 --set grid=7x7x7x7x7";
  const RunDir ref = run_model("models/gl2.model", sets, "gl2_marginals_omp", 0, "netcdf");
  const RunDir two = run_model("models/gl2.model", sets, "gl2_marginals_2", 2, "netcdf");
  EXPECT_EQ(compare_run_nc(ref.dir / "run.nc", two.dir / "run.nc"), "ok\n");
  EXPECT_EQ(ref.summary.at("mass"), two.summary.at("mass"));
  EXPECT_EQ(two.summary.at("ranks").get<int>(), 2);
  // What was compared: a marginal per pair of the five axes.
  const std::string python = hybgen::testing::python_with("netCDF4");
  ASSERT_FALSE(python.empty()) << "no python3 with netCDF4 (scripts/setup.sh --tests)";
  const auto pairs = hybgen::testing::run_shell(
      python + " -c \"import netCDF4; d = netCDF4.Dataset('" + (two.dir / "run.nc").string() +
      "'); print(sum(v.startswith('marginal_') for v in d.variables))\"");
  EXPECT_EQ(pairs.out, "10\n");
}

TEST(Mpi, AFrameLargerThanAChunkIsWrittenInSlabsByEveryRank) {
  // 129³ nodes = 2 146 689 > 2²¹: the density is stored in chunks of 126 slices of the first
  // axis (hyperslab.hpp, c_order_chunk), and each rank's block ends inside a chunk, so both
  // ranks write parts of one compressed chunk. The file must still be the one-process file.
  const std::string sets =
      "--set grid=129x129x129 --set t_end=0.5 --set dt=0.5 --set method=particles "
      "--set particles=20000";
  const RunDir ref = run_model("models/sir_3d.model", sets, "chunks_omp", 0, "netcdf");
  const RunDir r = run_model("models/sir_3d.model", sets, "chunks_2", 2, "netcdf");
  EXPECT_EQ(compare_run_nc(ref.dir / "run.nc", r.dir / "run.nc"), "ok\n");
  const std::string python = hybgen::testing::python_with("netCDF4");
  ASSERT_FALSE(python.empty()) << "no python3 with netCDF4 (scripts/setup.sh --tests)";
  const auto chunks =
      hybgen::testing::run_shell(python + " -c \"import netCDF4; print(netCDF4.Dataset('" +
                                 (r.dir / "run.nc").string() + "')['density'].chunking())\" 2>&1");
  EXPECT_EQ(chunks.out, "[1, 126, 129, 129]\n");
}

TEST(Mpi, VtiOverSeveralRanksIsRefusedWithTheWayOut) {
  const fs::path dir = e2e_dir("mpi") / "vti";
  const auto r = run_hybgen(
      "run models/bouncing_ball.model --set grid=21x21 --set t_end=1 --set outputs=vti "
      "--ranks 2 -q --out '" +
          dir.string() + "'",
      e2e_dir("mpi") / "cache", kMpiEnv);
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("run.nc has the same arrays"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir));
}

TEST(Mpi, AMissingLauncherIsAClearError) {
  const auto r = run_hybgen("run models/bouncing_ball.model --ranks 2 -q --out '" +
                                (e2e_dir("mpi") / "nolauncher").string() + "'",
                            e2e_dir("mpi") / "cache", "HYBGEN_MPIEXEC=no-such-mpiexec");
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("the MPI launcher 'no-such-mpiexec' is not on PATH"), std::string::npos)
      << r.out;
}

#else

TEST(Mpi, WithoutTheBackendRanksAreABuildErrorThatSaysWhatToInstall) {
  const auto r = run_hybgen("run models/bouncing_ball.model --ranks 2 -q --out '" +
                                (e2e_dir("mpi") / "none").string() + "'",
                            e2e_dir("mpi") / "cache");
  EXPECT_EQ(r.code, exit_status(ExitCode::BuildFailed)) << r.out;
  EXPECT_NE(r.out.find("scripts/setup.sh --mpi"), std::string::npos) << r.out;
}

#endif

TEST(Mpi, RanksWithoutTheMpiBackendAreRefused) {
  const auto r = run_hybgen("run models/bouncing_ball.model --set ranks=2 -q --out '" +
                                (e2e_dir("mpi") / "refused").string() + "'",
                            e2e_dir("mpi") / "cache");
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("needs backend=mpi"), std::string::npos) << r.out;
}

}  // namespace
