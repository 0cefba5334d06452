// Validation of the observables (`observe NAME = [MODE:] EXPR`, `--set observe.NAME=EXPR`;
// runtime/include/hybgen/rt/methods/observables.hpp) through the whole pipeline: `hybgen run`
// on .model files, summary.json's `observables.NAME.values` / `.errors` read back, against
// references that do not come from hybgen:
//  * the thermostat's invariant density (heat T' = 4 − T until T = 2, cool T' = −T until
//    T = 1; tests/validation/models/thermostat_fv.model): u = c/|T'| on [1, 2] in each mode,
//    one flux c for both, so with ∫₁² dT/(4 − T) = ln(3/2) and ∫₁² dT/T = ln 2
//        P[heat] = ln(3/2)/ln 3,
//        E[T]    = (∫₁² T/(4 − T) dT + ∫₁² dT)/ln 3 = (4 ln(3/2) − 1 + 1)/ln 3 = 4 ln(3/2)/ln 3
//    (∫ T/(4 − T) = ∫ 4/(4 − T) − 1);
//  * the same thermostat started in `heat` from exp(−20 (T − 1.5)²)
//    (tests/validation/models/thermostat_transient.model), whose expectations up to t = 0.6
//    the test integrates itself over the initial states with the exact flow: heating
//    T(t) = 4 − (4 − T₀)e^{−t} reaches 2 at t* = ln((4 − T₀)/2) (for T₀ < 2), cooling
//    T = 2e^{−(t − t*)} after it; nothing completes the cooling branch before t = ln 2. A
//    heating state that starts at T₀ ≥ 2 is past its guard and leaves the box at T = 2.2;
//  * the elastic bouncing ball with its initial density on the energy annulus
//    0.6 ≤ H ≤ 1.8 (tests/validation/models/ball_annulus.model: no mass meets the box's faces,
//    none comes near the origin): every trajectory keeps its energy H = p²/2 + x, so
//    E[H](t) = E[H](0) at every time, and E[x](t) is the test's integral over the initial
//    states of the height after the exact elastic flow (tests/support/ball_closed_form.hpp,
//    run forwards). Near the origin (ball_compact.model) the exact density winds into stripes
//    finer than the grid, and the estimates, which assume the grids are in the asymptotic
//    regime, can fall short there (docs/methods.md, "Observables").
// Each method's error must cover its true error, and not by more than a factor the test
// states. Particles' errors are twice a standard error: the bound there is twice the error
// (four standard errors), and the width at most 30× (19× measured: the collapsed strata's
// estimate counts the differences of mean between neighbouring strata, largest for the mode
// indicator where neighbours straddle the switching line).

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "support/ball_closed_form.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_observables");
const fs::path kCache = kWork / "cache";
const std::string kModels = std::string(HYBGEN_SOURCE_DIR) + "/tests/validation/models/";

/// `hybgen run MODEL --quiet EXTRA` into its own directory: summary.json (null when the run
/// failed; the output is in the test's message).
json run(const std::string& model, const std::string& tag, const std::string& extra) {
  return hybgen::testing::run_summary(kModels + model, hybgen::testing::own_dir(kWork) / tag,
                                      "--set outputs=netcdf " + extra, kCache);
}

/// The observables every run of the thermostat adds (the heating fraction is a mode piece).
const std::string kThermostatObservables =
    "--set 'observe.T=T' --set 'observe.heating=heat: 1' --set 'observe.T2=T^2'";

/// ∫_a^b g by the composite Simpson rule on 20,000 panels (0 when a ≥ b).
template <class G>
double simpson(G g, double a, double b) {
  constexpr int kPanels = 20000;
  if (!(a < b)) return 0.0;
  const double h = (b - a) / kPanels;
  double sum = g(a) + g(b);
  for (int i = 1; i < kPanels; ++i) sum += g(a + i * h) * (i % 2 ? 4.0 : 2.0);
  return sum * h / 3.0;
}

/// The thermostat's transient expectations at time t ≤ 0.6 (file comment): E[T], P[heat],
/// E[T²] over the states in the box [0.8, 2.2]. Heating from T₀ < 2 reaches the guard at
/// t* = ln((4 − T₀)/2), so by time t the states T₀ ∈ [4 − 2eᵗ, 2) have switched. The initial
/// states fall in three intervals on which the flow is smooth, each integrated by Simpson's
/// rule:
///  * still heating below the guard, T₀ ∈ [4 − 3.2eᵗ, 4 − 2eᵗ): T = 4 − (4 − T₀)e^{−t}
///    (from 0.8 up: the part of it below 0.8 at t = 0 has heated into the box);
///  * heating past the guard, T₀ ∈ [2, 4 − 1.8eᵗ]: the same T, up to the face 2.2;
///  * switched, T₀ ∈ [4 − 2eᵗ, 2): cooling since t*, T = 2e^{−(t − t*)} = (4 − T₀)e^{−t} ≥ 1.
std::vector<double> transient_reference(double t) {
  const double et = std::exp(t);
  const auto u0 = [](double t0) { return std::exp(-20.0 * (t0 - 1.5) * (t0 - 1.5)); };
  const double lo = 0.0;  // u0 < 1e-19 below
  const auto heating = [&](double t0) { return 4.0 - (4.0 - t0) / et; };
  const auto cooling = [&](double t0) { return (4.0 - t0) / et; };
  const double below_a = std::max(lo, 4.0 - 3.2 * et), switched_a = 4.0 - 2.0 * et;
  const double past_b = 4.0 - 1.8 * et;
  std::vector<double> moment(3, 0.0);  // ∫ u0 Tᵖ over the states in the box, p = 0, 1, 2
  double heat_mass = 0.0;
  for (int power = 0; power < 3; ++power) {
    const auto heat_part = [&](double t0) { return u0(t0) * std::pow(heating(t0), power); };
    const auto cool_part = [&](double t0) { return u0(t0) * std::pow(cooling(t0), power); };
    const double heat = simpson(heat_part, below_a, switched_a) + simpson(heat_part, 2.0, past_b);
    moment[static_cast<std::size_t>(power)] = heat + simpson(cool_part, switched_a, 2.0);
    if (power == 0) heat_mass = heat;
  }
  return {moment[1] / moment[0], heat_mass / moment[0], moment[2] / moment[0]};
}

/// The elastic ball of ball_annulus.model at times `times`: {E[H], E[x]} per time, by the
/// midpoint rule on 2000 × 2000 initial states in the support's box [0, 1.8] × [−1.9, 1.9]
/// (u0 vanishes outside 0.6 < H < 1.8, C² at both edges), each moved by the exact flow.
std::vector<std::vector<double>> ball_reference(const std::vector<double>& times) {
  constexpr int kSteps = 2000;
  const double hx = 1.8 / kSteps, hp = 3.8 / kSteps;
  std::vector<std::vector<double>> sums(times.size(), std::vector<double>(3, 0.0));
  for (int i = 0; i < kSteps; ++i)
    for (int j = 0; j < kSteps; ++j) {
      const double x0 = (i + 0.5) * hx, p0 = -1.9 + (j + 0.5) * hp;
      const double energy = 0.5 * p0 * p0 + x0;
      if (energy >= 1.8 || energy <= 0.6) continue;
      const double a = (1.8 - energy) / 0.6, b = (energy - 0.6) / 0.6;
      const double w = std::exp(-(x0 - 1.0) * (x0 - 1.0) - p0 * p0) * a * a * a * b * b * b;
      for (std::size_t k = 0; k < times.size(); ++k) {
        double height = x0;  // φ_t(x0, p0) = φ_{−(−t)}: the pull-back by −t
        hybgen::testing::ball_pullback_elastic(x0, p0, -times[k], [&](double x, double) {
          height = x;
          return 1.0;
        });
        sums[k][0] += w, sums[k][1] += w * energy, sums[k][2] += w * height;
      }
    }
  std::vector<std::vector<double>> means;
  for (const auto& s : sums) means.push_back({s[1] / s[0], s[2] / s[0]});
  return means;
}

/// Check run `s`'s observables `names` against `reference(k)` (their means at frame k): each
/// error covers the true one at every frame (`cover` times the error, plus 1e-12 for
/// rounding), and is at most `widest` times the largest true error of that observable over
/// the frames, or `floor` relative to the value. (Against the run's error scale, not each
/// frame's: a mean's error can vanish at one frame by cancellation, as the mean of a density
/// whose smoothing is symmetric, or as a front between nodes falls luckily for the grid and
/// not for the coarser ones that estimate it.)
template <class Reference>
void expect_covered(const json& s, const std::string& what, Reference reference, double widest,
                    double floor, double cover = 1.0,
                    const std::vector<std::string>& names = {"T", "heating", "T2"}) {
  ASSERT_TRUE(s.is_object()) << what;
  ASSERT_TRUE(s.contains("observables")) << what;
  const json& o = s["observables"];
  const std::size_t frames = o[names.front()]["values"].size();
  ASSERT_GE(frames, 1U) << what;
  for (std::size_t i = 0; i < names.size(); ++i) {
    std::vector<double> actual, error, ref;
    for (std::size_t k = 0; k < frames; ++k) {
      const json& v = o[names[i]]["values"][k];
      const json& e = o[names[i]]["errors"][k];
      ASSERT_TRUE(v.is_number() && e.is_number()) << what << " " << names[i] << " frame " << k;
      ref.push_back(reference(k)[i]);
      actual.push_back(std::fabs(v.get<double>() - ref.back()));
      error.push_back(e.get<double>());
      std::printf("%s E[%s] frame %zu: %.10f (reference %.10f) true error %.2e, estimate %.2e\n",
                  what.c_str(), names[i].c_str(), k, v.get<double>(), ref.back(), actual.back(),
                  error.back());
    }
    double scale = 0.0;  // the run's largest true error of this observable
    for (const double a : actual) scale = std::max(scale, a);
    for (std::size_t k = 0; k < frames; ++k) {
      EXPECT_LE(actual[k], cover * error[k] + 1e-12)
          << what << " E[" << names[i] << "] frame " << k;
      EXPECT_LE(error[k], std::max(widest * scale, floor * std::fabs(ref[k])) + 1e-12)
          << what << " E[" << names[i] << "] frame " << k;
    }
  }
}

// The invariant density by both schemes: fv (order 3, jumps at the guards) and hat (first
// order, the box wider than the cycle).
TEST(Observables, TheThermostatsInvariantMeansHaveErrorsThatCoverThem) {
  const double l3 = std::log(3.0), l32 = std::log(1.5);
  // E[T²] = (∫₁² T²/(4 − T) dT + ∫₁² T dT)/ln 3, ∫ T²/(4 − T) = 16 ln(3/2) − ∫₁² (T + 4) dT.
  const std::vector<double> exact = {4.0 * l32 / l3, l32 / l3, (16.0 * l32 - 5.5 + 1.5) / l3};
  const auto reference = [&](std::size_t) { return exact; };
  expect_covered(run("thermostat_fv.model", "fv", kThermostatObservables), "fv", reference, 10.0,
                 1e-9);
  expect_covered(run("thermostat_fv.model", "hat", kThermostatObservables + " --set scheme=hat"),
                 "hat", reference, 10.0, 1e-6);
}

TEST(Observables, TheThermostatsTransientMeansByEveryMethodAgreeWithTheFlow) {
  const std::vector<double> times = {0.0, 0.2, 0.4, 0.6};
  const auto reference = [&](std::size_t k) { return transient_reference(times.at(k)); };
  expect_covered(run("thermostat_transient.model", "characteristics", kThermostatObservables),
                 "characteristics", reference, 10.0, 1e-4);
  expect_covered(run("thermostat_transient.model", "transfer",
                     kThermostatObservables + " --set method=transfer"),
                 "transfer", reference, 10.0, 1e-4);
  expect_covered(run("thermostat_transient.model", "particles",
                     kThermostatObservables + " --set method=particles --set particles=200000"),
                 "particles", reference, 30.0, 1e-4, 2.0);
}

// A 2-D Hamiltonian impact system, each method on 129² nodes up to t = 10. Each estimate
// covers its error; characteristics' (exact node values, the trapezoid rule's error) is at
// most 10× the run's largest, transfer's at most 100× (or 1e-4 of the value).
TEST(Observables, TheElasticBallKeepsItsMeanEnergyAndEveryMethodSaysHowClose) {
  const std::vector<double> times = {0.0, 2.5, 5.0, 7.5, 10.0};
  const std::vector<std::vector<double>> ref = ball_reference(times);
  const auto reference = [&](std::size_t k) { return ref.at(k); };
  const std::vector<std::string> names = {"energy", "height"};
  const std::string common =
      "--set grid=129x129 --set dt=2.5 --set 'observe.energy=p^2/2 + x' --set 'observe.height=x' ";
  expect_covered(
      run("ball_annulus.model", "ball_characteristics", common + "--set method=characteristics"),
      "characteristics", reference, 10.0, 1e-4, 1.0, names);
  // transfer's estimates come from 65² and 33² nodes, further from the asymptotic regime
  // than 129²: they cover, conservatively (docs/methods.md).
  expect_covered(run("ball_annulus.model", "ball_transfer", common), "transfer hat", reference,
                 100.0, 1e-4, 1.0, names);
  expect_covered(run("ball_annulus.model", "ball_fv", common + "--set scheme=fv"), "transfer fv",
                 reference, 100.0, 1e-4, 1.0, names);
  expect_covered(run("ball_annulus.model", "ball_particles",
                     common + "--set method=particles --set particles=200000"),
                 "particles", reference, 30.0, 1e-4, 2.0, names);
}

/// The integrate-and-fire neuron's spiking cycle (models/integrate_and_fire.model: v' = I − v − w,
/// w' = −w/τ, at v = 1 the reset (0, w + b); I = 2, τ = 2, b = 0.3), integrated here by RK4 from
/// the reset with step h, the crossing of v = 1 located by linear interpolation, until the
/// cycle's w after the reset repeats: the period and the time averages of v and w over it.
struct SpikingCycle {
  double period = 0.0, mean_v = 0.0, mean_w = 0.0;
};
SpikingCycle spiking_cycle() {
  constexpr double I = 2.0, tau = 2.0, b = 0.3, h = 1e-4;
  const auto f = [&](double v, double w) { return std::array<double, 2>{I - v - w, -w / tau}; };
  double w0 = 0.7;
  SpikingCycle c;
  for (int turn = 0; turn < 60; ++turn) {
    double v = 0.0, w = w0, t = 0.0, iv = 0.0, iw = 0.0;
    for (;;) {
      const auto k1 = f(v, w), k2 = f(v + h / 2 * k1[0], w + h / 2 * k1[1]),
                 k3 = f(v + h / 2 * k2[0], w + h / 2 * k2[1]), k4 = f(v + h * k3[0], w + h * k3[1]);
      const double vn = v + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]);
      const double wn = w + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]);
      const double s = vn >= 1.0 ? (1.0 - v) / (vn - v) : 1.0;  // the part of the step before v = 1
      iv += s * h * (v + (v + s * (vn - v))) / 2, iw += s * h * (w + (w + s * (wn - w))) / 2;
      t += s * h;
      if (vn >= 1.0) {
        w += s * (wn - w);
        break;
      }
      v = vn, w = wn;
    }
    c = {t, iv / t, iw / t};
    if (std::fabs(w + b - w0) < 1e-13) break;
    w0 = w + b;
  }
  return c;
}

TEST(Observables, TheNeuronsSpikingCycleIsAMeasureOnACurveWhoseMeansConverge) {
  // The shipped neuron's invariant measure lives on its spiking cycle: a curve, so the
  // density's maximum doubles as the grid halves, no L1 error applies, and the run says so
  // (methods.hpp, kConcentratedGrowth). Its means do converge: the invariant measure of a
  // cycle weights each point by the time spent there, so E[f] is f's time average over one
  // period, which the test integrates itself (spiking_cycle: period 1.11429, E[v] 0.564111,
  // E[w] 0.538458). Measured (2026-11-29, hat on 129 × 167, the default): E[w] off by 4.6e-5
  // with an estimate of 6.0e-4 (13×), E[v] by 7e-6 with 3.0e-4 (43×).
  const SpikingCycle c = spiking_cycle();
  std::printf("[ neuron ] cycle: period %.6f, E[v] %.6f, E[w] %.6f\n", c.period, c.mean_v,
              c.mean_w);
  ASSERT_NEAR(c.period, 1.114, 1e-3);  // the model file's comment
  const json s = run("../../../models/integrate_and_fire.model", "neuron",
                     "--set 'observe.v=v' --set 'observe.w=w'");
  ASSERT_FALSE(s.is_null());
  const json& inv = s["invariant"];
  EXPECT_TRUE(inv["concentrated"].get<bool>()) << inv.dump();
  EXPECT_NEAR(inv["max_growth"][1].get<double>(), 2.0, 0.3) << inv.dump();
  EXPECT_NE(inv["note"].get<std::string>().find("converge as a measure"), std::string::npos);
  for (const auto& [name, exact] : {std::pair{"v", c.mean_v}, std::pair{"w", c.mean_w}}) {
    const double value = s["observables"][name]["values"][0].get<double>();
    const double error = s["observables"][name]["errors"][0].get<double>();
    const double truth = std::fabs(value - exact);
    std::printf("[ neuron ] E[%s] = %.6f +/- %.1e against %.6f: off by %.1e (%.0fx)\n", name, value,
                error, exact, truth, error / truth);
    EXPECT_LE(truth, error) << name;
    EXPECT_LE(error, std::max(100.0 * truth, 1e-4)) << name;
  }
}

}  // namespace
