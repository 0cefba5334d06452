// End to end: the Lie-group models through the `hybgen` executable — check,
// derive (text, json with its `reduction` block, --unreduced), the rejected
// models (exit 1 naming the hypothesis), and runs on tiny grids, the 2-D
// matrix-groups system against its closed-form density.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "hybgen/gen/fs.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::read_json_file;
using nlohmann::json;

const fs::path kWork = e2e_dir("e2e_lie");

using Result = hybgen::testing::ShellResult;  // out: stdout (+ stderr where merged)

/// hybgen from the source directory with this test's own cache (support/e2e.hpp).
const hybgen::testing::Hybgen hybgen{kWork / "cache"};

TEST(LieCli, CheckShippedLieModels) {
  for (const char* m :
       {"gl2", "gl3", "matrix_groups_impacts", "heisenberg", "heisenberg_algebra", "chaplygin"}) {
    const Result r = hybgen(std::string("check models/") + m + ".model");
    EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << m << "\n" << r.out;
    EXPECT_NE(r.out.find(": ok: model '" + std::string(m) + "'"), std::string::npos) << r.out;
  }
}

TEST(LieCli, RejectedModelsNameTheHypothesis) {
  const Result so3 = hybgen("check models/so3_rigid_body.model");
  EXPECT_EQ(so3.code, exit_status(ExitCode::ModelError)) << so3.out;
  EXPECT_EQ(so3.out.rfind("models/so3_rigid_body.model:12:1: error: hypothesis 'codim1' fails", 0),
            0u)
      << so3.out;
  const Result aff = hybgen("check models/aff1.model");
  EXPECT_EQ(aff.code, exit_status(ExitCode::ModelError)) << aff.out;
  EXPECT_EQ(aff.out.rfind("models/aff1.model:12:1: error: hypothesis 'normal' fails", 0), 0u)
      << aff.out;
  EXPECT_NE(aff.out.find("[E_b, E_a] = -E_b"), std::string::npos) << aff.out;
  EXPECT_NE(aff.out.find("^"), std::string::npos) << aff.out;  // caret under the statement
}

TEST(LieCli, DeriveJsonHasTheReductionBlock) {
  const Result r = hybgen.stdout_only("derive models/gl2.model --format json");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["model"], "gl2");
  EXPECT_EQ(j["kind"], "lie");
  EXPECT_EQ(j["state"], json({"zeta1", "zeta2", "zeta3", "zeta4", "q"}));
  const json& red = j["reduction"];
  ASSERT_TRUE(red.is_object());
  EXPECT_EQ(red["algebra_dim"], 4);
  EXPECT_EQ(red["momenta"], json({"zeta1", "zeta2", "zeta3", "zeta4"}));
  EXPECT_EQ(red["q"], "q");
  ASSERT_EQ(red["bracket"].size(), 4u);
  // [E12, E21] = E11 − E22 (matrix commutator of elementary matrices).
  EXPECT_EQ(red["bracket"][1][2], "E11 - E22");
  EXPECT_EQ(red["bracket"][2][1], "-E11 + E22");
  ASSERT_EQ(red["coadjoint"].size(), 4u);
  ASSERT_EQ(red["coadjoint"][0].size(), 4u);
  // Row 1 of ad*_{∂h/∂ζ} (column-vector convention): (0, −ζ2, ζ3, 0), the
  // transpose of the paper's row-vector matrix (erratum E2 of test_lie.cpp).
  EXPECT_EQ(red["coadjoint"][0], json({"0", "-zeta2", "zeta3", "0"}));
  EXPECT_EQ(
      red["hypotheses"],
      json({{"normal", true}, {"codim1", true}, {"left_invariant", true}, {"transversal", true}}));
  EXPECT_EQ(red["q_equation"], "(q+1)*(zeta1+zeta4)");  // factored; = (q + 1) tr ζ
  EXPECT_EQ(red["homomorphism"], "multiplicative");
  ASSERT_EQ(j["modes"].size(), 1u);
  EXPECT_EQ(j["modes"][0]["divergence"], "zeta1+zeta4");
  ASSERT_EQ(j["guards"].size(), 1u);
  EXPECT_EQ(j["guards"][0]["hybrid_jacobian"], "e^2");  // +1 for e = 1; the paper prints −1
  // General models keep "kind": "hybrid" and a null reduction.
  const Result g = hybgen.stdout_only("derive models/matrix_groups_impacts.model --format json");
  ASSERT_EQ(g.code, exit_status(ExitCode::Success));
  const json jg = json::parse(g.out);
  EXPECT_EQ(jg["kind"], "hybrid");
  EXPECT_TRUE(jg["reduction"].is_null());
}

TEST(LieCli, DeriveTextAndLatexShowTheReduction) {
  const Result t = hybgen("derive models/gl2.model");
  ASSERT_EQ(t.code, exit_status(ExitCode::Success)) << t.out;
  for (const char* part :
       {"Lie-group reduction", "ad*_{dh}", "[0, -zeta2, zeta3, 0]",
        "q'           = (q+1)*(zeta1+zeta4)", "Delta zeta",
        "hypotheses   normal: yes, codim1: yes, left_invariant: yes, transversal: yes",
        "hybrid Frobenius-Perron PDE"})
    EXPECT_NE(t.out.find(part), std::string::npos) << part << "\n" << t.out;
  const Result l = hybgen("derive models/gl2.model --format latex");
  ASSERT_EQ(l.code, exit_status(ExitCode::Success)) << l.out;
  EXPECT_NE(l.out.find("\\mathrm{ad}^*_{\\partial h/\\partial\\zeta} &= \\begin{pmatrix}"),
            std::string::npos)
      << l.out;
  EXPECT_NE(l.out.find("\\Delta\\zeta_{"), std::string::npos) << l.out;
  // A group given by structure constants has no coordinates and no formula for φ.
  const Result a = hybgen("derive models/heisenberg_algebra.model");
  ASSERT_EQ(a.code, exit_status(ExitCode::Success)) << a.out;
  for (const char* part :
       {"H3, given by structure constants on the basis (E_x, E_y, E_z)", "[E_x, E_y] = E_z",
        "q            = phi(g)  (a homomorphism to R or "
        "S^1, given by dphi_e)",
        "dphi_e = (1, 0, 0)", "q'           = zeta_x"})
    EXPECT_NE(a.out.find(part), std::string::npos) << part << "\n" << a.out;
}

TEST(LieCli, Gl3DerivesWithinFiveSeconds) {
  const auto t0 = std::chrono::steady_clock::now();
  const Result r = hybgen.stdout_only("derive models/gl3.model --format json");
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("[ hybgen derive models/gl3.model ] %.3f s\n", secs);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_LT(secs, 5.0);
  const json j = json::parse(r.out);
  EXPECT_EQ(j["reduction"]["algebra_dim"], 9);
  EXPECT_EQ(j["state"].size(), 10u);
  // Its run (particles keeping marginals: 10-D) is tests/e2e/test_gl3.cpp.
}

TEST(LieCli, UnreducedTwin) {
  const Result r = hybgen.stdout_only("derive models/gl2.model --unreduced --format json");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["model"], "gl2_unreduced");
  EXPECT_EQ(j["kind"], "hybrid");
  EXPECT_EQ(j["state"].size(), 8u);
  EXPECT_EQ(j["guards"][0]["surface"], "a11*a22-a12*a21-1");
  EXPECT_EQ(hybgen("check models/gl2.model --unreduced").code, exit_status(ExitCode::Success));
  // The constrained (nonholonomic) twin: the Chaplygin sleigh on TG, state
  // (c, ċ), its resets explicit (impulsive Lagrange–d'Alembert).
  const Result c = hybgen.stdout_only("derive --unreduced models/chaplygin.model --format json");
  ASSERT_EQ(c.code, exit_status(ExitCode::Success)) << c.out;
  const json jc = json::parse(c.out);
  EXPECT_EQ(jc["model"], "chaplygin_unreduced");
  EXPECT_EQ(jc["state"].size(), 6u);
  EXPECT_EQ(jc["guards"].size(), 2u);
  EXPECT_EQ(jc["guards"][0]["surface"], "th-theta0");
  EXPECT_EQ(hybgen("check models/chaplygin.model --unreduced").code,
            exit_status(ExitCode::Success));
  // --unreduced on a general model is a usage error.
  const Result bad = hybgen("check models/bouncing_ball.model --unreduced");
  EXPECT_EQ(bad.code, exit_status(ExitCode::UsageError)) << bad.out;
}

/// Run a shipped model into a fresh directory; return its summary.
json run(const std::string& model, const std::string& tag, const std::string& sets) {
  const fs::path out = hybgen::testing::own_dir(kWork) / "runs" / tag;
  fs::remove_all(out);
  const Result r =
      hybgen("run models/" + model + ".model --quiet --out '" + out.string() + "' " + sets +
             " --set outputs=netcdf+png+npy");  // run.nc, pictures and the .npy frames read here
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  return read_json_file(out / "summary.json");
}

TEST(LieCli, RunGl2OnATinyGrid) {
  const json s = run("gl2", "gl2", "--set grid=5x5x5x5x5 --set t_end=0.5 --set dt=0.5");
  ASSERT_EQ(s["grid"]["axes"].size(), 5u);
  EXPECT_EQ(s["grid"]["axes"][4]["name"], "q");
  ASSERT_EQ(s["times"].size(), 2u);
  const auto arr = hybgen::rt::read_npy(
      (hybgen::testing::own_dir(kWork) / "runs" / "gl2" / s["files"][1].get<std::string>())
          .string());
  EXPECT_EQ(arr.shape, (std::vector<std::size_t>{5, 5, 5, 5, 5}));
  for (double v : arr.data) EXPECT_TRUE(std::isfinite(v) && v >= 0);
}

TEST(LieCli, RunHeisenbergOnATinyGrid) {
  // A group the paper does not treat: 4-D reduced state, two walls.
  const json s = run("heisenberg", "heisenberg", "--set grid=7x7x7x7 --set t_end=1 --set dt=0.5");
  ASSERT_EQ(s["grid"]["axes"].size(), 4u);
  ASSERT_EQ(s["times"].size(), 3u);
  for (const auto& f : s["files"]) {
    const auto arr = hybgen::rt::read_npy(
        (hybgen::testing::own_dir(kWork) / "runs" / "heisenberg" / f.get<std::string>()).string());
    EXPECT_EQ(arr.shape, (std::vector<std::size_t>{7, 7, 7, 7}));
    for (double v : arr.data) EXPECT_TRUE(std::isfinite(v) && v >= 0);
  }
  // div X = 0 and J = 1 (e = 1): the density is transported, so its maximum
  // over the grid cannot exceed the initial maximum (1 at the grid's nodes).
  const auto last = hybgen::rt::read_npy(
      (hybgen::testing::own_dir(kWork) / "runs" / "heisenberg" / s["files"][2].get<std::string>())
          .string());
  for (double v : last.data) EXPECT_LE(v, 1.0 + 1e-9);
}

// H3 given by its structure constants ([E_x, E_y] = E_z, no coordinates) is the same
// reduced system as heisenberg.model's parametrised group: the densities agree.
TEST(LieCli, RunHeisenbergByStructureConstantsLikeTheParametrisedGroup) {
  const std::string sets = "--set grid=7x7x7x7 --set t_end=1 --set dt=0.5";
  const json a = run("heisenberg_algebra", "heisenberg_algebra", sets);
  const json b = run("heisenberg", "heisenberg_b", sets);
  ASSERT_EQ(a["times"].size(), 3u);
  ASSERT_EQ(a["files"], b["files"]);
  for (const auto& f : a["files"]) {
    const auto ua = hybgen::rt::read_npy(
        (hybgen::testing::own_dir(kWork) / "runs" / "heisenberg_algebra" / f.get<std::string>())
            .string());
    const auto ub = hybgen::rt::read_npy(
        (hybgen::testing::own_dir(kWork) / "runs" / "heisenberg_b" / f.get<std::string>())
            .string());
    ASSERT_EQ(ua.shape, ub.shape);
    ASSERT_EQ(ua.data.size(), ub.data.size());
    // The same flow, resets and J derived by two routes; the kernels may differ only in the
    // order of floating-point operations: agreement to the ODE tolerance's scale.
    for (std::size_t i = 0; i < ua.data.size(); ++i)
      EXPECT_NEAR(ua.data[i], ub.data[i], 1e-9) << f << " node " << i;
  }
}

TEST(LieCli, RunChaplyginOnASmallGrid) {
  const json s = run("chaplygin", "chaplygin", "--set grid=11x11x11 --set t_end=1 --set dt=0.5");
  ASSERT_EQ(s["grid"]["axes"].size(), 3u);
  EXPECT_EQ(s["grid"]["axes"][2]["name"], "theta");
  ASSERT_EQ(s["times"].size(), 3u);
  const auto arr = hybgen::rt::read_npy(
      (hybgen::testing::own_dir(kWork) / "runs" / "chaplygin" / s["files"][2].get<std::string>())
          .string());
  EXPECT_EQ(arr.shape, (std::vector<std::size_t>{11, 11, 11}));
  for (double v : arr.data) EXPECT_TRUE(std::isfinite(v) && v >= 0);
}

TEST(LieCli, MatrixGroupsImpactsMatchesClosedForm) {
  // (C, q) with C' = 0, q' = (q + 1)C, reset at q = 0 (decreasing): (C, q) ↦ (−eC, q),
  // J = e², div = C. Backward from (C, q) at time t: for C ≤ 0 no impact, and
  // u = u0(C, (q + 1)e^{−Ct} − 1) e^{−Ct}. For C > 0 the backward trajectory
  // reaches q = 0 after s* = ln(q + 1)/C; if s* < t, the pre-impact state is
  // (−C/e, 0), then q0 + 1 = e^{(C/e)(t − s*)}, and
  // u = u0(−C/e, q0) exp(−[C s* − (C/e)(t − s*)]) / e².
  // Tolerance: the characteristics are integrated to tol = 1e-10, events
  // bisected; 1e-6 relative leaves a wide margin over that.
  const double e = 0.5, t = 2.0;
  const json s =
      run("matrix_groups_impacts", "mgi", "--set grid=41x31 --set e=0.5 --set t_end=2 --set dt=1");
  ASSERT_EQ(s["times"].size(), 3u);
  const auto arr = hybgen::rt::read_npy(
      (hybgen::testing::own_dir(kWork) / "runs" / "mgi" / s["files"][2].get<std::string>())
          .string());
  ASSERT_EQ(arr.shape, (std::vector<std::size_t>{41, 31}));
  auto u0 = [](double C, double q) {
    return q >= 0 ? std::exp(-2 * (C + 1) * (C + 1) - (q - 1.5) * (q - 1.5)) : 0.0;
  };
  int checked = 0, impacted = 0;
  for (std::size_t i = 0; i < 41; ++i)
    for (std::size_t k = 1; k < 31; ++k) {  // skip the guard row q = 0
      const double C = -2 + 4.0 * static_cast<double>(i) / 40,
                   q = 3.0 * static_cast<double>(k) / 30;
      double expect = 0;
      const double sstar = C > 0 ? std::log(q + 1) / C : 1e300;
      if (sstar >= t) {
        expect = u0(C, (q + 1) * std::exp(-C * t) - 1) * std::exp(-C * t);
      } else {
        const double q0 = std::exp(C / e * (t - sstar)) - 1;
        expect = u0(-C / e, q0) * std::exp(-(C * sstar - C / e * (t - sstar))) / (e * e);
        ++impacted;
      }
      const double got = arr.data[i * 31 + k];
      EXPECT_NEAR(got, expect, 1e-6 * (1e-3 + std::fabs(expect))) << "C=" << C << " q=" << q;
      ++checked;
    }
  EXPECT_GT(impacted, 50);
  EXPECT_EQ(checked, 41 * 30);
}

}  // namespace
