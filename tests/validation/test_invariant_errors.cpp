// The error estimates of `method=invariant` (runtime/include/hybgen/rt/methods/two_grid.hpp)
// against the true errors, for both kinds of scheme: the finite-volume generator (fv, order 3)
// and the sampled transfer operator (hat, first order at best). Five closed-form cases
// (tests/support/cycle_closed_forms.hpp derives them), each through the whole pipeline:
// `hybgen run` on a .model file, the density read back from the .npy files, the estimates
// from summary.json.
//
// What is asserted, per case and scheme:
//  * `invariant.error` covers the true relative L1 error and is at most 10 times it;
//  * λ₁'s error covers |λ₁ − 1| (the systems are closed); fv has |λ₁ − 1| ≤ 1e-9;
//  * λ₂'s error covers its distance from the nearest exact eigenvalue e^{2πih Σ k_i/T_i}
//    (the flows are periodic, of periods T_i);
//  * no decay is claimed (the gap is within its error of 0) and no leak (λ₁ within its
//    error of 1): a periodic flow neither mixes nor loses mass, whatever the scheme's damping;
//  * scheme=auto, the default, takes fv on every one of them (their guards are coordinate
//    planes), and hat with a warning naming the guard where fv does not apply.
//
// Measured (2026-11-28, the 2-core development machine, `ctest -R InvariantErrors -V`): the
// estimate over the true error is 6.8–7.2 for fv on all five; for hat 1.6–3.8, including the
// two cases where hat's observed order is far from 1 and the estimate is flagged unreliable
// (thermostat on a box wider than its cycle, quadratic cycle). True errors at the grids below:
// fv 1.3e-8 (thermostat), 1.6e-9 (sawtooth), 1.9e-9 (quadratic), 4.9e-9 (halving), 1.5e-7
// (product); hat 1.0e-1, 2.5e-4, 1.6e-3, 7.7e-3, 5.7e-2.

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <ostream>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/cycle_closed_forms.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::Axis;
using hybgen::testing::Point;
using nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_invariant_errors");
const hybgen::testing::Hybgen hybgen_cli{kWork / "cache"};

using hybgen::testing::Case;
using hybgen::testing::grid_setting;

/// The cases: the support header's five.
std::vector<Case> cases() {
  return hybgen::testing::cycle_cases();
}

/// One run of a case with a scheme, and what it wrote.
struct InvRun {
  int code = -1;
  std::string out;
  json inv;  ///< summary.json's invariant block.
  fs::path dir;
};

InvRun run(const Case& c, const std::string& scheme) {
  InvRun r;
  r.dir = hybgen::testing::own_dir(kWork) / (c.name + "_" + scheme);
  fs::remove_all(r.dir);
  const auto res = hybgen_cli("run '" + c.model + "' --out '" + r.dir.string() +
                              "' --set method=invariant --set scheme=" + scheme +
                              " --set outputs=npy --set grid=" + grid_setting(c.axes));
  r.code = res.code;
  r.out = res.out;
  if (r.code == 0) r.inv = hybgen::testing::read_json_file(r.dir / "summary.json")["invariant"];
  return r;
}

/// The true error: max over modes of the relative L1 error.
double true_error(const Case& c, const InvRun& r) {
  return hybgen::testing::cycle_case_error(c, r.dir);
}

std::complex<double> eigenvalue(const json& inv, int k) {
  const json& l = inv["eigenvalues"][k];
  return {l["re"].get<double>(), l["im"].get<double>()};
}

class InvariantErrors : public ::testing::TestWithParam<std::tuple<Case, std::string>> {};

TEST_P(InvariantErrors, EstimatesCoverTheTrueErrorsAndNoDecayIsClaimed) {
  const auto& [c, scheme] = GetParam();
  const InvRun r = run(c, scheme);
  ASSERT_EQ(r.code, 0) << r.out;
  ASSERT_EQ(r.inv["scheme"], scheme) << r.inv.dump();
  const double truth = true_error(c, r);
  ASSERT_TRUE(r.inv["error"].is_number()) << r.inv.dump();
  const double est = r.inv["error"].get<double>();
  const std::complex<double> l1 = eigenvalue(r.inv, 0), l2 = eigenvalue(r.inv, 1);
  // Bounded densities: hat does not take them for a measure concentrated below the grid
  // (its maximum grows by at most 1.08× per halving here; the neuron's cycle doubles it,
  // test_observables.cpp).
  if (scheme == "hat") {
    EXPECT_FALSE(r.inv["concentrated"].get<bool>()) << r.inv["max_growth"];
  }
  const double h = r.inv["step"].get<double>();
  // λ₂'s distance from the nearest exact eigenvalue other than 1 (|k_i| ≤ 3).
  double d2 = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 49; ++k) {
    const int k1 = k % 7 - 3, k2 = k / 7 - 3;
    if ((k1 == 0 && k2 == 0) || (k2 != 0 && c.periods.size() < 2)) continue;
    double phase = 2.0 * std::numbers::pi * h * k1 / c.periods[0];
    if (k2 != 0) phase += 2.0 * std::numbers::pi * h * k2 / c.periods[1];
    d2 = std::min(d2, std::abs(l2 - std::polar(1.0, phase)));
  }

  std::printf(
      "%s %s: true error %.3e, estimated %.3e (ratio %.2f, observed order %s); "
      "|l1 - 1| %.1e (+/- %.1e); |l2 - exact| %.1e (+/- %.1e)\n",
      c.name.c_str(), scheme.c_str(), truth, est, est / truth,
      r.inv["observed_order"].dump().c_str(), std::abs(l1 - 1.0),
      r.inv["eigenvalues"][0]["error"].get<double>(), d2,
      r.inv["eigenvalues"][1]["error"].get<double>());
  EXPECT_GE(est, truth);
  EXPECT_LE(est, 10.0 * truth);
  // The eigenvalues' errors cover their distances from the exact spectrum and are at most 10×
  // them (measured 1.7–7.9× for λ₂, 2026-11-30); λ₁ = 1 to rounding or to the eigensolver's
  // tolerance (1e-10 relative, invariant.hpp) has that floor (measured 1.01e-10 at most).
  const double e1 = r.inv["eigenvalues"][0]["error"].get<double>();
  const double e2 = r.inv["eigenvalues"][1]["error"].get<double>();
  EXPECT_GE(e1, std::abs(l1 - 1.0));
  EXPECT_LE(e1, 10.0 * std::abs(l1 - 1.0) + 2e-10);
  EXPECT_GE(e2, d2);
  EXPECT_LE(e2, 10.0 * d2);
  if (scheme == "fv") {
    EXPECT_LE(std::abs(l1 - 1.0), 1e-9);
  }
  EXPECT_EQ(r.inv["decays"], false) << r.inv.dump();
  EXPECT_EQ(r.inv["leaks"], false) << r.inv.dump();
  EXPECT_LE(r.inv["spectral_gap"].get<double>(), r.inv["spectral_gap_error"].get<double>());
}

INSTANTIATE_TEST_SUITE_P(FiveCycles, InvariantErrors,
                         ::testing::Combine(::testing::ValuesIn(cases()),
                                            ::testing::Values("fv", "hat")),
                         [](const auto& param_info) {
                           return std::get<0>(param_info.param).name + "_" +
                                  std::get<1>(param_info.param);
                         });

TEST(InvariantErrors, AStepThatMovesNothingIsToldNotEstimated) {
  // The sawtooth by hat over step = 1e-300: the operator is the identity to rounding, every
  // density is invariant, and the eigen-solver returns its start vector (a constant) on both
  // grids. Before, that was reported as the invariant density with an error of 9e-13 (it is
  // 17 % off the closed form). Now λ₂ within the errors of λ₁ says the density is not unique:
  // a warning, `unique` false and no error estimate.
  const Case c = cases()[1];  // sawtooth
  ASSERT_EQ(c.name, "sawtooth");
  const fs::path dir = hybgen::testing::own_dir(kWork) / "sawtooth_tiny_step";
  fs::remove_all(dir);
  const auto res = hybgen_cli("run '" + c.model + "' --out '" + dir.string() +
                              "' --set method=invariant --set scheme=hat --set step=1e-300 "
                              "--set outputs=npy --set grid=" +
                              grid_setting(c.axes));
  ASSERT_EQ(res.code, 0) << res.out;
  EXPECT_NE(res.out.find("the invariant density is not unique"), std::string::npos) << res.out;
  const json inv = hybgen::testing::read_json_file(dir / "summary.json")["invariant"];
  EXPECT_EQ(inv["unique"], false) << inv.dump();
  EXPECT_TRUE(inv["error"].is_null()) << inv.dump();
  EXPECT_EQ(inv["error_reliable"], false) << inv.dump();
}

TEST(InvariantErrors, TwoInvariantSetsAreToldNotUnique) {
  // tests/validation/models/two_sawtooths.model: x' = 1 wrapping on [0, 1] and on [2, 3], two
  // invariant sets, λ₁ = λ₂ = 1 exactly. The default scheme (fv: its guards are coordinate
  // planes) finds μ₂ = μ₁ = 0 to rounding; before, it reported one density with the two grids'
  // disagreement, 0.42, as its error. (hat's deposit leaks the first cycle's mass across
  // x = 1 into the second, its known defect at a guard that no `where` bounds: for hat only
  // the density on [2, 3] is invariant, and λ₂ is the cycle's rotation, 0.81 + 0.59i.)
  const fs::path dir = hybgen::testing::own_dir(kWork) / "two_sawtooths";
  fs::remove_all(dir);
  const auto res = hybgen_cli("run tests/validation/models/two_sawtooths.model --out '" +
                              dir.string() + "' --set outputs=npy");
  ASSERT_EQ(res.code, 0) << res.out;
  const json inv = hybgen::testing::read_json_file(dir / "summary.json")["invariant"];
  EXPECT_EQ(inv["scheme"], "fv") << inv.dump();
  EXPECT_EQ(inv["unique"], false) << inv.dump();
  EXPECT_TRUE(inv["error"].is_null()) << inv.dump();
  EXPECT_NE(res.out.find("the invariant density is not unique"), std::string::npos) << res.out;
}

TEST(InvariantSchemeAuto, TakesTheGeneratorWhereTheGuardsAreCoordinatePlanes) {
  const Case c = cases()[3];  // halving: a reset that is not the identity
  const InvRun r = run(c, "auto");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.inv["scheme"], "fv") << r.inv.dump();
  EXPECT_LE(true_error(c, r), 1e-6);
}

TEST(InvariantSchemeAuto, TheNewcomersThermostatWithoutWhereIsExactToItsEstimate) {
  // models/thermostat.model: the thermostat a new user writes (no `where` lines, a box
  // [0.5, 2.5] wider than the cycle [1, 2]), which the hat scheme got 5-28 % wrong, by the
  // default scheme: u_heat = 1/(2 ln 2 (3 − T)), u_cool = 1/(2 ln 2 T) on [1, 2], 0 outside.
  // Measured (2026-11-28): 1.0e-7, estimated 7.0e-7, λ₁ = 1 to 2e-15.
  Case c;
  c.name = "newcomer";
  c.model = "models/thermostat.model";
  c.axes = {{0.5, 2.5, 201}};
  c.modes = {"heat", "cool"};
  c.exact = [](int mode, const hybgen::testing::Point& x) {
    const double T = x[0];
    if (T < 1.0 || T > 2.0) return 0.0;
    return 1.0 / (2.0 * std::log(2.0) * (mode == 0 ? 3.0 - T : T));
  };
  c.on_jump = hybgen::testing::thermostat_jump;
  const InvRun r = run(c, "auto");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.inv["scheme"], "fv") << r.inv.dump();
  const double truth = true_error(c, r), estimate = r.inv["error"].get<double>();
  std::printf("newcomer thermostat: true %.2e, estimated %.2e\n", truth, estimate);
  EXPECT_LE(truth, 1e-5);
  EXPECT_GE(estimate, truth);
  EXPECT_LE(estimate, 10.0 * truth);
  EXPECT_NEAR(std::abs(eigenvalue(r.inv, 0)), 1.0, 1e-9);
}

TEST(InvariantSchemeAuto, FallsBackToHatNamingTheGuard) {
  // A curved guard (radial_fv.model's rim): the generator does not cut it yet.
  Case c;
  c.name = "radial";
  c.model = "tests/validation/models/radial_fv.model";
  c.axes = {{-1.1, 1.1, 45}, {-1.1, 1.1, 45}};
  c.modes = {""};
  // The invariant density 1/(2π ln 2 r²) on 1/2 ≤ r ≤ 1 (the model file). hat's first-order
  // smearing at a curved guard on 45²: measured 0.20 relative L1, estimated 0.59, the observed
  // order −0.1 flagged as unreliable (2026-11-30, with the turn that makes it unique).
  c.exact = [](int, const hybgen::testing::Point& p) {
    const double r2 = p[0] * p[0] + p[1] * p[1];
    return r2 >= 0.25 && r2 <= 1.0 ? 1.0 / (2.0 * std::numbers::pi * std::log(2.0) * r2) : 0.0;
  };
  const InvRun r = run(c, "auto");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.inv["scheme"], "hat") << r.inv.dump();
  EXPECT_NE(r.out.find("scheme=auto used hat"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("guard 'rim'"), std::string::npos) << r.out;
  ASSERT_TRUE(r.inv["error"].is_number()) << r.inv.dump();
  const double truth = true_error(c, r), estimate = r.inv["error"].get<double>();
  std::printf("radial (hat): true %.3f, estimated %.3f, reliable %s\n", truth, estimate,
              r.inv["error_reliable"].dump().c_str());
  EXPECT_GE(estimate, truth);
  EXPECT_LE(estimate, 10.0 * truth);
  EXPECT_EQ(r.inv["error_reliable"], false) << r.inv.dump();
}

}  // namespace
