// Validation: a thermostat with hysteresis, a model hybgen does not ship, against closed forms
// derived here (none of them comes from hybgen).
//
// One state x (temperature), two modes: heating x' = f_on(x) = 4 − x until x = 2 (guard `cut`,
// s = x − 2 increasing, identity reset, on → off), cooling x' = f_off(x) = −1.5x until x = 1
// (guard `heat`, s = x − 1 decreasing, off → on). With an identity reset the hybrid Jacobian
// is J = ∇s·X⁺ / ∇s·X⁻ = f_off(2)/f_on(2) = −3/2 at `cut` and f_on(1)/f_off(1) = 3/(−3/2) = −2
// at `heat`: |J| ≠ 1 and negative, the case the withdrawn interpolating transfer scheme got
// wrong (+22 % mass).
//
// Closed forms. On the band [1, 2] the flow is a rotation of the phase θ ∈ [0, P): θ = ln(3/(4 −
// x)) in mode on (T_on = ln(3/2) from x = 1 to 2), θ = T_on + ln(2/x)/1.5 in mode off (T_off =
// ln 2/1.5), P = T_on + T_off. In 1-D, Liouville gives u(t, x(t))·f(x(t)) = u0(x0)·f(x0) along
// a characteristic, and the jump condition u⁺ = u⁻/|J| = u⁻|f⁻|/|f⁺| keeps u|f| across a switch:
// the flux q = u|f| is carried unchanged along the phase. Hence
//   invariant density:  u*_m(x) = (1/P)/|f_m(x)|  (unit mass; the "u ∝ 1/|T′|"),
//   any initial flux q0(θ):  u(t, m, x) = q0(θ(m, x) − t mod P)/|f_m(x)|.
// The paper's general theorem is not used: these follow from the ODE and mass conservation.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/invariant.hpp"
#include "hybgen/rt/methods/transfer.hpp"

namespace {

namespace rt = hybgen::rt;

/// The thermostat as a generated model would be (tests/validation: written by hand).
struct Thermostat {
  static constexpr int n_state = 1;                                        ///< x
  static constexpr int n_param = 0;                                        ///< none
  static constexpr int n_mode = 2;                                         ///< on, off
  static constexpr int n_guard = 2;                                        ///< cut, heat
  static constexpr const char* name = "thermostat";                        ///< Model name.
  static constexpr std::array<const char*, 1> state_names{"x"};            ///< State names.
  static constexpr std::array<const char*, 0> param_names{};               ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};                 ///< No parameters.
  static constexpr std::array<const char*, 2> mode_names{"on", "off"};     ///< Mode names.
  static constexpr std::array<const char*, 2> guard_names{"cut", "heat"};  ///< Guard names.
  /// cut: on → off increasing; heat: off → on decreasing; closed-form (identity) inverses.
  static constexpr std::array<rt::GuardInfo, 2> guards{rt::GuardInfo{0, 1, +1, true},
                                                       rt::GuardInfo{1, 0, -1, true}};
  /// f_m(x).
  static double f(int m, double x) { return m == 0 ? 4.0 - x : -1.5 * x; }
  /// X_m = f_m(x).
  static void flow(int m, const double* x, const double*, double* out) { out[0] = f(m, x[0]); }
  /// div X_m = f_m'.
  static double divergence(int m, const double*, const double*) { return m == 0 ? -1.0 : -1.5; }
  /// s_cut = x − 2, s_heat = x − 1.
  static double guard_surface(int g, const double* x, const double*) {
    return x[0] - (g == 0 ? 2.0 : 1.0);
  }
  /// ∇s = 1.
  static void guard_gradient(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// Identity reset.
  static void reset(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  /// Identity inverse.
  static void reset_inverse(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  /// DΔ = 1.
  static void reset_jacobian(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// J = f_to(x)/f_from(x) at the guard.
  static double hybrid_jacobian(int g, const double* x, const double*) {
    return g == 0 ? f(1, x[0]) / f(0, x[0]) : f(0, x[0]) / f(1, x[0]);
  }
  /// Set per test through `q0` (a flux profile over the phase); default the invariant one.
  static inline double (*q0)(double theta) = nullptr;
  /// u0_m(x) = q0(θ(m, x))/|f_m(x)|.
  static double initial_density(int m, const double* x, const double*);
  /// The band [1, 2].
  static bool in_support(const double* x, const double*) { return x[0] >= 1.0 && x[0] <= 2.0; }
};

const double kTon = std::log(1.5), kToff = std::log(2.0) / 1.5, kPeriod = kTon + kToff;

/// The phase of (m, x) on the band.
double phase(int m, double x) {
  return m == 0 ? std::log(3.0 / (4.0 - x)) : kTon + std::log(2.0 / x) / 1.5;
}

double Thermostat::initial_density(int m, const double* x, const double*) {
  const double q = q0 ? q0(phase(m, x[0])) : 1.0 / kPeriod;
  return q / std::fabs(f(m, x[0]));
}
static_assert(rt::HybridModel<Thermostat>);

/// A smooth flux profile over the phase: (1 + ½ sin(2πθ/P))/P (unit mass).
double wave(double theta) {
  return (1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * theta / kPeriod)) / kPeriod;
}

/// The exact density of the initial flux q0 at time t: q0(θ − t mod P)/|f_m(x)|.
double exact(double (*q0)(double), double t, int m, double x) {
  const double th = std::fmod(std::fmod(phase(m, x) - t, kPeriod) + kPeriod, kPeriod);
  return q0(th) / std::fabs(Thermostat::f(m, x));
}

rt::TensorGrid<1> band(int n) {
  rt::TensorGrid<1> g;
  g.axes = {rt::GridAxis{1.0, 2.0, n}};
  return g;
}

/// Relative L1 distance Σ w|u − v| / Σ w|v| over both modes, layout [mode][node].
double rel_l1(const std::vector<double>& w, const std::vector<double>& u,
              const std::vector<double>& v) {
  double num = 0.0, den = 0.0;
  for (std::size_t r = 0; r < u.size(); ++r) {
    num += w[r] * std::fabs(u[r] - v[r]);
    den += w[r] * std::fabs(v[r]);
  }
  return num / den;
}

TEST(Thermostat, InvariantDensityMatchesTheClosedForm) {
  // The bar: on 401 nodes the invariant density within 1 % (relative L1) of
  // u* = (1/P)/|f_m| and λ₁ ≤ 1 + 1e-9. A closed system (no sample leaves the band: the
  // guards sit on its ends), so also λ₁ ≥ 1 − 1e-9, no outflow and no atom. The withdrawn
  // interpolating scheme gave λ₁ = 1.0025 and 20–44 % errors here.
  // Measured (h = 0.05): hat 3.4e-3; asserted < 1e-2. (Ulam's `cell`, withdrawn, gave 1.5e-1
  // with 4 samples — its 1/K quantisation: the flow moves every sample of a cell by nearly
  // the same amount, so each cell's mass was split in quarters the same way every step.)
  Thermostat::q0 = nullptr;
  const auto grid = band(401);
  for (const auto& [scheme, k] : {std::pair{rt::TransferScheme::hat, 0}}) {
    SCOPED_TRACE(std::string(rt::scheme_name(scheme)) + " K=" + std::to_string(k));
    rt::TransferOptions o;
    o.step = 0.05;
    o.scheme = scheme;
    o.samples_per_axis = k;
    const auto op = rt::assemble_transfer<Thermostat>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    for (std::size_t r = 0; r < op.size(); ++r) {
      ASSERT_EQ(op.outflow[r], 0.0) << r;
      ASSERT_EQ(op.atom[r], 0.0) << r;
    }
    const auto inv = rt::invariant_density(op);
    ASSERT_TRUE(inv.converged);
    std::vector<double> ref(op.size());
    for (std::size_t r = 0; r < op.size(); ++r) {
      const int m = static_cast<int>(r / op.n_node);
      ref[r] = 1.0 / kPeriod / std::fabs(Thermostat::f(m, grid.node(r % op.n_node)[0]));
    }
    const double err = rel_l1(op.weight, inv.density, ref);
    const double lam = inv.eigenvalues[0].real();
    std::printf(
        "[ thermostat ] %s K=%d 401 nodes h=0.05: invariant rel L1 %.3e, lambda1 - 1 = %.2e\n",
        rt::scheme_name(scheme), op.samples_per_axis, err, lam - 1.0);
    EXPECT_LE(lam, 1.0 + 1e-9);
    EXPECT_GE(lam, 1.0 - 1e-9);
    EXPECT_GE(inv.min_value, 0.0);
    EXPECT_LT(err, 1e-2);
  }
}

TEST(Thermostat, MarchedDensityFollowsThePhaseRotation) {
  // A smooth flux wave q0 = (1 + ½ sin 2πθ/P)/P marched to t = 2 (≈ 1.5 periods, 3 and 4
  // switches per state) with step 0.05 on 101 … 401 nodes: the mass stays what it was to
  // rounding (a closed system: no outflow, no atom), every density ≥ 0, and the relative L1
  // error against q0(θ − t)/|f| is small. Measured: 2.9e-3, 3.0e-3, 2.5e-3 — NOT falling with
  // Δx: the error is made where mass switches mode, where a sample's sub-cell that straddles
  // the crossing front is booked whole in one mode (transfer.hpp), and it is carried along
  // with the mass; 8 and 16 samples give 2.9e-3, 1.9e-3, 8.0e-4 and 2.5e-3, 7.4e-4, 7.8e-4.
  // Asserted: below 1 % on every grid and below 1.5e-3 with 16 samples at 401 nodes.
  Thermostat::q0 = wave;
  for (const int n : {101, 201, 401}) {
    const auto grid = band(n);
    rt::TransferOptions o;
    o.step = 0.05;
    const auto op = rt::assemble_transfer<Thermostat>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto u0 = rt::initial_vector<Thermostat>(grid, nullptr);
    const std::vector<double> times{0.0, 1.0, 2.0};
    const auto run = rt::march(op, u0, times);
    ASSERT_TRUE(run.ok()) << run.failure;
    std::vector<double> ref(op.size()), u(op.size());
    for (std::size_t r = 0; r < op.size(); ++r) {
      const int m = static_cast<int>(r / op.n_node);
      ref[r] = exact(wave, 2.0, m, grid.node(r % op.n_node)[0]);
      u[r] = run.solution.u[2 * op.size() + r];
      ASSERT_GE(u[r], 0.0);
    }
    const double err = rel_l1(op.weight, u, ref);
    std::printf("[ thermostat ] hat %d nodes: t = 2 rel L1 %.3e, mass %.15f -> %.15f\n", n, err,
                run.budget.mass0, run.budget.mass[2]);
    EXPECT_NEAR(run.budget.mass[2], run.budget.mass0, 1e-13);
    EXPECT_EQ(run.budget.outflow[2], 0.0);
    EXPECT_LT(err, 1e-2);
    if (n == 401) {
      o.samples_per_axis = 16;
      const auto op16 = rt::assemble_transfer<Thermostat>(grid, nullptr, o);
      const auto run16 = rt::march(op16, u0, times);
      ASSERT_TRUE(run16.ok()) << run16.failure;
      for (std::size_t r = 0; r < op.size(); ++r) u[r] = run16.solution.u[2 * op.size() + r];
      const double err16 = rel_l1(op.weight, u, ref);
      std::printf("[ thermostat ] hat K=16 401 nodes: t = 2 rel L1 %.3e\n", err16);
      EXPECT_LT(err16, 1.5e-3);
    }
  }
  Thermostat::q0 = nullptr;
}

}  // namespace
