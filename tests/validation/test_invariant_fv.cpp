// Validation of `method=invariant` with `scheme=fv` (the finite-volume generator,
// runtime/include/hybgen/rt/methods/generator.hpp) through the whole pipeline: `hybgen run` on
// .model files (tests/validation/models/, models/sawtooth.model), the densities read back from
// the .npy files and summary.json, against closed forms (tests/support/cycle_closed_forms.hpp
// derives them; none comes from hybgen):
//   thermostat (heat T' = 4 − T until T = 2, cool T' = −T until T = 1): on [1, 2],
//     u_heat = 1/(ln 3 (4 − T)), u_cool = 1/(ln 3 T) (period ln(3/2) + ln 2 = ln 3), and 0 on
//     the transients (heat above 2, cool below 1) of the box [0.8, 2.2];
//   sawtooth (x' = 1 + x on [0, 1], x ↦ 0 at 1): u = 1/(ln 2 (1 + x)), period ln 2;
//   their product (independent factors): the product of the densities.
// The flows are periodic, so the generator's spectrum is 2πik/period (k ∈ ℤ), all on the
// imaginary axis: λ = e^{μh} on the unit circle, no decay, and arg λ₂ = 2πh/period.
//
// Measured (2026-12, this machine, p = 3; see docs/methods.md): thermostat 281 nodes 1.3e-8
// (estimate 9.2e-8), sawtooth 401 nodes 1.6e-9 (1.1e-8), product 141 × 101 1.5e-7 (1.1e-6),
// |λ₁| − 1 ≤ 1e-15, period of λ₂ 2.6e-7 relative, order 3.0. The bounds asserted are the
// brief's targets: 1e-3, 1e-4, 1e-3, 1e-9, 1e-4, order ≥ 2.5, estimate in [1, 10]× the error.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/cycle_closed_forms.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::run_hybgen;
using nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_invariant_fv");
const fs::path kCache = kWork / "cache";
const std::string kModels = std::string(HYBGEN_SOURCE_DIR) + "/tests/validation/models/";

/// One run: its summary.json and its directory.
struct FvRun {
  int code = -1;    ///< hybgen's exit status.
  std::string out;  ///< What it printed.
  json summary;     ///< summary.json (when it succeeded).
  fs::path dir;     ///< The output directory.
};

/// `hybgen run MODEL --set method=METHOD --set scheme=fv EXTRA` into its own directory.
FvRun run(const std::string& model, const std::string& tag, const std::string& extra,
          const std::string& method = "invariant") {
  FvRun r;
  r.dir = hybgen::testing::own_dir(kWork) / tag;
  fs::remove_all(r.dir);
  const auto res =
      run_hybgen("run '" + model + "' --quiet --out '" + r.dir.string() +
                     "' --set method=" + method + " --set scheme=fv --set outputs=npy " + extra,
                 kCache);
  r.code = res.code;
  r.out = res.out;
  if (r.code == 0) r.summary = hybgen::testing::read_json_file(r.dir / "summary.json");
  return r;
}

/// A mode's density as written (`invariant_<mode>.npy`, or `invariant.npy` for one mode).
std::vector<double> density(const FvRun& r, const std::string& mode) {
  const fs::path p = r.dir / (mode.empty() ? "invariant.npy" : "invariant_" + mode + ".npy");
  return hybgen::rt::read_npy(p.string()).data;
}

using hybgen::testing::grid_node;
using hybgen::testing::on_thermostat_jump;
using hybgen::testing::sawtooth_density;
using hybgen::testing::thermostat_density;
using hybgen::testing::trapezoid_weight;

/// Relative L1 error per thermostat mode on n nodes of [0.8, 2.2], jumps excluded.
std::vector<double> thermostat_errors(const FvRun& r, int n) {
  std::vector<double> out;
  const char* modes[] = {"heat", "cool"};
  for (int m = 0; m < 2; ++m) {
    const std::vector<double> u = density(r, modes[m]);
    EXPECT_EQ(u.size(), static_cast<std::size_t>(n));
    double num = 0.0, den = 0.0;
    for (int i = 0; i < n && static_cast<std::size_t>(i) < u.size(); ++i) {
      const double T = grid_node(0.8, 2.2, n, i);
      if (on_thermostat_jump(T)) continue;
      num += trapezoid_weight(n, i) *
             std::fabs(u[static_cast<std::size_t>(i)] - thermostat_density(m, T));
      den += trapezoid_weight(n, i) * thermostat_density(m, T);
    }
    out.push_back(num / den);
  }
  return out;
}

/// Relative L1 error of the sawtooth on n nodes of [0, 1].
double sawtooth_error(const FvRun& r, int n) {
  const std::vector<double> u = density(r, "");
  EXPECT_EQ(u.size(), static_cast<std::size_t>(n));
  double num = 0.0, den = 0.0;
  for (int i = 0; i < n && static_cast<std::size_t>(i) < u.size(); ++i) {
    const double x = grid_node(0.0, 1.0, n, i);
    num += trapezoid_weight(n, i) * std::fabs(u[static_cast<std::size_t>(i)] - sawtooth_density(x));
    den += trapezoid_weight(n, i) * sawtooth_density(x);
  }
  return num / den;
}

/// |λ₁| of a run.
double lambda1(const FvRun& r) {
  return r.summary["invariant"]["eigenvalues"][0]["abs"].get<double>();
}

/// The estimated error covers the true one and is at most 10 times it.
void expect_calibrated(const FvRun& r, double truth, const char* what) {
  const double est = r.summary["invariant"]["error"].get<double>();
  std::printf("%s: true error %.3e, estimated %.3e (ratio %.2f)\n", what, truth, est, est / truth);
  EXPECT_GE(est, truth) << what;
  EXPECT_LE(est, 10.0 * truth) << what;
}

TEST(InvariantFv, ThermostatPerModeWithinTheTarget) {
  const FvRun r = run(kModels + "thermostat_fv.model", "thermostat", "");
  ASSERT_EQ(r.code, 0) << r.out;
  const json& inv = r.summary["invariant"];
  EXPECT_EQ(inv["scheme"], "fv");
  EXPECT_EQ(inv["order"], 5);
  EXPECT_EQ(inv["coarse_grid"], json::array({141}));
  const std::vector<double> e = thermostat_errors(r, 281);
  std::printf("thermostat 281 nodes: heat %.3e, cool %.3e, |lambda1| - 1 = %.1e, %.2f s\n", e[0],
              e[1], lambda1(r) - 1.0, r.summary["seconds"]["solve"].get<double>());
  EXPECT_LE(e[0], 1e-3);
  EXPECT_LE(e[1], 1e-3);
  EXPECT_NEAR(lambda1(r), 1.0, 1e-9);
  expect_calibrated(r, std::max(e[0], e[1]), "thermostat 281");
}

TEST(InvariantFv, SawtoothDensityAndPeriodWithNoDecayClaimed) {
  const std::string model = std::string(HYBGEN_SOURCE_DIR) + "/models/sawtooth.model";
  const FvRun r = run(model, "sawtooth", "--set grid=401");
  ASSERT_EQ(r.code, 0) << r.out;
  const json& inv = r.summary["invariant"];
  const double e = sawtooth_error(r, 401);
  // The period from the phase of λ₂ = e^{2πi h/T}: T = 2π h / arg λ₂.
  const double h = inv["step"].get<double>();
  const json& l2 = inv["eigenvalues"][1];
  const double period = 2.0 * std::numbers::pi * h /
                        std::fabs(std::atan2(l2["im"].get<double>(), l2["re"].get<double>()));
  std::printf("sawtooth 401 nodes: %.3e, |lambda1| - 1 = %.1e, period %.10f (ln 2 = %.10f)\n", e,
              lambda1(r) - 1.0, period, std::log(2.0));
  EXPECT_LE(e, 1e-4);
  EXPECT_NEAR(lambda1(r), 1.0, 1e-9);
  EXPECT_NEAR(period / std::log(2.0), 1.0, 1e-4);
  ASSERT_TRUE(inv["decays"].is_boolean()) << inv.dump();
  EXPECT_FALSE(inv["decays"].get<bool>());
  EXPECT_LE(inv["spectral_gap"].get<double>(), inv["spectral_gap_error"].get<double>());
  // λ₂'s error covers its distance from the exact e^{2πih/ln 2}.
  const double exact_phase = 2.0 * std::numbers::pi * h / std::log(2.0);
  const double d = std::hypot(l2["re"].get<double>() - std::cos(exact_phase),
                              std::fabs(l2["im"].get<double>()) - std::sin(exact_phase));
  EXPECT_GE(l2["error"].get<double>(), d);
  expect_calibrated(r, e, "sawtooth 401");
  EXPECT_EQ(inv["oscillates"], false);
  EXPECT_EQ(inv["growing_modes"], 0);
}

TEST(InvariantFv, ProductOfTwoCyclesInTwoDimensions) {
  const FvRun r = run(kModels + "thermostat_sawtooth_fv.model", "product", "");
  ASSERT_EQ(r.code, 0) << r.out;
  const int nT = 141, nx = 101;
  double worst = 0.0;
  const char* modes[] = {"heat", "cool"};
  for (int m = 0; m < 2; ++m) {
    const std::vector<double> u = density(r, modes[m]);
    ASSERT_EQ(u.size(), static_cast<std::size_t>(nT * nx));
    double num = 0.0, den = 0.0;
    for (int i = 0; i < nT; ++i) {
      const double T = grid_node(0.8, 2.2, nT, i);
      if (on_thermostat_jump(T)) continue;
      for (int j = 0; j < nx; ++j) {
        const double x = grid_node(0.0, 1.0, nx, j),
                     w = trapezoid_weight(nT, i) * trapezoid_weight(nx, j);
        const double exact = thermostat_density(m, T) * sawtooth_density(x);
        num += w * std::fabs(u[static_cast<std::size_t>(i * nx + j)] - exact);
        den += w * exact;
      }
    }
    worst = std::max(worst, num / den);
  }
  std::printf("thermostat x sawtooth 141 x 101: %.3e, |lambda1| - 1 = %.1e, %.2f s\n", worst,
              lambda1(r) - 1.0, r.summary["seconds"]["solve"].get<double>());
  EXPECT_LE(worst, 1e-3);
  EXPECT_NEAR(lambda1(r), 1.0, 1e-9);
  expect_calibrated(r, worst, "product 141 x 101");
  EXPECT_EQ(r.summary["invariant"]["oscillates"], false);
  EXPECT_EQ(r.summary["invariant"]["growing_modes"], 0);
}

// scheme=fv by name where the invariant measure concentrates on an attracting point
// (models/sir.model: the epidemic's endemic equilibrium): the fifth-order reconstruction
// oscillates and the discrete generator has growing modes. The run keeps what it was asked
// for, but says both, in the terminal and in summary.json (a density from −1.2e5 to 3.4e5
// and |λ₁| = 1.0187 went out with neither, before).
TEST(InvariantFv, ADensityThatOscillatesAndGrowingModesAreToldNotSilent) {
  const FvRun r = run(std::string(HYBGEN_SOURCE_DIR) + "/models/sir.model", "sir", "");
  ASSERT_EQ(r.code, 0) << r.out;
  const json& inv = r.summary["invariant"];
  EXPECT_LT(inv["min_value"].get<double>(), 0.0);
  EXPECT_EQ(inv["oscillates"], true);
  EXPECT_GT(inv["growing_modes"].get<int>(), 0);
  EXPECT_GT(lambda1(r), 1.0);  // the growing mode is really there
  EXPECT_NE(r.out.find("density oscillates"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("growing mode(s)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("scheme=hat"), std::string::npos) << r.out;
}

TEST(InvariantFv, OrderOfConvergenceIsThreeAndOrderOneIsOne) {
  // The sawtooth on 101, 201 and 401 nodes: e(n) ∝ n^-p, measured as log2 of successive ratios.
  const std::string model = std::string(HYBGEN_SOURCE_DIR) + "/models/sawtooth.model";
  for (const int p : {3, 1}) {
    std::vector<double> e;
    for (const int n : {101, 201, 401}) {
      const FvRun r =
          run(model, "order" + std::to_string(p) + "_" + std::to_string(n),
              "--set grid=" + std::to_string(n) + " --set fv_order=" + std::to_string(p));
      ASSERT_EQ(r.code, 0) << r.out;
      e.push_back(sawtooth_error(r, n));
    }
    const double o1 = std::log2(e[0] / e[1]), o2 = std::log2(e[1] / e[2]);
    std::printf("sawtooth p = %d: errors %.3e %.3e %.3e, orders %.2f %.2f\n", p, e[0], e[1], e[2],
                o1, o2);
    if (p == 3) {
      EXPECT_GE(o1, 2.5);
      EXPECT_GE(o2, 2.5);
    } else {
      EXPECT_LT(o2, 1.5);  // the measurement tells the orders apart
    }
  }
}

TEST(InvariantFv, CurvedGuardIsRefusedNamingTheGuard) {
  const FvRun r = run(kModels + "radial_fv.model", "radial", "");
  EXPECT_EQ(r.code, hybgen::rt::exit_status(hybgen::rt::ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("guard 'rim'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("scheme=hat"), std::string::npos) << r.out;
}

// method=transfer steps the generator in time (generator_march.hpp; its accuracy in
// tests/validation/test_transient_closed_forms.cpp); the escape rate is not built on it, and
// says so before anything runs, with both ways out.
TEST(InvariantFv, EscapeWithTheGeneratorIsRefused) {
  const FvRun r = run(kModels + "thermostat_fv.model", "escape", "", "escape");
  EXPECT_EQ(r.code, hybgen::rt::exit_status(hybgen::rt::ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("scheme=fv"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("method=invariant or transfer"), std::string::npos) << r.out;
  const FvRun t = run(kModels + "thermostat_fv.model", "transfer", "", "transfer");
  EXPECT_EQ(t.code, 0) << t.out;
  EXPECT_EQ(t.summary["transfer"]["scheme"], "fv") << t.out;
}

}  // namespace
