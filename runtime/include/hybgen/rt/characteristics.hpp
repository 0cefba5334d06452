#pragma once
/// \file characteristics.hpp
/// The method of characteristics for the hybrid Frobenius–Perron equation (paper Thm 3.11):
///   ∂u/∂t + du(X) = −u·div X        off Δ(S),
///   u(t⁺, y) = u(t⁻, Δ⁻¹y) / |J(Δ⁻¹y)|  on Δ(S)   (|J|: J < 0 flips orientation).
///
/// For a node y in mode m, the BACKWARD hybrid flow dx/dτ = −X_m(x), x(0) = y, is integrated
/// once from τ = 0 to the last output time, together with I(τ) = ∫₀^τ div X(x(σ)) dσ.
/// Along the forward flow d/dt u(φₜx₀) = −div X·u, hence for every output time t
///   u(t, y) = Σ_branches  u0_mode(x(t)) · exp(−I(t)) · Π 1/|J_g(z)|.
///
/// Backward events in mode m:
///  * incoming guards g (to = m): b_g(x) = s_g(Δ_g⁻¹(x)) (closed-form Δ⁻¹, or Newton on
///    Δ_g(z) = x from z = x). At a root y*, z = Δ_g⁻¹(y*) is a true pre-image only if the guard
///    fires there: sign(∇s_g(z)·X_from(z)) = guards[g].direction. Then a REVERSED-RESET BRANCH
///    (state z, mode `from`, weight/|J_g(z)|, same I) is spawned; it serves the output times
///    after τ*. A reset with SEVERAL pre-images on S_g (a fold; the pre-flight finds them and
///    passes seeds, CharacteristicsOptions::preimage_seeds) spawns one branch per pre-image,
///    all enumerated by Newton from the seeds: the paper's general theorem sums over them.
///  * outgoing guards h (from = m): if the backward path crosses S_h the way the forward flow
///    would make h fire (direction −guards[h].direction in τ), no forward history can continue
///    in mode m beyond it: the branch ends there (contributes nothing further).
/// The continuing branch is NOT dropped at an incoming root: a state just past Δ(S) in the
/// flow direction generally has two histories (arrived by the flow of mode m across Δ(S), or
/// by the reset) and the density is their sum (the paper's "General hybrid infinitesimal
/// generator" theorem sums over pre-images likewise). Branches that
/// leave `in_support` (checked at step ends) end, and a reversed reset whose pre-image lies
/// outside `in_support` spawns no branch — no state outside the state space has a history.
/// For the bouncing ball this means: at each backward impact the reset branch continues and
/// the straight continuation into x < 0 ends at its step's end.
///
/// Ties at a measure-zero coincidence (an output time equal to a reset time up to ~1e-12) are
/// resolved consistently: the reset branch serves t_k iff the continuing trajectory at t_k is
/// on the far side of the event surface (b_g has its post-crossing sign), so a point on such a
/// discontinuity gets one of its two one-sided values, never their sum or zero.
///
/// Grazing mid-trace: at every guard crossing the tracer meets — a root of an outgoing guard
/// h (forward, h fires at x) or the pre-image z = Δ_g⁻¹(y*) of an incoming root — the flow of
/// the firing mode is tested for tangency by the pre-flight scan's criterion (`grazing`, one
/// function for both): |∇s·X| ≤ graze_tol·|∇s||X| and the orbit crosses S in the firing
/// direction over ±δ, δ = 1e-3·(last output time). Such a crossing is a `grazing` failure
/// (named with the state, τ and the guard): its event location is ill-conditioned and J's
/// denominator ∇s·X vanishes. The pre-flight only sees crossings on the grid edges at t = 0;
/// this catches those reached later, e.g. outside the grid box. A tangency the orbit does not
/// cross at that scale (the ball's Zeno point) passes, as in the pre-flight.
///
/// Failures (NaN/Inf anywhere, |J| = 0, Newton not converging, more than `max_events` resets
/// per characteristic, ODE step limit/underflow, grazing) are returned as a `TraceStatus`,
/// never hidden.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <iomanip>
#include <limits>
#include <numbers>
#include <ostream>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/model.hpp"
#include "hybgen/rt/ode.hpp"
#include "hybgen/rt/progress.hpp"

namespace hybgen::rt {

/// Dimension N of a model's state, as a compile-time size.
template <class M>
inline constexpr std::size_t state_dim_v = static_cast<std::size_t>(M::n_state);

/// Name of mode `m` of M for messages, or "?" when `m` is no mode index.
template <HybridModel M>
const char* mode_name(int m) {
  return m >= 0 && m < M::n_mode ? M::mode_names[static_cast<std::size_t>(m)] : "?";
}

/// Name of guard `g` of M for messages, or "?" when `g` is no guard index.
template <HybridModel M>
const char* guard_name(int g) {
  return g >= 0 && g < M::n_guard ? M::guard_names[static_cast<std::size_t>(g)] : "?";
}

/// Writes the state x as "(x = 0, p = -2)" with M's state names, at os's precision.
template <HybridModel M>
void write_state(std::ostream& os, const std::array<double, state_dim_v<M>>& x) {
  os << '(';
  for (std::size_t i = 0; i < x.size(); ++i)
    os << (i ? ", " : "") << M::state_names[i] << " = " << x[i];
  os << ')';
}

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
};

/// Default tolerance of the grazing test |∇s·X| ≤ graze_tol·|∇s||X| (the pre-flight scan, the
/// backward tracer and the forward flow share it). Near a fold of S crossings met on grid
/// edges have a ratio of order (grid spacing)/(scale), far above 1e-8 for every grid hybgen
/// allows (≤ 2²⁸ nodes); only a tangency met to ~8 digits trips it.
inline constexpr double kGrazeTol = 1e-8;

/// Options of the characteristics method.
struct CharacteristicsOptions {
  OdeOptions ode{};              ///< Tolerances and step control of the backward integration.
  int max_events = 100000;       ///< Cap on resets crossed by one characteristic (all branches).
  int newton_max_iter = 50;      ///< Newton iterations for a numeric Δ⁻¹.
  double newton_tol = 1e-14;     ///< Newton stop: ‖δz‖∞ ≤ tol·(1 + ‖z‖∞).
  double graze_tol = kGrazeTol;  ///< Grazing test at crossings (see `detail::grazing`).
  Progress* progress = nullptr;  ///< Advanced once per traced (mode, point) when set.
  /// When > 0, each output is the time integral ∫₀^{t_k} u(t, y) dt instead of u(t_k, y), to
  /// this relative tolerance (adaptive Gauss–Legendre in time along every branch; see
  /// `detail::Tracer::accumulate`). The boundary flux of the mass budget uses it.
  double cumulative_tol = 0.0;
  /// Guards whose reset has SEVERAL pre-images on the guard (the pre-flight's
  /// `find_preimage_seeds`): (*preimage_seeds)[g] holds start points on S_g, N doubles each,
  /// from which every incoming crossing enumerates all pre-images by Newton (each spawns a
  /// branch, weight 1/|J|, as the paper's general theorem sums them). Empty or null for a
  /// guard: its reset is taken as injective on S_g (one pre-image: Δ⁻¹ or Newton from y).
  const std::vector<std::vector<double>>* preimage_seeds = nullptr;
};

/// What went wrong on a characteristic.
enum class TraceError {
  none,                ///< Nothing.
  non_finite_flow,     ///< X or div X not finite (ODE could not continue).
  non_finite_reset,    ///< Δ⁻¹(y*) not finite at a reset image.
  zero_jacobian,       ///< |J| = 0 or J not finite at a pre-image.
  inverse_failed,      ///< Newton for Δ⁻¹ did not converge.
  event_cap,           ///< More than `max_events` resets on one characteristic.
  branch_cap,          ///< Too many pending reversed-reset branches.
  step_limit,          ///< ODE `max_steps` exceeded.
  step_underflow,      ///< ODE step size underflow (singular or stiff flow).
  non_finite_density,  ///< u0 · weight · exp(−∫div) not finite at a foot point.
  grazing,             ///< The flow is tangent to the guard where the orbit crosses it.
};

/// Human-readable name of a `TraceError`.
inline const char* trace_error_name(TraceError e) {
  switch (e) {
    case TraceError::none:
      return "no error";
    case TraceError::non_finite_flow:
      return "non-finite vector field or divergence";
    case TraceError::non_finite_reset:
      return "non-finite inverse reset";
    case TraceError::zero_jacobian:
      return "zero or non-finite hybrid Jacobian";
    case TraceError::inverse_failed:
      return "Newton iteration for the inverse reset did not converge";
    case TraceError::event_cap:
      return "too many resets on one characteristic (max_events)";
    case TraceError::branch_cap:
      return "too many pending reset branches";
    case TraceError::step_limit:
      return "ODE step limit exceeded";
    case TraceError::step_underflow:
      return "ODE step size underflow";
    case TraceError::non_finite_density:
      return "non-finite density value";
    case TraceError::grazing:
      return "grazing: the flow is tangent to the guard at a crossing";
  }
  return "?";
}

/// Outcome of one characteristic: where (mode, guard, backward time τ, state) it failed.
template <std::size_t N>
struct TraceStatus {
  TraceError error = TraceError::none;  ///< What happened.
  int mode = -1;                        ///< Mode at the failure.
  int guard = -1;                       ///< Guard involved, or −1.
  double tau = 0.0;                     ///< Backward time τ of the failure.
  std::array<double, N> state{};        ///< State at the failure.
  int events = 0;                       ///< Resets crossed so far.
  double value = 0.0;                   ///< grazing: |∇s·X|/(|∇s||X|) at `state`; else 0.
  /// Whether nothing failed.
  bool ok() const { return error == TraceError::none; }
};

/// A failed characteristic together with its starting point.
template <std::size_t N>
struct TraceFailure {
  TraceStatus<N> status{};        ///< What failed, where (status.ok() if nothing failed).
  int start_mode = -1;            ///< Mode of the starting point.
  std::size_t start_index = 0;    ///< Index of the starting point (grid node / point).
  std::array<double, N> start{};  ///< Coordinates of the starting point.
  /// Whether nothing failed.
  bool ok() const { return status.ok(); }
};

/// Context for evaluating on a face of the box [lo, hi] (boundary flux): the value is the
/// limit from inside the box, and mass reset from inside the closed box (an internal
/// transfer, not inflow) is excluded from a reset image lying on the face.
template <std::size_t N>
struct FaceContext {
  std::array<double, N> inward{};  ///< Inward unit normal of the face.
  std::array<double, N> lo{};      ///< Box lower corner.
  std::array<double, N> hi{};      ///< Box upper corner.
};

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
template <HybridModel M>
bool newton_reset_solve(int g, const double* y, const double* start, const double* par,
                        int max_iter, double tol, std::array<double, state_dim_v<M>>& z) {
  constexpr std::size_t N = state_dim_v<M>;
  for (std::size_t i = 0; i < N; ++i) z[i] = start[i];
  std::array<double, N * N> A;
  std::array<double, N> r;
  for (int it = 0; it < max_iter; ++it) {
    M::reset(g, z.data(), par, r.data());
    for (std::size_t i = 0; i < N; ++i) r[i] -= y[i];
    M::reset_jacobian(g, z.data(), par, A.data());
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

/// Throws std::invalid_argument unless the output times are finite, ≥ 0 and sorted.
inline void validate_times(std::span<const double> times) {
  for (std::size_t k = 0; k < times.size(); ++k) {
    if (!std::isfinite(times[k]) || times[k] < 0.0)
      throw std::invalid_argument("characteristics: output times must be finite and >= 0");
    if (k > 0 && times[k] < times[k - 1])
      throw std::invalid_argument("characteristics: output times must be sorted ascending");
  }
}

/// Per-thread workspace tracing backward characteristics of model M. No heap allocation.
template <HybridModel M>
class Tracer {
 public:
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  static constexpr std::size_t D = N + 1;           ///< ODE dimension: state, then I = ∫div dτ.
  /// Guards (≥ 1 for array sizes; model.hpp).
  static constexpr std::size_t kGuards = guard_capacity_v<M>;
  static constexpr std::size_t kMaxEv = 2 * kGuards;  ///< Events per mode: incoming + outgoing.
  static constexpr std::size_t kMaxPending = 64;      ///< Pending reversed-reset branches.
  static constexpr std::size_t kMaxPreimages = 16;    ///< Pre-images of one crossing.
  using State = std::array<double, N>;                ///< A state.
  using Vec = std::array<double, D>;                  ///< A state with I appended.

  /// A workspace for parameters `par` (kept by pointer) and options `opt` (copied).
  Tracer(const double* par, const CharacteristicsOptions& opt)
      : par_(par), opt_(opt), ode_(opt.ode) {}

  /// u(t_k, mode, y) into out[k] (see `trace`), or ∫₀^{t_k} u(t, mode, y) dt when
  /// opt.cumulative_tol > 0; `times` is assumed valid.
  TraceStatus<N> run(const State& y, int mode, std::span<const double> times, std::span<double> out,
                     const FaceContext<N>* face) {
    std::fill(out.begin(), out.end(), 0.0);
    status_ = TraceStatus<N>{};
    events_ = 0;
    npend_ = 0;
    times_ = times;
    out_ = out;
    cmax_ = 0.0;
    if (times.empty() || !M::in_support(y.data(), par_)) return status_;
    Branch root{};
    for (std::size_t i = 0; i < N; ++i) root.x[i] = y[i];
    root.x[N] = 0.0;
    root.mode = mode;
    root.weight = 1.0;
    process(root, face);
    while (npend_ > 0 && status_.ok()) {
      const Branch b = pend_[--npend_];
      process(b, nullptr);
    }
    status_.events = events_;
    return status_;
  }

 private:
  struct Branch {
    Vec x{};  // state and I at τ
    int mode = 0;
    double tau = 0.0;
    double weight = 1.0;      // Π 1/|J|
    double h = 0.0;           // trial step (0: automatic)
    int via = -1;             // guard whose reverse created this branch, or −1
    std::size_t k_begin = 0;  // first output index this branch serves
  };

  void fail(TraceError err, const double* state, int mode, int guard, double tau,
            double value = 0.0) {
    if (!status_.ok()) return;
    status_.error = err;
    status_.value = value;
    for (std::size_t i = 0; i < N; ++i) status_.state[i] = state[i];
    status_.mode = mode;
    status_.guard = guard;
    status_.tau = tau;
    status_.events = events_;
  }

  void fail_ode(OdeStatus st, const Vec& x, double tau) {
    const TraceError e = st == OdeStatus::step_limit       ? TraceError::step_limit
                         : st == OdeStatus::step_underflow ? TraceError::step_underflow
                                                           : TraceError::non_finite_flow;
    fail(e, x.data(), mode_, -1, tau);
  }

  bool newton_inverse(int g, const double* y, State& z) {
    return newton_reset_inverse<M>(g, y, par_, opt_.newton_max_iter, opt_.newton_tol, z);
  }

  bool reset_inverse(int g, const double* y, State& z) {
    if (guard_info<M>(static_cast<std::size_t>(g)).has_inverse) {
      M::reset_inverse(g, y, par_, z.data());
      return true;
    }
    return newton_inverse(g, y, z);
  }

  /// Event e of the current mode at x: b_g = s_g∘Δ_g⁻¹ (incoming) or s_h (outgoing).
  double event_value(int e, const Vec& x) {
    const auto ei = static_cast<std::size_t>(e);
    const int g = guard_[ei];
    if (incoming_[ei]) {
      State z;
      bool ok = reset_inverse(g, x.data(), z);
      // Several pre-images: s_g is the same on every branch of Δ_g⁻¹ near the image (they
      // meet S_g together), so any branch that converges serves; Newton from x may not (at a
      // fold, where DΔ is singular), the seeds then do.
      const std::span<const double> sd = seeds(g);
      for (std::size_t j = 0; !ok && j < sd.size() / N; ++j)
        ok = newton_reset_solve<M>(g, x.data(), sd.data() + j * N, par_, opt_.newton_max_iter,
                                   opt_.newton_tol, z);
      if (!ok) {
        fail(TraceError::inverse_failed, x.data(), mode_, g, ode_.t());
        return std::numeric_limits<double>::quiet_NaN();
      }
      return M::guard_surface(g, z.data(), par_);
    }
    return M::guard_surface(g, x.data(), par_);
  }

  void setup_events(int mode) {
    std::array<int, kMaxEv> dirs{};
    int n = 0;
    for (std::size_t g = 0; g < static_cast<std::size_t>(M::n_guard); ++g) {
      const GuardInfo gi = guard_info<M>(g);
      if (gi.to == mode) {
        guard_[static_cast<std::size_t>(n)] = static_cast<int>(g);
        incoming_[static_cast<std::size_t>(n)] = true;
        dirs[static_cast<std::size_t>(n)] = 0;
        ++n;
      }
      if (gi.from == mode) {
        guard_[static_cast<std::size_t>(n)] = static_cast<int>(g);
        incoming_[static_cast<std::size_t>(n)] = false;
        // Forward firing direction d ⇒ backward (τ = −t) crossing direction −d.
        dirs[static_cast<std::size_t>(n)] = -gi.direction;
        ++n;
      }
    }
    n_ev_ = n;
    loc_.configure(n, dirs.data());
  }

  double contribution(const Vec& x, int mode, double w, double tau) {
    // The model contract: u0 is already 0 outside the support/region of `mode`.
    const double u0 = M::initial_density(mode, x.data(), par_);
    const double v = w * std::exp(-x[N]) * u0;
    if (!std::isfinite(v)) {
      fail(TraceError::non_finite_density, x.data(), mode, -1, tau);
      return 0.0;
    }
    return v;
  }

  /// Try the reversed reset through guard g at (τ, x) found by event e; `dir` is the sign
  /// b_g takes after the crossing (0 for a root at the branch start).
  /// The seed points of guard g for enumerating its pre-images (N doubles each), or none.
  std::span<const double> seeds(int g) const {
    if (opt_.preimage_seeds == nullptr ||
        static_cast<std::size_t>(g) >= opt_.preimage_seeds->size())
      return {};
    return (*opt_.preimage_seeds)[static_cast<std::size_t>(g)];
  }

  /// Try the reversed reset through guard g at (τ, x) found by event e: one branch per
  /// pre-image. For a guard with seeds, every pre-image is enumerated by Newton on Δ_g(z) = x
  /// from z = x and from every seed; converged roots on S_g (after projection) closer than
  /// 1e-8·(1 + ‖z‖∞) are one. (A multi-start: the pre-flight checks at sampled image points
  /// that its seeds find as many pre-images as starts from every crossing point it met.)
  void try_spawn(int e, double tau, const Vec& x, const FaceContext<N>* face, bool at_start,
                 int dir) {
    const int g = guard_[static_cast<std::size_t>(e)];
    const std::span<const double> sd = seeds(g);
    if (sd.empty()) {
      State z;
      if (!reset_inverse(g, x.data(), z)) {
        fail(TraceError::inverse_failed, x.data(), mode_, g, tau);
        return;
      }
      spawn_from(e, z, tau, x, face, at_start, dir);
      return;
    }
    std::array<State, kMaxPreimages> found{};
    std::size_t nfound = 0;
    const std::size_t ns = sd.size() / N;
    for (std::size_t j = 0; j <= ns && status_.ok(); ++j) {
      State start, z;
      for (std::size_t i = 0; i < N; ++i) start[i] = j == 0 ? x[i] : sd[(j - 1) * N + i];
      if (!newton_reset_solve<M>(g, x.data(), start.data(), par_, opt_.newton_max_iter,
                                 opt_.newton_tol, z) ||
          !all_finite(z))
        continue;
      project_onto_guard(g, z);
      const double s = M::guard_surface(g, z.data(), par_);
      State grad;
      M::guard_gradient(g, z.data(), par_, grad.data());
      double zn = 0.0;
      for (std::size_t i = 0; i < N; ++i) zn = std::max(zn, std::fabs(z[i]));
      if (!(std::fabs(s) <= 1e-9 * (1.0 + zn) * std::sqrt(dot<N>(grad.data(), grad.data()))))
        continue;  // a solution of Δ(z) = x off the guard is no pre-image
      bool dup = false;
      for (std::size_t q = 0; q < nfound && !dup; ++q) {
        double d = 0.0;
        for (std::size_t i = 0; i < N; ++i) d = std::max(d, std::fabs(found[q][i] - z[i]));
        dup = d <= 1e-8 * (1.0 + zn);
      }
      if (dup) continue;
      if (nfound == kMaxPreimages) {
        fail(TraceError::branch_cap, x.data(), mode_, g, tau);
        return;
      }
      found[nfound++] = z;
    }
    for (std::size_t q = 0; q < nfound && status_.ok(); ++q)
      spawn_from(e, found[q], tau, x, face, at_start, dir);
  }

  /// Two Newton steps along ∇s_g moving z onto S_g (see spawn_from).
  void project_onto_guard(int g, State& z) const {
    State grad;
    for (int it = 0; it < 2; ++it) {
      M::guard_gradient(g, z.data(), par_, grad.data());
      const double gg = dot<N>(grad.data(), grad.data());
      const double s = M::guard_surface(g, z.data(), par_);
      if (!(gg > 0.0) || !std::isfinite(gg) || !std::isfinite(s) || s == 0.0) break;
      for (std::size_t i = 0; i < N; ++i) z[i] -= s * grad[i] / gg;
    }
  }

  /// Spawn the reversed-reset branch of the pre-image z of x through the guard of event e
  /// (if it is one: on the support's side, where the guard fires; see try_spawn).
  void spawn_from(int e, State z, double tau, const Vec& x, const FaceContext<N>* face,
                  bool at_start, int dir) {
    const int g = guard_[static_cast<std::size_t>(e)];
    const GuardInfo gi = guard_info<M>(static_cast<std::size_t>(g));
    if (!all_finite(z)) {
      fail(TraceError::non_finite_reset, x.data(), mode_, g, tau);
      return;
    }
    // The root y* is located to rounding only, so s_g(z) = O(ε) of either sign; project z
    // onto S_g (Newton steps along ∇s_g) so that a support bounded by S_g (x ≥ 0 for the
    // ball) contains it and u0(z) is not cut off by rounding.
    State grad, X;
    project_onto_guard(g, z);
    // A pre-image outside the state space has no history: the branch would contribute
    // nothing, and from there its own reversed resets could spawn pre-images without end
    // (tests/validation/test_support_pruning.cpp). Tested just BEFORE the crossing, at
    // z − δ·X_from(z) with δ|X| = 1e-7·(1 + ‖z‖∞): z itself is on S_g only to rounding, and a
    // support that is open at S_g (x > 0 for the ball) or curved there must keep its histories.
    {
      State Xf, zb;
      M::flow(gi.from, z.data(), par_, Xf.data());
      const double speed = std::sqrt(dot<N>(Xf.data(), Xf.data()));
      double zn = 0.0;
      for (std::size_t i = 0; i < N; ++i) zn = std::max(zn, std::fabs(z[i]));
      const double delta = speed > 0.0 && std::isfinite(speed) ? 1e-7 * (1.0 + zn) / speed : 0.0;
      for (std::size_t i = 0; i < N; ++i) zb[i] = z[i] - delta * Xf[i];
      if (!M::in_support(zb.data(), par_)) return;
    }
    // A pre-image where the flow of `from` grazes S_g: the forward guard fires at a tangency.
    const double ratio = grazing<M>(g, gi.from, z, par_, opt_.graze_tol,
                                    [this](double) { return graze_delta(times_.back()); });
    if (ratio >= 0.0) {
      fail(TraceError::grazing, z.data(), gi.from, g, tau, ratio);
      return;
    }
    // z is a pre-image only if the guard fires there: sign(∇s_g·X_from)(z) = direction.
    M::guard_gradient(g, z.data(), par_, grad.data());
    M::flow(gi.from, z.data(), par_, X.data());
    const double sdot = dot<N>(grad.data(), X.data());
    if (!std::isfinite(sdot)) {
      fail(TraceError::non_finite_flow, z.data(), gi.from, g, tau);
      return;
    }
    if (sign_of(sdot) != gi.direction) return;
    if (face != nullptr) {
      // Limit from inside the box: the post-reset flow at y must point into the box; and
      // mass reset from inside the box is an internal transfer, not inflow.
      State Xto;
      M::flow(mode_, x.data(), par_, Xto.data());
      if (!(dot<N>(Xto.data(), face->inward.data()) > 0.0)) return;
      if (in_box<N>(z.data(), face->lo, face->hi)) return;
    }
    const double J = M::hybrid_jacobian(g, z.data(), par_);
    if (!std::isfinite(J) || J == 0.0) {
      fail(TraceError::zero_jacobian, z.data(), gi.from, g, tau);
      return;
    }
    if (++events_ > opt_.max_events) {
      fail(TraceError::event_cap, z.data(), gi.from, g, tau);
      return;
    }
    if (npend_ >= kMaxPending) {
      fail(TraceError::branch_cap, z.data(), gi.from, g, tau);
      return;
    }
    // Output times served by the new branch: those after τ*; within the tie window the
    // side of the event surface where the continuing trajectory is decides.
    const std::size_t K = times_.size();
    const double dw = opt_.ode.event_rearm * std::max(tau, times_[K - 1]);
    std::size_t kb = k_cur_;
    while (kb < K && times_[kb] <= tau + dw) {
      bool crossed;
      if (at_start || times_[kb] < tau - dw) {
        crossed = times_[kb] > tau;
      } else {
        Vec xc;
        dense_at(kb, xc);
        crossed = sign_of(event_value(e, xc)) == dir;
      }
      if (crossed) break;
      ++kb;
    }
    Branch& nb = pend_[npend_++];
    for (std::size_t i = 0; i < N; ++i) nb.x[i] = z[i];
    nb.x[N] = x[N];
    nb.mode = gi.from;
    nb.tau = tau;
    nb.weight = weight_ / std::fabs(J);
    nb.h = ode_.h_next();
    nb.via = g;
    nb.k_begin = kb;
  }

  /// The state at output time k from the current step's interpolant (clamped to the step),
  /// evaluated once per step: a tie (an event at an output time) is decided in try_spawn and
  /// the straight history's value taken in process from the very same numbers, so the two
  /// sides cannot both claim the output, or both refuse it, whatever the compiler's
  /// rounding (FMA contraction may round two inlined copies of one expression differently;
  /// tests/rt/test_ties.cpp).
  void dense_at(std::size_t k, Vec& x) {
    for (std::size_t i = 0; i < n_dense_; ++i)
      if (dense_k_[i] == k) {
        x = dense_x_[i];
        return;
      }
    ode_.dense(std::clamp(times_[k], ode_.t_prev(), ode_.t()), x);
    if (n_dense_ < dense_k_.size()) {
      dense_k_[n_dense_] = k;
      dense_x_[n_dense_++] = x;
    }
  }

  /// Gauss–Legendre rule of kPanelOrder nodes on [−1, 1] for `accumulate`.
  static const AxisRule& panel_rule() {
    static const AxisRule rule = gauss_legendre(kPanelOrder);
    return rule;
  }

  /// ∫_a^b c(σ) dσ on the current step's interpolant ([a, b] inside it), c(σ) = the current
  /// branch's contribution at backward time σ, by the kPanelOrder-point Gauss–Legendre rule.
  double panel(double a, double b) {
    const AxisRule& r = panel_rule();
    double s = 0.0;
    for (std::size_t q = 0; q < r.nodes.size(); ++q) {
      const double sig = 0.5 * (a + b) + 0.5 * (b - a) * r.nodes[q];
      Vec x;
      ode_.dense(sig, x);
      const double c = contribution(x, mode_, weight_, sig);
      cmax_ = std::max(cmax_, std::fabs(c));
      s += r.weights[q] * c;
    }
    return 0.5 * (b - a) * s;
  }

  /// acc_ += ∫_{cursor_}^{b} c(σ) dσ, cursor_ ← b, for b inside the current step. Panels of
  /// at most 1/kMinPanels of the horizon (a flux pulse narrower than all panels' nodes could
  /// otherwise be missed); each is accepted when its two halves' rules agree with the
  /// whole's, |I_L + I_R − I| ≤ tol·max(|I_L + I_R|, cmax·(panel length)), else halved (to
  /// depth kMaxDepth: a jump of u0 along the path converges linearly). cmax is the largest
  /// |c| seen on this characteristic, so the error per unit time is ≲ tol·max|u|.
  void accumulate(double b) {
    const double a0 = cursor_;
    cursor_ = std::max(cursor_, b);
    if (!(b > a0)) return;
    const double tol = opt_.cumulative_tol;
    const double hmax = times_.back() / kMinPanels;
    const int n = std::max(1, static_cast<int>(std::ceil((b - a0) / hmax)));
    for (int j = 0; j < n && status_.ok(); ++j) {
      const double pa = a0 + (b - a0) * j / n, pb = j + 1 == n ? b : a0 + (b - a0) * (j + 1) / n;
      struct Piece {
        double a, b, whole;
        int depth;
      };
      std::array<Piece, kMaxDepth + 2> stack{};
      std::size_t top = 0;
      stack[top++] = Piece{pa, pb, panel(pa, pb), 0};
      while (top > 0 && status_.ok()) {
        const Piece p = stack[--top];
        const double m = 0.5 * (p.a + p.b);
        const double L = panel(p.a, m), R = panel(m, p.b);
        const double err = std::fabs(L + R - p.whole);
        if (p.depth >= kMaxDepth || err <= tol * std::max(std::fabs(L + R), cmax_ * (p.b - p.a))) {
          acc_ += L + R;
          continue;
        }
        stack[top++] = Piece{m, p.b, R, p.depth + 1};
        stack[top++] = Piece{p.a, m, L, p.depth + 1};
      }
    }
  }

  /// Cumulative mode: the branch ends at σ; every later output gets its whole integral.
  void finish_cumulative(std::size_t k) {
    for (; k < times_.size(); ++k) out_[k] += acc_;
  }

  void process(const Branch& b, const FaceContext<N>* face) {
    const std::size_t K = times_.size();
    const double t_end = times_[K - 1];
    const bool cumulative = opt_.cumulative_tol > 0.0;
    std::size_t k = b.k_begin;
    while (k < K && times_[k] <= b.tau) {
      // Cumulative outputs before the branch starts get nothing from it (∫ over σ ≤ τ_b).
      if (!cumulative) out_[k] += contribution(b.x, b.mode, b.weight, b.tau);
      if (!status_.ok()) return;
      ++k;
    }
    acc_ = 0.0;
    cursor_ = b.tau;
    if (k >= K) return;
    mode_ = b.mode;
    weight_ = b.weight;
    k_cur_ = k;
    setup_events(mode_);
    const int m = mode_;
    auto rhs = [this, m](double, const Vec& x, Vec& dx) {
      M::flow(m, x.data(), par_, dx.data());
      for (std::size_t i = 0; i < N; ++i) dx[i] = -dx[i];
      dx[N] = M::divergence(m, x.data(), par_);
    };
    auto gfun = [this](int e, const Vec& x) { return event_value(e, x); };
    OdeStatus st = ode_.start(rhs, b.tau, b.x, t_end, b.h);
    if (st != OdeStatus::ok) {
      fail_ode(st, b.x, b.tau);
      return;
    }
    bool first = true;
    bool killed = false;
    auto on_root = [&](const EventRoot& r, const Vec& x) -> bool {
      if (incoming_[static_cast<std::size_t>(r.event)]) {
        try_spawn(r.event, r.t, x, nullptr, false, r.direction);
        return !status_.ok();
      }
      // The forward flow would have left mode m through guard h at x: no history continues
      // in mode m beyond it. If X_m grazes S_h there, h fires at a tangency: a failure.
      const int h = guard_[static_cast<std::size_t>(r.event)];
      State xs;
      for (std::size_t i = 0; i < N; ++i) xs[i] = x[i];
      const double ratio = grazing<M>(h, m, xs, par_, opt_.graze_tol,
                                      [t_end](double) { return graze_delta(t_end); });
      if (ratio >= 0.0) fail(TraceError::grazing, xs.data(), m, h, r.t, ratio);
      killed = true;
      return true;
    };
    for (;;) {
      st = ode_.step(rhs);
      if (st != OdeStatus::ok) {
        fail_ode(st, ode_.y(), ode_.t());
        return;
      }
      if (first) {
        first = false;
        std::array<int, kMaxEv> expected{};
        std::array<bool, kMaxEv> at_start{};
        if (b.via >= 0) {
          // Leaving S_via backwards: s_via takes the pre-firing sign −direction.
          for (int e = 0; e < n_ev_; ++e) {
            const auto ei = static_cast<std::size_t>(e);
            if (!incoming_[ei] && guard_[ei] == b.via)
              expected[ei] = -guard_info<M>(static_cast<std::size_t>(b.via)).direction;
          }
        }
        loc_.arm(ode_, gfun, expected.data(), at_start.data());
        if (!status_.ok()) return;
        // A start on a reset image Δ(S_g): the reversed reset applies at once (outputs > τ₀).
        for (int e = 0; e < n_ev_; ++e) {
          const auto ei = static_cast<std::size_t>(e);
          if (at_start[ei] && incoming_[ei]) {
            try_spawn(e, b.tau, b.x, face, true, 0);
            if (!status_.ok()) return;
          }
        }
      }
      double t_stop = ode_.t();
      n_dense_ = 0;  // a new step: a new interpolant
      loc_.scan(ode_, gfun, on_root, t_stop);
      if (!status_.ok()) return;
      while (k < K && times_[k] <= t_stop) {
        if (cumulative) {
          accumulate(times_[k]);
          out_[k] += acc_;
        } else {
          Vec x;
          dense_at(k, x);
          out_[k] += contribution(x, mode_, weight_, times_[k]);
        }
        if (!status_.ok()) return;
        ++k;
        k_cur_ = k;
      }
      if (cumulative && k < K) {
        accumulate(t_stop);
        if (!status_.ok()) return;
      }
      // The branch ends (killed, or no history outside the state space): cumulative outputs
      // after its end keep its integral.
      if (killed || k >= K || !M::in_support(ode_.y().data(), par_)) {
        if (cumulative) finish_cumulative(k);
        return;
      }
    }
  }

  const double* par_;
  CharacteristicsOptions opt_;
  Dopri5<D> ode_;
  EventLocator<D, kMaxEv> loc_;
  TraceStatus<N> status_{};
  std::span<const double> times_{};
  std::span<double> out_{};
  int events_ = 0;
  int mode_ = 0;
  double weight_ = 1.0;
  std::size_t k_cur_ = 0;
  int n_ev_ = 0;
  std::array<int, kMaxEv> guard_{};
  std::array<bool, kMaxEv> incoming_{};
  std::array<Branch, kMaxPending> pend_{};
  std::array<std::size_t, 8> dense_k_{};  // output indices evaluated in the current step
  std::array<Vec, 8> dense_x_{};          // their states (dense_at)
  std::size_t n_dense_ = 0;
  std::size_t npend_ = 0;
  // Cumulative mode (opt_.cumulative_tol > 0): the current branch's ∫ c dσ from its start to
  // cursor_, and the largest |c| met on this characteristic.
  static constexpr int kPanelOrder = 5;  // Gauss–Legendre nodes per panel
  static constexpr int kMinPanels = 64;  // panels per horizon, at least
  static constexpr int kMaxDepth = 40;   // halvings of a panel
  double acc_ = 0.0;
  double cursor_ = 0.0;
  double cmax_ = 0.0;
};

}  // namespace detail

/// u(t_k, y) in `mode` for the sorted output times `times` (all ≥ 0) into out[k]
/// (out.size() == times.size()), by one backward characteristic from y to τ = times.back().
/// y outside `M::in_support` gives 0. With `face` (y on a face of a box), the value is the
/// limit from inside that box (see `FaceContext`). Returns the failure, if any.
template <HybridModel M>
TraceStatus<state_dim_v<M>> trace(const std::array<double, state_dim_v<M>>& y, int mode,
                                  std::span<const double> times, const double* par,
                                  const CharacteristicsOptions& opt, std::span<double> out,
                                  const FaceContext<state_dim_v<M>>* face = nullptr) {
  detail::validate_times(times);
  if (out.size() != times.size())
    throw std::invalid_argument("characteristics: out.size() != times.size()");
  detail::Tracer<M> tracer(par, opt);
  return tracer.run(y, mode, times, out, face);
}

/// Densities at points for all modes and output times: u[(k·n_mode + m)·n_point + i].
template <std::size_t N>
struct Solution {
  std::size_t n_time = 0;     ///< Number of output times.
  std::size_t n_mode = 0;     ///< Number of modes.
  std::size_t n_point = 0;    ///< Number of points (grid nodes, C order).
  std::vector<double> u;      ///< Values, layout [time][mode][point].
  TraceFailure<N> failure{};  ///< The failure with the smallest (mode, point) index, if any.

  /// Whether every characteristic succeeded.
  bool ok() const { return failure.ok(); }
  /// Flat index of (time k, mode m, point i).
  std::size_t index(std::size_t k, std::size_t m, std::size_t i) const {
    return (k * n_mode + m) * n_point + i;
  }
  /// u(t_k, mode m, point i).
  double at(std::size_t k, std::size_t m, std::size_t i) const { return u[index(k, m, i)]; }
  /// All points of mode m at time k (a C-order grid-shaped array for grid solutions).
  std::span<const double> slice(std::size_t k, std::size_t m) const {
    return {u.data() + index(k, m, 0), n_point};
  }
};

namespace detail {

/// Trace every (mode, point) in parallel. `point(i)` gives the coordinates, `face(i)` a
/// `const FaceContext<N>*` (or nullptr).
template <HybridModel M, class PointFn, class FaceFn>
Solution<state_dim_v<M>> solve_points(std::size_t n_point, PointFn&& point, FaceFn&& face,
                                      std::span<const double> times, const double* par,
                                      const CharacteristicsOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  validate_times(times);
  Solution<N> sol;
  sol.n_time = times.size();
  sol.n_mode = static_cast<std::size_t>(M::n_mode);
  sol.n_point = n_point;
  sol.u.assign(sol.n_time * sol.n_mode * n_point, 0.0);
  if (sol.n_time == 0 || n_point == 0) return sol;
  const auto total = static_cast<long long>(sol.n_mode * n_point);
  const auto np = static_cast<long long>(n_point);
  std::atomic<long long> first_fail{total};
#pragma omp parallel
  {
    Tracer<M> tracer(par, opt);
    std::vector<double> buf(sol.n_time);
#pragma omp for schedule(dynamic, 16)
    for (long long idx = 0; idx < total; ++idx) {
      // Failures are reported for the smallest index: later ones need not be traced.
      if (idx > first_fail.load(std::memory_order_relaxed)) continue;
      const auto m = static_cast<std::size_t>(idx / np);
      const auto i = static_cast<std::size_t>(idx % np);
      if (opt.progress) opt.progress->advance();
      const std::array<double, N> y = point(i);
      if (!M::in_support(y.data(), par)) continue;
      const TraceStatus<N> st = tracer.run(y, static_cast<int>(m), times, buf, face(i));
      if (!st.ok()) {
#pragma omp critical(hybgen_rt_characteristics_failure)
        {
          if (idx < first_fail.load()) {
            first_fail.store(idx);
            sol.failure = TraceFailure<N>{st, static_cast<int>(m), i, y};
          }
        }
        continue;
      }
      for (std::size_t k = 0; k < sol.n_time; ++k) sol.u[sol.index(k, m, i)] = buf[k];
    }
  }
  return sol;
}

}  // namespace detail

/// The characteristics solution on every node of `grid` for every mode and output time
/// (OpenMP over (mode, node), dynamic schedule). Nodes outside `M::in_support` are 0.
/// On failure, `failure` names the first failing (mode, node); other values are partial.
template <HybridModel M>
Solution<state_dim_v<M>> solve_grid(const TensorGrid<state_dim_v<M>>& grid,
                                    std::span<const double> times, const double* par,
                                    const CharacteristicsOptions& opt) {
  using Face = const FaceContext<state_dim_v<M>>*;
  return detail::solve_points<M>(
      grid.size(), [&grid](std::size_t i) { return grid.node(i); },
      [](std::size_t) -> Face { return nullptr; }, times, par, opt);
}

/// u at arbitrary points (all modes, all output times), same layout as `solve_grid`.
/// `faces`, if not empty, gives per point the box face it lies on (boundary flux).
template <HybridModel M>
Solution<state_dim_v<M>> evaluate(std::span<const std::array<double, state_dim_v<M>>> points,
                                  std::span<const double> times, const double* par,
                                  const CharacteristicsOptions& opt,
                                  std::span<const FaceContext<state_dim_v<M>>> faces = {}) {
  using Face = const FaceContext<state_dim_v<M>>*;
  if (!faces.empty() && faces.size() != points.size())
    throw std::invalid_argument("characteristics: faces.size() != points.size()");
  return detail::solve_points<M>(
      points.size(), [points](std::size_t i) { return points[i]; },
      [faces](std::size_t i) -> Face { return faces.empty() ? nullptr : &faces[i]; }, times, par,
      opt);
}

/// One-line description of a failed characteristic for an error message (exit code 3).
template <HybridModel M>
std::string describe(const TraceFailure<state_dim_v<M>>& f) {
  constexpr std::size_t N = state_dim_v<M>;
  std::ostringstream os;
  os << std::setprecision(17);
  auto point = [&os](const std::array<double, N>& x) { write_state<M>(os, x); };
  const TraceStatus<N>& s = f.status;
  os << "characteristic from ";
  point(f.start);
  os << " in mode '" << mode_name<M>(f.start_mode) << "' failed: " << trace_error_name(s.error);
  if (s.guard >= 0 && s.guard < M::n_guard) os << " at guard '" << guard_name<M>(s.guard) << "'";
  os << " at backward time tau = " << s.tau << ", state ";
  point(s.state);
  os << ", mode '" << mode_name<M>(s.mode) << "', after " << s.events << " resets";
  if (s.error == TraceError::grazing) detail::describe_grazing(os, s.value);
  return os.str();
}

// ---------------------------------------------------------------------------------------
// Mass budget.

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

/// The mass budget over a box: for each output time t_k,
///   mass[k] = Σ_modes ∫_box u(t_k),  outflow[k] = ∫₀^{t_k} Σ_modes ∮_∂box u X·n_out,
///   atom[k] = mass0 − mass[k] − outflow[k]  (mass neither in the box nor gone through its
///   faces: concentrated on atoms such as a Zeno point, or reset out of the box from inside).
struct MassBudget {
  std::vector<double> times;    ///< Output times.
  double mass0 = 0.0;           ///< Σ_modes ∫_box u0.
  std::vector<double> mass;     ///< Mass in the box at each output time.
  std::vector<double> outflow;  ///< Net outflow through the box faces during [0, t_k].
  /// Mass at atoms: measured at Zeno points by `adaptive_mass_budget` (budget.hpp); for the
  /// fixed-rule budgets below, the remainder mass0 − mass − outflow.
  std::vector<double> atom;
  /// Estimated |error| of mass[k] (`adaptive_mass_budget`, budget.hpp); empty for fixed rules.
  std::vector<double> mass_error;
  double mass0_error = 0.0;           ///< Estimated |error| of mass0 (adaptive only).
  std::vector<double> outflow_error;  ///< Estimated |error| of outflow[k] (adaptive only).
  std::vector<double> atom_error;     ///< Estimated |error| of atom[k] (adaptive only).
};

/// mass0 − mass[k] − outflow[k] − atom[k]: what no term of the budget accounts for.
inline std::vector<double> budget_defect(const MassBudget& b) {
  std::vector<double> d(b.mass.size(), 0.0);
  for (std::size_t k = 0; k < d.size() && k < b.outflow.size() && k < b.atom.size(); ++k)
    d[k] = b.mass0 - b.mass[k] - b.outflow[k] - b.atom[k];
  return d;
}

/// Estimated |error| of budget_defect(b)[k]: the sum of its terms' estimates.
inline std::vector<double> budget_defect_error(const MassBudget& b) {
  std::vector<double> e(b.mass.size(), 0.0);
  auto at = [](const std::vector<double>& v, std::size_t k) { return k < v.size() ? v[k] : 0.0; };
  for (std::size_t k = 0; k < e.size(); ++k)
    e[k] = at(b.mass_error, k) + b.mass0_error + at(b.outflow_error, k) + at(b.atom_error, k);
  return e;
}

/// A mass budget and the first failed characteristic, if any.
template <std::size_t N>
struct BudgetResult {
  MassBudget budget;          ///< The budget (partial if a trace failed).
  TraceFailure<N> failure{};  ///< First failed characteristic.
  std::string message;        ///< Another failure (a forward flow of the atom), or empty.
  /// Whether every characteristic and flow succeeded.
  bool ok() const { return failure.ok() && message.empty(); }
};

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

/// The outward normal flux density X_m·n_out of mode m at a point y of the face of the box
/// [lo, hi] normal to `axis` (n_out = `sign` e_axis), or 0 where the mass crossing there is
/// not gained or lost by the box: at a point of a guard surface S_h where h fires, the mass is
/// reset to Δ_h(y); it leaves the box iff it crosses outwards and Δ_h(y) is outside, and it
/// enters iff it arrives from outside and Δ_h(y) is inside. `diam` scales the surface test.
template <HybridModel M>
double face_flux(int m, const double* y, std::size_t axis, double sign,
                 const std::array<double, state_dim_v<M>>& lo,
                 const std::array<double, state_dim_v<M>>& hi, double diam, const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> X{};
  M::flow(m, y, par, X.data());
  const double xn = sign * X[axis];
  bool fires = false, image_in_box = false;
  for (std::size_t g = 0; g < static_cast<std::size_t>(M::n_guard) && !fires; ++g) {
    const GuardInfo gi = guard_info<M>(g);
    if (gi.from != m) continue;
    std::array<double, N> grad{}, img{};
    M::guard_gradient(static_cast<int>(g), y, par, grad.data());
    const double gn = std::sqrt(dot<N>(grad.data(), grad.data()));
    if (!(std::fabs(M::guard_surface(static_cast<int>(g), y, par)) <= 1e-12 * gn * diam)) continue;
    if (sign_of(dot<N>(grad.data(), X.data())) != gi.direction) continue;
    M::reset(static_cast<int>(g), y, par, img.data());
    fires = true;
    image_in_box = in_box<N>(img.data(), lo, hi);
  }
  const bool counts = !fires || (xn > 0.0 ? !image_in_box : image_in_box);
  return counts ? xn : 0.0;
}

/// Default relative tolerance of the time integral of the boundary flux
/// (CharacteristicsOptions::cumulative_tol) when the caller sets none.
inline constexpr double kFluxTimeTol = 1e-8;

/// `opt` with the time integral of the flux switched on (its own tolerance, or kFluxTimeTol).
inline CharacteristicsOptions cumulative_options(const CharacteristicsOptions& opt) {
  CharacteristicsOptions o = opt;
  if (!(o.cumulative_tol > 0.0)) o.cumulative_tol = kFluxTimeTol;
  return o;
}

/// Cumulative net outflow through the faces of `box` at the output times, with the tensor
/// rules `face` (rule of axis b used along b on every face normal to another axis); in time,
/// ∫₀^{t_k} u dt at each face point adaptively along its characteristic (`cumulative_tol`).
/// Resets on the faces are accounted for: at a face point on a guard surface S_h where h fires,
/// the crossing mass counts as outflow only if Δ_h(y) lies outside the box (and as inflow,
/// when it arrives from outside, only if Δ_h(y) lies inside); on a reset image the part of
/// the density reset from inside the box is no inflow (see `FaceContext`). For the bouncing
/// ball the ground face therefore carries no net flux, exactly, instead of two log-divergent
/// fluxes near a Zeno point whose quadratures do not cancel.
template <HybridModel M>
std::vector<double> outflow(const TensorGrid<state_dim_v<M>>& box,
                            const std::array<AxisRule, state_dim_v<M>>& face,
                            std::span<const double> times, const double* par,
                            const CharacteristicsOptions& opt,
                            TraceFailure<state_dim_v<M>>& failure) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::size_t K = times.size();
  std::vector<double> result(K, 0.0);
  if (K == 0 || times.back() <= 0.0) return result;
  // Face points.
  std::array<double, N> lo{}, hi{};
  double diam = 0.0;
  for (std::size_t a = 0; a < N; ++a) {
    lo[a] = box.axes[a].min;
    hi[a] = box.axes[a].max;
    diam = std::max(diam, hi[a] - lo[a]);
  }
  std::vector<std::array<double, N>> pts;
  std::vector<FaceContext<N>> ctx;
  std::vector<double> wts;
  std::vector<std::size_t> axis_of;
  std::vector<double> sign_of_face;
  for (std::size_t a = 0; a < N; ++a) {
    for (int side = -1; side <= 1; side += 2) {
      if (side == 1 && hi[a] == lo[a]) continue;
      std::size_t total = 1;
      for (std::size_t b = 0; b < N; ++b)
        if (b != a) total *= face[b].nodes.size();
      for (std::size_t flat = 0; flat < total; ++flat) {
        std::array<double, N> y{};
        double w = 1.0;
        std::size_t rem = flat;
        for (std::size_t b = N; b-- > 0;) {
          if (b == a) continue;
          const std::size_t n = face[b].nodes.size();
          y[b] = face[b].nodes[rem % n];
          w *= face[b].weights[rem % n];
          rem /= n;
        }
        y[a] = side < 0 ? lo[a] : hi[a];
        FaceContext<N> c{};
        c.inward[a] = side < 0 ? 1.0 : -1.0;
        c.lo = lo;
        c.hi = hi;
        pts.push_back(y);
        ctx.push_back(c);
        wts.push_back(w);
        axis_of.push_back(a);
        sign_of_face.push_back(static_cast<double>(side));
      }
    }
  }
  const Solution<N> sol =
      evaluate<M>(std::span<const std::array<double, N>>(pts), times, par, cumulative_options(opt),
                  std::span<const FaceContext<N>>(ctx));
  if (!sol.ok()) {
    failure = sol.failure;
    return result;
  }
  // Flux weights w·(X_m·n_out) per (mode, point), 0 where the mass is reset into the box.
  const std::size_t nm = static_cast<std::size_t>(M::n_mode);
  std::vector<double> fw(nm * pts.size(), 0.0);
  for (std::size_t m = 0; m < nm; ++m) {
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const double* y = pts[i].data();
      if (!M::in_support(y, par)) continue;
      fw[m * pts.size() + i] = wts[i] * face_flux<M>(static_cast<int>(m), y, axis_of[i],
                                                     sign_of_face[i], lo, hi, diam, par);
    }
  }
  for (std::size_t k = 0; k < K; ++k)
    for (std::size_t m = 0; m < nm; ++m)
      for (std::size_t i = 0; i < pts.size(); ++i)
        result[k] += fw[m * pts.size() + i] * sol.at(k, m, i);
  return result;
}

template <HybridModel M>
double initial_mass(const std::array<const AxisRule*, state_dim_v<M>>& rules, const double* par) {
  double s = 0.0;
  for (int m = 0; m < M::n_mode; ++m) {
    s += tensor_sum<state_dim_v<M>>(rules, [&](std::size_t flat) {
      const auto y = tensor_node<state_dim_v<M>>(rules, flat);
      return M::in_support(y.data(), par) ? M::initial_density(m, y.data(), par) : 0.0;
    });
  }
  return s;
}

}  // namespace detail

/// Mass budget of a grid solution (the runner's default): masses by the tensor trapezoid rule
/// on the grid nodes (from `sol`), outflow through the faces of the grid box by the trapezoid
/// rule on the face nodes and adaptively in time (`detail::outflow`).
template <HybridModel M>
BudgetResult<state_dim_v<M>> mass_budget(const TensorGrid<state_dim_v<M>>& grid,
                                         const Solution<state_dim_v<M>>& sol,
                                         std::span<const double> times, const double* par,
                                         const CharacteristicsOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  BudgetResult<N> res;
  std::array<AxisRule, N> rules;
  std::array<const AxisRule*, N> rp{};
  for (std::size_t a = 0; a < N; ++a) {
    rules[a] = trapezoid_rule(grid.axes[a]);
    rp[a] = &rules[a];
  }
  MassBudget& mb = res.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = detail::initial_mass<M>(rp, par);
  mb.mass.assign(times.size(), 0.0);
  for (std::size_t k = 0; k < times.size() && k < sol.n_time; ++k)
    for (std::size_t m = 0; m < sol.n_mode; ++m)
      mb.mass[k] += detail::tensor_sum<N>(rp, [&](std::size_t i) { return sol.at(k, m, i); });
  mb.outflow = detail::outflow<M>(grid, rules, times, par, opt, res.failure);
  mb.atom.resize(times.size());
  for (std::size_t k = 0; k < times.size(); ++k) mb.atom[k] = mb.mass0 - mb.mass[k] - mb.outflow[k];
  return res;
}

/// Mass budget with explicit tensor quadrature rules: `volume` (one rule per axis, spanning
/// the box of `box`) for the masses, `face` for the faces; the density is evaluated by
/// characteristics at the quadrature nodes (use graded Gauss–Legendre near singularities).
template <HybridModel M>
BudgetResult<state_dim_v<M>> mass_budget(const TensorGrid<state_dim_v<M>>& box,
                                         const std::array<AxisRule, state_dim_v<M>>& volume,
                                         const std::array<AxisRule, state_dim_v<M>>& face,
                                         std::span<const double> times, const double* par,
                                         const CharacteristicsOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  BudgetResult<N> res;
  std::array<const AxisRule*, N> rp{};
  std::size_t total = 1;
  for (std::size_t a = 0; a < N; ++a) {
    rp[a] = &volume[a];
    total *= volume[a].nodes.size();
  }
  MassBudget& mb = res.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = detail::initial_mass<M>(rp, par);
  const Solution<N> sol = detail::solve_points<M>(
      total, [&rp](std::size_t i) { return detail::tensor_node<N>(rp, i); },
      [](std::size_t) -> const FaceContext<N>* { return nullptr; }, times, par, opt);
  mb.mass.assign(times.size(), 0.0);
  if (!sol.ok()) res.failure = sol.failure;
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t m = 0; m < sol.n_mode; ++m)
      mb.mass[k] += detail::tensor_sum<N>(rp, [&](std::size_t i) { return sol.at(k, m, i); });
  TraceFailure<N> flux_failure;
  mb.outflow = detail::outflow<M>(box, face, times, par, opt, flux_failure);
  if (res.failure.ok()) res.failure = flux_failure;
  mb.atom.resize(times.size());
  for (std::size_t k = 0; k < times.size(); ++k) mb.atom[k] = mb.mass0 - mb.mass[k] - mb.outflow[k];
  return res;
}

}  // namespace hybgen::rt
