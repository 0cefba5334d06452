#pragma once
/// \file cell_averages.hpp
/// Cell averages of the exact density: for every node y_i of the grid, mode m and output time
/// t_k, the mean of u(t_k, m, ·) over the node's dual cell
///   C_i = Π_a [y_ia − h_a/2, y_ia + h_a/2] ∩ box      (h_a the grid's spacing),
/// ū_i = (1/|C_i|) ∫_{C_i} u, by the adaptive cubature (budget/cubature.hpp) with every dual
/// cell a root (`per_root`) and u traced by backward characteristics at its Gauss nodes.
///
/// Why: characteristics give u exactly at the nodes, but a flow that concentrates the density
/// below the grid's spacing (a sink, an attracting cycle, dissipative impacts) leaves node
/// samples that are speckle. The dual cells tile the box and their volumes are the trapezoid
/// weights, so Σ_i |C_i| ū_i is the mass in the box, and a ring narrower than a cell shows as
/// the ring of cells that hold its mass.
///
/// Error: per time, E_k = Σ_m Σ_i E_{i,(k,m)}, the cubature's per-root estimates summed: an
/// estimate (≈ 2σ per root, budget/cubature.hpp) of the L1 error Σ_i |C_i|·|ū_i − exact ū_i|
/// in units of mass. The cubature refines until E_{(k,m)} ≤ rel_tol·scale for every slot, or
/// stops at its point cap (`converged` false; the estimate then carries the leaves'
/// check-point misfits one-signed). The grid's nodes, with the run's exact values there, are
/// the check points: a feature at a node that the cell's Gauss nodes straddle makes that cell
/// refine. Its blind spot is the cubature's: a feature narrower than the cells' Gauss nodes'
/// spacing that no check point sees.
///
/// Blind spot, and the check that catches it. A cell's Gauss nodes see no feature that lies
/// between them. The rule has three nodes per axis (kCellAverageOrder), the centre among
/// them: with two, a density symmetric about the cell's centre in x (a peak at a node, the
/// usual place for a sink) looks constant in x, its null rule is 0 there, the cell is split
/// along another axis and its halves' nodes sit at the same x, for ever (tests/rt/
/// test_cubature.cpp measured an estimate of 6e-5 against an L1 error of 0.28). A feature
/// between the three nodes that leaves their values on a line is still unseen; the dual cells
/// as roots (`aopt.root_parts` = 1) are each split once, so the first pass is cheap but can
/// miss a thin feature aligned with an axis. Missed mass is one-signed,
/// so the sum of the cell masses against the mass budget's own cubature (whose check points are
/// many per cell) finds it: methods.hpp's `cell_average_stage` then starts again with each
/// dual cell cut into 2, then 4 parts per axis, and an estimate never below the gap.
///
/// Observables: the cubature integrates Σ_m f_o·u over the cells too, on the cells the masses
/// chose (passive slots), so E[f] = ∫ Σ_m f u / mass comes with the cubature's estimates of
/// both integrals: error = (err_F + |E|·err_M)/M.
///
/// Cost: 3·3^N·p^N traced points per node at least (order-3 Gauss rule on p^N parts of each
/// dual cell, each split once), each a backward characteristic for every output time at once;
/// then refinement up to the cap. Memory: 8·5·K·n_mode bytes per node for the roots' sums, as
/// much per live leaf.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/methods/budget/check_points.hpp"
#include "hybgen/rt/methods/budget/cubature.hpp"
#include "hybgen/rt/methods/budget/volume.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/observables.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// What `cell_averages` computed.
template <std::size_t N>
struct CellAverages : CubatureStats {
  /// ū per (time, mode, node), the layout of `solve_grid`'s solution (whole, on every rank).
  Solution<N> averages;
  /// Per output time: the estimated L1 error Σ_m Σ_i |C_i|·|ū − exact| (mass units).
  std::vector<double> l1_error;
  std::vector<double> mass;  ///< Per output time: Σ_m Σ_i |C_i|·ū, the mass they hold.
  /// M's observables' means over the box per output time (the file comment), with errors.
  std::vector<ObservableSeries> observables;
};

namespace detail {

/// The dual cell of grid node `flat`: [y − h/2, y + h/2] on every axis, clipped to the box.
template <std::size_t N>
Cell<N> dual_cell(const TensorGrid<N>& grid, std::size_t flat) {
  Cell<N> c;
  const std::array<double, N> y = grid.node(flat);
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    const double h = (ax.max - ax.min) / (ax.n - 1);
    c.lo[a] = std::max(ax.min, y[a] - 0.5 * h);
    c.hi[a] = std::min(ax.max, y[a] + 0.5 * h);
  }
  c.tag = flat;
  return c;
}

/// The check points of the cell averages: every node with the run's values in the cubature's
/// slots (VolumeValues with per_mode, budget/volume.hpp): u(t_k, m) at k·n_mode + m, then each
/// observable's Σ_m f_o(m, y)·u(t_k, m) at K·n_mode + k·n_obs + o (summed over the ranks of a
/// distributed solution), each hinted to its own dual cell.
template <HybridModel M>
CheckPoints<state_dim_v<M>> cell_checks(const TensorGrid<state_dim_v<M>>& grid,
                                        const Solution<state_dim_v<M>>& nodes, const double* par,
                                        const Backend* backend) {
  constexpr std::size_t N = state_dim_v<M>;
  CheckPoints<N> checks;
  std::array<double, N> lo{}, hi{};
  for (std::size_t a = 0; a < N; ++a) lo[a] = grid.axes[a].min, hi[a] = grid.axes[a].max;
  const std::vector<std::size_t> flat = check_lattice(grid, grid.size(), lo, hi, checks);
  const std::size_t K = nodes.n_time, Mn = nodes.n_mode, P = nodes.n_point;
  const auto n_obs = static_cast<std::size_t>(observable_count<M>());
  const std::size_t S = K * (Mn + n_obs);  // values per point
  std::vector<double> v(flat.size() * S, 0.0);
  const Block own = nodes.distributed ? nodes.owned : Block{0, Mn * P};
  for (std::size_t j = 0; j < flat.size(); ++j)
    for (std::size_t m = 0; m < Mn; ++m)
      if (const std::size_t pair = m * P + flat[j]; pair >= own.begin && pair < own.end)
        for (std::size_t k = 0; k < K; ++k) v[j * S + k * Mn + m] = nodes.at(k, m, flat[j]);
  // Each (mode, node) pair on one rank: the sum over the ranks is exact, and every rank then
  // has every u and forms the observables' sums over the modes in the same order.
  if (nodes.distributed && backend != nullptr) backend->sum_disjoint(std::span<double>(v));
  for (std::size_t j = 0; j < flat.size() && n_obs > 0; ++j)
    for (std::size_t m = 0; m < Mn; ++m)
      for (std::size_t o = 0; o < n_obs; ++o) {
        const double f =
            observable_value<M>(static_cast<int>(o), static_cast<int>(m), checks.x[j].data(), par);
        for (std::size_t k = 0; k < K; ++k)
          v[j * S + K * Mn + k * n_obs + o] += f * v[j * S + k * Mn + m];
      }
  checks.root = flat;
  keep_samples<M>(checks, std::move(v), S, par);
  return checks;
}

}  // namespace detail

/// The order of the Gauss rule on each cell of the cell averages (nodes per axis).
inline constexpr int kCellAverageOrder = 3;

/// Cell averages of the density over the dual cells of `grid`'s nodes at `times`, to
/// `aopt.rel_tol`·`scale` in L1 per (time, mode) (file comment); `nodes` is the run's solution
/// at the grid's nodes (the check points). The cubature's order is kCellAverageOrder whatever
/// aopt.order says. On a failed characteristic `failure` is set and the result is partial
/// (converged = false). Every rank computes the whole answer (opt.backend shares the tracing).
template <HybridModel M>
CellAverages<state_dim_v<M>> cell_averages(const TensorGrid<state_dim_v<M>>& grid,
                                           std::span<const double> times, const double* par,
                                           const CharacteristicsOptions& opt, AdaptiveOptions aopt,
                                           double scale, const Solution<state_dim_v<M>>& nodes,
                                           TraceFailure<state_dim_v<M>>& failure) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::size_t K = times.size(), Mn = static_cast<std::size_t>(M::n_mode);
  aopt.order = kCellAverageOrder;
  std::vector<detail::Cell<N>> roots(grid.size());
  for (std::size_t i = 0; i < roots.size(); ++i) roots[i] = detail::dual_cell(grid, i);
  const detail::CheckPoints<N> checks = detail::cell_checks<M>(grid, nodes, par, opt.backend);
  // The masses per (time, mode) steer the cubature; each observable's Σ_m f u per time is
  // integrated on the same cells, passively.
  const auto n_obs = static_cast<std::size_t>(observable_count<M>());
  const std::size_t slots = K * (Mn + n_obs);
  detail::VolumeValues<M> values{times, par, &opt, {}, true};
  detail::AdaptiveCubature<N, detail::VolumeValues<M>> cub(std::move(roots), slots, slots, aopt,
                                                           scale, values, &checks, K * Mn, true);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  CellAverages<N> res;
  std::vector<double> totals;
  detail::collect(cub, ok, 0, K * Mn, totals, res);
  Solution<N>& s = res.averages;
  s.n_time = K, s.n_mode = Mn, s.n_point = grid.size();
  s.u.assign(K * Mn * s.n_point, 0.0);
  res.l1_error.assign(K, 0.0);
  res.mass.assign(K, 0.0);
  for (std::size_t i = 0; i < s.n_point; ++i) {
    const double vol = detail::dual_cell(grid, i).volume();
    for (std::size_t k = 0; k < K; ++k)
      for (std::size_t m = 0; m < Mn; ++m) {
        s.u[s.index(k, m, i)] = cub.root_integral(i, k * Mn + m) / vol;
        res.mass[k] += cub.root_integral(i, k * Mn + m);
        res.l1_error[k] += cub.root_error(i, k * Mn + m);
      }
  }
  // E[f] = F/M with F = ∫ Σ_m f u and M the mass, each the sum over the roots; their errors
  // are the cubature's estimates of those sums.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t o = 0; o < n_obs; ++o) {
    ObservableSeries series;
    series.name = observable_name<M>(static_cast<int>(o));
    for (std::size_t k = 0; k < K; ++k) {
      double mass = 0.0, mass_error = 0.0;
      for (std::size_t m = 0; m < Mn; ++m)
        mass += cub.integral(k * Mn + m), mass_error += cub.error(k * Mn + m);
      const std::size_t slot = K * Mn + k * n_obs + o;
      const double e = mass > 0.0 ? cub.integral(slot) / mass : nan;
      series.values.push_back(e);
      series.errors.push_back(mass > 0.0 ? (cub.error(slot) + std::fabs(e) * mass_error) / mass
                                         : nan);
    }
    res.observables.push_back(std::move(series));
  }
  return res;
}

}  // namespace hybgen::rt
