#pragma once
/// \file volume.hpp
/// The volume term of the mass budget: Σ_modes ∫_box u(t_k) for every output time at once,
/// by the adaptive cubature (budget/cubature.hpp) of the density traced exactly (to the ODE
/// tolerance) by backward characteristics at its nodes, with the grid's nodes as check
/// points (budget/check_points.hpp). mass0 is the same cubature at t = 0.
///
/// The drops mass0 − mass[k] are integrated by the same cubature too, as passive slots of the
/// integrand u(0) − u(t_k): the cubature is linear, so the slot's integral is mass0 − mass[k]
/// and its estimate is the error model (cubature.hpp) applied to the difference. The errors of
/// mass0 and mass[k] come from the same cells and partly cancel in it (exactly at t = 0, where
/// the drop is 0); the budget's defect (core/solution.hpp, `budget_defect_error`) takes this
/// estimate instead of the sum mass0_error + error[k], which counted them twice. The error
/// model is nearly subadditive (the discrepancies are linear in the integrand, the null-rule
/// indicators obey the triangle inequality, one ρ scales every slot), but not quite: where a
/// leaf's check-point misfit stands for its discrepancy, that choice is made per slot, and the
/// drop's can take a misfit larger than both masses'. So the estimate is taken at most that
/// sum.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <utility>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/methods/budget/check_points.hpp"
#include "hybgen/rt/methods/budget/cubature.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Result of `adaptive_mass` (`error[k]` is the estimated |error| of mass[k]).
struct AdaptiveMass : CubatureStats {
  std::vector<double> mass;  ///< Σ_modes ∫_box u(t_k), per output time.
  double mass0 = 0.0;        ///< Σ_modes ∫_box u0 by the same cubature.
  double mass0_error = 0.0;  ///< Estimated |error| of mass0 (also in error_estimate).
  /// Estimated |error| of mass0 − mass[k], per output time (the file comment).
  std::vector<double> drop_error;
  std::size_t check_points = 0;  ///< Grid nodes the cubature checked itself against.
};

namespace detail {

/// The drops of one point's row of 2K − 1 values whose first K are the slots' (the file
/// comment): row[K + j] = row[0] − row[1 + j] for j < K − 1.
inline void fill_drops(double* row, std::size_t K) {
  for (std::size_t j = 0; j + 1 < K; ++j) row[K + j] = row[0] - row[1 + j];
}

/// Volume integrand: Σ_modes u(t_k) at the points, for the time slots `slots`, or each mode's
/// u on its own and then each observable's Σ_m f_o u (`per_mode`: the cell averages,
/// budget/cell_averages.hpp).
template <HybridModel M>
struct VolumeValues {
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  std::span<const double> slots;                    ///< Times (slots[0] = 0 for the budget).
  const double* par = nullptr;                      ///< Parameters.
  const CharacteristicsOptions* opt = nullptr;      ///< Characteristics options.
  TraceFailure<N> failure{};                        ///< First failure.
  bool per_mode = false;                            ///< See the struct comment.
  /// Also the drops (the file comment): with S = 2K − 1 values per point,
  /// U[i·S + K + j] = U[i·S] − U[i·S + 1 + j] for j < K − 1 (not with per_mode).
  bool drops = false;

  /// Values per point: K slots, the drops' K − 1 with `drops`.
  std::size_t width() const { return drops ? 2 * slots.size() - 1 : slots.size(); }

  /// U[i·S + k] = Σ_m u(slots[k], m, pts[i]), S = width(); per_mode, with
  /// S = K·(n_mode + n_obs) values per point:
  ///   U[i·S + k·n_mode + m] = u(slots[k], m, pts[i]),
  ///   U[i·S + K·n_mode + k·n_obs + o] = Σ_m f_o(m, pts[i])·u(slots[k], m, pts[i]).
  bool operator()(std::span<const Cell<N>>, std::span<const std::array<double, N>> pts, std::size_t,
                  std::vector<double>& U) {
    const Solution<N> sol = evaluate<M>(pts, slots, par, *opt);
    if (!sol.ok()) {
      failure = sol.failure;
      return false;
    }
    const std::size_t K = slots.size(), Mn = sol.n_mode;
    const std::size_t n_obs = per_mode ? static_cast<std::size_t>(observable_count<M>()) : 0;
    const std::size_t S = per_mode ? K * (Mn + n_obs) : width();
    for (std::size_t i = 0; i < pts.size(); ++i) {
      for (std::size_t m = 0; m < Mn; ++m) {
        for (std::size_t k = 0; k < K; ++k) {
          if (per_mode)
            U[i * S + k * Mn + m] = sol.at(k, m, i);
          else
            U[i * S + k] += sol.at(k, m, i);
        }
        for (std::size_t o = 0; o < n_obs; ++o) {
          const double f =
              observable_value<M>(static_cast<int>(o), static_cast<int>(m), pts[i].data(), par);
          for (std::size_t k = 0; k < K; ++k)
            U[i * S + K * Mn + k * n_obs + o] += f * sol.at(k, m, i);
        }
      }
      if (drops && !per_mode) fill_drops(&U[i * S], K);
    }
    return true;
  }
};

}  // namespace detail

/// Largest number of check points of the volume cubature: their values come with the run's
/// solution (`detail::volume_checks`), so all the nodes of most grids.
inline std::size_t max_volume_checks(const AdaptiveOptions& aopt) {
  return std::max<std::size_t>(aopt.max_points, std::size_t{1} << 14);
}

namespace detail {

/// The volume cubature's check points: the grid's nodes (`check_lattice` to
/// `max_volume_checks`: all of them on the grids of the shipped models), each with Σ_modes u at the
/// cubature's slots. `nodes` (may be null) is the run's solution at all grid nodes for the times
/// slots[off..] (solve_grid); without it, or for the t = 0 slot that `times` lacks, the values are
/// computed here (characteristics; u0). A characteristic traced here that fails (a flow that
/// is singular on the box's boundary, which the cubature's interior nodes never touch)
/// leaves the cubature without check points: its own nodes report the failures that matter.
/// With `drops`, each point also carries the drops' values (VolumeValues).
template <HybridModel M>
void volume_checks(const TensorGrid<state_dim_v<M>>& grid, std::span<const double> slots,
                   std::size_t off, const Solution<state_dim_v<M>>* nodes, const double* par,
                   const CharacteristicsOptions& opt, const AdaptiveOptions& aopt,
                   CheckPoints<state_dim_v<M>>& checks, bool drops) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::size_t K = slots.size();
  if (nodes != nullptr &&
      (nodes->n_point != grid.size() || nodes->n_time + off != K || !nodes->ok()))
    nodes = nullptr;
  std::array<double, N> lo{}, hi{};
  for (std::size_t a = 0; a < N; ++a) {
    lo[a] = grid.axes[a].min;
    hi[a] = grid.axes[a].max;
  }
  const std::vector<std::size_t> flat =
      check_lattice(grid, max_volume_checks(aopt), lo, hi, checks);
  const std::size_t S = drops ? 2 * K - 1 : K;  // values per point
  std::vector<double> v(flat.size() * S, 0.0);
  if (nodes != nullptr) {
    // A distributed solution (several ranks) holds each (mode, node) on one rank: the values
    // at the check points are summed over the ranks per mode (0 + u: exact), then over the
    // modes in order, as here in one process: the same bits on every rank and as one process.
    const std::size_t n_mode = nodes->n_mode;
    std::vector<double> u(flat.size() * K * n_mode, 0.0);
    const Block own = nodes->distributed ? nodes->owned : Block{0, n_mode * nodes->n_point};
    for (std::size_t j = 0; j < flat.size(); ++j)
      for (std::size_t k = 0; k + off < K; ++k)
        for (std::size_t m = 0; m < n_mode; ++m)
          if (const std::size_t pair = m * nodes->n_point + flat[j];
              pair >= own.begin && pair < own.end)
            u[(j * K + k + off) * n_mode + m] = nodes->at(k, m, flat[j]);
    if (nodes->distributed && opt.backend != nullptr)
      opt.backend->sum_disjoint(std::span<double>(u));
    for (std::size_t j = 0; j < flat.size(); ++j)
      for (std::size_t k = 0; k < K; ++k)
        for (std::size_t m = 0; m < n_mode; ++m) v[j * S + k] += u[(j * K + k) * n_mode + m];
    for (std::size_t j = 0; j < flat.size(); ++j) {
      if (off == 1 && M::in_support(checks.x[j].data(), par))
        for (int m = 0; m < M::n_mode; ++m)
          v[j * S] += M::initial_density(m, checks.x[j].data(), par);
    }
  } else {
    const Solution<N> sol =
        evaluate<M>(std::span<const std::array<double, N>>(checks.x), slots, par, opt);
    if (!sol.ok()) {
      checks = {};
      return;
    }
    for (std::size_t j = 0; j < flat.size(); ++j)
      for (std::size_t k = 0; k < K; ++k)
        for (std::size_t m = 0; m < sol.n_mode; ++m) v[j * S + k] += sol.at(k, m, j);
  }
  if (drops)
    for (std::size_t j = 0; j < flat.size(); ++j) fill_drops(&v[j * S], K);
  keep_samples<M>(checks, std::move(v), S, par);
}

}  // namespace detail

/// Adaptive cubature of Σ_modes ∫_box u(t_k) for every output time at once (one
/// characteristics evaluation per node serves all times), `box` = the box of the grid's
/// axes. mass0 is the same cubature at t = 0 (the t = 0 slot of `times`, or an extra slot),
/// so atom(0) = 0 exactly when times[0] = 0. The grid's nodes are the cubature's check
/// points (`detail::volume_checks`; `nodes`: the run's solution there, or null to compute
/// it), so its estimate sees what the grid resolves. On a failed characteristic `failure` is
/// set and the partial result returned (converged = false).
template <HybridModel M>
AdaptiveMass adaptive_mass(const TensorGrid<state_dim_v<M>>& box, std::span<const double> times,
                           const double* par, const CharacteristicsOptions& opt,
                           const AdaptiveOptions& aopt, TraceFailure<state_dim_v<M>>& failure,
                           const Solution<state_dim_v<M>>* nodes = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  detail::validate_times(times);
  const std::size_t off = !times.empty() && times.front() == 0.0 ? 0 : 1;
  std::vector<double> slots(times.size() + off, 0.0);
  for (std::size_t k = 0; k < times.size(); ++k) slots[k + off] = times[k];
  detail::Cell<N> root;
  for (std::size_t a = 0; a < N; ++a) {
    root.lo[a] = box.axes[a].min;
    root.hi[a] = box.axes[a].max;
  }
  detail::CheckPoints<N> checks;
  detail::volume_checks<M>(box, slots, off, nodes, par, opt, aopt, checks, true);
  detail::VolumeValues<M> values{slots, par, &opt, {}, false, true};
  const std::size_t K = slots.size(), S = values.width();
  const std::size_t per_point = K * static_cast<std::size_t>(M::n_mode) + S;
  // Only the K masses steer the cubature; the drops ride on its cells.
  detail::AdaptiveCubature<N, detail::VolumeValues<M>> cub({root}, S, per_point, aopt, 0.0, values,
                                                           &checks, K);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  AdaptiveMass res;
  res.check_points = checks.x.size();
  res.mass0 = cub.integral(0);
  res.mass0_error = cub.error(0);
  res.error_estimate = res.mass0_error;
  detail::collect(cub, ok, off, times.size(), res.mass, res);
  // The drops' estimates (0 at t = 0: the same slot). A cubature stopped short (`collect`
  // widened every time's estimate to the largest) keeps the sum.
  res.drop_error.assign(times.size(), 0.0);
  for (std::size_t k = 0; k < times.size(); ++k) {
    const std::size_t slot = k + off;
    const double sum = res.mass0_error + res.error[k];
    res.drop_error[k] = slot == 0       ? 0.0
                        : res.converged ? std::fmin(cub.error(K + slot - 1), sum)
                                        : sum;
  }
  return res;
}

}  // namespace hybgen::rt
