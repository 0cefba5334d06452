#pragma once
/// \file two_grid.hpp
/// Errors of a long-term answer (an invariant density, a spectrum) estimated from the same
/// answer on a coarser grid: the mechanism every scheme of the invariant method uses
/// (methods.hpp: `solve_by_invariant`, generator_solve.hpp: scheme=fv).
///
/// The coarse grid `halved_grid` has (n+1)/2 nodes per axis on the same box (twice the
/// spacing for odd n; every coarse node is then a fine one). For a scheme of order p the
/// error on the fine grid is E ≈ C·Δx^p and the coarse one 2^p·E, so their difference is
/// D ≈ (2^p − 1)·E. An estimate factor·D covers E when factor·(2^p − 1) ≥ 1.
///
/// Density. D = max over modes of Σ w_c |I u_f − u_c| / Σ w_c |I u_f| over the coarse nodes
/// (trapezoid weights w_c), I u_f the fine density at the coarse node (the node itself for odd
/// n, else multilinear interpolation between the fine nodes around it, whose error O(Δx²) is
/// below a first-order scheme's). Nodes on a cut of the mode (a jump of the density,
/// two-valued there) are left out on both grids when the scheme marks them.
///
/// Spectrum. Each fine eigenvalue λ_k is matched to the nearest coarse one λ'_j; its error is
/// factor·|λ_k − λ'_j|. The derived rates take the same difference: the spectral gap
/// g = 1 − |λ₂/λ₁|, the decay rate −ln|λ₂/λ₁|/h, the leak rate −ln|λ₁|/h (h the operator's
/// step). Two decisions follow, and the outputs state them instead of the bare numbers:
///  * `decays`: g > its error. Otherwise the gap is numerical (a periodic flow's eigenvalues
///    lie on the unit circle, and every scheme's damping moves them inside by an amount that
///    falls with Δx): no decay is claimed.
///  * `leaks`: the leak rate > its error (λ₁ clearly below 1). Then no density in the box is
///    invariant: mass leaves it, and the eigenvector is the conditionally invariant density,
///    whose escape rate method=escape reports with its error.
///
/// Observed order. A third grid (halved again) gives D' on the coarser pair and
/// p_obs = log2(D'/D). An estimate is `reliable` when p_obs is near the scheme's order p
/// (|p_obs − p| ≤ max(0.5, p/3)): the grids are then in the asymptotic regime where
/// E ≈ D/(2^p − 1). Otherwise the outputs say that the estimate cannot be trusted (a density
/// with unresolved features, or a scheme whose error does not fall with Δx).

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstddef>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "hybgen/rt/core/grid.hpp"

namespace hybgen::rt {

/// The grid of the same box with (n + 1)/2 nodes per axis (at least 2): for odd n, every
/// other node of `grid`.
template <std::size_t N>
TensorGrid<N> halved_grid(const TensorGrid<N>& grid) {
  TensorGrid<N> coarse = grid;
  for (GridAxis& a : coarse.axes) a.n = std::max(2, (a.n + 1) / 2);
  return coarse;
}

/// The factor on the two-resolution difference D that makes it cover the error of a scheme
/// of order p: D ≈ (2^p − 1)·E covers E with the margin 2^p − 1 for p = 2 and 3 (3 and 7);
/// above, the factor 8/2^p keeps the margin near 8 (31 at p = 5 would make the estimate too
/// wide to tell a user anything) and still covers a true order down to 2.3 (where data that
/// is only C², a jump or a wall's third-order stencil limit a fifth-order scheme); at p = 1
/// the margin is 1, and the factor 2 makes it 2 (and covers p ≥ 0.58).
constexpr double error_factor(int p) {
  return p <= 1 ? 2.0 : p <= 3 ? 1.0 : 8.0 / static_cast<double>(1 << p);
}

/// 2^p − 1 at the observed order p clamped to ≥ 1/4: a difference D between a grid and its
/// halved one is this times the fine grid's error at order p (Richardson), so D over it is
/// that error (4.1 D at most).
inline double richardson_divisor(double p) {
  return std::exp2(std::max(p, 0.25)) - 1.0;
}

/// Whether |p_obs − p| ≤ max(0.5, p/3): an observed order near the scheme's (file comment).
inline bool order_near(double observed, double order) {
  return std::isfinite(observed) && std::fabs(observed - order) <= std::max(0.5, order / 3.0);
}

namespace detail {

/// The fine nodes around `y` on axis `a` and their linear weights: one node when y is one.
struct AxisStencil {
  std::array<int, 2> node{};       ///< Fine node indices.
  std::array<double, 2> weight{};  ///< Their weights (sum 1).
  int count = 1;                   ///< 1 or 2.
};

inline AxisStencil axis_stencil(const GridAxis& a, double y) {
  AxisStencil s;
  if (a.n <= 1) return s;
  const double t = (y - a.min) / (a.max - a.min) * static_cast<double>(a.n - 1);
  const int i = std::clamp(static_cast<int>(std::floor(t)), 0, a.n - 2);
  const double f = t - i;
  constexpr double kOnNode = 1e-9;
  if (f <= kOnNode) {
    s.node[0] = i, s.weight[0] = 1.0;
  } else if (f >= 1.0 - kOnNode) {
    s.node[0] = i + 1, s.weight[0] = 1.0;
  } else {
    s.node = {i, i + 1}, s.weight = {1.0 - f, f}, s.count = 2;
  }
  return s;
}

}  // namespace detail

/// D of the file comment: max over modes of Σ w_c |I u_f − u_c| / Σ w_c |I u_f| over the
/// coarse nodes; per mode into `per_mode` (NaN: a mode without mass). Densities are laid out
/// [mode][node]; `fine_jump` and `coarse_jump` (empty: none) mark the nodes on a cut of the
/// mode, left out.
template <std::size_t N>
double coarse_difference(const TensorGrid<N>& fine, std::span<const double> u_fine,
                         std::span<const char> fine_jump, const TensorGrid<N>& coarse,
                         std::span<const double> u_coarse, std::span<const char> coarse_jump,
                         int n_mode, std::vector<double>* per_mode) {
  const std::size_t nf = fine.size(), nc = coarse.size();
  std::array<AxisRule, N> rules;
  std::array<std::vector<detail::AxisStencil>, N> stencils;
  for (std::size_t a = 0; a < N; ++a) {
    rules[a] = trapezoid_rule(coarse.axes[a]);
    for (const double y : rules[a].nodes)
      stencils[a].push_back(detail::axis_stencil(fine.axes[a], y));
  }
  std::vector<double> num(static_cast<std::size_t>(n_mode), 0.0), den(num);
  std::array<std::size_t, N> k{};
  for (std::size_t i = 0; i < nc; ++i) {
    std::size_t rem = i;
    double w = 1.0;
    for (std::size_t a = N; a-- > 0;) {
      const auto na = static_cast<std::size_t>(std::max(coarse.axes[a].n, 1));
      k[a] = rem % na, rem /= na;
      w *= rules[a].weights[k[a]];
    }
    // The stencil's fine nodes: the tensor product of the axes' (at most 2^N).
    std::size_t corners = 1;
    for (std::size_t a = 0; a < N; ++a)
      corners *= static_cast<std::size_t>(stencils[a][k[a]].count);
    for (int m = 0; m < n_mode; ++m) {
      const std::size_t jc = static_cast<std::size_t>(m) * nc + i;
      if (!coarse_jump.empty() && coarse_jump[jc]) continue;
      double value = 0.0;
      bool jump = false;
      for (std::size_t c = 0; c < corners && !jump; ++c) {
        std::size_t fi = 0, rc = c;
        double wf = 1.0;
        for (std::size_t a = 0; a < N; ++a) {
          const detail::AxisStencil& s = stencils[a][k[a]];
          const auto pick = static_cast<std::size_t>(s.count == 2 ? rc % 2 : 0);
          rc /= static_cast<std::size_t>(s.count);
          fi = fi * static_cast<std::size_t>(fine.axes[a].n) +
               static_cast<std::size_t>(s.node[pick]);
          wf *= s.weight[pick];
        }
        const std::size_t jf = static_cast<std::size_t>(m) * nf + fi;
        if (!fine_jump.empty() && fine_jump[jf]) jump = true;
        value += wf * u_fine[jf];
      }
      if (jump) continue;
      num[static_cast<std::size_t>(m)] += w * std::fabs(value - u_coarse[jc]);
      den[static_cast<std::size_t>(m)] += w * std::fabs(value);
    }
  }
  double total = 0.0, worst = 0.0;
  for (const double d : den) total += d;
  if (per_mode)
    per_mode->assign(static_cast<std::size_t>(n_mode), std::numeric_limits<double>::quiet_NaN());
  for (int m = 0; m < n_mode; ++m) {
    const auto mu = static_cast<std::size_t>(m);
    if (!(den[mu] > 1e-12 * total)) continue;
    const double e = num[mu] / den[mu];
    if (per_mode) (*per_mode)[mu] = e;
    worst = std::max(worst, e);
  }
  return worst;
}

/// The spectrum's numbers and their errors (file comment). NaN: no estimate.
struct SpectrumErrors {
  std::vector<double> lambda_error;                                    ///< Per fine eigenvalue.
  double gap = 0.0;                                                    ///< 1 − |λ₂/λ₁|.
  double gap_error = std::numeric_limits<double>::quiet_NaN();         ///< Its error.
  double decay_rate = 0.0;                                             ///< −ln|λ₂/λ₁|/h.
  double decay_rate_error = std::numeric_limits<double>::quiet_NaN();  ///< Its error.
  double leak_rate = 0.0;                                              ///< −ln|λ₁|/h.
  double leak_rate_error = std::numeric_limits<double>::quiet_NaN();   ///< Its error.
  std::optional<bool> decays;  ///< gap > gap_error; unknown without an estimate.
  std::optional<bool> leaks;   ///< leak_rate > leak_rate_error; unknown without an estimate.
};

namespace detail {

/// The index of the eigenvalue of `c` nearest z, or -1.
inline long nearest(std::span<const std::complex<double>> c, std::complex<double> z) {
  long best = -1;
  for (std::size_t k = 0; k < c.size(); ++k)
    if (best < 0 || std::abs(c[k] - z) < std::abs(c[static_cast<std::size_t>(best)] - z))
      best = static_cast<long>(k);
  return best;
}

/// gap, decay rate and leak rate of λ₁, λ₂ over a step h.
struct Rates {
  double gap = 0.0, decay = 0.0, leak = 0.0;
};
inline Rates rates(std::complex<double> l1, std::complex<double> l2, double h) {
  const double a1 = std::abs(l1), ratio = a1 > 0.0 ? std::abs(l2) / a1 : 0.0;
  return {1.0 - ratio, -std::log(ratio) / h, -std::log(a1) / h};
}

}  // namespace detail

/// Whether λ₂ lies within the errors of λ₁ (`l` by decreasing modulus, `error` per eigenvalue;
/// NaN errors: `floor` each): the leading eigenvalue is then not simple, and P has several
/// independent invariant densities — a system with several invariant sets, or an operator
/// that is the identity to within the eigen-solver's tolerance (a step that moves no sample
/// measurably). Which one the solver returns is its start vector's choice, on each grid.
inline bool leading_eigenvalue_repeats(std::span<const std::complex<double>> l,
                                       std::span<const double> error, double floor) {
  if (l.size() < 2) return false;
  const auto err = [&](std::size_t k) {
    return k < error.size() && std::isfinite(error[k]) ? error[k] : floor;
  };
  return std::abs(l[1] - l[0]) <= err(0) + err(1);
}

/// The spectrum's rates and their errors from the eigenvalues on the grid (`fine`, by
/// decreasing modulus, λ₁ first) and on the coarse grid (`coarse`; empty: no estimate), for
/// an operator of step h; `factor` as for the density (file comment). `floor` is added to
/// every eigenvalue's error (the eigen-solver's tolerance).
inline SpectrumErrors spectrum_errors(std::span<const std::complex<double>> fine,
                                      std::span<const std::complex<double>> coarse, double h,
                                      double factor, double floor = 0.0) {
  SpectrumErrors e;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  e.lambda_error.assign(fine.size(), nan);
  if (fine.empty()) return e;
  const detail::Rates r =
      detail::rates(fine[0], fine.size() >= 2 ? fine[1] : std::complex<double>{}, h);
  e.leak_rate = r.leak;
  if (fine.size() >= 2) e.gap = r.gap, e.decay_rate = r.decay;
  if (coarse.empty()) return e;
  std::vector<long> match(fine.size());
  for (std::size_t k = 0; k < fine.size(); ++k) {
    match[k] = detail::nearest(coarse, fine[k]);
    e.lambda_error[k] =
        factor * std::abs(fine[k] - coarse[static_cast<std::size_t>(match[k])]) + floor;
  }
  const std::complex<double> c1 = coarse[static_cast<std::size_t>(match[0])];
  // λ₁'s error in the leak rate: |d ln|λ|/dλ| = 1/|λ|.
  e.leak_rate_error =
      factor * std::fabs(r.leak - (-std::log(std::abs(c1)) / h)) + floor / (std::abs(fine[0]) * h);
  e.leaks = e.leak_rate > e.leak_rate_error;
  if (fine.size() >= 2) {
    const detail::Rates rc = detail::rates(c1, coarse[static_cast<std::size_t>(match[1])], h);
    e.gap_error = factor * std::fabs(r.gap - rc.gap) + 2.0 * floor;
    e.decay_rate_error = factor * std::fabs(r.decay - rc.decay) + 2.0 * floor / h;
    e.decays = e.gap > e.gap_error;
  }
  return e;
}

}  // namespace hybgen::rt
