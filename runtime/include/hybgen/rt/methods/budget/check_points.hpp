#pragma once
/// \file check_points.hpp
/// Check points of the mass budget's cubatures: points where the integrand is already known
/// (the grid's nodes, with the values the run solved there, or the forward flows' from a
/// finer lattice through them), against which the adaptive cubature (budget/cubature.hpp)
/// tests every leaf's interpolant, so that a feature the lattice resolves cannot hide between
/// a cell's Gauss nodes. Here: the lattice of nodes in a box under a cap on their number, the
/// finer lattice, and the choice of the points that are samples of the cells around them
/// (finite, off the support's boundary).

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

/// The index range [first[a], last[a]] of the grid's nodes in [lo, hi] per axis, a node
/// counting as in within `slack` × its axis's spacing; false when an axis has none.
template <std::size_t N>
bool node_range(const TensorGrid<N>& grid, const std::array<double, N>& lo,
                const std::array<double, N>& hi, double slack, std::array<std::size_t, N>& first,
                std::array<std::size_t, N>& last) {
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    const auto n = static_cast<std::size_t>(std::max(ax.n, 1));
    const double tol = ax.n > 1 ? slack * (ax.max - ax.min) / (ax.n - 1) : 0.0;
    first[a] = n;
    last[a] = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = axis_node(ax, static_cast<int>(i));
      if (x < lo[a] - tol || x > hi[a] + tol) continue;
      first[a] = std::min(first[a], i);
      last[a] = std::max(last[a], i);
    }
    if (first[a] > last[a]) return false;
  }
  return true;
}

/// The grid's nodes in the box [lo, hi], every s-th per axis (node indices divisible by s)
/// with the smallest s that keeps them to `cap`: their flat indices, in C order;
/// `checks.x` and `checks.spacing` (s times the grid's) are set, and `*shape` (when given) to
/// their number per axis.
template <std::size_t N>
std::vector<std::size_t> check_lattice(const TensorGrid<N>& grid, std::size_t cap,
                                       const std::array<double, N>& lo,
                                       const std::array<double, N>& hi, CheckPoints<N>& checks,
                                       std::array<std::size_t, N>* shape = nullptr) {
  std::array<std::size_t, N> first{}, last{};  // node index range in [lo, hi] per axis
  if (!node_range(grid, lo, hi, 0.0, first, last)) return {};
  std::size_t stride = 1;
  std::array<std::size_t, N> kept{};  // the nodes kept per axis at this stride
  for (;; ++stride) {
    std::size_t count = 1;
    for (std::size_t a = 0; a < N; ++a)
      count *= kept[a] = last[a] / stride - (first[a] + stride - 1) / stride + 1;
    if (count <= cap) break;
  }
  if (shape != nullptr) *shape = kept;
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

/// A lattice coordinate y's factor in the trapezoid weight over [lo, hi] on an axis of
/// spacing h: h, halved where y lies on lo or hi (to 1e-9·h; a box's face, where the
/// integrand need not vanish: a full weight there counts half a cell outside the box).
inline double trapezoid_factor(double y, double lo, double hi, double h) {
  const double tol = 1e-9 * h;
  return (std::fabs(y - lo) <= tol || std::fabs(y - hi) <= tol ? 0.5 : 1.0) * h;
}

/// Largest number of lattice points per grid spacing of `fine_lattice`.
inline constexpr std::size_t kMaxLatticeRefinement = 64;

/// A lattice of points in the box [lo, hi] whose integrand the caller computes (the forward
/// flows', budget/atom.hpp), not the grid's solved nodes: spacing h/r through the grid's
/// nodes (h the grid's spacing per axis), r ≤ kMaxLatticeRefinement the largest that keeps
/// the points to `cap` and, for r > 1, to `fine_cap` (budget/atom.hpp,
/// `max_fine_lattice_points`); where the nodes alone exceed `cap`, `check_lattice`'s every
/// s-th node.
/// Sets `checks.x` (in C order) and `checks.spacing`, `shape` to the lattice's points per
/// axis, and `weights` to each point's weight in the
/// lattice's trapezoid sum over [lo, hi]: the spacings' product, halved per axis where the
/// point lies on lo or hi (a box's face, where the integrand need not vanish: a full weight
/// there counts half a cell outside the box). The lattice sum of a step function (an impact
/// count) is off by about the step's jump times r/h-th of the cells its jump crosses, so the
/// finer lattice is the sharper check (budget/atom.hpp, `collect_step`).
template <std::size_t N>
void fine_lattice(const TensorGrid<N>& grid, std::size_t cap, std::size_t fine_cap,
                  const std::array<double, N>& lo, const std::array<double, N>& hi,
                  CheckPoints<N>& checks, std::vector<double>& weights,
                  std::array<std::size_t, N>& shape) {
  checks = {};
  weights.clear();
  shape.fill(0);
  std::array<std::size_t, N> first{}, last{};
  if (!node_range(grid, lo, hi, 1e-9, first, last)) return;
  auto count = [&](std::size_t r) {
    std::size_t c = 1;
    for (std::size_t a = 0; a < N; ++a) c *= (last[a] - first[a]) * r + 1;
    return c;
  };
  if (count(1) > cap) {
    check_lattice(grid, cap, lo, hi, checks, &shape);
  } else {
    std::size_t r = 1;
    while (r < kMaxLatticeRefinement && count(r + 1) <= std::min(cap, fine_cap)) ++r;
    std::array<std::size_t, N>& n = shape;
    for (std::size_t a = 0; a < N; ++a) {
      const GridAxis& ax = grid.axes[a];
      n[a] = (last[a] - first[a]) * r + 1;
      checks.spacing[a] =
          ax.n > 1 ? (ax.max - ax.min) / (ax.n - 1) / static_cast<double>(r) : ax.max - ax.min;
    }
    checks.x.resize(count(r));
    for (std::size_t j = 0; j < checks.x.size(); ++j) {
      std::size_t rem = j;
      for (std::size_t a = N; a-- > 0;) {
        const std::size_t i = rem % n[a];
        rem /= n[a];
        // A node, then i mod r steps of h/r past it: the grid's nodes are points exactly.
        checks.x[j][a] = axis_node(grid.axes[a], static_cast<int>(first[a] + i / r)) +
                         static_cast<double>(i % r) * checks.spacing[a];
      }
    }
  }
  weights.assign(checks.x.size(), 1.0);
  for (std::size_t j = 0; j < checks.x.size(); ++j)
    for (std::size_t a = 0; a < N; ++a)
      weights[j] *= trapezoid_factor(checks.x[j][a], lo[a], hi[a], checks.spacing[a]);
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
