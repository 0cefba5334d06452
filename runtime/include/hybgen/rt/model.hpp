#pragma once
/// \file model.hpp
/// The contract between generated kernels and the runtime: a generated model
/// is a struct with static members satisfying `HybridModel`. The runtime is
/// templated over it and never sees GiNaC.
///
/// Conventions (docs/design.md): state x ∈ ℝᴺ, parameters `par` ∈ ℝᴾ (run-time
/// values, defaults in `param_defaults`), modes 0..M-1, guards 0..G-1.
/// A guard g fires in mode `guards[g].from` when s_g(x) crosses 0 in its
/// direction; the state jumps to Δ_g(x) and the mode becomes `guards[g].to`.
/// The transfer rule across it is u⁺(Δx) = u⁻(x) / |J_g(x)| (paper Thm 3.11,
/// with |J| because J may be negative when orientation flips).

#include <array>
#include <concepts>
#include <cstddef>
#include <type_traits>

namespace hybgen::rt {

/// Static description of one guard.
struct GuardInfo {
  int from;          ///< Source mode index.
  int to;            ///< Target mode index; −1: absorbing (`reset absorb`, see below).
  int direction;     ///< -1: s decreases through 0; +1: s increases through 0.
  bool has_inverse;  ///< Whether `reset_inverse` is a closed form (else Newton).
  /// The axis i of a reset with a constant component (Δ_i independent of the state: the
  /// sawtooth's x ↦ 0, integrate-and-fire's v ↦ 0), or −1. Such a Δ has no inverse in the
  /// whole space, but is injective on its guard S; with s and the other components affine
  /// (derive.cpp sets the axis only then) it maps S onto the plane x_i = Δ_i, and the
  /// pre-image of y there solves Δ_j(z) = y_j (j ≠ i), s(z) = 0 (core/geometry.hpp,
  /// newton_reset_solve), which is what the backward characteristics need.
  int image_axis = -1;
};

/// Whether guard info `gi` absorbs (`reset absorb`): the mass that reaches its surface
/// leaves the system. Such a guard has no target mode and no reset; its reset kernels' cases
/// give NaN and are never called. Every method ends a trajectory there and counts its mass
/// per guard (summary.json `absorbed`), with the outflow of the mass budget.
constexpr bool absorbs(const GuardInfo& gi) {
  return gi.to < 0;
}

/// What the runtime needs of a generated model. All functions are pure; `x`
/// has `n_state` entries, `par` has `n_param` entries.
template <class M>
concept HybridModel = requires(int i, const double* x, const double* par, double* out) {
  { M::n_state } -> std::convertible_to<int>;
  { M::n_param } -> std::convertible_to<int>;
  { M::n_mode } -> std::convertible_to<int>;
  { M::n_guard } -> std::convertible_to<int>;
  M::name;            // const char*: model name
  M::state_names;     // std::array<const char*, n_state>
  M::param_names;     // std::array<const char*, n_param>
  M::param_defaults;  // std::array<double, n_param>
  M::mode_names;      // std::array<const char*, n_mode>
  M::guard_names;     // std::array<const char*, n_guard>
  M::guards;          // std::array<GuardInfo, n_guard>
  /// X_mode(x) into out[0..N).
  { M::flow(i, x, par, out) } -> std::same_as<void>;
  /// div X_mode(x) = Σ ∂Xⁱ/∂xⁱ.
  { M::divergence(i, x, par) } -> std::same_as<double>;
  /// s_g(x); the guard surface is s_g = 0.
  { M::guard_surface(i, x, par) } -> std::same_as<double>;
  /// ∇s_g(x) into out[0..N).
  { M::guard_gradient(i, x, par, out) } -> std::same_as<void>;
  /// Δ_g(x) into out[0..N).
  { M::reset(i, x, par, out) } -> std::same_as<void>;
  /// Δ_g⁻¹(y) into out[0..N) when `guards[g].has_inverse`; otherwise unused.
  { M::reset_inverse(i, x, par, out) } -> std::same_as<void>;
  /// DΔ_g(x), row-major N×N, into out[0..N*N) (for Newton inverses and checks).
  { M::reset_jacobian(i, x, par, out) } -> std::same_as<void>;
  /// Hybrid Jacobian J_g(x) at x ∈ S_g (docs/design.md formula).
  { M::hybrid_jacobian(i, x, par) } -> std::same_as<double>;
  /// Initial density of mode `i` at x (already 0 outside the support/region).
  { M::initial_density(i, x, par) } -> std::same_as<double>;
  /// Whether x is in the state space (the `support` relations).
  { M::in_support(x, par) } -> std::same_as<bool>;
};

/// Guards a table model may have: the per-thread workspaces size their event arrays by it
/// (characteristics.hpp, forward.hpp), so it is a compile-time capacity, not a limit of the
/// mathematics. A model with more guards is built with the runtime inlined instead
/// (table_model.hpp).
inline constexpr int kTableMaxGuards = 32;

/// Compile-time capacity for M's guards: n_guard itself where it is a constant expression
/// (a generated struct), kTableMaxGuards for a table model. At least 1, for array sizes.
template <class M>
inline constexpr std::size_t guard_capacity_v = [] {
  if constexpr (requires { typename std::integral_constant<int, M::n_guard>; })
    return M::n_guard > 0 ? static_cast<std::size_t>(M::n_guard) : std::size_t{1};
  else
    return static_cast<std::size_t>(kTableMaxGuards);
}();

/// Whether x lies in (the closure of) mode m's region: M::in_region(m, x, par) where the model
/// has modes restricted by `where` relations (the generator emits it only then), else true.
/// The forward methods keep a mode's mass inside its region with it (transfer.hpp).
template <HybridModel M>
bool in_mode_region(int m, const double* x, const double* par) {
  if constexpr (requires {
                  { M::in_region(m, x, par) } -> std::same_as<bool>;
                })
    return M::in_region(m, x, par);
  else
    return true;
}

/// The number of M's observables (`observe` lines of the model's simulation block): the
/// generator emits `n_observable`, `observable_names` and
/// `observable(i * n_mode + k, x, par)` = f_i(x) in mode k only for a model that has some.
template <HybridModel M>
int observable_count() {
  if constexpr (requires { M::n_observable; })
    return static_cast<int>(M::n_observable);
  else
    return 0;
}

/// The name of M's observable i (i < observable_count<M>()).
template <HybridModel M>
const char* observable_name(int i) {
  if constexpr (requires { M::observable_names; })
    return M::observable_names[static_cast<std::size_t>(i)];
  else
    return "";
}

/// f_i(x) in mode k: M's observable i (i < observable_count<M>()).
template <HybridModel M>
double observable_value(int i, int k, const double* x, const double* par) {
  if constexpr (requires(const double* y, const double* q) {
                  { M::observable(0, y, q) } -> std::same_as<double>;
                })
    return M::observable(i * M::n_mode + k, x, par);
  else
    return 0.0;
}

}  // namespace hybgen::rt
