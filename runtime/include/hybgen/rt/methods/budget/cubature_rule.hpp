#pragma once
/// \file cubature_rule.hpp
/// The cells of the mass budget's adaptive cubature (budget/cubature.hpp) and the rule on
/// one cell: tensor Gauss–Legendre with q nodes per axis on the reference cell [0, 1]^D,
/// exact for degree 2q − 1, with the parent's predictions of its halves and a null rule.
/// Invariants: Σ_n W_n = 1; for every axis a, Σ_s half[(2a + s)·Q + n] = W_n; the null rule
/// annihilates polynomials of degree ≤ q − 2 along its axis.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <vector>

#include "hybgen/rt/core/grid.hpp"

namespace hybgen::rt {

namespace detail {

/// The reference cell [0, 1]^D with the tensor Gauss rule of q nodes per axis (flat node
/// index n = Σ_a n_a q^a): node offsets xi, weights W (Σ W = 1); for a split into the halves
/// s = 0, 1 along axis a, the parent's predictions half[(2a + s)·Q + n] = ∫_{half} ℓ_n (ℓ_n:
/// the tensor Lagrange basis function of node n; Σ_s half = W); and the 1-D null rule nu:
/// Σ_i nu_i f(x_i) = c·∫₀¹|L̂_{q−1}| where c L̂_{q−1} is the top (shifted Legendre) component
/// of the degree-(q − 1) interpolant of f; nu annihilates polynomials of degree ≤ q − 2.
template <std::size_t D>
struct CubatureRule {
  std::size_t q = 0;                      ///< Nodes per axis.
  std::size_t Q = 0;                      ///< Nodes per cell, q^D.
  std::vector<std::array<double, D>> xi;  ///< Node offsets in [0, 1]^D.
  std::vector<double> W;                  ///< Weights, Σ = 1.
  std::vector<double> half;               ///< Half-cell predictions, [axis][side][node].
  std::vector<double> x1;                 ///< 1-D nodes on [0, 1].
  std::vector<double> w1;                 ///< 1-D weights on [0, 1].
  std::vector<double> nu;                 ///< 1-D null rule (all 0 for q = 1).

  /// The rule of `order` nodes per axis.
  explicit CubatureRule(int order) {
    const AxisRule g = gauss_legendre(std::max(order, 1));
    q = g.nodes.size();
    x1.resize(q);
    w1.resize(q);
    for (std::size_t i = 0; i < q; ++i) {
      x1[i] = 0.5 * (1.0 + g.nodes[i]);
      w1[i] = 0.5 * g.weights[i];
    }
    // p1[s·q + i] = ∫_{s/2}^{(s+1)/2} ℓ_i (degree q − 1: the q-point Gauss rule is exact).
    std::vector<double> p1(2 * q, 0.0);
    for (std::size_t s = 0; s < 2; ++s) {
      for (std::size_t m = 0; m < q; ++m) {
        const double eta = 0.5 * (static_cast<double>(s) + x1[m]), om = 0.5 * w1[m];
        for (std::size_t i = 0; i < q; ++i) p1[s * q + i] += om * lagrange(i, eta);
      }
    }
    // Null rule: L(x) = P_{q−1}(2x − 1), c = Σ w L f / Σ w L² (discrete orthogonality of the
    // Gauss nodes), ∫₀¹|L| by a fine midpoint sum (it only fixes a constant factor).
    nu.assign(q, 0.0);
    if (q > 1) {
      const auto legendre = [this](double x) {
        double p0 = 1.0, p = 2.0 * x - 1.0;
        for (std::size_t j = 1; j + 1 < q; ++j) {
          const double jj = static_cast<double>(j);
          const double pn = ((2.0 * jj + 1.0) * (2.0 * x - 1.0) * p - jj * p0) / (jj + 1.0);
          p0 = p;
          p = pn;
        }
        return p;
      };
      double norm = 0.0, l1 = 0.0;
      for (std::size_t i = 0; i < q; ++i) norm += w1[i] * legendre(x1[i]) * legendre(x1[i]);
      constexpr int kMid = 4096;
      for (int j = 0; j < kMid; ++j) l1 += std::fabs(legendre((j + 0.5) / kMid)) / kMid;
      for (std::size_t i = 0; i < q; ++i) nu[i] = w1[i] * legendre(x1[i]) * l1 / norm;
    }
    Q = 1;
    for (std::size_t a = 0; a < D; ++a) Q *= q;
    xi.resize(Q);
    W.assign(Q, 1.0);
    half.assign(2 * D * Q, 1.0);
    for (std::size_t n = 0; n < Q; ++n) {
      std::size_t rem = n;
      for (std::size_t a = 0; a < D; ++a) {
        const std::size_t i = rem % q;
        rem /= q;
        xi[n][a] = x1[i];
        W[n] *= w1[i];
        for (std::size_t b = 0; b < D; ++b)
          for (std::size_t s = 0; s < 2; ++s)
            half[(b * 2 + s) * Q + n] *= b == a ? p1[s * q + i] : w1[i];
      }
    }
  }

  /// The 1-D Lagrange basis function of node i at t ∈ [0, 1].
  double lagrange(std::size_t i, double t) const {
    double l = 1.0;
    for (std::size_t r = 0; r < q; ++r)
      if (r != i) l *= (t - x1[r]) / (x1[i] - x1[r]);
    return l;
  }
};

/// A box cell [lo, hi] with the index of the root box it belongs to.
template <std::size_t D>
struct Cell {
  std::array<double, D> lo{};  ///< Lower corner.
  std::array<double, D> hi{};  ///< Upper corner.
  std::size_t tag = 0;         ///< Root box index.
  /// Volume (1 for D = 0).
  double volume() const {
    double v = 1.0;
    for (std::size_t a = 0; a < D; ++a) v *= hi[a] - lo[a];
    return v;
  }
  /// Half s (0: lower, 1: upper) along axis a.
  Cell half(std::size_t a, std::size_t s) const {
    Cell c = *this;
    const double mid = 0.5 * (lo[a] + hi[a]);
    (s == 0 ? c.hi[a] : c.lo[a]) = mid;
    return c;
  }
};

}  // namespace detail

}  // namespace hybgen::rt
