#pragma once
/// \file grid.hpp
/// Where densities are sampled: the tensor grid of the run (GridAxis, TensorGrid, C order as
/// the .npy files), the 1-D quadrature rules the budgets build tensor cubatures from, and the
/// check every method makes of its output times.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <span>
#include <stdexcept>
#include <vector>

namespace hybgen::rt {

/// A 1-D quadrature rule: ∫ f ≈ Σ weights[i]·f(nodes[i]).
struct AxisRule {
  std::vector<double> nodes;    ///< Abscissae.
  std::vector<double> weights;  ///< Weights.
};

/// Gauss–Legendre nodes and weights on [−1, 1] (Newton on P_n; exact for degree ≤ 2n−1).
inline AxisRule gauss_legendre(int n) {
  AxisRule r;
  const auto un = static_cast<std::size_t>(std::max(n, 1));
  n = static_cast<int>(un);
  r.nodes.assign(un, 0.0);
  r.weights.assign(un, 0.0);
  for (int i = 0; i < (n + 1) / 2; ++i) {
    double z = std::cos(std::numbers::pi * (i + 0.75) / (n + 0.5));
    double pp = 1.0;
    for (int it = 0; it < 100; ++it) {
      double p1 = 1.0, p2 = 0.0;
      for (int j = 0; j < n; ++j) {
        const double p3 = p2;
        p2 = p1;
        p1 = ((2.0 * j + 1.0) * z * p2 - j * p3) / (j + 1.0);
      }
      pp = n * (z * p1 - p2) / (z * z - 1.0);
      const double z1 = z;
      z = z1 - p1 / pp;
      if (std::fabs(z - z1) <= 1e-16) break;
    }
    const auto lo = static_cast<std::size_t>(i), hi = un - 1 - lo;
    r.nodes[lo] = -z;
    r.nodes[hi] = z;
    r.weights[lo] = r.weights[hi] = 2.0 / ((1.0 - z * z) * pp * pp);
  }
  return r;
}

/// One axis of a tensor grid: n nodes at linspace(min, max, n), both ends included.
struct GridAxis {
  double min = 0.0;  ///< First node.
  double max = 1.0;  ///< Last node.
  int n = 2;         ///< Number of nodes (≥ 1).
};

/// Coordinate of node i on an axis: exact at both ends and symmetric (0 is hit exactly on a
/// symmetric axis with an odd n).
inline double axis_node(const GridAxis& a, int i) {
  if (a.n <= 1 || i <= 0) return a.min;
  if (i >= a.n - 1) return a.max;
  const double nm1 = static_cast<double>(a.n - 1);
  return (a.min * (nm1 - static_cast<double>(i)) + a.max * static_cast<double>(i)) / nm1;
}

/// A tensor grid over the box Π[min_a, max_a]; flat node index in C order (last axis fastest),
/// matching the .npy layout of docs/design.md.
template <std::size_t N>
struct TensorGrid {
  std::array<GridAxis, N> axes{};  ///< One axis per state variable, in state order.

  /// Number of nodes.
  std::size_t size() const {
    std::size_t s = 1;
    for (const GridAxis& a : axes) s *= static_cast<std::size_t>(std::max(a.n, 1));
    return s;
  }
  /// Coordinates of node `flat`.
  std::array<double, N> node(std::size_t flat) const {
    std::array<double, N> y{};
    for (std::size_t a = N; a-- > 0;) {
      const auto n = static_cast<std::size_t>(std::max(axes[a].n, 1));
      y[a] = axis_node(axes[a], static_cast<int>(flat % n));
      flat /= n;
    }
    return y;
  }
  /// The flat index of the node nearest `y` (per axis; a point outside the box goes to the
  /// nearest face's node).
  std::size_t nearest(const std::array<double, N>& y) const {
    std::size_t flat = 0;
    for (std::size_t a = 0; a < N; ++a) {
      const GridAxis& ax = axes[a];
      const double h = ax.n > 1 ? (ax.max - ax.min) / (ax.n - 1) : 1.0;
      const double k = std::clamp(std::round((y[a] - ax.min) / h), 0.0,
                                  static_cast<double>(std::max(ax.n, 1) - 1));
      flat = flat * static_cast<std::size_t>(std::max(ax.n, 1)) + static_cast<std::size_t>(k);
    }
    return flat;
  }
};

/// Composite Gauss–Legendre rule of `order` points on each panel [b_j, b_{j+1}] of the
/// ascending `breakpoints` (use graded breakpoints near singularities).
inline AxisRule gauss_legendre_rule(std::span<const double> breakpoints, int order) {
  const AxisRule ref = gauss_legendre(order);
  AxisRule r;
  for (std::size_t j = 0; j + 1 < breakpoints.size(); ++j) {
    const double a = breakpoints[j], b = breakpoints[j + 1];
    for (std::size_t q = 0; q < ref.nodes.size(); ++q) {
      r.nodes.push_back(0.5 * (a + b) + 0.5 * (b - a) * ref.nodes[q]);
      r.weights.push_back(0.5 * (b - a) * ref.weights[q]);
    }
  }
  return r;
}

/// Composite Gauss–Legendre rule on `panels` equal panels of [lo, hi].
inline AxisRule gauss_legendre_rule(double lo, double hi, int panels, int order) {
  std::vector<double> bp;
  for (int j = 0; j <= panels; ++j) bp.push_back(lo + (hi - lo) * j / panels);
  bp.back() = hi;
  return gauss_legendre_rule(bp, order);
}

/// Trapezoid rule on the nodes of a grid axis.
inline AxisRule trapezoid_rule(const GridAxis& a) {
  AxisRule r;
  const int n = std::max(a.n, 1);
  for (int i = 0; i < n; ++i) r.nodes.push_back(axis_node(a, i));
  if (n == 1) {
    r.weights.push_back(1.0);
    return r;
  }
  const double h = (a.max - a.min) / (n - 1);
  for (int i = 0; i < n; ++i) r.weights.push_back(i == 0 || i == n - 1 ? 0.5 * h : h);
  return r;
}

namespace detail {

/// Σ over the tensor nodes of Π weights · value(flat index).
template <std::size_t N, class F>
double tensor_sum(const std::array<const AxisRule*, N>& rules, F&& value) {
  std::size_t total = 1;
  for (const AxisRule* r : rules) total *= r->nodes.size();
  double s = 0.0;
  for (std::size_t flat = 0; flat < total; ++flat) {
    std::size_t rem = flat;
    double w = 1.0;
    for (std::size_t a = N; a-- > 0;) {
      const std::size_t n = rules[a]->nodes.size();
      w *= rules[a]->weights[rem % n];
      rem /= n;
    }
    s += w * value(flat);
  }
  return s;
}

template <std::size_t N>
std::array<double, N> tensor_node(const std::array<const AxisRule*, N>& rules, std::size_t flat) {
  std::array<double, N> y{};
  for (std::size_t a = N; a-- > 0;) {
    const std::size_t n = rules[a]->nodes.size();
    y[a] = rules[a]->nodes[flat % n];
    flat /= n;
  }
  return y;
}

/// Throws std::invalid_argument unless the output times are finite, ≥ 0 and sorted.
inline void validate_times(std::span<const double> times) {
  for (std::size_t k = 0; k < times.size(); ++k) {
    if (!std::isfinite(times[k]) || times[k] < 0.0)
      throw std::invalid_argument("characteristics: output times must be finite and >= 0");
    if (k > 0 && times[k] < times[k - 1])
      throw std::invalid_argument("characteristics: output times must be sorted ascending");
  }
}

}  // namespace detail

}  // namespace hybgen::rt
