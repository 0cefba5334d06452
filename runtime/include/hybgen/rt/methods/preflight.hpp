#pragma once
/// \file preflight.hpp
/// The pre-flight scan: forward checks made once, at t = 0, before the solve, of what the
/// backward characteristics cannot see (or see only late and far from the cause).
///
///  1. The initial density: at every grid node inside `in_support` and for every mode,
///     u0 must be finite and ≥ 0 (a density).
///  2. Every guard g: its crossing points in the grid box are found on the grid edges — a sign
///     change of s_g between two neighbouring nodes is refined by bisection onto s_g = 0; a node
///     with s_g = 0 exactly is one too — and kept when inside `in_support`. At each crossing
///     point x* (∇s·X_from(x*) has the firing sign `direction`):
///       - X_from(x*) and div X_from(x*) are finite;
///       - Δ(x*) is finite and in the support (or within surface_tol·diam of it on the way to
///         x*: outside by rounding, `support_within`). Δ(x*) outside the grid box is no failure:
///         the mass reset there leaves the computed region and every method counts it as outflow
///         (the characteristics' budget measures it with forward flows, budget/atom.hpp); the
///         first such point of each guard is a note (`reset_outside_box`), which the runner
///         prints as a warning;
///       - Δ(x*) is not on a guard h of the target mode that fires there at once
///         (|s_h(Δx*)| ≤ surface_tol·|∇s_h|·diam and sign(∇s_h·X_to(Δx*)) = direction_h:
///         an instantaneous re-trigger, the paper's H.5);
///       - no other guard h of the same mode fires at x* (|s_h(x*)| ≤ surface_tol·|∇s_h|·diam and
///         sign(∇s_h·X_from(x*)) = direction_h): the model would not say which reset applies,
///         and each would carry the whole flux (the characteristics would sum both images and
///         create mass; the forward methods would take the first guard);
///       - J_g(x*) is finite and ≠ 0;
///       - for a numeric inverse (Newton) and the backward characteristics (`backward`), Newton
///         from Δ(x*) — started at Δ(x*) itself, as the characteristics do — converges, and
///         (`check_preimages`) the pre-images of Δ(x*) are counted: several give the tracer
///         seeds to enumerate them all, after a check that a wider search finds no more.
///     Grazing: at any point x* of S_g found in the support (firing or not) where the flow is
///     tangent to the guard, |∇s·X| ≤ graze_tol·|∇s||X|, the orbit through x* is followed a
///     short time δ both ways (RK4, δ|X| = 1e-3·diam); if it passes from the pre-firing side of
///     S_g to the firing side, the guard fires at a tangency — the event location is
///     ill-conditioned and J's denominator ∇s·X vanishes — and that is reported. A tangency the
///     orbit does not cross (the bouncing ball's Zeno point (0, 0): x(t) = −g t²/2 ≤ 0 on both
///     sides) is no crossing and passes. The criterion is `detail::grazing`
///     (core/geometry.hpp), which the backward tracer and the forward flow apply at every
///     crossing they meet later, anywhere — this scan sees only the grid edges at t = 0.
///
/// Cost: O(grid nodes · (N + guards)) model evaluations plus a bisection per crossing edge;
/// OpenMP over the nodes from 2¹⁸ nodes on (one thread below). The failure reported is the one with
/// the smallest (guard, node) index, so the message does not depend on the number of threads.
/// Size: one scan per failure class it must catch before the solve (support, resets,
/// grazing, folds of the reset, Zeno), each with its located message.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/method_table.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// What the pre-flight scan found wrong.
enum class PreflightError {
  none,                   ///< Nothing.
  negative_density,       ///< u0 < 0 at a grid node in the support.
  non_finite_density,     ///< u0 not finite at a grid node in the support.
  non_finite_guard,       ///< s_g not finite at a grid node in the support.
  non_finite_flow,        ///< X_from or div X_from not finite at a crossing point.
  non_finite_reset,       ///< Δ(x*) not finite.
  reset_outside_support,  ///< Δ(x*) outside `in_support`.
  reset_outside_box,      ///< Δ(x*) outside the grid box: a note, never a failure.
  reset_retriggers,       ///< Δ(x*) on a guard of the target mode that fires at once.
  guards_overlap,         ///< Another guard of the same mode fires at x* too.
  zero_jacobian,          ///< J(x*) = 0 or not finite.
  inverse_failed,         ///< Newton for Δ⁻¹ at Δ(x*) did not converge.
  grazing,                ///< The flow is tangent to the guard where the orbit crosses it.
  several_preimages,      ///< Δ(x*) has a second pre-image on S_g (numeric inverse only).
  preimages_missed,       ///< The tracer's multi-start misses a pre-image that a wider one finds.
};

/// Human-readable name of a `PreflightError`.
inline const char* preflight_error_name(PreflightError e) {
  switch (e) {
    case PreflightError::none:
      return "no error";
    case PreflightError::negative_density:
      return "negative initial density";
    case PreflightError::non_finite_density:
      return "non-finite initial density";
    case PreflightError::non_finite_guard:
      return "non-finite guard function";
    case PreflightError::non_finite_flow:
      return "non-finite vector field or divergence";
    case PreflightError::non_finite_reset:
      return "non-finite reset";
    case PreflightError::reset_outside_support:
      return "the reset lands outside the support (the state space)";
    case PreflightError::reset_outside_box:
      return "the reset carries mass out of the domain (the grid box)";
    case PreflightError::reset_retriggers:
      return "the reset lands on a guard that fires again at once (instantaneous re-trigger)";
    case PreflightError::guards_overlap:
      return "two guards of one mode fire at the same state";
    case PreflightError::zero_jacobian:
      return "zero or non-finite hybrid Jacobian";
    case PreflightError::inverse_failed:
      return "Newton iteration for the inverse reset did not converge";
    case PreflightError::grazing:
      return "grazing: the flow is tangent to the guard at a crossing";
    case PreflightError::several_preimages:
      return "the reset is not injective on its guard";
    case PreflightError::preimages_missed:
      return "the reset is not injective on its guard and its pre-images cannot be enumerated";
  }
  return "?";
}

/// Tolerances of the pre-flight scan.
struct PreflightOptions {
  /// Grazing when |∇s·X| ≤ graze_tol·|∇s||X| at a crossing (`kGrazeTol`, core/geometry.hpp,
  /// shared with the tracers).
  double graze_tol = kGrazeTol;
  /// Δ(x*) is on S_h when |s_h| ≤ surface_tol·|∇s_h|·diam(box): bisection leaves s_g(x*) at
  /// rounding level, which Δ maps to O(ε·|DΔ|·scale), far below 1e-9.
  double surface_tol = 1e-9;
  int newton_max_iter = 50;   ///< As CharacteristicsOptions::newton_max_iter.
  double newton_tol = 1e-14;  ///< As CharacteristicsOptions::newton_tol.
  /// The method inverts resets (the backward characteristics): check that a numeric inverse
  /// converges at every crossing and count its pre-images (`check_preimages`: the tracer
  /// follows ONE pre-image, so a second one is a failure). The forward methods (transfer,
  /// invariant, particles, escape: method_table.hpp, forward_methods) need no inverse and skip
  /// both.
  bool backward = true;
  /// Crossing points per guard used by `check_preimages` (evenly spaced among those found):
  /// the starts of the pre-image search, and the tracer's seeds.
  int preimage_points = 64;
  /// Starts of the wider search that checks the seeds' count (`check_preimages`).
  int preimage_check_points = 1024;
};

/// The first failure of the pre-flight scan, with where it happened.
template <std::size_t N>
struct PreflightFailure {
  PreflightError error = PreflightError::none;  ///< What.
  int mode = -1;         ///< Mode of the node (density) or source mode (guards).
  int guard = -1;        ///< Guard scanned, or −1 for the density.
  int other_guard = -1;  ///< The re-triggered (reset_retriggers) or overlapping guard, else −1.
  std::array<double, N> state{};  ///< The grid node or the crossing point x*.
  std::array<double, N> image{};  ///< Δ(x*) (reset errors), else unused.
  std::array<double, N> other{};  ///< The second pre-image (several_preimages), else unused.
  double value = 0.0;             ///< u0, J or |∇s·X|/(|∇s||X|), whichever applies.
  std::size_t node = 0;           ///< Flat index of the grid node (the edge's first node).
  /// Whether nothing failed.
  bool ok() const { return error == PreflightError::none; }
};

/// Re-triggers within this many grid cells of each other are one isolated point
/// (`check_guard`).
inline constexpr double kIsolatedCells = 2.0;

/// Grids smaller than this are scanned by one thread: the scan costs ~40–60 ns per node and
/// guard (0.2 ms for 75×75), less than starting a thread team on a busy machine.
inline constexpr std::size_t kPreflightParallelMin = std::size_t{1} << 18;

namespace detail {

/// Keeps the failure with the smallest index across threads.
template <std::size_t N>
struct FirstFailure {
  std::atomic<std::size_t> index{std::numeric_limits<std::size_t>::max()};  ///< Its index.
  PreflightFailure<N> failure{};                                            ///< The failure.
  /// Whether index `i` can still improve on the recorded failure.
  bool wanted(std::size_t i) const { return i < index.load(std::memory_order_relaxed); }
  /// Record `f` found at index `i` if it comes first.
  void offer(std::size_t i, const PreflightFailure<N>& f) {
#pragma omp critical(hybgen_rt_preflight_failure)
    {
      if (i < index.load()) {
        index.store(i);
        failure = f;
      }
    }
  }
};

/// Whether Newton for Δ_g(z) = y from z = y converges (the characteristics' Tracer's).
template <HybridModel M>
bool newton_converges(int g, const std::array<double, state_dim_v<M>>& y, const double* par,
                      const PreflightOptions& opt) {
  std::array<double, state_dim_v<M>> z{};
  return newton_reset_inverse<M>(g, y.data(), par, opt.newton_max_iter, opt.newton_tol, z);
}

/// Whether the support holds a point within `dist` of y on the way to x (in the support): y
/// is outside it by rounding only. A restitution reset at e = 1 keeps |p|, so on the edge of a
/// support |p| ≤ 2 it lands at |p| = 2(1 + ε) (tests/validation/test_reset_outflow.cpp).
template <HybridModel M>
bool support_within(const std::array<double, state_dim_v<M>>& y,
                    const std::array<double, state_dim_v<M>>& x, double dist, const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> d{};
  for (std::size_t a = 0; a < N; ++a) d[a] = x[a] - y[a];
  const double len = std::sqrt(dot<N>(d.data(), d.data()));
  if (!(len > 0.0)) return false;
  std::array<double, N> z{};
  for (std::size_t a = 0; a < N; ++a) z[a] = y[a] + std::min(dist, len) / len * d[a];
  return M::in_support(z.data(), par);
}

/// All checks at a point x of S_g inside the support; returns the failure (ok() if none), or,
/// when every check passes and only Δ(x) lies outside the box [lo, hi], `reset_outside_box`
/// (a note for `check_guard`, not a failure).
template <HybridModel M>
PreflightFailure<state_dim_v<M>> check_crossing(int g, const std::array<double, state_dim_v<M>>& x,
                                                const std::array<double, state_dim_v<M>>& lo,
                                                const std::array<double, state_dim_v<M>>& hi,
                                                double diam, const double* par,
                                                const PreflightOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  const GuardInfo gi = guard_info<M>(static_cast<std::size_t>(g));
  PreflightFailure<N> f;
  f.guard = g;
  f.mode = gi.from;
  f.state = x;
  auto fail = [&f](PreflightError e, double v) {
    f.error = e;
    f.value = v;
    return f;
  };
  std::array<double, N> X{}, grad{};
  M::flow(gi.from, x.data(), par, X.data());
  const double div = M::divergence(gi.from, x.data(), par);
  if (!all_finite(X) || !std::isfinite(div)) return fail(PreflightError::non_finite_flow, div);
  M::guard_gradient(g, x.data(), par, grad.data());
  const double rate = dot<N>(grad.data(), X.data());
  if (!std::isfinite(rate)) return fail(PreflightError::non_finite_flow, rate);
  // Grazing: tangent here, and the orbit crosses S_g in the firing direction (the criterion
  // the tracers share, core/geometry.hpp), followed until it has moved 1e-3·diam each way.
  const double ratio = grazing<M>(g, gi.from, x, par, opt.graze_tol,
                                  [diam](double speed) { return 1e-3 * diam / speed; });
  if (ratio >= 0.0) return fail(PreflightError::grazing, ratio);
  if (!(rate * gi.direction > 0.0)) return f;  // the guard does not fire here
  for (std::size_t h = 0; h < static_cast<std::size_t>(M::n_guard); ++h) {
    const GuardInfo other = guard_info<M>(h);
    const int hh = static_cast<int>(h);
    if (hh == g || other.from != gi.from) continue;
    std::array<double, N> gh{};
    M::guard_gradient(hh, x.data(), par, gh.data());
    const double ghn = std::sqrt(dot<N>(gh.data(), gh.data()));
    if (!(std::fabs(M::guard_surface(hh, x.data(), par)) <= opt.surface_tol * ghn * diam)) continue;
    if (dot<N>(gh.data(), X.data()) * other.direction > 0.0) {
      f.other_guard = hh;
      return fail(PreflightError::guards_overlap, 0.0);
    }
  }
  if (absorbs(gi)) return f;  // nothing is reset (model.hpp): no image to check
  std::array<double, N> y{};
  M::reset(g, x.data(), par, y.data());
  f.image = y;
  if (!all_finite(y)) return fail(PreflightError::non_finite_reset, 0.0);
  const double J = M::hybrid_jacobian(g, x.data(), par);
  if (!std::isfinite(J) || J == 0.0) return fail(PreflightError::zero_jacobian, J);
  if (!M::in_support(y.data(), par) && !support_within<M>(y, x, opt.surface_tol * diam, par))
    return fail(PreflightError::reset_outside_support, 0.0);
  const bool outside = !in_box<N>(y.data(), lo, hi);
  for (std::size_t h = 0; h < static_cast<std::size_t>(M::n_guard); ++h) {
    const GuardInfo hi_ = guard_info<M>(h);
    if (hi_.from != gi.to) continue;
    const int hh = static_cast<int>(h);
    std::array<double, N> gh{}, Xt{};
    M::guard_gradient(hh, y.data(), par, gh.data());
    const double ghn = std::sqrt(dot<N>(gh.data(), gh.data()));
    if (!(std::fabs(M::guard_surface(hh, y.data(), par)) <= opt.surface_tol * ghn * diam)) continue;
    M::flow(gi.to, y.data(), par, Xt.data());
    if (dot<N>(gh.data(), Xt.data()) * hi_.direction > 0.0) {
      f.other_guard = hh;
      return fail(PreflightError::reset_retriggers, 0.0);
    }
  }
  if (opt.backward && !gi.has_inverse && !newton_converges<M>(g, y, par, opt))
    return fail(PreflightError::inverse_failed, 0.0);
  if (outside) return fail(PreflightError::reset_outside_box, 0.0);
  return f;
}

}  // namespace detail

/// Check u0 at every grid node in the support, for every mode: finite and ≥ 0. Returns the
/// failure at the smallest (mode, node) index.
template <HybridModel M>
PreflightFailure<state_dim_v<M>> check_initial_density(const TensorGrid<state_dim_v<M>>& grid,
                                                       const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::size_t n = grid.size(), nm = static_cast<std::size_t>(M::n_mode);
  const auto total = static_cast<long long>(n * nm);
  detail::FirstFailure<N> first;
#pragma omp parallel for schedule(static) if (n * nm >= kPreflightParallelMin)
  for (long long idx = 0; idx < total; ++idx) {
    const auto ui = static_cast<std::size_t>(idx);
    if (!first.wanted(ui)) continue;
    const std::size_t m = ui / n, i = ui % n;
    const std::array<double, N> y = grid.node(i);
    if (!M::in_support(y.data(), par)) continue;
    const double u = M::initial_density(static_cast<int>(m), y.data(), par);
    if (u >= 0.0 && std::isfinite(u)) continue;
    PreflightFailure<N> f;
    f.error =
        std::isfinite(u) ? PreflightError::negative_density : PreflightError::non_finite_density;
    f.mode = static_cast<int>(m);
    f.state = y;
    f.value = u;
    f.node = i;
    first.offer(ui, f);
  }
  return first.failure;
}

/// Scan guard g's crossing points on the grid edges (see the file comment). Returns the
/// failure at the smallest node index (the edge's first node; per node, axes in order).
/// `crossings`, if given, receives the bisected crossing points that passed every check, each
/// with its edge index (node·N + axis), in no particular order.
///
/// Re-triggers at ISOLATED points: when every crossing whose reset lands on a guard that
/// fires at once lies within kIsolatedCells grid cells (the largest spacing) of the first
/// one — a corner where two guards' surfaces meet, as in a water-tank model at (r1, r2) — the
/// set has measure zero on S_g: no mass is there, the point is excluded, and the re-trigger is
/// a note in `notes` (the runner prints it as a warning) instead of the failure. A re-trigger
/// on a stretch of S_g (several cells apart) stays the failure. So do overlapping guards
/// (`guards_overlap`): two surfaces that meet at a corner pass with a note, two that coincide
/// along a stretch (or at the point that a 1-D guard is) fail.
///
/// Resets out of the box: a crossing whose reset lands outside the grid box passes (its mass
/// is outflow); the first such crossing (smallest index) is a note in `notes`.
template <HybridModel M>
PreflightFailure<state_dim_v<M>> check_guard(
    int g, const TensorGrid<state_dim_v<M>>& grid, const double* par,
    const PreflightOptions& opt = {},
    std::vector<std::pair<std::size_t, std::array<double, state_dim_v<M>>>>* crossings = nullptr,
    std::vector<PreflightFailure<state_dim_v<M>>>* notes = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  std::vector<std::pair<std::size_t, PreflightFailure<N>>> retriggers;
  detail::FirstFailure<N> outside;  // the first crossing reset out of the box (a note)
  // A crossing reset out of the box passes; the first one is kept for the note.
  auto pass_outside = [&outside](std::size_t i, PreflightFailure<N>& f) {
    if (f.error != PreflightError::reset_outside_box) return;
    f.node = i;
    if (outside.wanted(i)) outside.offer(i, f);
    f.error = PreflightError::none;
  };
  // A failure at edge/node index i: re-triggers are held back (see above).
  auto offer = [&](detail::FirstFailure<N>& first, std::size_t i, const PreflightFailure<N>& f) {
    if (f.error == PreflightError::reset_retriggers || f.error == PreflightError::guards_overlap) {
#pragma omp critical(hybgen_rt_preflight_retriggers)
      retriggers.emplace_back(i, f);
      return;
    }
    first.offer(i, f);
  };
  std::array<double, N> lo{}, hi{};
  std::array<std::size_t, N> stride{}, count{};
  double diam = 0.0;
  std::size_t s = 1;
  for (std::size_t a = N; a-- > 0;) {
    lo[a] = grid.axes[a].min;
    hi[a] = grid.axes[a].max;
    diam = std::max(diam, hi[a] - lo[a]);
    count[a] = static_cast<std::size_t>(std::max(grid.axes[a].n, 1));
    stride[a] = s;
    s *= count[a];
  }
  const std::size_t n = grid.size();
  detail::FirstFailure<N> first;
#pragma omp parallel for schedule(dynamic, 256) if (n >= kPreflightParallelMin)
  for (long long idx = 0; idx < static_cast<long long>(n); ++idx) {
    const auto i = static_cast<std::size_t>(idx);
    if (!first.wanted(i)) continue;
    const std::array<double, N> y = grid.node(i);
    const bool in_y = M::in_support(y.data(), par);
    const double sy = M::guard_surface(g, y.data(), par);
    if (in_y && !std::isfinite(sy)) {
      PreflightFailure<N> f;
      f.error = PreflightError::non_finite_guard;
      f.guard = g;
      f.mode = detail::guard_info<M>(static_cast<std::size_t>(g)).from;
      f.state = y;
      f.value = sy;
      f.node = i;
      first.offer(i, f);
      continue;
    }
    if (in_y && sy == 0.0) {  // the node is on S_g
      PreflightFailure<N> f = detail::check_crossing<M>(g, y, lo, hi, diam, par, opt);
      pass_outside(i, f);
      if (!f.ok()) {
        f.node = i;
        offer(first, i, f);
        continue;
      }
      if (crossings != nullptr) {
#pragma omp critical(hybgen_rt_preflight_crossings)
        crossings->emplace_back(i * N, y);
      }
    }
    if (!std::isfinite(sy) || sy == 0.0) continue;
    for (std::size_t a = 0; a < N; ++a) {
      if ((i / stride[a]) % count[a] + 1 >= count[a]) continue;  // last node on axis a
      std::array<double, N> b = grid.node(i + stride[a]);
      const double sb = M::guard_surface(g, b.data(), par);
      if (!std::isfinite(sb) || sb == 0.0 || (sb < 0.0) == (sy < 0.0)) continue;
      // Bisection on the edge [y, b] along axis a: s(lo_) has the sign of sy.
      double l = y[a], r = b[a];
      std::array<double, N> x = y;
      for (int it = 0; it < 200; ++it) {
        const double mid = 0.5 * (l + r);
        if (mid <= l || mid >= r) break;
        x[a] = mid;
        const double sm = M::guard_surface(g, x.data(), par);
        if (sm == 0.0) {
          l = r = mid;
          break;
        }
        if ((sm < 0.0) == (sy < 0.0))
          l = mid;
        else
          r = mid;
      }
      // The end with the smaller |s| (both ends bracket the root to rounding).
      x[a] = l;
      const double sl = std::fabs(M::guard_surface(g, x.data(), par));
      x[a] = r;
      if (!(std::fabs(M::guard_surface(g, x.data(), par)) <= sl)) x[a] = l;
      if (!M::in_support(x.data(), par)) continue;
      PreflightFailure<N> f = detail::check_crossing<M>(g, x, lo, hi, diam, par, opt);
      pass_outside(i, f);
      if (!f.ok()) {
        f.node = i;
        offer(first, i, f);
        if (f.error != PreflightError::reset_retriggers &&
            f.error != PreflightError::guards_overlap)
          break;
        continue;
      }
      if (crossings != nullptr) {
#pragma omp critical(hybgen_rt_preflight_crossings)
        crossings->emplace_back(i * N + a, x);
      }
    }
  }
  if (notes != nullptr && !outside.failure.ok()) notes->push_back(outside.failure);
  if (retriggers.empty()) return first.failure;
  std::sort(retriggers.begin(), retriggers.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });  // thread order
  double h = 0.0;
  for (std::size_t a = 0; a < N; ++a)
    if (count[a] > 1) h = std::max(h, (hi[a] - lo[a]) / static_cast<double>(count[a] - 1));
  const PreflightFailure<N>& r0 = retriggers.front().second;
  bool isolated = true;
  for (const auto& [i, f] : retriggers) {
    double d = 0.0;
    for (std::size_t a = 0; a < N; ++a) d = std::max(d, std::fabs(f.state[a] - r0.state[a]));
    // (In 1-D a guard is a point: two guards firing there overlap on the whole guard.)
    isolated = isolated && d <= kIsolatedCells * h &&
               (N >= 2 || f.error != PreflightError::guards_overlap);
  }
  if (!isolated) {
    if (first.wanted(retriggers.front().first)) return r0;
    return first.failure;
  }
  if (notes != nullptr) notes->push_back(r0);
  return first.failure;
}

/// Pre-images of a guard g with a numeric inverse, counted by multi-start Newton: among the
/// crossing points of S_g found by `check_guard` (in the support, where g fires), take up to
/// opt.preimage_points evenly spaced ones p_i; for each image y_i = Δ_g(p_i), start Newton on
/// Δ_g(z) = y_i from every p_j. The distinct converged z (farther apart than 1e-6·diam) that
/// lie on S_g (|s_g| ≤ surface_tol·|∇s_g|·diam), in the support, where g fires, are the
/// pre-images of y_i found.
///
/// One everywhere: the reset is injective on its guard as far as the search sees; nothing to
/// do. Two or more somewhere (a fold): with `seeds` null the failure `several_preimages`
/// names a second one; otherwise the p_i become the tracer's seeds (*seeds, N doubles each,
/// CharacteristicsOptions::preimage_seeds), from which it enumerates every pre-image at each
/// crossing, after a COUNT CHECK: at every y_i, starts from up to opt.preimage_check_points
/// crossing points must find no more pre-images than the seeds do (else `preimages_missed`,
/// naming y_i and the pre-image the seeds miss). This is a search with a check, not a proof:
/// pre-images that no crossing point leads Newton to are not seen.
template <HybridModel M>
PreflightFailure<state_dim_v<M>> check_preimages(
    int g, std::vector<std::pair<std::size_t, std::array<double, state_dim_v<M>>>> crossings,
    double diam, const double* par, const PreflightOptions& opt,
    std::vector<double>* seeds = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  using State = std::array<double, N>;
  PreflightFailure<N> f;
  const GuardInfo gi = detail::guard_info<M>(static_cast<std::size_t>(g));
  if (gi.has_inverse || crossings.size() < 2) return f;
  std::sort(crossings.begin(), crossings.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });  // thread order
  auto spread = [&crossings](int count) {
    std::vector<State> pts;
    const std::size_t want =
        std::min(static_cast<std::size_t>(std::max(2, count)), crossings.size());
    for (std::size_t k = 0; k < want; ++k)
      pts.push_back(crossings[k * crossings.size() / want].second);
    return pts;
  };
  const std::vector<State> pts = spread(opt.preimage_points);
  auto fires = [&](const State& z) {
    State grad{}, X{};
    M::guard_gradient(g, z.data(), par, grad.data());
    M::flow(gi.from, z.data(), par, X.data());
    const double gn = std::sqrt(detail::dot<N>(grad.data(), grad.data()));
    return M::in_support(z.data(), par) &&
           detail::dot<N>(grad.data(), X.data()) * gi.direction > 0.0 &&
           std::fabs(M::guard_surface(g, z.data(), par)) <= opt.surface_tol * gn * diam;
  };
  // Whether z is one of `found` (closer than 1e-6·diam in the max norm).
  auto among = [diam](const std::vector<State>& found, const State& z) {
    for (const State& q : found) {
      double dist = 0.0;
      for (std::size_t a = 0; a < N; ++a) dist = std::max(dist, std::fabs(z[a] - q[a]));
      if (dist <= 1e-6 * diam) return true;
    }
    return false;
  };
  // The distinct pre-images of y found from `starts`.
  auto preimages = [&](const State& y, const std::vector<State>& starts) {
    std::vector<State> found;
    for (const State& start : starts) {
      State z{};
      if (detail::newton_reset_solve<M>(g, y.data(), start.data(), par, opt.newton_max_iter,
                                        opt.newton_tol, z) &&
          fires(z) && !among(found, z))
        found.push_back(z);
    }
    return found;
  };
  std::vector<std::vector<State>> found(pts.size());
  bool several = false;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    State y{};
    M::reset(g, pts[i].data(), par, y.data());
    found[i] = preimages(y, pts);
    if (found[i].size() < 2) continue;
    several = true;
    if (seeds == nullptr) {
      f.error = PreflightError::several_preimages;
      f.guard = g;
      f.mode = gi.from;
      f.state = found[i][0];
      f.image = y;
      f.other = found[i][1];
      return f;
    }
  }
  if (!several || seeds == nullptr) return f;
  // The count check: a wider multi-start must not find more.
  const std::vector<State> wide = spread(opt.preimage_check_points);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    State y{};
    M::reset(g, pts[i].data(), par, y.data());
    const std::vector<State> more = preimages(y, wide);
    if (more.size() <= found[i].size()) continue;
    f.error = PreflightError::preimages_missed;
    f.guard = g;
    f.mode = gi.from;
    f.state = pts[i];
    f.image = y;
    for (const State& z : more)  // one the seeds did not find
      if (!among(found[i], z)) f.other = z;
    return f;
  }
  seeds->clear();
  for (const State& p : pts) seeds->insert(seeds->end(), p.begin(), p.end());
  return f;
}

/// The whole pre-flight scan: the initial density, then every guard in order. Returns the
/// first failure (ok() if none).
/// With `seeds` (the characteristics method), a guard whose reset has several pre-images
/// gets the tracer's seeds in (*seeds)[g] (`check_preimages`; empty for the others);
/// without, it is the failure `several_preimages`.
/// Re-triggers at isolated points, and each guard's first reset out of the box, are appended
/// to `notes` (see `check_guard`).
template <HybridModel M>
PreflightFailure<state_dim_v<M>> preflight(
    const TensorGrid<state_dim_v<M>>& grid, const double* par, const PreflightOptions& opt = {},
    std::vector<std::vector<double>>* seeds = nullptr,
    std::vector<PreflightFailure<state_dim_v<M>>>* notes = nullptr) {
  PreflightFailure<state_dim_v<M>> f = check_initial_density<M>(grid, par);
  double diam = 0.0;
  for (const GridAxis& a : grid.axes) diam = std::max(diam, a.max - a.min);
  if (seeds != nullptr) seeds->assign(static_cast<std::size_t>(M::n_guard), {});
  for (int g = 0; g < M::n_guard && f.ok(); ++g) {
    const bool count =
        opt.backward && !detail::guard_info<M>(static_cast<std::size_t>(g)).has_inverse;
    std::vector<std::pair<std::size_t, std::array<double, state_dim_v<M>>>> crossings;
    f = check_guard<M>(g, grid, par, opt, count ? &crossings : nullptr, notes);
    if (f.ok() && count)
      f = check_preimages<M>(g, std::move(crossings), diam, par, opt,
                             seeds != nullptr ? &(*seeds)[static_cast<std::size_t>(g)] : nullptr);
  }
  return f;
}

/// One-line description of a pre-flight failure for an error message (exit code 3), or of a
/// note for a warning, e.g. "pre-flight scan of guard 'ground' at t = 0: the reset lands
/// outside the support (the state space) at the point (x = 0, p = -2) of its surface in mode
/// 'flight': Delta = (x = -0.5, p = 2)".
template <HybridModel M>
std::string describe_preflight(const PreflightFailure<state_dim_v<M>>& f) {
  constexpr std::size_t N = state_dim_v<M>;
  std::ostringstream os;
  os << std::setprecision(17);
  auto point = [&os](const std::array<double, N>& x) { write_state<M>(os, x); };
  if (f.guard < 0) {
    os << "pre-flight scan of the initial density at t = 0: " << preflight_error_name(f.error)
       << " u0 = " << f.value << " at the grid node ";
    point(f.state);
    os << " in mode '" << mode_name<M>(f.mode) << "'";
    return os.str();
  }
  os << "pre-flight scan of guard '" << guard_name<M>(f.guard)
     << "' at t = 0: " << preflight_error_name(f.error);
  os << (f.error == PreflightError::non_finite_guard ? " at the grid node " : " at the point ");
  point(f.state);
  os << " of its surface in mode '" << mode_name<M>(f.mode) << "'";
  switch (f.error) {
    case PreflightError::non_finite_guard:
      os << ": s = " << f.value;
      break;
    case PreflightError::grazing:
      os << ": |grad s . X| / (|grad s| |X|) = " << f.value
         << ", and the orbit crosses the surface there";
      break;
    case PreflightError::zero_jacobian:
      os << ": J = " << f.value + 0.0;  // + 0.0: print -0 as 0
      break;
    case PreflightError::non_finite_reset:
    case PreflightError::reset_outside_support:
    case PreflightError::reset_outside_box:
    case PreflightError::inverse_failed:
      os << ": Delta = ";
      point(f.image);
      break;
    case PreflightError::several_preimages:
      os << ": Delta = ";
      point(f.image);
      os << " is also the image of ";
      point(f.other);
      os << " (a caller that cannot sum over pre-images; the characteristics method enumerates "
            "them)";
      break;
    case PreflightError::preimages_missed:
      os << ": Delta = ";
      point(f.image);
      os << " has the pre-image ";
      point(f.other);
      os << ", which a multi-start from " << PreflightOptions{}.preimage_points
         << " points of the guard misses, so the characteristics method cannot sum over all "
            "pre-images; use method="
         << forward_methods() << " (they push mass forward and need no inverse)";
      break;
    case PreflightError::guards_overlap:
      os << ": guard '" << guard_name<M>(f.other_guard)
         << "' fires there too, so the model does not say which reset applies there (each "
            "would carry the whole flux)";
      break;
    case PreflightError::reset_retriggers: {
      const auto to = detail::guard_info<M>(static_cast<std::size_t>(f.guard)).to;
      os << ": Delta = ";
      point(f.image);
      os << " is on guard '" << guard_name<M>(f.other_guard) << "' of mode '" << mode_name<M>(to)
         << "', which fires there at once";
      break;
    }
    default:
      break;
  }
  return os.str();
}

}  // namespace hybgen::rt
