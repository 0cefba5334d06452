#pragma once
/// \file hand_models.hpp
/// Parts of the models the validation tests write by hand in the form of a generated kernel
/// (rt::HybridModel, runtime/include/hybgen/rt/model.hpp), shared by the models that have
/// the same guard: a base class D derives from (CRTP) gives the sizes and names, the guard
/// table and the guard's functions; D gives the model's name and the rest.

#include <array>

#include "hybgen/rt/model.hpp"

namespace hybgen::testing {

/// A planar mechanical model x₀' = x₁ with one mode, no parameters and one guard `wall`: the
/// wall x₀ = D::wall, crossed in the direction Dir (+1 increasing, −1 decreasing), with the
/// restitution reset (x₀, x₁) ↦ (x₀, −e x₁), e = D::restitution, and its closed-form inverse.
/// J = e²: Δ scales the wall's x₁ by −e, and the normal speed x₀' = x₁ by −e too.
/// D gives name, state_names, mode_names, flow, divergence, initial_density and in_support
/// (tests/validation/test_bounce_exit.cpp, test_zeno_wall.cpp, test_oscillator_wall.cpp,
/// test_pendulum_wall.cpp).
template <class D, int Dir>
struct PlanarWall {
  static constexpr int n_state = 2;                                 ///< x₀, x₁
  static constexpr int n_param = 0;                                 ///< none
  static constexpr int n_mode = 1;                                  ///< one mode
  static constexpr int n_guard = 1;                                 ///< wall
  static constexpr std::array<const char*, 0> param_names{};        ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};          ///< No parameters.
  static constexpr std::array<const char*, 1> guard_names{"wall"};  ///< Guard names.
  /// wall: direction Dir, closed-form inverse.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, Dir, true}};
  /// s = x₀ − wall.
  static double guard_surface(int, const double* x, const double*) { return x[0] - D::wall; }
  /// ∇s = (1, 0).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  /// Δ(x₀, x₁) = (x₀, −e x₁).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = -D::restitution * x[1];
  }
  /// Δ⁻¹(x₀, x₁) = (x₀, −x₁/e).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = -x[1] / D::restitution;
  }
  /// DΔ = diag(1, −e).
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
    out[2] = 0.0;
    out[3] = -D::restitution;
  }
  /// J = e².
  static double hybrid_jacobian(int, const double*, const double*) {
    return D::restitution * D::restitution;
  }
};

/// A planar model on a clock: one mode x' = 1, y' = 0 (div X = 0), no parameters, and one
/// guard x = 1, increasing, with the reset (x, y) ↦ (x − 1, D::T(y)) and a numeric inverse (as
/// hybgen derives for a reset that is not affine); J = D::dT(y) (X⁺ = X⁻ = (1, 0)). D gives
/// name, guard_names, T, dT, initial_density and in_support (tests/validation/test_fold.cpp,
/// test_tent_map.cpp).
template <class D>
struct ClockMap {
  static constexpr int n_state = 2;                                   ///< x, y
  static constexpr int n_param = 0;                                   ///< none
  static constexpr int n_mode = 1;                                    ///< one mode
  static constexpr int n_guard = 1;                                   ///< the clock's tick
  static constexpr std::array<const char*, 2> state_names{"x", "y"};  ///< State names.
  static constexpr std::array<const char*, 0> param_names{};          ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};            ///< No parameters.
  static constexpr std::array<const char*, 1> mode_names{"run"};      ///< Mode names.
  /// Numeric inverse, as hybgen derives for a reset that is not affine.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, false}};
  /// X = (1, 0).
  static void flow(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// s = x − 1.
  static double guard_surface(int, const double* x, const double*) { return x[0] - 1.0; }
  /// ∇s = (1, 0).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  /// Δ = (x − 1, T(y)).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0] - 1.0;
    out[1] = D::T(x[1]);
  }
  /// Unused (numeric inverse).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  /// DΔ = diag(1, T′).
  static void reset_jacobian(int, const double* x, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
    out[2] = 0.0;
    out[3] = D::dT(x[1]);
  }
  /// J = T′(y).
  static double hybrid_jacobian(int, const double* x, const double*) { return D::dT(x[1]); }
};

}  // namespace hybgen::testing
