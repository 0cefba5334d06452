#pragma once
/// \file line_closed_forms.hpp
/// Closed forms of three one-dimensional validation models (tests/validation/models/), derived
/// by hand and shared by the tests that hold hybgen's budget terms against them:
///  * leap_out.model: x' = 1 on [0, 1.5], x ↦ x + 2 at x = 1 (out of the box), u0 =
///    exp(−(x − ½)²/0.02). With I(a, b) = ∫_a^b u0, for t ≤ 1: the reset outflow R(t) =
///    I(1 − t, 1) (what reached the guard), the face outflow F(t) = R(t) + I(max(1, 1.5 − t),
///    1.5) − I(−t, 0) (what started past the guard and left through x = 1.5, minus the inflow
///    through x = 0 of the density outside the box), the mass I(0, 1.5) − F(t).
///  * shuttle_trap.model: x' = 1 in up, turned into down (x' = −1) at x = 1, absorbed where
///    down crosses x = 1/4. A point x0 is absorbed at t = 7/4 − x0: by time t the mass of u0
///    on [7/4 − t, ∞) is gone. u0 = ((1 − s²)₊)², s = (x − 0.4)/0.2, whose mass on [c, ∞) is
///    0.2 (G(1) − G(s_c)), G(s) = s − 2s³/3 + s⁵/5 (s_c clamped to [−1, 1]).
///  * absorb_growth.model: x' = a x on [0, 1], absorbed at x = 1 (the box's face): x0 reaches
///    1 at t = ln(1/x0)/a, so the mass 1 − F(e^(−a t)) is gone by t (u0 = 6x(1 − x), F(y) =
///    3y² − 2y³).

#include <algorithm>
#include <cmath>
#include <numbers>

namespace hybgen::testing {

/// leap_out: ∫_a^b exp(−(x − ½)²/0.02) dx.
inline double leap_integral(double a, double b) {
  const double s = 0.1;  // 2s² = 0.02
  const double c = s * std::sqrt(std::numbers::pi / 2.0);
  return c * (std::erf((b - 0.5) / (s * std::numbers::sqrt2)) -
              std::erf((a - 0.5) / (s * std::numbers::sqrt2)));
}

/// leap_out: the mass that reached the guard by t (and left the box by the reset).
inline double leap_reset_outflow(double t) {
  return leap_integral(1.0 - t, 1.0);
}

/// leap_out: the net outflow by t, through the reset and the faces.
inline double leap_outflow(double t) {
  return leap_reset_outflow(t) + leap_integral(std::max(1.0, 1.5 - t), 1.5) -
         leap_integral(-t, 0.0);
}

/// leap_out: the mass in the box [0, 1.5] at t.
inline double leap_mass(double t) {
  return leap_integral(0.0, 1.5) - leap_outflow(t);
}

/// shuttle_trap: the initial density ((1 − s²)₊)², s = (x − 0.4)/0.2.
inline double shuttle_bump(double x) {
  const double s = (x - 0.4) / 0.2, v = 1.0 - s * s;
  return v > 0.0 ? v * v : 0.0;
}

/// shuttle_trap: the mass of `shuttle_bump` on [c, ∞).
inline double shuttle_bump_mass_above(double c) {
  const double s = std::clamp((c - 0.4) / 0.2, -1.0, 1.0);
  const auto G = [](double z) { return z - 2.0 * z * z * z / 3.0 + z * z * z * z * z / 5.0; };
  return 0.2 * (G(1.0) - G(s));
}

/// shuttle_trap: the mass absorbed by the trap by t.
inline double shuttle_absorbed(double t) {
  return shuttle_bump_mass_above(1.75 - t);
}

/// absorb_growth.model's a.
inline constexpr double kGrowthRate = 0.7;

/// absorb_growth: the mass absorbed by the trap by t.
inline double growth_absorbed(double t) {
  const double y = std::exp(-kGrowthRate * t);
  return 1.0 - (3.0 * y * y - 2.0 * y * y * y);
}

}  // namespace hybgen::testing
