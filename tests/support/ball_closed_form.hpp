#pragma once
/// \file ball_closed_form.hpp
/// Closed forms of the bouncing ball of the paper's §4.1 (models/bouncing_ball.model,
/// tests/rt/bouncing_ball_model.hpp), shared by the runtime tests, the end-to-end tests and
/// the benchmarks: the initial density, the exact elastic density, and the Zeno mass with
/// restitution e < 1. State (x, p), flow (p/m, −m g), ground x = 0, reset p ↦ −e p.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/characteristics.hpp"

namespace hybgen::testing {

/// u0(x, p) = exp(−(x − 1)² − p²) on the support x ≥ 0.
inline double ball_u0(double x, double p) {
  return x >= 0.0 ? std::exp(-(x - 1.0) * (x - 1.0) - p * p) : 0.0;
}

/// The exact density of the elastic ball (e = 1) at (x, p) and time T: the motion is
/// periodic and measure-preserving (div X = 0, J = 1), so u(T) = u0 ∘ φ_{−T}. Energy
/// E = p²/(2m) + m g x, ground momentum P0 = √(2 m E), period 2 P0/(m g); time since the
/// last impact σ = (P0 − p)/(m g); going back T: σ' = (σ − T) mod period, state
/// (P0 σ'/m − g σ'²/2, P0 − m g σ'). At E = 0 (the Zeno point) the density has no limit;
/// 0 is returned (and for E < 0, outside the state space).
/// The same for any initial density u0(x, p) (a callable).
template <class U0>
double ball_pullback_elastic(double x, double p, double T, U0&& u0, double m = 1.0,
                             double g = 1.0) {
  if (T == 0.0) return u0(x, p);
  const double E = p * p / (2.0 * m) + m * g * x;
  if (E <= 0.0) return 0.0;
  const double P0 = std::sqrt(2.0 * m * E);
  const double period = 2.0 * P0 / (m * g);
  double sigma = std::fmod((P0 - p) / (m * g) - T, period);
  if (sigma < 0.0) sigma += period;
  return u0(P0 * sigma / m - 0.5 * g * sigma * sigma, P0 - m * g * sigma);
}

/// `ball_pullback_elastic` of the paper's u0 (`ball_u0`).
inline double ball_exact_elastic(double x, double p, double T, double m = 1.0, double g = 1.0) {
  return ball_pullback_elastic(x, p, T, ball_u0, m, g);
}

/// Mass (m = g = 1) of the initial states, anywhere in the half plane x0 ≥ 0, that reach the
/// Zeno point (0, 0) by time t with restitution e < 1. From (x0, p0) the first impact is at
/// t1 = p0 + v1 with speed v1 = √(p0² + 2 x0); the flights then last 2 e^k v1, so
/// T_Z = t1 + 2 e v1/(1 − e) = p0 + v1 (1 + e)/(1 − e). Hence T_Z ≤ t ⇔ v1 ≤ V(p0) :=
/// (t − p0)(1 − e)/(1 + e) ⇔ x0 ≤ X(p0) = (V² − p0²)/2, non-empty iff V > |p0|. The x0
/// integral of exp(−(x0 − 1)²) over [0, X] is (√π/2)(erf(X − 1) + erf(1)); the p0 integral
/// (smooth on the interval where V > |p0|) by 64-panel, 16-point Gauss–Legendre.
inline double zeno_mass(double t, double e) {
  const double c = (1.0 - e) / (1.0 + e);
  const double p_hi = t * c / (1.0 + c), p_lo = -t * c / (1.0 - c);
  const rt::AxisRule r = rt::gauss_legendre_rule(p_lo, p_hi, 64, 16);
  double s = 0.0;
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    const double p0 = r.nodes[i];
    const double V = (t - p0) * c;
    const double X = 0.5 * (V * V - p0 * p0);
    s += r.weights[i] * std::exp(-p0 * p0) * 0.5 * std::sqrt(std::numbers::pi) *
         (std::erf(X - 1.0) + std::erf(1.0));
  }
  return s;
}

/// Mass (m = g = 1) of the initial states u0 = exp(−((x0 − xc)² + p0²)/(2σ²)) on x0 ≥ 0 whose
/// n-th impact on the ground comes by time t, where t_n = p0 + c·v1 (v1 = √(p0² + 2 x0), the
/// first landing speed): c = 2n − 1 for an elastic ball, c = 1 + 2e(1 − e^(n−1))/(1 − e) with
/// restitution e, c = (1 + e)/(1 − e) for the Zeno time (`zeno_mass`). As there: t_n ≤ t ⇔
/// v1 ≤ V := (t − p0)/c ⇔ x0 ≤ X(p0) = (V² − p0²)/2, non-empty iff V > |p0|, i.e. p0 <
/// t/(1 + c) and, for c > 1, p0 > −t/(c − 1); the x0 integral in erf, the p0 integral (smooth
/// there) by 64-panel, 16-point Gauss–Legendre over that interval clipped to ±12σ.
inline double ball_impact_mass(double t, double c, double xc, double sigma) {
  const double p_hi = std::min(t / (1.0 + c), 12.0 * sigma);
  const double p_lo = c > 1.0 ? std::max(-t / (c - 1.0), -12.0 * sigma) : -12.0 * sigma;
  if (!(p_lo < p_hi)) return 0.0;
  const rt::AxisRule r = rt::gauss_legendre_rule(p_lo, p_hi, 64, 16);
  const double s2 = sigma * std::sqrt(2.0);
  double s = 0.0;
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    const double p0 = r.nodes[i];
    const double V = (t - p0) / c;
    const double X = 0.5 * (V * V - p0 * p0);
    s += r.weights[i] * std::exp(-p0 * p0 / (2.0 * sigma * sigma)) * sigma *
         std::sqrt(std::numbers::pi / 2.0) * (std::erf((X - xc) / s2) + std::erf(xc / s2));
  }
  return s;
}

/// The impacts on the ground by t (methods/impacts.hpp: the initial mass counted once per
/// impact) of the ball with u0 as in `ball_impact_mass` and restitution e (1: elastic), over
/// the impacts n ≤ n_max: Σ_n ball_impact_mass(t, c_n, xc, σ). For e < 1 the sum diverges
/// once mass reaches the Zeno point (`zeno_mass`); n_max truncates it.
inline double ball_impacts(double t, double e, double xc, double sigma, int n_max = 100000) {
  double s = 0.0;
  for (int n = 1; n <= n_max; ++n) {
    const double c =
        e == 1.0 ? 2.0 * n - 1.0 : 1.0 + 2.0 * e * (1.0 - std::pow(e, n - 1)) / (1.0 - e);
    const double m = ball_impact_mass(t, c, xc, sigma);
    s += m;
    if (e == 1.0 && m == 0.0) break;
  }
  return s;
}

/// ∫ over the paper's box [0, 2] × [−2, 2] of u0: ∫₀² exp(−(x−1)²) dx · ∫₋₂² exp(−p²) dp =
/// (√π/2 · 2 erf(1)) · (√π/2 · 2 erf(2)) = π erf(1) erf(2).
inline double ball_box_mass0() {
  return std::numbers::pi * std::erf(1.0) * std::erf(2.0);
}

/// Relative L1 error, over all output times and grid nodes, of a solution of the elastic
/// ball (m = g = 1; one mode) against `ball_exact_elastic`. The node (0, 0), if on the grid,
/// is left out: it is the Zeno point, where stripes of every phase meet and the density has
/// no limit.
inline double ball_relative_l1(const rt::TensorGrid<2>& grid, const rt::Solution<2>& sol,
                               const std::vector<double>& times) {
  double err = 0.0, norm = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const auto y = grid.node(i);
      if (y[0] == 0.0 && y[1] == 0.0) continue;
      const double ue = ball_exact_elastic(y[0], y[1], times[k]);
      err += std::fabs(sol.at(k, 0, i) - ue);
      norm += std::fabs(ue);
    }
  return err / norm;
}

}  // namespace hybgen::testing
