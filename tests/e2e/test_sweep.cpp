// End to end: `hybgen sweep` (generator/src/sweep.cpp). One runner for every point, the
// table against separate runs and against closed forms of a model hybgen does not ship, a
// point that fails, a value refused before anything runs, and an interrupted sweep.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "hybgen/gen/fs.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;
using hybgen::testing::write_model_file;
using nlohmann::json;

const fs::path kWork = e2e_dir("e2e_sweep");

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

std::size_t lines(const fs::path& p) {
  std::ifstream in(p);
  std::size_t n = 0;
  for (std::string l; std::getline(in, l);) ++n;
  return n;
}

/// `hybgen COMMAND models/bouncing_ball.model SETS --out OUT` into a fresh OUT.
hybgen::testing::ShellResult run_ball(const std::string& command, const std::string& sets,
                                      const fs::path& out, const fs::path& cache) {
  fs::remove_all(out);
  return run_hybgen(
      command + " models/bouncing_ball.model " + sets + " --out '" + out.string() + "'", cache);
}

TEST(Sweep, SixValuesOfEShareOneRunner) {
  // The issue's case: 6 values of e; the first point's build compiles (a private cache), no
  // other compile happens, and each row is what `hybgen run` gives for that value.
  const fs::path cache = kWork / "cache_six";
  const fs::path out = hybgen::testing::own_dir(kWork) / "six";
  fs::remove_all(cache);
  fs::remove_all(out);
  const auto r = run_hybgen(
      "sweep models/bouncing_ball.model --set e=0.5:1.0:6 --set grid=21x21 "
      "--set t_end=2 --set dt=0.5 --set outputs=netcdf+npy --out '" +
          out.string() + "'",
      cache);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_EQ(count(r.out, "runner (built in"), 1u) << r.out;
  EXPECT_EQ(count(r.out, ": ok"), 6u) << r.out;
  std::size_t entries = 0;
  for (const auto& e : fs::directory_iterator(cache)) entries += e.is_directory() ? 1 : 0;
  EXPECT_EQ(entries, 1u);

  const json table = read_json_file(out / "sweep.json");
  EXPECT_EQ(table["model"], "bouncing_ball");
  ASSERT_EQ(table["rows"].size(), 6u);
  EXPECT_EQ(lines(out / "sweep.csv"), 7u);  // header + 6 rows
  for (std::size_t i = 0; i < 6; ++i) {
    const json& row = table["rows"][i];
    const double e = 0.5 + 0.1 * static_cast<double>(i);
    EXPECT_NEAR(row["e"].get<double>(), e, 1e-15) << i;
    EXPECT_EQ(row["status"], "ok") << i;
    EXPECT_EQ(row["t"], 2.0);
    // The point's own outputs, run with that value.
    const json s = read_json_file(out / row["dir"].get<std::string>() / "summary.json");
    EXPECT_EQ(s["parameters"]["e"], row["e"]) << i;
    EXPECT_EQ(s["mass"].back(), row["mass"]) << i;
    EXPECT_TRUE(fs::exists(out / row["dir"].get<std::string>() / "u_0004.npy")) << i;
  }
  // Energy is lost at every bounce for e < 1, so mass collects in the Zeno atom as e falls:
  // the atom column decreases along the sweep and is zero at e = 1 (no atom without loss).
  for (std::size_t i = 1; i < 6; ++i)
    EXPECT_LE(table["rows"][i]["atom"].get<double>(), table["rows"][i - 1]["atom"].get<double>())
        << i;
  EXPECT_EQ(table["rows"][5]["atom"].get<double>(), 0.0);

  // A separate run of one value: the same runner (cached) and the same numbers.
  const fs::path one = hybgen::testing::own_dir(kWork) / "six_one";
  const auto single =
      run_ball("run", "--set e=0.7 --set grid=21x21 --set t_end=2 --set dt=0.5", one, cache);
  ASSERT_EQ(single.code, exit_status(ExitCode::Success)) << single.out;
  EXPECT_NE(single.out.find("runner (cached)"), std::string::npos) << single.out;
  const json s = read_json_file(one / "summary.json");
  const json& row = table["rows"][2];
  for (const char* k : {"mass", "outflow", "atom"})
    EXPECT_NEAR(s[k].back().get<double>(), row[k].get<double>(),
                1e-12 * (1 + std::fabs(row[k].get<double>())))
        << k;
}

// x' = k on [0, 1] with a Gaussian bump u0 = exp(-((x - c)/w)^2): every particle moves by kT,
// so by t = T the mass that started in [1 - kT, 1] has left through x = 1 and nothing came in
// through x = 0 (u0 is below e^-36 there). With E(a, b) = w·√π/2·(erf((b-c)/w) - erf((a-c)/w)),
// the integral of u0 over [a, b]:
//   initial mass = E(0, 1),  outflow(T) = E(1 - kT, 1),  mass(T) = E(0, 1 - kT).
constexpr double kC = 0.3, kW = 0.05;
double bump_integral(double a, double b) {
  return kW * std::sqrt(M_PI) / 2 * (std::erf((b - kC) / kW) - std::erf((a - kC) / kW));
}

TEST(Sweep, AWarningSaysWhichPointItIsAboutAndCountsInTheTable) {
  // The ball with e = 0.5 on a coarse grid by t = 6 concentrates below the grid's spacing (the
  // output stage warns); e = 1 does not. The warning names its point on stderr, the point's
  // progress line says it has one, and its row counts it.
  const fs::path out = hybgen::testing::own_dir(kWork) / "warned";
  const auto r =
      run_ball("sweep",
               "--set e=0.5,1 --set grid=21x21 --set t_end=6 --set dt=2 --set outputs=npy "
               "--set values=nodes",
               out, kWork / "cache");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_NE(r.out.find("hybgen: warning: [0_e=0.5] the grid under-resolves the density"),
            std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("hybgen: warning: the grid"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0_e=0.5: ok, with 1 warning (above, marked [0_e=0.5]; column warnings)"),
            std::string::npos)
      << r.out;
  const json table = read_json_file(out / "sweep.json");
  ASSERT_EQ(table["rows"].size(), 2u);
  EXPECT_EQ(table["rows"][0]["warnings"], 1) << table.dump();
  EXPECT_EQ(table["rows"][1]["warnings"], 0) << table.dump();
  const json s = read_json_file(out / "0_e=0.5" / "summary.json");
  ASSERT_TRUE(s.contains("output_warnings")) << s.dump();
  EXPECT_NE(s["output_warnings"][0].get<std::string>().find("under-resolves"), std::string::npos);
}

TEST(Sweep, TableAgreesWithTheClosedFormsOfADrift) {
  const std::string model = write_model_file(kWork, "drift.model", R"(model drift
state x
parameter k = 0.5
mode go {
  x' = k
}
simulation {
  domain x in [0, 1]
  grid 201
  initial exp(-((x - 0.3)/0.05)^2)
  t_end 1
  dt 0.5
}
)");
  const fs::path out = hybgen::testing::own_dir(kWork) / "drift";
  fs::remove_all(out);
  // 1 - kT = 0.5, 0.4, 0.3, 0.2, 0.1: none, a tail, half, nearly all and all of the bump out.
  const auto r =
      run_hybgen("sweep '" + model + "' --set k=0.5:0.9:5 --jobs 2 --out '" + out.string() + "'",
                 kWork / "cache_drift");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const json table = read_json_file(out / "sweep.json");
  ASSERT_EQ(table["rows"].size(), 5u);
  for (const json& row : table["rows"]) {
    const double k = row["k"].get<double>(), edge = 1 - k * 1.0;
    const double mass0 = bump_integral(0, 1), outflow = bump_integral(edge, 1),
                 mass = bump_integral(0, edge);
    std::printf(
        "[ sweep ] k = %.1f: mass %.9f (exact %.9f +/- %.1e), outflow %.9f (exact %.9f "
        "+/- %.1e)\n",
        k, row["mass"].get<double>(), mass, row["mass_error"].get<double>(),
        row["outflow"].get<double>(), outflow, row["outflow_error"].get<double>());
    // The initial mass on the grid by the budget's cubature (fast: measured 5e-5 relative).
    EXPECT_NEAR(row["initial_mass"].get<double>(), mass0, 1e-3 * mass0) << k;
    // The error bars the table reports cover the error, and the error is small.
    EXPECT_LE(std::fabs(row["mass"].get<double>() - mass), row["mass_error"].get<double>() + 1e-9)
        << k;
    EXPECT_LE(std::fabs(row["outflow"].get<double>() - outflow),
              row["outflow_error"].get<double>() + 1e-9)
        << k;
    EXPECT_LT(std::fabs(row["mass"].get<double>() - mass), 1e-3 * mass0) << k;
    EXPECT_LT(std::fabs(row["outflow"].get<double>() - outflow), 1e-3 * mass0) << k;
  }
}

TEST(Sweep, AFailedPointKeepsItsRowAndTheExitCode) {
  // k = 0 makes the flow 1/k infinite: that point's runner stops with a numerical failure
  // (exit 3) at its pre-flight scan; the other point runs, the table says which failed, and
  // the sweep exits 3.
  const std::string model = write_model_file(kWork, "inverse_speed.model", R"(model inverse_speed
state x
parameter k = 1
mode go {
  x' = 1/k
}
simulation {
  domain x in [0, 1]
  grid 41
  initial exp(-((x - 0.3)/0.1)^2)
  t_end 0.2
  dt 0.1
}
)");
  const fs::path out = hybgen::testing::own_dir(kWork) / "failed";
  fs::remove_all(out);
  const auto r = run_hybgen("sweep '" + model + "' --set k=1,0 --out '" + out.string() + "'",
                            kWork / "cache_failed");
  EXPECT_EQ(r.code, exit_status(ExitCode::Numerical)) << r.out;
  EXPECT_NE(r.out.find("1 failed"), std::string::npos) << r.out;
  const json table = read_json_file(out / "sweep.json");
  ASSERT_EQ(table["rows"].size(), 2u);
  EXPECT_EQ(table["rows"][0]["status"], "ok");
  EXPECT_TRUE(fs::exists(out / table["rows"][0]["dir"].get<std::string>() / "summary.json"));
  EXPECT_EQ(table["rows"][1]["status"], "failed");
  EXPECT_EQ(table["rows"][1]["exit"], exit_status(ExitCode::Numerical));
  EXPECT_FALSE(table["rows"][1].contains("mass"));
  EXPECT_FALSE(fs::exists(out / table["rows"][1]["dir"].get<std::string>()));  // half-written
}

TEST(Sweep, AValueTheModelRefusesStopsItBeforeAnythingRuns) {
  const fs::path out = hybgen::testing::own_dir(kWork) / "refused";
  fs::remove_all(out);
  const auto r =
      run_hybgen("sweep models/bouncing_ball.model --set tol=1e-6,0.5 --out '" + out.string() + "'",
                 kWork / "cache_refused");
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("sweep point 1_tol=0.5"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("tol"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(kWork / "cache_refused"));  // not even a build

  const auto bad =
      run_hybgen("sweep models/bouncing_ball.model --set e=0.5:1", kWork / "cache_refused");
  EXPECT_EQ(bad.code, exit_status(ExitCode::UsageError)) << bad.out;
  EXPECT_NE(bad.out.find("A:B:N"), std::string::npos) << bad.out;
}

TEST(Sweep, AnInterruptedSweepLeavesTheEarlierOutputsAsTheyWere) {
  // A first sweep's outputs, then a long sweep stopped by SIGTERM while its runners run:
  // hybgen stops them, removes its staging directory, leaves OUT as it was and ends by the
  // signal. (SIGTERM: a shell's background job ignores SIGINT.)
  const fs::path cache = kWork / "cache_interrupt";
  const fs::path out = hybgen::testing::own_dir(kWork) / "interrupted";
  fs::remove_all(out);
  const auto first = run_hybgen(
      "sweep models/bouncing_ball.model --set e=0.8,0.9 --set grid=11x11 "
      "--set t_end=1 --out '" +
          out.string() + "'",
      cache);
  ASSERT_EQ(first.code, exit_status(ExitCode::Success)) << first.out;
  const std::string before = hybgen::gen::read_file((out / "sweep.csv").string());
  // Stopped once its runners run (their configurations are in the staging directory), not
  // after a fixed delay: on a loaded machine the derivation and build can take seconds.
  const std::string staging_glob =
      (hybgen::testing::own_dir(kWork) / "interrupted.partial-").string() + "*/*/config.json";
  const std::string cmd =
      "cd '" + hybgen::testing::hybgen_source_dir() + "' && HYBGEN_CACHE='" + cache.string() +
      "' '" + hybgen::testing::hybgen_exe() +
      "' sweep models/bouncing_ball.model --set e=0.8,0.9 --set method=particles "
      "--set particles=1e7 --set t_end=5 --out '" +
      out.string() + "' 2>&1 & pid=$!; for i in $(seq 600); do ls " + staging_glob +
      " >/dev/null 2>&1 && break; sleep 0.05; done; sleep 0.5; start=$(date +%s); "
      "kill -TERM $pid; wait $pid; echo \"rc=$?\"; echo \"took=$(( $(date +%s) - start ))\"";
  const auto r = hybgen::testing::run_shell(cmd);
  EXPECT_NE(r.out.find("interrupted by signal 15"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("rc=143"), std::string::npos) << r.out;  // 128 + SIGTERM
  // The runners were stopped, not waited out (each has about 10 s of particles to push).
  const auto took = r.out.find("took=");
  ASSERT_NE(took, std::string::npos) << r.out;
  EXPECT_LE(std::stoi(r.out.substr(took + 5)), 3) << r.out;
  EXPECT_EQ(hybgen::gen::read_file((out / "sweep.csv").string()), before);
  for (const auto& e : fs::directory_iterator(kWork)) {
    const std::string n = e.path().filename().string();
    EXPECT_EQ(n.find("interrupted.partial-"), std::string::npos) << n;
    EXPECT_EQ(n.find("interrupted.old-"), std::string::npos) << n;
  }
}

TEST(Sweep, TheThreadCountDoesNotChangeTheDensities) {
  // The setting `threads` (settings.hpp), swept: the characteristics densities (one
  // characteristic per node) and the particles' histograms (counter-based streams, one per
  // particle) are bit-identical on 1 and 2 threads.
  const fs::path out = hybgen::testing::own_dir(kWork) / "threads";
  fs::remove_all(out);
  const auto r = run_hybgen(
      "sweep models/bouncing_ball.model --set method=characteristics,particles "
      "--set threads=1,2 --set particles=20000 --set grid=21x21 --set t_end=2 "
      "--set dt=1 --set outputs=npy --jobs 1 --out '" +
          out.string() + "'",
      kWork / "cache_threads");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const json table = read_json_file(out / "sweep.json");
  ASSERT_EQ(table["rows"].size(), 4u);  // (characteristics, 1), (characteristics, 2), ...
  for (std::size_t m = 0; m < 2; ++m) {
    const std::string one = table["rows"][2 * m]["dir"], two = table["rows"][2 * m + 1]["dir"];
    EXPECT_EQ(table["rows"][2 * m]["threads"], 1.0);
    EXPECT_EQ(table["rows"][2 * m + 1]["threads"], 2.0);
    // The runs had the threads they were given (summary.json records them).
    EXPECT_EQ(read_json_file(out / one / "summary.json")["threads"], 1);
    EXPECT_EQ(read_json_file(out / two / "summary.json")["threads"], 2);
    for (const char* frame : {"u_0001.npy", "u_0002.npy"}) {
      const auto a = hybgen::rt::read_npy((out / one / frame).string());
      const auto b = hybgen::rt::read_npy((out / two / frame).string());
      ASSERT_EQ(a.data.size(), b.data.size());
      double peak = 0;
      for (double v : a.data) peak = std::max(peak, v);
      EXPECT_GT(peak, 0.1) << one;
      EXPECT_EQ(a.data, b.data) << one << " vs " << two << ", " << frame;
    }
  }
}

}  // namespace
