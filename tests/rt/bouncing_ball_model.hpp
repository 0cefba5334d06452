#pragma once
/// \file bouncing_ball_model.hpp
/// Hand-written `hybgen::rt::HybridModel`s used by the runtime tests: the bouncing ball (what
/// the emitter should produce for models/bouncing_ball.model), a guard-free spiral and a
/// two-mode switching system on the line.
///
/// State (x, p), parameters (m, g, e). One mode `flight`: X = (p/m, −m g), div X = 0.
/// Guard `ground`: s = x, decreasing; Δ(x, p) = (x, −e p); Δ⁻¹(y) = (x, −p/e);
/// J = e² (docs/design.md formula with tangent t = (0, 1): det[DΔ t | X(Δx)] / det[t | X(x)]
/// = (−e²p/m) / (−p/m)). u0 = exp(−(x−1)² − p²) on the support x ≥ 0.

#include <array>
#include <cmath>

#include "hybgen/rt/model.hpp"

namespace hybgen::rt::testing {

/// The bouncing ball of the paper's §4.1.
struct BouncingBall {
  static constexpr int n_state = 2;                                        ///< (x, p)
  static constexpr int n_param = 3;                                        ///< (m, g, e)
  static constexpr int n_mode = 1;                                         ///< flight
  static constexpr int n_guard = 1;                                        ///< ground
  static constexpr const char* name = "bouncing_ball";                     ///< Model name.
  static constexpr std::array<const char*, 2> state_names{"x", "p"};       ///< State names.
  static constexpr std::array<const char*, 3> param_names{"m", "g", "e"};  ///< Parameter names.
  static constexpr std::array<double, 3> param_defaults{1.0, 1.0, 1.0};    ///< Defaults.
  static constexpr std::array<const char*, 1> mode_names{"flight"};        ///< Mode names.
  static constexpr std::array<const char*, 1> guard_names{"ground"};       ///< Guard names.
  static constexpr std::array<GuardInfo, 1> guards{GuardInfo{0, 0, -1, true}};  ///< Guards.

  /// X = (p/m, −m g).
  static void flow(int, const double* x, const double* par, double* out) {
    out[0] = x[1] / par[0];
    out[1] = -par[0] * par[1];
  }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// s = x.
  static double guard_surface(int, const double* x, const double*) { return x[0]; }
  /// ∇s = (1, 0).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  /// Δ(x, p) = (x, −e p).
  static void reset(int, const double* x, const double* par, double* out) {
    out[0] = x[0];
    out[1] = -par[2] * x[1];
  }
  /// Δ⁻¹(x, p) = (x, −p/e).
  static void reset_inverse(int, const double* x, const double* par, double* out) {
    out[0] = x[0];
    out[1] = -x[1] / par[2];
  }
  /// DΔ = diag(1, −e).
  static void reset_jacobian(int, const double*, const double* par, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
    out[2] = 0.0;
    out[3] = -par[2];
  }
  /// J = e².
  static double hybrid_jacobian(int, const double*, const double* par) { return par[2] * par[2]; }
  /// u0 = exp(−(x−1)² − p²) for x ≥ 0, else 0.
  static double initial_density(int, const double* x, const double*) {
    return x[0] >= 0.0 ? std::exp(-(x[0] - 1.0) * (x[0] - 1.0) - x[1] * x[1]) : 0.0;
  }
  /// Support x ≥ 0.
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0; }
};

static_assert(HybridModel<BouncingBall>);

/// A guard-free test model: x' = a x − p, p' = x + a p (div = 2a). φ_t(y) = e^{at} R(t) y
/// with R the rotation by t, so the Gaussian u0 = exp(−4|y − (1/2, 0)|²) stays a Gaussian
/// and spirals out: u(t, y) = e^{−2at} u0-shaped around φ_t(c) with width e^{at}.
struct Spiral2D {
  /// Dimensions: (x, p), parameter a, one mode, no guard.
  static constexpr int n_state = 2, n_param = 1, n_mode = 1, n_guard = 0;
  /// Model name.
  static constexpr const char* name = "spiral";
  /// State names.
  static constexpr std::array<const char*, 2> state_names{"x", "p"};
  /// Parameter names.
  static constexpr std::array<const char*, 1> param_names{"a"};
  /// Default a.
  static constexpr std::array<double, 1> param_defaults{0.15};
  /// Mode names.
  static constexpr std::array<const char*, 1> mode_names{"only"};
  /// No guards.
  static constexpr std::array<const char*, 0> guard_names{};
  /// No guards.
  static constexpr std::array<GuardInfo, 0> guards{};
  /// X = (a x − p, x + a p).
  static void flow(int, const double* x, const double* par, double* out) {
    out[0] = par[0] * x[0] - x[1];
    out[1] = x[0] + par[0] * x[1];
  }
  /// div X = 2a.
  static double divergence(int, const double*, const double* par) { return 2.0 * par[0]; }
  /// Unused (no guards).
  static double guard_surface(int, const double*, const double*) { return 1.0; }
  /// Unused (no guards).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = out[1] = 0.0;
  }
  /// Unused (no guards).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  /// Unused (no guards).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  /// Unused (no guards).
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = out[3] = 1.0;
    out[1] = out[2] = 0.0;
  }
  /// Unused (no guards).
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  /// u0 = exp(−4((x − 1/2)² + p²)).
  static double initial_density(int, const double* x, const double*) {
    return std::exp(-4.0 * ((x[0] - 0.5) * (x[0] - 0.5) + x[1] * x[1]));
  }
  /// The whole plane.
  static bool in_support(const double*, const double*) { return true; }
};
/// The HybridModel function `static_assert`.
static_assert(HybridModel<Spiral2D>);

/// Two modes on the line with identity resets (a switching system with branching
/// histories; closed form in test_characteristics.cpp): A: x' = +1, guard "up" A → B at
/// x = 1 (increasing); B: x' = −2, guard "down" B → A at x = −1 (decreasing).
/// J = X⁺(Δx)/X⁻(x) (docs/design.md in 1-D): J_up = −2/1, J_down = 1/(−2).
struct TwoModeLine {
  static constexpr int n_state = 1, n_param = 0, n_mode = 2, n_guard = 2;
  static constexpr const char* name = "two_mode";
  static constexpr std::array<const char*, 1> state_names{"x"};
  static constexpr std::array<const char*, 0> param_names{};
  static constexpr std::array<double, 0> param_defaults{};
  static constexpr std::array<const char*, 2> mode_names{"A", "B"};
  static constexpr std::array<const char*, 2> guard_names{"up", "down"};
  static constexpr std::array<GuardInfo, 2> guards{GuardInfo{0, 1, 1, true},
                                                   GuardInfo{1, 0, -1, true}};
  static void flow(int m, const double*, const double*, double* out) {
    out[0] = m == 0 ? 1.0 : -2.0;
  }
  static double divergence(int, const double*, const double*) { return 0.0; }
  static double guard_surface(int g, const double* x, const double*) {
    return g == 0 ? x[0] - 1.0 : x[0] + 1.0;
  }
  static void guard_gradient(int, const double*, const double*, double* out) { out[0] = 1.0; }
  static void reset(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  static void reset_inverse(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  static void reset_jacobian(int, const double*, const double*, double* out) { out[0] = 1.0; }
  static double hybrid_jacobian(int g, const double*, const double*) {
    return g == 0 ? -2.0 : -0.5;
  }
  static double initial_density(int m, const double* x, const double*) {
    return m == 0 ? std::exp(-4.0 * (x[0] - 0.5) * (x[0] - 0.5))
                  : 0.5 * std::exp(-4.0 * (x[0] + 0.2) * (x[0] + 0.2));
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(HybridModel<TwoModeLine>);

}  // namespace hybgen::rt::testing
