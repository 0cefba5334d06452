#pragma once
/// \file observables.hpp
/// The expectations of a model's observables (`observe NAME = [MODE:] EXPR`; model.hpp,
/// `observable_value`) over a run's frames, and their errors.
///
/// The expectation. At each frame, over the density in the box (the Zeno atoms left out):
///     E[f] = Σ_k ∫ f_k(x) u_k(x) dx / Σ_k ∫ u_k(x) dx,
/// the mean of f under the density normalised to a probability (for method=invariant and
/// method=escape the invariant and the conditionally invariant density). The unconditional
/// integral is E[f]·mass. Each integral is the trapezoid rule on the grid's nodes; the ratio
/// is NaN where the box holds no mass.
///
/// The error, from the same expectation at three resolutions E₀ (the grid), E₁ and E₂, with
/// d₁ = E₀ − E₁, d₂ = E₁ − E₂. For an error C·h^q, d₁ = (2^q − 1)·C·h^q and d₂ = 2^q·d₁, so
///     error = 2·max(|d₁|, |d₂|/2^q) / (2^q − 1),   q = log2(|d₂|/|d₁|) clamped to [q_lo, q_hi],
/// twice the Richardson estimate of E₀'s error (2× the error where q is the true order). The
/// term |d₂|/2^q keeps a d₁ that vanishes by cancellation (E₀ and E₁ on either side of the
/// limit) from passing for a small error. With two resolutions only, q = q_hi. The three
/// resolutions and the clamp, by method:
///  * exact node values (characteristics): the error is the quadrature's, and E₁, E₂ are the
///    trapezoid rule on every second and every fourth node of the grid (each axis's last node
///    kept, so any n ≥ 3 works), q ∈ [1, 2]: second order where u·f is smooth, first where the
///    density jumps (a guard, the support, a mode's region);
///  * a scheme of order p with coarse answers (transfer and invariant: the same scheme on the
///    halved and quartered grids that their density errors use, two_grid.hpp): E₁, E₂ on those
///    grids, q ∈ [1/4, min(max(p, 1), 2)]: the density's order p, but a mean is a trapezoid sum
///    of node values on each grid, second order at most (fv's third-order u0 at t = 0 is
///    integrated at second order);
///  * samples (particles): E = Σ wᵢ fᵢ / Σ wᵢ over the samples in the box, its error twice the
///    delta-method standard error of the stratified sample (each particle draws from its own
///    slice of the proposal, particles.hpp): with zᵢ = wᵢ(fᵢ − E)·[in box], √(Σ_pairs
///    (z_a − z_b)²)/Σ wᵢ over the pairs of neighbouring strata (collapsed strata), which
///    overestimates the variance by the neighbours' differences of mean only.
/// No error is estimated where a method keeps no coarser answer: `transfer` and `invariant`
/// over several processes.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// One observable's expectation per frame and its estimated error.
struct ObservableSeries {
  std::string name;            ///< The observable's name.
  std::vector<double> values;  ///< E[f] per frame (NaN where the box holds no mass).
  std::vector<double> errors;  ///< Its estimated |error| per frame (NaN: none estimated).
};

/// The same method's answer on a coarser grid, kept for the observables' errors.
template <std::size_t N>
struct CoarseAnswer {
  TensorGrid<N> grid;    ///< The coarser grid (two_grid.hpp, halved_grid).
  Solution<N> solution;  ///< The answer there, the fine answer's frames.
};

/// How a method's answer is to be integrated (the file comment).
enum class ObservableErrorKind {
  quadrature,  ///< Exact node values: the trapezoid rule's error (characteristics).
  coarse,      ///< A scheme of order `order` with coarse answers (transfer, invariant).
  samples,     ///< Sample means with their standard errors (particles).
  cells,       ///< The cell averages' cubature of f u (budget/cell_averages.hpp).
  none,        ///< No estimate.
};

namespace detail {

/// The trapezoid rule of axis `a` on its nodes 0, s, 2s, … and its last node: (node index,
/// weight) pairs.
inline std::vector<std::pair<std::size_t, double>> strided_trapezoid(const GridAxis& a,
                                                                     std::size_t stride) {
  const auto n = static_cast<std::size_t>(std::max(a.n, 1));
  std::vector<std::size_t> idx;
  for (std::size_t i = 0; i < n; i += stride) idx.push_back(i);
  if (idx.back() != n - 1) idx.push_back(n - 1);
  std::vector<std::pair<std::size_t, double>> rule;
  if (idx.size() == 1) return {{0, 1.0}};
  for (std::size_t j = 0; j < idx.size(); ++j) {
    const double left = j > 0 ? axis_node(a, static_cast<int>(idx[j - 1])) : 0.0;
    const double right = j + 1 < idx.size() ? axis_node(a, static_cast<int>(idx[j + 1])) : 0.0;
    const double x = axis_node(a, static_cast<int>(idx[j]));
    const double w = 0.5 * ((j > 0 ? x - left : 0.0) + (j + 1 < idx.size() ? right - x : 0.0));
    rule.emplace_back(idx[j], w);
  }
  return rule;
}

/// Σ_k Σ_nodes w f_i u_k for every observable i, and Σ w u last: frame `k` of `sol` on `grid`
/// with the strided trapezoid rule (stride 1: the grid's own). A distributed solution: this
/// process's pairs, summed over the ranks by `backend`.
template <HybridModel M>
std::vector<double> observable_sums(const TensorGrid<state_dim_v<M>>& grid,
                                    const Solution<state_dim_v<M>>& sol, std::size_t k,
                                    std::size_t stride, const double* par, const Backend& backend) {
  constexpr std::size_t N = state_dim_v<M>;
  const int n_obs = observable_count<M>();
  std::vector<double> sums(static_cast<std::size_t>(n_obs) + 1, 0.0);
  std::array<std::vector<std::pair<std::size_t, double>>, N> rules;
  std::array<std::size_t, N> stride_of{};
  for (std::size_t a = 0; a < N; ++a) rules[a] = strided_trapezoid(grid.axes[a], stride);
  std::size_t s = 1;
  for (std::size_t a = N; a-- > 0;) stride_of[a] = s, s *= static_cast<std::size_t>(grid.axes[a].n);
  const auto add = [&](std::size_t m, std::size_t node, double w) {
    const double u = sol.at(k, m, node);
    if (u == 0.0) return;
    const std::array<double, N> x = grid.node(node);
    sums.back() += w * u;
    for (int i = 0; i < n_obs; ++i)
      sums[static_cast<std::size_t>(i)] +=
          w * u * observable_value<M>(i, static_cast<int>(m), x.data(), par);
  };
  if (sol.distributed) {
    std::array<std::vector<double>, N> weight;
    for (std::size_t a = 0; a < N; ++a) {
      weight[a].assign(static_cast<std::size_t>(grid.axes[a].n), 0.0);
      for (const auto& [i, w] : rules[a]) weight[a][i] = w;
    }
    for (std::size_t pair = sol.owned.begin; pair < sol.owned.end; ++pair) {
      const std::size_t m = pair / sol.n_point, node = pair % sol.n_point;
      double w = 1.0;
      for (std::size_t a = 0; a < N; ++a) w *= weight[a][(node / stride_of[a]) % grid.axes[a].n];
      add(m, node, w);
    }
    backend.sum(std::span<double>(sums));
    return sums;
  }
  std::array<std::size_t, N> at{};  // the position in each axis's rule
  const std::size_t total = [&] {
    std::size_t t = 1;
    for (const auto& r : rules) t *= r.size();
    return t;
  }();
  for (std::size_t flat = 0; flat < total; ++flat) {
    std::size_t rem = flat, node = 0;
    double w = 1.0;
    for (std::size_t a = N; a-- > 0;) {
      at[a] = rem % rules[a].size();
      rem /= rules[a].size();
      node += rules[a][at[a]].first * stride_of[a];
      w *= rules[a][at[a]].second;
    }
    for (std::size_t m = 0; m < sol.n_mode; ++m) add(m, node, w);
  }
  return sums;
}

/// E[f_i] from `observable_sums`' output (NaN where the mass is not positive).
inline double expectation(const std::vector<double>& sums, std::size_t i) {
  return sums.back() > 0.0 ? sums[i] / sums.back() : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace detail

/// The error of E₀ from E₁, E₂ (NaN: not known) with the observed order clamped to
/// [q_lo, q_hi] (the file comment).
inline double observable_error(double e0, double e1, double e2, double q_lo, double q_hi) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (!std::isfinite(e0) || !std::isfinite(e1)) return nan;
  const double d1 = std::fabs(e0 - e1);
  double q = q_hi, d2 = 0.0;
  if (std::isfinite(e2)) {
    d2 = std::fabs(e1 - e2);
    if (d1 > 0.0 && d2 > 0.0) q = std::clamp(std::log2(d2 / d1), q_lo, q_hi);
  }
  return 2.0 * std::max(d1, d2 / std::exp2(q)) / (std::exp2(q) - 1.0);
}

/// The expectations of M's observables over the frames of `sol` on `grid`, with errors of
/// `kind` (the file comment): `coarse` the coarser answers (halved, then quartered grid; for
/// `ObservableErrorKind::coarse`) of a scheme of order `order`. Collective over `backend`'s
/// ranks for a distributed solution.
template <HybridModel M>
std::vector<ObservableSeries> observable_expectations(
    const TensorGrid<state_dim_v<M>>& grid, const Solution<state_dim_v<M>>& sol, const double* par,
    ObservableErrorKind kind, std::span<const CoarseAnswer<state_dim_v<M>>> coarse, int order,
    const Backend& backend) {
  const int n_obs = observable_count<M>();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<ObservableSeries> out(static_cast<std::size_t>(n_obs));
  for (int i = 0; i < n_obs; ++i) out[static_cast<std::size_t>(i)].name = observable_name<M>(i);
  for (std::size_t k = 0; k < sol.n_time; ++k) {
    const std::vector<double> fine = detail::observable_sums<M>(grid, sol, k, 1, par, backend);
    std::vector<double> level1, level2;
    double q_lo = 1.0, q_hi = 2.0;
    if (kind == ObservableErrorKind::quadrature) {
      level1 = detail::observable_sums<M>(grid, sol, k, 2, par, backend);
      level2 = detail::observable_sums<M>(grid, sol, k, 4, par, backend);
    } else if (kind == ObservableErrorKind::coarse) {
      // The means are trapezoid sums of node values on every grid: second order at most.
      q_lo = 0.25, q_hi = std::clamp(order, 1, 2);
      if (!coarse.empty() && coarse[0].solution.n_time == sol.n_time)
        level1 = detail::observable_sums<M>(coarse[0].grid, coarse[0].solution, k, 1, par, backend);
      if (coarse.size() > 1 && coarse[1].solution.n_time == sol.n_time)
        level2 = detail::observable_sums<M>(coarse[1].grid, coarse[1].solution, k, 1, par, backend);
    }
    for (std::size_t i = 0; i < out.size(); ++i) {
      const double e0 = detail::expectation(fine, i);
      const double e1 = level1.empty() ? nan : detail::expectation(level1, i);
      const double e2 = level2.empty() ? nan : detail::expectation(level2, i);
      out[i].values.push_back(e0);
      out[i].errors.push_back(observable_error(e0, e1, e2, q_lo, q_hi));
    }
  }
  return out;
}

}  // namespace hybgen::rt
