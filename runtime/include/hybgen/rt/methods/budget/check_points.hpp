#pragma once
/// \file check_points.hpp
/// Check points of the mass budget's cubatures: points where the integrand is already known
/// (the grid's nodes, with the values the run solved there, or the atom's forward flows from
/// them), against which the adaptive cubature (budget/cubature.hpp) tests every leaf's
/// interpolant, so that a feature the grid resolves cannot hide between a cell's Gauss
/// nodes. Here: the lattice of nodes in a box under a cap on their number, and the choice of
/// the nodes that are samples of the cells around them (finite, off the support's boundary).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

namespace detail {

/// Points where the integrand is already known (the grid nodes the run solved): x[j] and
/// its K slot values v[j·K + k]. The cubature compares every leaf's interpolant with the
/// check points inside it (see `AdaptiveCubature`), so a feature the grid resolves cannot
/// hide between a cell's Gauss nodes.
template <std::size_t D>
struct CheckPoints {
  std::vector<std::array<double, D>> x;  ///< Coordinates.
  std::vector<double> v;                 ///< Values, K per point.
  std::array<double, D> spacing{};       ///< Their lattice's spacing per axis.
  /// Optional: the cubature's root box each point lies in (a hint: AdaptiveCubature tries
  /// it first), one per point of x, or empty.
  std::vector<std::size_t> root;
};

/// The grid's nodes in the box [lo, hi], every s-th per axis (node indices divisible by s)
/// with the smallest s that keeps them to `cap`: their flat indices, in C order;
/// `checks.x` and `checks.spacing` (s times the grid's) are set.
template <std::size_t N>
std::vector<std::size_t> check_lattice(const TensorGrid<N>& grid, std::size_t cap,
                                       const std::array<double, N>& lo,
                                       const std::array<double, N>& hi, CheckPoints<N>& checks) {
  std::array<std::size_t, N> first{}, last{};  // node index range in [lo, hi] per axis
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    const auto n = static_cast<std::size_t>(std::max(ax.n, 1));
    first[a] = n;
    last[a] = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = axis_node(ax, static_cast<int>(i));
      if (x < lo[a] || x > hi[a]) continue;
      first[a] = std::min(first[a], i);
      last[a] = std::max(last[a], i);
    }
    if (first[a] > last[a]) return {};
  }
  std::size_t stride = 1;
  for (;; ++stride) {
    std::size_t count = 1;
    for (std::size_t a = 0; a < N; ++a)
      count *= last[a] / stride - (first[a] + stride - 1) / stride + 1;
    if (count <= cap) break;
  }
  std::vector<std::size_t> flat;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    std::size_t rem = i;
    bool keep = true;
    for (std::size_t a = N; a-- > 0 && keep;) {
      const auto n = static_cast<std::size_t>(std::max(grid.axes[a].n, 1));
      const std::size_t ia = rem % n;
      keep = ia % stride == 0 && ia >= first[a] && ia <= last[a];
      rem /= n;
    }
    if (keep) flat.push_back(i);
  }
  checks.x.resize(flat.size());
  for (std::size_t j = 0; j < flat.size(); ++j) checks.x[j] = grid.node(flat[j]);
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    checks.spacing[a] =
        ax.n > 1 ? static_cast<double>(stride) * (ax.max - ax.min) / (ax.n - 1) : ax.max - ax.min;
  }
  return flat;
}

/// Whether x lies on the boundary of M's support, to the resolution `h`: one of the probes
/// x ± 1e-6·h_a e_a is on the other side of it.
template <HybridModel M>
bool on_support_boundary(const std::array<double, state_dim_v<M>>& x,
                         const std::array<double, state_dim_v<M>>& h, const double* par) {
  const bool in = M::in_support(x.data(), par);
  for (std::size_t a = 0; a < x.size(); ++a) {
    for (const double sign : {-1.0, 1.0}) {
      std::array<double, state_dim_v<M>> y = x;
      y[a] += sign * 1e-6 * h[a];
      if (M::in_support(y.data(), par) != in) return true;
    }
  }
  return false;
}

/// Set checks.v = v (K values per point of checks.x), leaving out the points with a
/// non-finite value (a node at a singularity) and the points on the support's boundary:
/// the density jumps to 0 there, and a node on the jump holds one side's value, no sample of
/// the cell around it (a support aligned with the grid, sir's s + i ≤ 1 or the ball's
/// x ≥ 0, puts a whole row of nodes on it, and their misfits would all have one sign).
template <HybridModel M>
void keep_samples(CheckPoints<state_dim_v<M>>& checks, std::vector<double> v, std::size_t K,
                  const double* par) {
  std::size_t kept = 0;
  for (std::size_t j = 0; j < checks.x.size(); ++j) {
    bool finite = true;
    for (std::size_t k = 0; k < K; ++k) finite = finite && std::isfinite(v[j * K + k]);
    if (!finite || on_support_boundary<M>(checks.x[j], checks.spacing, par)) continue;
    checks.x[kept] = checks.x[j];
    if (!checks.root.empty()) checks.root[kept] = checks.root[j];
    std::copy_n(v.begin() + static_cast<std::ptrdiff_t>(j * K), K,
                v.begin() + static_cast<std::ptrdiff_t>(kept * K));
    ++kept;
  }
  checks.x.resize(kept);
  if (!checks.root.empty()) checks.root.resize(kept);
  v.resize(kept * K);
  checks.v = std::move(v);
}

}  // namespace detail

}  // namespace hybgen::rt
