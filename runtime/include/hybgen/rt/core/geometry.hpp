#pragma once
/// \file geometry.hpp
/// Geometry of guards and flows shared by every method: the box test, small dense linear
/// algebra, Newton's method for a reset's pre-image, RK4 steps, and THE grazing criterion
/// (the pre-flight scan, the backward tracer and the forward flow use the same function).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <ostream>

#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Default tolerance of the grazing test |∇s·X| ≤ graze_tol·|∇s||X| (the pre-flight scan, the
/// backward tracer and the forward flow share it). Near a fold of S crossings met on grid
/// edges have a ratio of order (grid spacing)/(scale), far above 1e-8 for every grid hybgen
/// allows (≤ 2²⁸ nodes); only a tangency met to ~8 digits trips it.
inline constexpr double kGrazeTol = 1e-8;

namespace detail {

template <std::size_t N>
inline bool in_box(const double* z, const std::array<double, N>& lo,
                   const std::array<double, N>& hi) {
  for (std::size_t a = 0; a < N; ++a) {
    const double tol = 1e-12 * (hi[a] - lo[a]);
    if (!(z[a] >= lo[a] - tol && z[a] <= hi[a] + tol)) return false;
  }
  return true;
}

template <std::size_t N>
inline double dot(const double* a, const double* b) {
  double s = 0.0;
  for (std::size_t i = 0; i < N; ++i) s += a[i] * b[i];
  return s;
}

/// Solve A x = b in place (b ← x) by Gaussian elimination with partial pivoting.
template <std::size_t N>
inline bool solve_linear(std::array<double, N * N>& A, std::array<double, N>& b) {
  for (std::size_t c = 0; c < N; ++c) {
    std::size_t p = c;
    for (std::size_t r = c + 1; r < N; ++r)
      if (std::fabs(A[r * N + c]) > std::fabs(A[p * N + c])) p = r;
    if (!(std::fabs(A[p * N + c]) > 0.0)) return false;
    if (p != c) {
      for (std::size_t k = 0; k < N; ++k) std::swap(A[c * N + k], A[p * N + k]);
      std::swap(b[c], b[p]);
    }
    for (std::size_t r = c + 1; r < N; ++r) {
      const double f = A[r * N + c] / A[c * N + c];
      for (std::size_t k = c; k < N; ++k) A[r * N + k] -= f * A[c * N + k];
      b[r] -= f * b[c];
    }
  }
  for (std::size_t c = N; c-- > 0;) {
    double s = b[c];
    for (std::size_t k = c + 1; k < N; ++k) s -= A[c * N + k] * b[k];
    b[c] = s / A[c * N + c];
  }
  return true;
}

/// Guard g's static info (a dummy for guard-free models, whose guard array is empty, and
/// for g out of range, which no caller passes: the test keeps GCC's -Warray-bounds, which
/// loses track of the event index through the inlined event locator at -O3, quiet).
template <HybridModel M>
inline GuardInfo guard_info(std::size_t g) {
  if (g < M::guards.size()) return M::guards[g];
  return GuardInfo{0, 0, 0, true};
}

/// A solution z of Δ_g(z) = y by Newton's method from z = start: stops when
/// ‖δz‖∞ ≤ tol·(1 + ‖z‖∞); false if the Jacobian is singular, a value is not finite, or
/// `max_iter` iterations do not reach the tolerance.
/// For a guard with a constant component i (GuardInfo::image_axis), Δ_i(z) = y_i holds for
/// every z once y is on the plane of the image, and row i of DΔ is 0: equation i is replaced
/// by s_g(z) = 0 (row i of the Jacobian by ∇s_g), so z is THE pre-image of y on S_g, where Δ
/// is injective (derive.cpp checks it). y_i is not used.
template <HybridModel M>
bool newton_reset_solve(int g, const double* y, const double* start, const double* par,
                        int max_iter, double tol, std::array<double, state_dim_v<M>>& z) {
  constexpr std::size_t N = state_dim_v<M>;
  for (std::size_t i = 0; i < N; ++i) z[i] = start[i];
  const int axis = guard_info<M>(static_cast<std::size_t>(g)).image_axis;
  std::array<double, N * N> A;
  std::array<double, N> r;
  for (int it = 0; it < max_iter; ++it) {
    M::reset(g, z.data(), par, r.data());
    for (std::size_t i = 0; i < N; ++i) r[i] -= y[i];
    M::reset_jacobian(g, z.data(), par, A.data());
    if (axis >= 0 && static_cast<std::size_t>(axis) < N) {
      const auto a = static_cast<std::size_t>(axis);
      r[a] = M::guard_surface(g, z.data(), par);
      M::guard_gradient(g, z.data(), par, A.data() + a * N);
    }
    if (!solve_linear<N>(A, r)) return false;
    double dz = 0.0, zn = 0.0;
    for (std::size_t i = 0; i < N; ++i) {
      z[i] -= r[i];
      dz = std::max(dz, std::fabs(r[i]));
      zn = std::max(zn, std::fabs(z[i]));
    }
    if (!std::isfinite(dz) || !std::isfinite(zn)) return false;
    if (dz <= tol * (1.0 + zn)) return true;
  }
  return false;
}

/// Δ_g⁻¹(y) by Newton's method on Δ_g(z) = y from z = y (`newton_reset_solve`), into z.
template <HybridModel M>
bool newton_reset_inverse(int g, const double* y, const double* par, int max_iter, double tol,
                          std::array<double, state_dim_v<M>>& z) {
  return newton_reset_solve<M>(g, y, y, par, max_iter, tol, z);
}

/// One RK4 step of mode m's flow (sign +1 forward, −1 backward) of size h.
template <HybridModel M>
void rk4_step(int m, std::array<double, state_dim_v<M>>& x, double h, double sign,
              const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> k1{}, k2{}, k3{}, k4{}, t{};
  auto f = [&](const std::array<double, N>& y, std::array<double, N>& out) {
    M::flow(m, y.data(), par, out.data());
    for (double& v : out) v *= sign;
  };
  f(x, k1);
  for (std::size_t i = 0; i < N; ++i) t[i] = x[i] + 0.5 * h * k1[i];
  f(t, k2);
  for (std::size_t i = 0; i < N; ++i) t[i] = x[i] + 0.5 * h * k2[i];
  f(t, k3);
  for (std::size_t i = 0; i < N; ++i) t[i] = x[i] + h * k3[i];
  f(t, k4);
  for (std::size_t i = 0; i < N; ++i) x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

/// Whether the orbit of mode m through x (on S_g) passes from the pre-firing side of S_g to
/// the firing side over [−δ, δ]: s_g(φ_{−δ}x)·dir < −floor, floor < s_g(φ_δ x)·dir (20 RK4
/// steps each way; the callers take δ so that the displacement is far above the steps' error).
template <HybridModel M>
bool orbit_crosses(int g, int m, const std::array<double, state_dim_v<M>>& x, double delta,
                   const double* par, double floor = 0.0) {
  const int dir = guard_info<M>(static_cast<std::size_t>(g)).direction;
  constexpr int steps = 20;
  std::array<double, state_dim_v<M>> fwd = x, bwd = x;
  for (int k = 0; k < steps; ++k) {
    rk4_step<M>(m, fwd, delta / steps, 1.0, par);
    rk4_step<M>(m, bwd, delta / steps, -1.0, par);
  }
  const double after = M::guard_surface(g, fwd.data(), par) * dir;
  const double before = M::guard_surface(g, bwd.data(), par) * dir;
  return after > floor && before < -floor;
}

/// THE grazing criterion — the one function the pre-flight scan (preflight.hpp), the backward
/// tracer and the forward flow (forward.hpp) use. At a point x of S_g in mode m (the mode g
/// fires from): the flow is tangent to S_g,
///   |∇s_g·X_m| ≤ tol·|∇s_g||X_m|   (∇s_g ≠ 0, X_m ≠ 0, all finite),
/// and the orbit through x crosses S_g from the pre-firing to the firing side over [−δ, δ],
/// δ = delta(|X_m|) (`orbit_crosses`): the guard fires at a tangency — the event location is
/// ill-conditioned and J's denominator ∇s·X vanishes. A tangency the orbit does not cross
/// at that scale (the bouncing ball's Zeno point (0, 0): x = −g t²/2 ≤ 0 both ways) is no
/// grazing. Returns the ratio |∇s·X|/(|∇s||X|) (≥ 0) if x grazes, else −1. Cost: one flow and
/// one gradient evaluation, plus 160 flow evaluations only when the flow is tangent.
template <HybridModel M, class Delta>
double grazing(int g, int m, const std::array<double, state_dim_v<M>>& x, const double* par,
               double tol, Delta&& delta) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> X{}, grad{};
  M::flow(m, x.data(), par, X.data());
  M::guard_gradient(g, x.data(), par, grad.data());
  const double rate = dot<N>(grad.data(), X.data());
  const double gn = std::sqrt(dot<N>(grad.data(), grad.data()));
  const double xn = std::sqrt(dot<N>(X.data(), X.data()));
  if (!(xn > 0.0 && gn > 0.0 && std::isfinite(rate) && std::isfinite(gn * xn))) return -1.0;
  if (!(std::fabs(rate) <= tol * gn * xn)) return -1.0;
  // An orbit inside S_g (GL₂'s tr ζ = 0 on q = 0: s stays at rounding level, ~1e-22, of
  // either sign) does not cross it: the crossing must clear a floor far above rounding and
  // far below a real tangential crossing (cubic: |s| ~ δ³ ≫ 1e-12·|∇s||X|δ for δ ≥ 1e-5).
  const double d = delta(xn);
  if (!orbit_crosses<M>(g, m, x, d, par, 1e-12 * gn * xn * d)) return -1.0;
  return std::fabs(rate) / (gn * xn);
}

/// The details of a grazing failure met along a trace (backward tracer, forward flow):
/// the tangency ratio `ratio` at the reported state.
inline void describe_grazing(std::ostream& os, double ratio) {
  os << ": |grad s . X| / (|grad s| |X|) = " << ratio
     << " there, and the orbit crosses the surface";
}

/// δ of the grazing test along a trace over [0, horizon] (backward tracer, forward flow): the
/// orbit is followed 1e-3 of the horizon each way, the time resolution of the solution.
inline double graze_delta(double horizon) {
  return 1e-3 * std::fabs(horizon);
}

/// Whether z + side·δ·X_m(z) lies in `M::in_support`, δ|X| = 1e-7·(1 + ‖z‖∞): just after z
/// along the flow of mode m (side = 1) or just before it (side = −1); z itself where X_m(z) is
/// 0 or not finite.
template <HybridModel M>
bool in_support_along(int m, const std::array<double, state_dim_v<M>>& z, const double* par,
                      double side) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> X{}, zb{};
  M::flow(m, z.data(), par, X.data());
  const double speed = std::sqrt(dot<N>(X.data(), X.data()));
  double zn = 0.0;
  for (std::size_t i = 0; i < N; ++i) zn = std::max(zn, std::fabs(z[i]));
  const double delta = speed > 0.0 && std::isfinite(speed) ? 1e-7 * (1.0 + zn) / speed : 0.0;
  for (std::size_t i = 0; i < N; ++i) zb[i] = z[i] + side * delta * X[i];
  return M::in_support(zb.data(), par);
}

/// Whether the flow of mode m reaches the point z of a guard's surface from inside
/// `M::in_support`: tested just BEFORE z, at z − δ·X_m(z) with δ|X| = 1e-7·(1 + ‖z‖∞) (z is on
/// the surface only to rounding, and a support that is open at the surface, x > 0 for the
/// ball, or curved there must keep its crossings). The backward tracer spawns no pre-image
/// where this fails (characteristics.hpp). The forward flow tests its crossings off the
/// surface instead (`crossing_in_support`, below).
template <HybridModel M>
bool reaches_from_support(int m, const std::array<double, state_dim_v<M>>& z, const double* par) {
  return in_support_along<M>(m, z, par, -1.0);
}

/// Whether the flow of mode m leaves the point z into `M::in_support`: tested just AFTER z, at
/// z + δ·X_m(z) (δ as in `reaches_from_support`). The backward tracer spawns no pre-image
/// through a reset whose image point z fails it: its path left the state space before it met
/// the image (characteristics.hpp, try_spawn).
template <HybridModel M>
bool leaves_into_support(int m, const std::array<double, state_dim_v<M>>& z, const double* par) {
  return in_support_along<M>(m, z, par, 1.0);
}

/// Whether guard g's crossing at z (on S_g) by the flow of mode m lies in `M::in_support`:
/// tested just off S_g on the side the flow comes from, at z − ε·sign(∇s·X)·∇s/|∇s| with
/// ε = 1e-7·(1 + ‖z‖∞) (at z itself where the flow is tangent or ∇s vanishes). Off the surface
/// along its normal, not back along the flow as `reaches_from_support`: where S_g is the
/// support's own edge (the ball's ground, x ≥ 0), a crossing deep in a Zeno accumulation moves
/// along the flow by less than rounding (|p| → 0) and would read as outside
/// (tests/validation/test_two_balls.cpp's particles lost 1.6e-4 that way). A forward flow
/// whose crossing fails it has left the state space before the guard (forward.hpp).
template <HybridModel M>
bool crossing_in_support(int g, int m, const std::array<double, state_dim_v<M>>& z,
                         const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> grad{}, X{}, zb{};
  M::guard_gradient(g, z.data(), par, grad.data());
  M::flow(m, z.data(), par, X.data());
  const double gn = std::sqrt(dot<N>(grad.data(), grad.data()));
  const double gx = dot<N>(grad.data(), X.data());
  if (!(gn > 0.0) || !std::isfinite(gn) || !std::isfinite(gx) || gx == 0.0)
    return M::in_support(z.data(), par);
  double zn = 0.0;
  for (std::size_t i = 0; i < N; ++i) zn = std::max(zn, std::fabs(z[i]));
  const double step = (gx > 0.0 ? 1.0 : -1.0) * 1e-7 * (1.0 + zn) / gn;
  for (std::size_t i = 0; i < N; ++i) zb[i] = z[i] - step * grad[i];
  return M::in_support(zb.data(), par);
}

}  // namespace detail

}  // namespace hybgen::rt
