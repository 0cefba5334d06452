// Transient densities of `method=characteristics` through the whole pipeline (`hybgen run` on
// the .model files of tests/validation/models/, the frames read back from the .npy files)
// against closed forms derived here; none comes from hybgen.
//
//  * wrap_circle: x' = 1 on [0, 1], x ↦ x − 1 at 1, `support x >= 0` (the state space is the
//    circle): the density is carried unchanged, u(x, t) = u0(x − t) with u0 periodic.
//  * log_circle: x' = 1 + x, the same wrap. In s = ln(1 + x) the motion is uniform of period
//    ln 2 and the flux u·(1 + x) is carried: u(x, t) = g(s − t)/(1 + x), g(s) = 1 +
//    ½ sin(2πs/ln 2) (the reset lands where the speed is half: the density doubles across it).
//  * halve_transient: x' = 1, x ↦ x/2 at 1: the reset's image 1/2 lies inside the box, and a
//    point past it has two histories, the flow's and the reset's; for t ≤ 1/2,
//    u(x, t) = u0(x − t) + [1/2 ≤ x ≤ 1/2 + t] u0(x + 1/2 − t) (the mass crosses at the rate
//    it arrives, at the same speed). The nodes x = 1/2 and 1/2 + t are on jumps: left out.
//  * wrap_decay: the wrap in x times y' = −y (divergence −1): u = e^t u0(x − t, y e^t), mass
//    flowing in through the faces y = ±2 (the state space is the whole line in y).
//
//  * thermostat_transient: thermostat_fv.model's thermostat started in heat (two modes,
//    identity resets), until no mass has completed the cooling branch (t < ln 2).
//  * sawtooth_transient: log_circle with the constant reset x ↦ 0 (no inverse in the line,
//    inverted on its guard); three_mode_cycle: three modes, every reset constant; the shipped
//    integrate_and_fire neuron against an independent backward tracer (`fire`).
//  * oscillator_wall: a Hamiltonian mode and a restitution reset; helix_switch: a 3-D
//    rotation whose sense switches with two modes; qif_neuron: a quadratic integrate-and-fire
//    neuron (constant reset, five spikes); swap_clock_5d: five dimensions, a tick that swaps
//    and shrinks two rotating planes (J = 0.64); shear_reset: a saddle with a shear-and-scale
//    reset (det 0.4) and outflow, against an independent backward tracer (`shear`).
//  * method=transfer's error estimates on seven of them (the last test).
//
// Measured (2026-11-28, `ctest -R TransientClosedForms -V`): relative L1 errors 5e-16 (wrap),
// 1.5e-11 (log), 7e-16 (halve), 3.5e-11 (wrap_decay), 9e-10 (thermostat), 1.5e-11
// (sawtooth), 3e-11 (three modes), 3.5e-10 (integrate-and-fire, t = 2), 1.6e-10
// (oscillator), 8.4e-11 (helix), 1.1e-10 (qif), 1.9e-10 (5-D), 2e-10 (shear) at the ODE
// tolerance 1e-10. Asserted: 1e-8 on every frame (and mode).

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/ball_closed_form.hpp"
#include "support/cycle_closed_forms.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::Axis;
using hybgen::testing::Point;

const fs::path kWork = hybgen::testing::e2e_dir("validation_transient_closed_forms");
const hybgen::testing::Hybgen hybgen_cli{kWork / "cache"};

/// A model, its grid, and its density u(point, t) (per mode: `modes`, empty for the sum);
/// `skip` leaves out nodes on a jump at t.
struct Transient {
  std::string name;
  std::vector<Axis> axes;
  std::function<double(const Point&, double)> exact;
  std::function<bool(const Point&, double)> skip;
  std::vector<std::string> modes = {};
  std::function<double(int, const Point&, double)> exact_by_mode = {};
  std::string model = {};  ///< The .model file (default tests/validation/models/NAME.model).
  std::string sets = {};   ///< More --set options.
};

/// Run `c` by `method`; per output time and mode, the relative L1 error of its frame (nodes
/// on a jump left out when `skip_jumps`). The run's summary into *summary.
std::vector<double> frame_errors(const Transient& c, nlohmann::json* summary = nullptr,
                                 const std::string& method = "characteristics",
                                 bool skip_jumps = true) {
  const fs::path dir = hybgen::testing::own_dir(kWork) / c.name;
  fs::remove_all(dir);
  const std::string model =
      c.model.empty() ? "tests/validation/models/" + c.name + ".model" : c.model;
  // Node values against the closed forms (values=nodes: not the cell averages of
  // values=auto where the nodes under-resolve the density; read by characteristics only).
  const auto r =
      hybgen_cli("run " + model + " --quiet --out '" + dir.string() + "' --set method=" + method +
                 " --set outputs=npy --set values=nodes " + c.sets);
  EXPECT_EQ(r.code, 0) << r.out;
  if (r.code != 0) return {};
  const nlohmann::json s = hybgen::testing::read_json_file(dir / "summary.json");
  if (summary != nullptr) *summary = s;
  std::vector<double> errors;
  for (std::size_t k = 0; k < s["times"].size(); ++k) {
    const double t = s["times"][k].get<double>();
    const std::size_t n_files = c.modes.empty() ? 1 : c.modes.size();
    for (std::size_t m = 0; m < n_files; ++m) {
      char frame[64];
      if (c.modes.empty())
        std::snprintf(frame, sizeof frame, "u_%04zu.npy", k);
      else
        std::snprintf(frame, sizeof frame, "u_%04zu_%s.npy", k, c.modes[m].c_str());
      const std::vector<double> u = hybgen::rt::read_npy((dir / frame).string()).data;
      const auto mode = static_cast<int>(m);
      const double e = hybgen::testing::relative_l1(
          u, c.axes,
          [&](const Point& x) {
            return c.modes.empty() ? c.exact(x, t) : c.exact_by_mode(mode, x, t);
          },
          [&](const Point& x) { return skip_jumps && c.skip && c.skip(x, t); });
      errors.push_back(e);  // NaN (a frame of the wrong size) fails below
      std::printf("%s %s t = %.2f: relative L1 %.2e\n", c.name.c_str(),
                  c.modes.empty() ? "" : c.modes[m].c_str(), t, errors.back());
    }
  }
  return errors;
}

void expect_exact(const Transient& c) {
  const std::vector<double> e = frame_errors(c);
  ASSERT_FALSE(e.empty());
  for (const double x : e) EXPECT_LE(x, 1e-8) << c.name;
}

double wrap_u0(double x) {
  return 1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * x);
}

/// wrap_decay.model's density: e^t u0(x − t, y e^t).
double wrap_decay_density(const Point& p, double t) {
  return std::exp(t) * wrap_u0(p[0] - t) * std::exp(-4.0 * std::pow(p[1] * std::exp(t), 2));
}

// models/integrate_and_fire.model at its defaults (I = 2, τ = 2, b = 0.3). The flow is linear:
// w(t) = w0 e^{−t/2}, v(t) = I − 2 w0 e^{−t/2} + (v0 − I + 2 w0) e^{−t} (for t < 0 too), with
// divergence −3/2, so a history carries u0 e^{3t/2}. Backward from (v, w) over [0, t]:
//  * at a crossing of the image line v = 0 at backward time s, the mass reset from the
//    threshold arrives: the pre-image (1, w − b) if the neuron fires there (v' > 0), with the
//    flux ratio 1/|J|, J = v'(0, w)/v'(1, w − b) (the flux through the threshold per unit w
//    is the flux out of the image: dw is kept), and the history continues before the spike
//    at time t − s; the flow's history through v = 0 continues too (the state space is the
//    plane, and u0 is the Gaussian everywhere);
//  * a crossing of v = 1 in the firing direction ends the history (the neuron would have
//    spiked there).
// Roots by `sign_changes`; nothing from hybgen.
/// The s ∈ (1e-12, t] where g changes sign: a scan of 400 steps and bisection to 1e-15 (the
/// independent tracers below; two roots within one step would be missed).
template <class G>
std::vector<double> sign_changes(G g, double t) {
  std::vector<double> out;
  if (!(t > 1e-12)) return out;
  double a = 1e-12, ga = g(a);
  for (int k = 1; k <= 400; ++k) {
    const double b = t * k / 400, gb = g(b);
    if ((ga < 0.0) != (gb < 0.0)) {
      double lo = a, hi = b;
      for (int it = 0; it < 200 && hi - lo > 1e-15; ++it) {
        const double mid = 0.5 * (lo + hi);
        ((g(lo) < 0.0) != (g(mid) < 0.0) ? hi : lo) = mid;
      }
      out.push_back(0.5 * (lo + hi));
    }
    a = b, ga = gb;
  }
  return out;
}

namespace fire {

constexpr double kI = 2.0, kB = 0.3;

/// The flow map φ_t(v0, w0).
std::pair<double, double> flow(double v0, double w0, double t) {
  const double w = w0 * std::exp(-0.5 * t);
  return {kI - 2.0 * w + (v0 - kI + 2.0 * w0) * std::exp(-t), w};
}

/// v' at (v, w).
double speed(double v, double w) {
  return kI - v - w;
}

double u0(double v, double w) {
  return std::exp(-((v - 0.5) * (v - 0.5) + (w - 0.5) * (w - 0.5)) / 0.02);
}

/// Backward times s ∈ (1e-12, t] at which v(−s) = level.
std::vector<double> roots(double v, double w, double t, double level) {
  return sign_changes([&](double s) { return flow(v, w, -s).first - level; }, t);
}

/// u(t, v, w); *tie set when an event falls within 1e-7 of the trace's end (a node on a jump).
double density(double v, double w, double t, bool* tie) {
  std::vector<std::pair<double, double>> events;  // (s, level)
  for (const double level : {0.0, 1.0})
    for (const double s : roots(v, w, t, level)) events.emplace_back(s, level);
  std::sort(events.begin(), events.end());
  double u = 0.0;
  for (const auto& [s, level] : events) {
    if (t - s < 1e-7) *tie = true;
    const auto [ve, we] = flow(v, w, -s);
    if (level == 1.0) {
      if (speed(1.0, we) > 0.0) return u;  // it would have spiked here
      continue;
    }
    const double pre = we - kB;
    if (speed(1.0, pre) <= 0.0) continue;  // no spike lands here
    const double J = speed(0.0, we) / speed(1.0, pre);
    u += std::exp(1.5 * s) * density(1.0, pre, t - s, tie) / std::fabs(J);
  }
  const auto [v0, w0] = flow(v, w, -t);
  return u + std::exp(1.5 * t) * u0(v0, w0);
}

}  // namespace fire

/// log_circle.model's density (and sawtooth_transient.model's): g(s − t)/(1 + x), s = ln(1 + x).
double log_circle_density(const Point& x, double t) {
  const double s = std::log(1.0 + x[0]);
  return (1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * (s - t) / std::log(2.0))) / (1.0 + x[0]);
}

Transient wrap_circle() {
  return {"wrap_circle",
          {{0.0, 1.0, 201}},
          [](const Point& x, double t) { return wrap_u0(x[0] - t); },
          {}};
}

Transient log_circle() {
  return {"log_circle", {{0.0, 1.0, 201}}, log_circle_density, {}};
}

TEST(TransientClosedForms, UniformMotionOnACircle) {
  expect_exact(wrap_circle());
}

TEST(TransientClosedForms, ANonUniformCircleDoublesTheDensityAcrossTheReset) {
  expect_exact(log_circle());
}

/// qif_neuron.model: v' = v² + 1 on [−1, 3], v ↦ −1 at 3 (a constant reset, J = 1/5). In the
/// phase θ = atan v + π/4 (period T = atan 3 + π/4) the flux is carried:
/// u(t, v) = q0(θ − t)/(v² + 1), q0(θ) = (1 + ½ sin 2πθ/T)/T.
Transient qif_neuron() {
  return {"qif_neuron",
          {{-1.0, 3.0, 201}},
          [](const Point& p, double t) {
            const double period = std::atan(3.0) + 0.25 * std::numbers::pi;
            const double theta = std::atan(p[0]) + 0.25 * std::numbers::pi;
            return (1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * (theta - t) / period)) / period /
                   (p[0] * p[0] + 1.0);
          },
          {}};
}

TEST(TransientClosedForms, AQuadraticIntegrateAndFireNeuronSpikesFiveTimes) {
  expect_exact(qif_neuron());
}

TEST(TransientClosedForms, AConstantResetIsInvertedOnItsGuard) {
  // log_circle's motion and density with the reset x ↦ 0 (DΔ = 0: no inverse in the line; the
  // characteristics find the pre-image x = 1 of the image x = 0 on the guard).
  expect_exact({"sawtooth_transient", {{0.0, 1.0, 201}}, log_circle_density, {}});
}

TEST(TransientClosedForms, AResetImageInsideTheBoxAddsABranch) {
  const auto u0 = [](double x) { return std::exp(-50.0 * (x - 0.6) * (x - 0.6)); };
  expect_exact({"halve_transient",
                {{0.0, 1.0, 201}},
                [u0](const Point& p, double t) {
                  const double x = p[0];
                  return u0(x - t) + (x >= 0.5 && x <= 0.5 + t ? u0(x + 0.5 - t) : 0.0);
                },
                [](const Point& p, double t) {
                  return std::fabs(p[0] - 0.5) < 1e-9 || std::fabs(p[0] - 0.5 - t) < 1e-9;
                }});
}

Transient wrap_decay() {
  return {"wrap_decay",
          {{0.0, 1.0, 81}, {-2.0, 2.0, 81}},
          wrap_decay_density,
          [](const Point& p, double t) {
            const double r = std::remainder(p[0] - t, 1.0);
            return t > 0.0 && std::fabs(r) < 1e-9;
          }};
}

TEST(TransientClosedForms, AWrapTimesAContractionInTwoDimensions) {
  // The column x = t (mod 1) at each t is left out here: its backward characteristics reach
  // the reset image x = 0 exactly at t = 0, a discontinuity; ATieAtTheInitialTimeKeepsAHistory
  // below keeps it.
  expect_exact(wrap_decay());
}

TEST(TransientClosedForms, AThermostatStartedInOneModeSwitchesIntoTheOther) {
  // Heat: the heating flow T(t) = 4 − (4 − T0)e^{−t}, so u = u0(T0) e^t with T0 = 4 − (4 − T)e^t,
  // except above 2 where the history crossed the guard (it continued in cool). Cool: the mass
  // that crossed T = 2 at s = t − ln(2/T) ≥ 0 with the flux 2·u_heat(2, s), compressed by the
  // cooling flow (u·T carried): u = 2 u_heat(2, s)/T. Nodes T = 2 and T = 2e^{−t}: jumps.
  const auto u0 = [](double T) { return std::exp(-20.0 * (T - 1.5) * (T - 1.5)); };
  const auto heat = [u0](double T, double t) {
    const double T0 = 4.0 - (4.0 - T) * std::exp(t);
    return T0 < 2.0 && T >= 2.0 ? 0.0 : u0(T0) * std::exp(t);
  };
  Transient c{"thermostat_transient", {{0.8, 2.2, 281}}, {}, [](const Point& p, double t) {
                return std::fabs(p[0] - 2.0) < 1e-9 || std::fabs(p[0] - 2.0 * std::exp(-t)) < 1e-9;
              }};
  c.modes = {"heat", "cool"};
  c.exact_by_mode = [heat](int mode, const Point& p, double t) {
    const double T = p[0];
    if (mode == 0) return heat(T, t);
    const double s = t - std::log(2.0 / T);
    return s >= 0.0 && T <= 2.0 ? 2.0 * heat(2.0 - 1e-15, s) / T : 0.0;
  };
  expect_exact(c);
}

/// Every reset sets x to a constant (inverted on its guard, a point). In the phase θ(m, x)
/// (the model file) the flux is carried: u(t, m, x) = q0(θ − t mod P)/|f_m(x)| with
/// q0(θ) = (1 + ½ sin 2πθ/P)/P, continuous across every switch; B lives on [0, 1/2] (its
/// node x = 1/2, the guard, is left out).
Transient three_mode_cycle() {
  const double ta = std::log(1.5), tb = std::log(4.0 / 3.0),
               period = std::log(2.0) + 0.5 * std::log(3.0);
  Transient c{"three_mode_cycle", {{0.0, 1.0, 201}}, {}, [](const Point& p, double) {
                return std::fabs(p[0] - 0.5) < 1e-9;
              }};
  c.modes = {"A", "B", "C"};
  c.exact_by_mode = [=](int m, const Point& p, double t) {
    const double x = p[0];
    if (m == 1 && x > 0.5) return 0.0;
    const double theta = m == 0   ? std::log((2.0 + x) / 2.0)
                         : m == 1 ? ta + std::log(2.0 / (2.0 - x))
                                  : ta + tb + 0.5 * std::log(3.0 / (1.0 + 2.0 * x));
    const double speed = m == 0 ? 2.0 + x : (m == 1 ? 2.0 - x : 1.0 + 2.0 * x);
    return (1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * (theta - t) / period)) / period / speed;
  };
  return c;
}

TEST(TransientClosedForms, AThreeModeCycleOfConstantResets) {
  expect_exact(three_mode_cycle());
}

/// The C¹ bump ((r² − ρ²)₊/(2r²))²·4 of radius r = 0.6 at (cx, cy), as the model files write it.
double c1_bump(double x, double y, double cx, double cy) {
  const double d = 0.36 - (x - cx) * (x - cx) - (y - cy) * (y - cy);
  return d > 0.0 ? (d / 0.36) * (d / 0.36) : 0.0;
}

/// A Hamiltonian mode and a restitution reset (e = 1): u(t, y) = u0(R₋ₜy) + u0(−R₋ₜy), R_t the
/// clockwise rotation (the model file); the bump reaches the wall between t = 1.36 and 2.54.
/// The support (the half-disk of radius 2) is where the bump and its images live.
Transient oscillator_wall() {
  return {"oscillator_wall",
          {{0.0, 2.0, 41}, {-2.0, 2.0, 81}},
          [](const Point& y, double t) {
            if (y[0] * y[0] + y[1] * y[1] > 4.0) return 0.0;
            const double c = std::cos(t), s = std::sin(t);
            const double bx = y[0] * c - y[1] * s, bp = y[0] * s + y[1] * c;  // R₋ₜy
            const auto u0 = [](double x, double p) {
              return x < 0.0 ? 0.0 : c1_bump(x, p, 1.0, 0.4);
            };
            return u0(bx, bp) + u0(-bx, -bp);
          },
          {}};
}

TEST(TransientClosedForms, AnOscillatorAgainstAnElasticWall) {
  expect_exact(oscillator_wall());
}

/// Two modes with identity resets, J = −2 and −1/2 (the model file): along the phase θ the
/// flux is carried and the plane turns by Ψ̃(θ) (Ψ̃(θ + nP) = Ψ(θ) + n/2), so
/// u(t, m, x, y, z) = G(R(−a)(x, y)) h(θ − t)/|z'_m|, a = Ψ̃(θ) − Ψ̃(θ − t). Up to three
/// switches by t = 3, both modes, the faces z = 0, 1 included.
Transient helix_switch() {
  const double period = 1.5;
  const auto turn = [period](double theta) {
    const double n = std::floor(theta / period), r = theta - n * period;
    return 0.5 * n + (r <= 1.0 ? r : 1.0 - (r - 1.0));
  };
  Transient c{"helix_switch", {{-1.2, 1.2, 25}, {-1.2, 1.2, 25}, {0.0, 1.0, 21}}, {}, {}};
  c.modes = {"up", "down"};
  c.exact_by_mode = [=](int m, const Point& p, double t) {
    if (p[0] * p[0] + p[1] * p[1] > 1.44) return 0.0;
    const double th = m == 0 ? p[2] : 1.0 + 0.5 * (1.0 - p[2]), th0 = th - t;
    const double a = -(turn(th) - turn(th0)), ca = std::cos(a), sa = std::sin(a);
    const double bx = ca * p[0] - sa * p[1], by = sa * p[0] + ca * p[1];
    const double h = 1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * th0 / period);
    return c1_bump(bx, by, 0.5, 0.0) * h / (m == 0 ? 1.0 : 2.0);
  };
  return c;
}

TEST(TransientClosedForms, AHelixWhoseSenseSwitchesInThreeDimensions) {
  expect_exact(helix_switch());
}

TEST(TransientClosedForms, TransferErrorEstimatesCoverTheTrueErrorsWithinTenTimes) {
  // method=transfer on seven of the models above (1-D to 3-D, one to three modes, constant and
  // identity resets, a restitution wall, inflow through faces), with each model's settings:
  // its summary's transfer.errors (methods.hpp, add_transfer_errors: the difference from the
  // halved grid, times max(2, 1/(2^p − 1)) for the observed order p) against the true
  // relative L1 error of each frame (max over modes, every node). Measured ratios 2.8–6.5
  // (2026-11-28). thermostat_transient is left out: its heat mode empties by t = 0.6 except
  // for mass flowing in through the face T = 0.8, which the characteristics count (the state
  // space is the line) and the transfer operator does not (the box is its world), so its
  // relative error there is 1 whatever the grid.
  for (const Transient& c : {wrap_circle(), log_circle(), qif_neuron(), wrap_decay(),
                             oscillator_wall(), three_mode_cycle(), helix_switch()}) {
    nlohmann::json s;
    const std::vector<double> e = frame_errors(c, &s, "transfer", false);
    const std::size_t n_mode = c.modes.empty() ? 1 : c.modes.size();
    ASSERT_EQ(e.size(), s["times"].size() * n_mode) << c.name;
    const nlohmann::json& est = s["transfer"]["errors"];
    ASSERT_EQ(est.size(), s["times"].size()) << c.name;
    for (std::size_t k = 0; k < est.size(); ++k) {
      double truth = 0.0;
      for (std::size_t m = 0; m < n_mode; ++m) truth = std::max(truth, e[k * n_mode + m]);
      const double t = s["times"][k].get<double>();
      ASSERT_TRUE(est[k].is_number()) << c.name << " t = " << t;
      const double estimate = est[k].get<double>();
      std::printf("%s transfer t = %.2f: true %.3e, estimated %.3e (ratio %.2f)\n", c.name.c_str(),
                  t, truth, estimate, truth > 0.0 ? estimate / truth : 0.0);
      if (t == 0.0) {
        EXPECT_EQ(estimate, 0.0) << c.name;  // u0 at the nodes
        EXPECT_LE(truth, 1e-14) << c.name;
        continue;
      }
      EXPECT_GE(estimate, truth) << c.name << " t = " << t;
      EXPECT_LE(estimate, 10.0 * truth) << c.name << " t = " << t;
    }
  }
}

/// ball_annulus.model (inner = 0.6) and ball_compact.model (inner = 0): the elastic ball
/// (m = g = 1) from u0 = exp(−(x − 1)² − p²)·((1.8 − E)₊/w)³·((E − inner)₊/0.6)³, w = 0.6 on
/// the annulus, (1.8 − E)₊³/1.8³ alone for the compact one; exact u(t) = u0 ∘ φ₋ₜ
/// (tests/support/ball_closed_form.hpp), on an n × n grid of [0, 2] × [−2, 2].
Transient ball(const std::string& name, int n, double inner) {
  const auto u0 = [inner](double x, double p) {
    if (x < 0.0) return 0.0;
    const double E = 0.5 * p * p + x, g = std::exp(-(x - 1.0) * (x - 1.0) - p * p);
    const auto cube = [](double v) { return v * v * v; };
    if (inner <= 0.0) return g * cube(std::max(1.8 - E, 0.0) / 1.8);
    return g * cube(std::max(1.8 - E, 0.0) / 0.6) * cube(std::max(E - inner, 0.0) / 0.6);
  };
  const std::string grid = std::to_string(n) + "x" + std::to_string(n);
  return {name + "_" + std::to_string(n),
          {{0.0, 2.0, n}, {-2.0, 2.0, n}},
          [u0](const Point& y, double t) {
            return hybgen::testing::ball_pullback_elastic(y[0], y[1], t, u0);
          },
          {},
          {},
          {},
          "tests/validation/models/" + name + ".model",
          "--set grid=" + grid + " --set scheme=fv"};
}

/// Per output time, the true error (max over modes; nodes on a jump left out: the generator
/// gives them the mean of their one-sided values) of `c` by `method=transfer` with its `sets`
/// (the scheme among them), after checking that each of the run's transfer.errors covers its error
/// within `wide` times (0 at t = 0) and the budget closes to rounding. The summary into *summary.
std::vector<double> covered_errors(const Transient& c, nlohmann::json* summary = nullptr,
                                   double wide = 10.0) {
  nlohmann::json s;
  const std::vector<double> e = frame_errors(c, &s, "transfer", true);
  if (summary) *summary = s;
  const std::size_t n_mode = c.modes.empty() ? 1 : c.modes.size();
  EXPECT_EQ(e.size(), s["times"].size() * n_mode) << c.name;
  if (e.size() != s["times"].size() * n_mode) return {};
  const nlohmann::json& est = s["transfer"]["errors"];
  EXPECT_EQ(est.size(), s["times"].size()) << c.name;
  EXPECT_LE(s["transfer"]["budget_defect"].get<double>(), 1e-12) << c.name;
  std::vector<double> truth(s["times"].size(), 0.0);
  for (std::size_t k = 0; k < truth.size() && k < est.size(); ++k) {
    for (std::size_t m = 0; m < n_mode; ++m) truth[k] = std::max(truth[k], e[k * n_mode + m]);
    const double t = s["times"][k].get<double>();
    EXPECT_TRUE(est[k].is_number()) << c.name << " t = " << t;
    if (!est[k].is_number()) continue;
    const double estimate = est[k].get<double>();
    std::printf("%s %s t = %.2f: true %.3e, estimated %.3e (ratio %.2f)\n", c.name.c_str(),
                s["transfer"]["scheme"].get<std::string>().c_str(), t, truth[k], estimate,
                truth[k] > 0.0 ? estimate / truth[k] : 0.0);
    if (t == 0.0) {
      EXPECT_EQ(estimate, 0.0) << c.name;
      continue;
    }
    EXPECT_GE(estimate, truth[k]) << c.name << " t = " << t;
    EXPECT_LE(estimate, wide * truth[k]) << c.name << " t = " << t;
  }
  return truth;
}

TEST(TransientClosedForms, TheTimeSteppedGeneratorOnCyclesWallsAndSwitches) {
  // method=transfer, scheme=fv (runtime/include/hybgen/rt/methods/generator_march.hpp) on the
  // models above whose guards are coordinate planes: the density jumps exactly at guards and
  // reset images, and each frame's estimate covers its error within ten times. The last
  // frame's error is held to twice what was measured (2026-11-29), against the hat scheme's
  // (the default, first order) on the same grid and settings.
  struct Bound {
    Transient c;
    double fv;  // the last frame's relative L1 error, at most
  };
  // Measured (fv_order 5, the default), fv against hat: wrap 3.0e-7 / 1.5e-4, log 1.3e-7 /
  // 5.0e-4, three modes 3.1e-8 / 1.2e-3, qif 8.2e-8 / 3.4e-3 (1-D, jumps exact); the
  // oscillator (a rotation, 41 × 81) 1.6e-2 / 7.9e-2 and the helix (25 × 25 × 21) 5.4e-2 /
  // 0.14, both a C¹ bump on a coarse grid. Estimates 2.5–6.7×. With fv_order=3: 7.9e-6,
  // 1.0e-5, 2.1e-6, 6.1e-5, 6.3e-2 and 0.13.
  for (const Bound& b : {Bound{wrap_circle(), 6e-7}, Bound{log_circle(), 3e-7},
                         Bound{three_mode_cycle(), 6.3e-8}, Bound{oscillator_wall(), 3.2e-2},
                         Bound{helix_switch(), 0.11}, Bound{qif_neuron(), 1.7e-7}}) {
    Transient fv = b.c, hat = b.c;
    fv.sets += " --set scheme=fv";
    fv.name += "_fv";
    if (fv.model.empty()) fv.model = "tests/validation/models/" + b.c.name + ".model";
    hat.sets += " --set scheme=hat";
    if (hat.model.empty()) hat.model = "tests/validation/models/" + hat.name + ".model";
    hat.name += "_hat";
    const std::vector<double> e = covered_errors(fv);
    // The hat scheme's error, printed for contrast; not run sanitized (the hat transfer runs
    // sanitized in tests/rt/test_transfer.cpp).
    const std::vector<double> h = hybgen::testing::kSanitized
                                      ? std::vector<double>{}
                                      : frame_errors(hat, nullptr, "transfer", false);
    ASSERT_FALSE(e.empty()) << b.c.name;
    std::printf("%s: last frame fv %.3e, hat %.3e\n", b.c.name.c_str(), e.back(),
                h.empty() ? -1.0 : h.back());
    EXPECT_LE(e.back(), b.fv) << b.c.name;
  }
}

TEST(TransientClosedForms, TheTimeSteppedGeneratorOnTheBallConvergesAtSecondOrderOrBetter) {
  // The elastic ball on the annulus 0.6 ≤ E ≤ 1.8 (ball_annulus.model), t = 0 … 10 every 0.5,
  // on 129² and 257² (fv_order 5, the default): the observed order against the closed form,
  // every estimate covering its error. Measured (2026-11-29): 1.13e-3 → 1.57e-4 at t = 2
  // (order 2.85), 1.02e-2 → 1.91e-3 at t = 10 (2.4: by then the orbits' shear has wound the
  // density into stripes a few cells wide, which any grid scheme damps); the third-order
  // reconstruction 1.9e-2 and the hat scheme 2.5e-2 at 257², t = 10. At 129² after t = 8 the
  // estimate is up to 12.2× the error: its coarse grid (65²) does not resolve the stripes, and
  // the difference from it alone is 11.5× the 129² error; 15× is allowed there.
  const std::vector<double> coarse = covered_errors(ball("ball_annulus", 129, 0.6), nullptr, 15.0);
  const std::vector<double> fine = covered_errors(ball("ball_annulus", 257, 0.6));
  ASSERT_EQ(coarse.size(), 21u);
  ASSERT_EQ(fine.size(), 21u);
  for (const std::size_t k : {std::size_t{4}, std::size_t{20}}) {
    const double order = std::log2(coarse[k] / fine[k]), t = 0.5 * static_cast<double>(k);
    std::printf("ball_annulus t = %.1f: %.3e -> %.3e, order %.2f\n", t, coarse[k], fine[k], order);
    EXPECT_GE(order, 2.0) << "t = " << t;
  }
  EXPECT_LE(fine[20], 4e-3);  // the aim at 257², t = 10, is 1e-2 (docs/methods.md, "transfer")
}

/// models/bouncing_ball.model's density in its box [0, 2] × [−2, 2] (e = m = g = 1): the exact
/// flow of u0 = exp(−(x − 1)² − p²) with the mass that has left the box through x = 2 or
/// |p| = 2 removed, since a grid method's box has no inflow. Backward from (x, p) the orbit is
/// the forward one from (x, −p) mirrored in p; with v = √(2E) and τ = v + p that orbit's phase
/// since its last impact (x = vτ − τ²/2, momentum v − τ), an orbit with E > 2 is in the box for
/// τ in [v − 2, τa] (rising, τa = v − √(v² − 4) where x = 2) or [2v − τa, v + 2] (falling), and
/// it stays in the box over t iff τ + t does not pass the end of its piece; E ≤ 2 never
/// leaves. By t = 10 every orbit with E > 2 has left: a jump along E = 2.
double paper_ball_in_box(double x, double p, double t) {
  const double E = 0.5 * p * p + x;
  if (E > 2.0) {
    const double v = std::sqrt(2.0 * E), tau = v + p, ta = v - std::sqrt(v * v - 4.0);
    if (tau + t > (tau <= ta ? ta : v + 2.0)) return 0.0;
  }
  return hybgen::testing::ball_pullback_elastic(
      x, p, t, [](double a, double b) { return std::exp(-(a - 1.0) * (a - 1.0) - b * b); });
}

/// Whether E = p²/2 + x = 2 crosses the dual cell of the node (x, p) of an n × n grid of
/// [0, 2] × [−2, 2] (E's least and largest values over the cell straddle 2).
bool on_ball_box_jump(double x, double p, int n) {
  const double hx = 2.0 / (n - 1), hp = 4.0 / (n - 1);
  const double p_far = std::fabs(p) + 0.5 * hp, p_near = std::max(std::fabs(p) - 0.5 * hp, 0.0);
  return x - 0.5 * hx + 0.5 * p_near * p_near <= 2.0 && x + 0.5 * hx + 0.5 * p_far * p_far >= 2.0;
}

/// The paper's ball (models/bouncing_ball.model) by method=transfer with `sets`, n × n, output at
/// t = 0 and 10 only (the transfer step set apart from dt); against paper_ball_in_box, the nodes
/// on the jump E = 2 left out with `skip_jumps` (frame_errors).
Transient paper_ball(int n, const std::string& sets) {
  const std::string grid = std::to_string(n) + "x" + std::to_string(n);
  return {"papers_ball_" + std::to_string(n),
          {{0.0, 2.0, n}, {-2.0, 2.0, n}},
          [](const Point& y, double t) { return paper_ball_in_box(y[0], y[1], t); },
          [n](const Point& y, double) { return on_ball_box_jump(y[0], y[1], n); },
          {},
          {},
          "models/bouncing_ball.model",
          "--set grid=" + grid + " --set t_end=10 --set dt=10 " + sets};
}

TEST(TransientClosedForms, TheGalerkinTransferOnThePapersBallIsWithinOnePercent) {
  // scheme=galerkin (transfer.hpp: the density's hat expansion moved exactly by the flow and
  // projected back, a conservative Lagrange–Galerkin step) on the paper's ball at 257², t = 10,
  // with the transfer step dt = 0.5 and 0.05: relative L1 against the box-limited closed form,
  // the nodes whose dual cell the jump E = 2 crosses (769 of 66049) left out, at most 1e-2 —
  // the aim of second order away from jumps. Measured (2026-12-01): 7.9e-3 off the jump and
  // 1.16e-2 on every node with either step (estimates 2.0e-2 and 2.8e-2); on the same grid hat
  // gives 2.7e-2 and 0.145 off the jump, fv 2.0e-2 (docs/methods.md, "transfer"): the error
  // does not grow with the number of steps as hat's does (×4.7 from 20 to 200 steps). The
  // estimate covers the error on every node, and mass + outflow balances to rounding.
  for (const char* step : {"0.5", "0.05"}) {
    Transient c = paper_ball(257, std::string("--set scheme=galerkin --set step=") + step);
    c.name += std::string("_galerkin_") + step;
    nlohmann::json s;
    const std::vector<double> off = frame_errors(c, &s, "transfer", true);
    ASSERT_EQ(off.size(), 2u) << c.name;
    const std::vector<double> u =
        hybgen::rt::read_npy((hybgen::testing::own_dir(kWork) / c.name / "u_0001.npy").string())
            .data;
    const double all = hybgen::testing::relative_l1(
        u, c.axes, [](const Point& y) { return paper_ball_in_box(y[0], y[1], 10.0); },
        [](const Point&) { return false; });
    const double estimate = s["transfer"]["errors"][1].get<double>();
    std::printf(
        "papers_ball galerkin step %s, t = 10: %.3e off the jump, %.3e on every node, "
        "estimated %.3e, min %.3g\n",
        step, off[1], all, estimate, s["transfer"]["min_value"].get<double>());
    EXPECT_LE(off[1], 1e-2) << step;
    EXPECT_GE(estimate, all) << step;
    EXPECT_LE(estimate, 10.0 * all) << step;
    EXPECT_LE(s["transfer"]["budget_defect"].get<double>(), 1e-12) << step;
    EXPECT_EQ(s["transfer"]["scheme"], "galerkin");
  }
}

/// rotation_bump.model: x' = −y, y' = x, no guard; u0 a Gaussian of width 0.25 about (1, 0),
/// turned unchanged: u(t) = u0(R(−t) y), on an n × n grid of [−2.6, 2.6]², by `sets`.
Transient rotation_bump(int n, const std::string& sets) {
  const std::string grid = std::to_string(n) + "x" + std::to_string(n);
  return {"rotation_bump_" + std::to_string(n),
          {{-2.6, 2.6, n}, {-2.6, 2.6, n}},
          [](const Point& y, double t) {
            const double a = std::cos(t) * y[0] + std::sin(t) * y[1];
            const double b = -std::sin(t) * y[0] + std::cos(t) * y[1];
            return std::exp(-((a - 1.0) * (a - 1.0) + b * b) / (2.0 * 0.25 * 0.25));
          },
          {},
          {},
          {},
          "tests/validation/models/rotation_bump.model",
          "--set grid=" + grid + " " + sets};
}

TEST(TransientClosedForms, TheGalerkinTransferIsSecondOrderAwayFromGuards) {
  // A rotation without guards (rotation_bump.model, step 0.5 to t = 2) by scheme=galerkin on
  // 65² and 129²: the observed order against the closed form, each estimate covering its
  // error within ten times (20 on 65², whose estimate comes from 33², where the spacing 0.16
  // does not resolve the width 0.25: 14–16× measured; 8.4× on 129² at t = 2). Measured
  // (2026-12-01): 6.25e-4 → 7.37e-5 (order 3.1) and 1.53e-5 at 257² (2.3); hat 1.9e-2 and 4.8e-3 at
  // 129² and 257². At a guard a sample's sub-cell that straddles the crossing is booked whole on
  // one side, as hat's (docs/methods.md, "transfer"): the ball's annulus converges at order 1.4–1.8
  // there.
  std::vector<double> e[2];
  int i = 0;
  for (const int n : {65, 129}) {
    Transient c = rotation_bump(n, "--set scheme=galerkin");
    e[i++] = covered_errors(c, nullptr, n == 65 ? 20.0 : 10.0);
  }
  ASSERT_EQ(e[0].size(), 5u);
  ASSERT_EQ(e[1].size(), 5u);
  const double order = std::log2(e[0][4] / e[1][4]);
  std::printf("rotation_bump galerkin t = 2: %.3e -> %.3e, order %.2f\n", e[0][4], e[1][4], order);
  EXPECT_GE(order, 1.8);
  EXPECT_LE(e[1][4], 1.5e-4);
}

TEST(TransientClosedForms, TheTimeSteppedGeneratorSaysHowFarOffItIsNearTheBallsOrigin) {
  // ball_compact.model keeps the mass near the origin, where the orbits' period 2√(2E) goes
  // to 0: by time t the exact density winds into stripes of width ~E^{3/2}/t in energy, finer
  // than the grid below E* ~ (tΔx)^{2/3}, a region of area ~tΔx — first order for any grid
  // method (measured 257² → 513²: 8.5e-2 → 3.7e-2 at t = 10). The estimate still covers.
  const std::vector<double> e = covered_errors(ball("ball_compact", 129, 0.0));
  ASSERT_EQ(e.size(), 21u);
}

/// swap_clock_5d.model: A = (x1, x2) turns at 1, B = (x3, x4) at 2, c' = 1; at c = 1 the state
/// jumps to (0.8 B, A, c − 1) with J = 0.64. Backward over t the clock meets the image c = 0 at
/// c, c + 1, …, each time (A, B) ← (B, A/0.8) and the density ×1/0.64: u = 0.64^−n u0(foot).
double swap_clock_density(const Point& y, double t) {
  if (y[4] < 0.0 || y[4] > 1.0) return 0.0;
  std::array<double, 4> x{y[0], y[1], y[2], y[3]};
  const auto rotate = [&x](std::size_t i, double a) {
    const double p = x[i], q = x[i + 1];
    x[i] = std::cos(a) * p - std::sin(a) * q;
    x[i + 1] = std::sin(a) * p + std::cos(a) * q;
  };
  double c = y[4], left = t, factor = 1.0;
  for (;;) {
    const double run = std::min(left, c);
    rotate(0, -run);
    rotate(2, -2.0 * run);
    if (left <= c) break;
    left -= c;
    x = {x[2], x[3], x[0] / 0.8, x[1] / 0.8};
    c = 1.0;
    factor /= 0.64;
  }
  const double r2 =
      (x[0] - 0.5) * (x[0] - 0.5) + x[1] * x[1] + x[2] * x[2] + (x[3] - 0.4) * (x[3] - 0.4);
  const double d = 0.36 - r2;
  const double bump = d > 0.0 ? (d / 0.36) * (d / 0.36) : 0.0;
  return factor * bump * (1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * (c - left)));
}

TEST(TransientClosedForms, FiveDimensionsWithATickThatSwapsAndShrinksThePlanes) {
  // Four ticks back by t = 2.8 (the output times avoid the ticks; the model file).
  expect_exact({"swap_clock_5d",
                {{-1.2, 1.2, 9}, {-1.2, 1.2, 9}, {-1.2, 1.2, 9}, {-1.2, 1.2, 9}, {0.0, 1.0, 12}},
                swap_clock_density,
                {},
                {},
                {},
                {},
                "--set budget=off"});
}

// shear_reset.model traced backward here, as the neuron above: the flow e^{At} in closed form
// (A's eigenvalues μ± = (−1/2 ± √2.49)/2), crossings of the image line x = 0.5 + 0.3125 y
// (B maps the guard x = 1 onto it) spawn the pre-image B⁻¹w = (2w_x − 0.625 w_y, 1.25 w_y)
// where the kick fires (x' > 0 there) with 1/|J|, J = (0.1625 + 0.40925 y)/(0.5 + 0.2 y) at
// the pre-image (∇sᵀ adj(B) X(Bz)/∇sᵀ X(z)); a crossing of x = 1 the way the kick fires ends
// a history; a history carries u0 e^{s/2}. Nothing from hybgen.
namespace shear {

/// e^{At} z.
std::array<double, 2> flow(const std::array<double, 2>& z, double t) {
  const double root = std::sqrt(0.25 + 2.24), mp = 0.5 * (-0.5 + root), mm = 0.5 * (-0.5 - root);
  const double ep = std::exp(mp * t), em = std::exp(mm * t);
  // e^{At} = (e^{μ+ t}(A − μ− I) − e^{μ− t}(A − μ+ I))/(μ+ − μ−).
  const auto apply = [&z](double mu) {
    return std::array<double, 2>{(0.5 - mu) * z[0] + 0.2 * z[1], 0.3 * z[0] + (-1.0 - mu) * z[1]};
  };
  const auto a = apply(mm), b = apply(mp);
  return {(ep * a[0] - em * b[0]) / (mp - mm), (ep * a[1] - em * b[1]) / (mp - mm)};
}

/// Backward times s ∈ (1e-12, t] where f(e^{−As} z) changes sign.
template <class F>
std::vector<double> roots(const std::array<double, 2>& z, double t, F f) {
  return sign_changes([&](double s) { return f(flow(z, -s)); }, t);
}

/// u(t, z); *tie set when an event falls within 1e-7 of the trace's end (a node on a jump).
double density(const std::array<double, 2>& z, double t, bool* tie) {
  std::vector<std::pair<double, int>> events;  // (s, 0: image line, 1: guard)
  for (const double s : roots(z, t, [](const auto& w) { return w[0] - 0.5 - 0.3125 * w[1]; }))
    events.emplace_back(s, 0);
  for (const double s : roots(z, t, [](const auto& w) { return w[0] - 1.0; }))
    events.emplace_back(s, 1);
  std::sort(events.begin(), events.end());
  double u = 0.0;
  for (const auto& [s, kind] : events) {
    if (t - s < 1e-7) *tie = true;
    const auto w = flow(z, -s);
    if (kind == 1) {
      if (0.5 * w[0] + 0.2 * w[1] > 0.0) return u;  // the kick would have fired here
      continue;
    }
    const std::array<double, 2> pre{2.0 * w[0] - 0.625 * w[1], 1.25 * w[1]};
    const double speed = 0.5 + 0.2 * pre[1];
    if (speed <= 0.0) continue;  // the kick does not fire there
    const double J = (0.1625 + 0.40925 * pre[1]) / speed;
    u += std::exp(0.5 * s) * density(pre, t - s, tie) / std::fabs(J);
  }
  const auto z0 = flow(z, -t);
  return u + std::exp(0.5 * t) * std::exp(-8.0 * (z0[0] * z0[0] + (z0[1] - 0.2) * (z0[1] - 0.2)));
}

}  // namespace shear

TEST(TransientClosedForms, AShearAndScaleResetWithOutflow) {
  // |det DΔ| = 0.4 with a shear, a saddle whose left side leaves through x = −1, the image
  // line inside the box (the model file), against `shear::density`. Left out: the nodes on
  // the image line and on the guard x = 1 (two one-sided values there) and on a jump.
  expect_exact({"shear_reset",
                {{-1.0, 1.0, 41}, {-1.5, 1.5, 61}},
                [](const Point& p, double t) {
                  bool tie = false;
                  return shear::density({p[0], p[1]}, t, &tie);
                },
                [](const Point& p, double t) {
                  bool tie = false;
                  (void)shear::density({p[0], p[1]}, t, &tie);
                  return tie || std::fabs(p[0] - 0.5 - 0.3125 * p[1]) < 1e-9 ||
                         std::fabs(p[0] - 1.0) < 1e-9;
                }});
}

TEST(TransientClosedForms, AReducedLieGroupSystemReflectsOffItsWall) {
  // translation_wall.model: a Lie-group model (the translations of the plane) reduced by
  // hybgen to ζ' = 0, q' = ζ_a with ζ_a ↦ −ζ_a at q = 0 (the model file). Backward from
  // (ζ_a, ζ_b, q) the particle meets the wall iff q − ζ_a t < 0: u = u0 at the foot, reflected
  // once. The nodes with q = ζ_a t lie on the jump (their history reaches the wall at t = 0).
  const auto u0 = [](double za, double zb, double q) {
    return std::exp(-4.0 * (za + 0.5) * (za + 0.5) - 2.0 * zb * zb - 8.0 * (q - 0.8) * (q - 0.8));
  };
  expect_exact(
      {"translation_wall",
       {{-1.5, 1.5, 31}, {-1.0, 1.0, 11}, {0.0, 2.0, 41}},
       [u0](const Point& p, double t) {
         const double q0 = p[2] - p[0] * t;
         return q0 >= 0.0 ? u0(p[0], p[1], q0) : u0(-p[0], p[1], -q0);
       },
       [](const Point& p, double t) { return t > 0.0 && std::fabs(p[2] - p[0] * t) < 1e-9; }});
}

TEST(TransientClosedForms, ATwoToOneResetSumsBothPreImages) {
  // tent_clock.model: the tick maps y through the tent map, two pre-images y/2 and 1 − y/2 of
  // every y (J = ±2). Backward the clock meets the image x = 0 at x, x + 1, … < t:
  // u = Pⁿ[u0(x − t + n, ·)](y), P[f](y) = (f(y/2) + f(1 − y/2))/2, and a history through y = 1
  // (outside the support y < 1) is none. derive once took 1 − |2y − 1| for affine (its second
  // derivative vanishes where defined) and inverted one branch: half the mass per tick.
  const auto u0 = [](double x, double y) {
    return y < 1.0
               ? (0.5 + 0.4 * y * (x - 0.5)) * (1.0 + 0.3 * std::sin(2.0 * std::numbers::pi * y))
               : 0.0;
  };
  expect_exact({"tent_clock",
                {{0.0, 1.0, 22}, {0.0, 1.0, 40}},
                [u0](const Point& p, double t) {
                  const int n = t <= p[0] ? 0 : static_cast<int>(std::ceil(t - p[0]));
                  const double x0 = p[0] - t + n;
                  const auto P = [&](const auto& self, int k, double y) -> double {
                    if (y >= 1.0) return 0.0;
                    if (k == 0) return u0(x0, y);
                    return 0.5 * (self(self, k - 1, 0.5 * y) + self(self, k - 1, 1.0 - 0.5 * y));
                  };
                  return P(P, n, p[1]);
                },
                {}});
}

/// zeno_ball.model (e = 0.6) backward from (x, p) over t: the ground after
/// s = −p + √(p² + 2x), where the ball arrived with √(p² + 2x) and left the ground before with
/// −√(p² + 2x)/e; each bounce back divides by J = e². *tie: a bounce within 1e-7 of the trace's
/// end (a node on a jump).
double zeno_ball_density(double x, double p, double t, bool* tie) {
  const double e = 0.6;
  double factor = 1.0, left = t;
  for (int bounce = 0; bounce < 200; ++bounce) {
    const double s = -p + std::sqrt(p * p + 2.0 * x);
    if (std::fabs(s - left) < 1e-7) *tie = true;
    if (s >= left) {
      const double x0 = x - p * left - 0.5 * left * left, p0 = p + left;
      return x0 >= 0.0 ? factor * std::exp(-(x0 - 1.0) * (x0 - 1.0) - p0 * p0) : 0.0;
    }
    left -= s;
    p = -std::sqrt(p * p + 2.0 * x) / e;
    x = 0.0;
    factor /= e * e;
  }
  return std::nan("");
}

TEST(TransientClosedForms, ABallWithRestitutionAndItsZenoAtom) {
  // The density by characteristics against `zeno_ball_density` (the ground x = 0 and nodes on
  // a jump left out), and the budget's atom, the mass come to rest at (0, 0), against the
  // closed form of support/ball_closed_form.hpp (zeno_mass: by t ≤ 6 every initial state that
  // has come to rest started in the box): covered by its error bar, at most 10× the true
  // error (measured 4.7–5.6×, 2026-11-28).
  nlohmann::json s;
  const std::vector<double> e = frame_errors({"zeno_ball",
                                              {{0.0, 2.0, 41}, {-2.0, 2.0, 41}},
                                              [](const Point& y, double t) {
                                                bool tie = false;
                                                return zeno_ball_density(y[0], y[1], t, &tie);
                                              },
                                              [](const Point& y, double t) {
                                                bool tie = false;
                                                (void)zeno_ball_density(y[0], y[1], t, &tie);
                                                return tie || y[0] < 1e-9;
                                              }},
                                             &s);
  ASSERT_EQ(e.size(), 4u);
  for (const double x : e) EXPECT_LE(x, 1e-8);
  for (std::size_t k = 1; k < 4; ++k) {
    const double t = s["times"][k].get<double>(), atom = s["atom"][k].get<double>();
    const double bar = s["atom_error"][k].get<double>();
    const double truth = std::fabs(atom - hybgen::testing::zeno_mass(t, 0.6));
    std::printf("zeno_ball t = %.0f: atom %.5f, closed form %.5f, bar %.2e (%.1fx the error)\n", t,
                atom, hybgen::testing::zeno_mass(t, 0.6), bar, bar / truth);
    EXPECT_GE(bar, truth) << "t = " << t;
    EXPECT_LE(bar, 10.0 * truth) << "t = " << t;
  }
}

TEST(TransientClosedForms, IntegrateAndFireByCharacteristics) {
  // The shipped neuron by method=characteristics (its reset (v, w) ↦ (0, w + b) is constant in
  // v) against `fire::density`, two spikes deep by t = 2; the columns v = 0 (the image) and
  // v = 1 (the threshold) and nodes on the jump curves left out. The mass budget closes within
  // its error. Sanitized on 33 × 43 nodes (the same paths, a quarter of the traces: 52 s of the
  // sanitized stage on 65 × 84, 2026-12-01).
  const int nv = hybgen::testing::kSanitized ? 33 : 65, nw = hybgen::testing::kSanitized ? 43 : 84;
  Transient c{"integrate_and_fire",
              {{0.0, 1.0, nv}, {0.0, 1.3, nw}},
              [](const Point& p, double t) {
                bool tie = false;
                return fire::density(p[0], p[1], t, &tie);
              },
              [](const Point& p, double t) {
                bool tie = false;
                (void)fire::density(p[0], p[1], t, &tie);
                return tie || p[0] < 1e-9 || p[0] > 1.0 - 1e-9;
              }};
  c.model = "models/integrate_and_fire.model";
  c.sets =
      "--set grid=" + std::to_string(nv) + "x" + std::to_string(nw) + " --set t_end=2 --set dt=0.5";
  nlohmann::json s;
  const std::vector<double> e = frame_errors(c, &s);
  ASSERT_EQ(e.size(), 5u);
  for (const double x : e) EXPECT_LE(x, 1e-8);
  const nlohmann::json& b = s["budget"];
  ASSERT_TRUE(b.contains("defect")) << b.dump();
  for (std::size_t k = 0; k < b["defect"].size(); ++k) {
    const double defect = b["defect"][k].get<double>(), err = b["defect_error"][k].get<double>();
    std::printf("integrate_and_fire budget t = %.1f: defect %.2e +/- %.2e\n",
                s["times"][k].get<double>(), defect, err);
    EXPECT_LE(std::fabs(defect), err + 1e-12);
    EXPECT_LE(err, 1e-3);
  }
}

TEST(TransientClosedForms, ATieAtTheInitialTimeKeepsAHistory) {
  // The column x = 0.5 at t = 0.5 reaches the reset image x = 0 at t = 0, where the solution
  // has two one-sided histories (they agree here, u0 being periodic). The image's event
  // b = s∘Δ⁻¹ = (x + 1) − 1 rounds a tiny negative x to 0, so the reset's side did not claim
  // the node, and the flow's side, just outside the support x ≥ 0, had no value: 4 of the 81
  // nodes got 0 (relative L1 8.7e-5 over the frame) before the tie rule took the support
  // into account (characteristics.hpp, spawn_from). Still left out: the columns x = 0 and 1
  // at the last time t = 1, whose ties fall at the END of their traces, where the image's
  // event rounds to 0 without a root to decide (docs/methods.md, known limits: 3.1e-4 under
  // the sanitized -O1 build, exact at -O3).
  expect_exact(
      {"wrap_decay",
       {{0.0, 1.0, 81}, {-2.0, 2.0, 81}},
       wrap_decay_density,
       [](const Point& p, double t) { return t == 1.0 && (p[0] < 1e-9 || p[0] > 1.0 - 1e-9); }});
}

}  // namespace
