#pragma once
/// \file forward.hpp
/// The FORWARD hybrid flow φ_t of a `HybridModel`: from (mode m, x) at time 0, integrate
/// dx/dt = X_m(x) with Dormand–Prince 5(4) (ode.hpp, dense output), locate the crossings of
/// the guards g with guards[g].from = m in their firing direction (guards[g].direction,
/// `EventLocator`), apply x ← Δ_g(x), m ← guards[g].to, and continue from the event time.
///
/// Conventions (the same as the backward tracer of characteristics.hpp):
///  * Trajectories are right-continuous: at an event time t_e the state is the reset image
///    Δ_g(x(t_e⁻)); an output time equal to t_e gets the post-reset state.
///  * The located event state x(t_e⁻) (exact to the root's rounding) is first projected onto
///    S_g (two Newton steps along ∇s_g), so a support bounded by S_g (x ≥ 0 for the ball)
///    contains it and its reset image exactly.
///  * No re-triggering: after a reset, a root of any event within the start window
///    [t_e, t_e + δ] (δ = ode.event_rearm·max(|t_e|, t_end)) is not a crossing (ode.hpp).
///  * At the START of the flow (time 0 only), a point on S_g moving to the firing side (the
///    sign of s_g just after the start equals guards[g].direction) fires g at once: a ball at
///    (0, p < 0) bounces at t = 0. Grid nodes on a guard surface rely on this.
///  * A state at rest: if a reset of g (to = from) maps the state to itself (to rounding) and g
///    fires again at once (as at the start of the flow), the flow ends with `zeno` there — the
///    ball's Zeno point (0, 0), e.g. when a flow is restarted from a Zeno state.
///  * An absorbing guard (model.hpp, `absorbs`) ends the flow where it fires: `absorbed`, at
///    the located (projected) point of its surface, with the guard and the time.
///  * `in_support` is checked at step ends (as in the tracer): the first step end outside it
///    stops the flow with `left_support` at that time; outputs inside that step are delivered.
///    A guard crossed outside it (tested just off the surface, on the side the flow comes
///    from: `detail::crossing_in_support`) stops the flow the same way, at the crossing, without
///    its reset.
///  * Grazing: a crossing where the flow is tangent to the guard and the orbit crosses it (the
///    pre-flight's criterion, `detail::grazing` of core/geometry.hpp, with δ = 1e-3·t_end)
///    ends the flow `failed` with TraceError::grazing at the crossing (state, time, guard).
///    The ball's Zeno bounces pass: at |p| ≤ graze_tol·g the orbit does not cross x = 0 over
///    ±δ (it would need δ < 2|p|/g).
///
/// Zeno versus chattering. Let t_1 < t_2 < … be the event times and x_j the (projected)
/// pre-reset event states, d_j = t_j − t_{j−1} the gaps and r_j = d_j/d_{j−1} their ratios.
/// A Zeno accumulation has geometrically shrinking gaps, r_j → r < 1, and converging states;
/// the accumulation time and state are then t_Z = t_n + d_n r/(1 − r) (the geometric tail
/// Σ_{i≥1} d_n rⁱ) and x_Z = x_n + (x_n − x_{n−1}) ρ/(1 − ρ), ρ = ‖x_n − x_{n−1}‖/‖x_{n−1} −
/// x_{n−2}‖ (Aitken; exact for geometric sequences, e.g. the ball). The SIGNATURE, tested
/// after every event on the last `kZenoGaps` gaps: all gaps > 0; all ratios ≤ `zeno_ratio`;
/// their spread max r − min r ≤ 0.1·(1 − max r) (a settled ratio, not a slow drift); state
/// increments non-increasing. Zeno is declared when the signature holds and the last gap is
/// ≤ zeno_time·t_end (deep in the accumulation, far above the re-arm window δ, so no event
/// has yet been lost), or when the event cap is hit with the signature and t_Z ≤ t_end. A cap
/// hit without it (e.g. constant gaps: chattering, sliding) is `event_cap`, an error. Zeno is
/// not an error: the trajectory has come to rest at x_Z, which is an atom of the pushed-
/// forward measure from t_Z on. Output times in [t_n, t_Z) get x_Z (their distance from it is
/// at most the motion during the remaining ≤ zeno_time·t_end·r/(1 − r)); if t_Z > t_end the
/// flow ends `ok` at x_Z for the same reason.
///
/// Limitations: the signature uses consecutive gaps (period 1). A Zeno cycle through several
/// guards with different gap ratios per guard (period ≥ 2) is reported as `event_cap`. Gaps
/// shrinking so fast that a flight is shorter than δ before kZenoGaps + 1 events are seen
/// (the ball at t_end = 10: e = 2e-4 works, 1e-4 does not; measured) lose that crossing: the
/// trajectory then leaves the support (`left_support`) instead of ending `zeno`.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/core/ode.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Options of the forward hybrid flow.
struct ForwardOptions {
  OdeOptions ode{};              ///< Tolerances, step control and event sampling of the ODE.
  int max_events = 1000;         ///< Cap on guard crossings per call (see the file doc).
  double zeno_time = 1e-7;       ///< Zeno: declared once the last gap is ≤ zeno_time·t_end.
  double zeno_ratio = 0.999;     ///< Zeno: largest admissible ratio of consecutive gaps.
  double graze_tol = kGrazeTol;  ///< Grazing test at crossings (`detail::grazing`).
};

/// How a forward flow ended.
enum class ForwardStatus {
  ok,            ///< Reached the final time.
  left_support,  ///< Left `M::in_support` (at a step end, t_stop).
  zeno,          ///< Came to rest at a Zeno accumulation point (x) at time t_stop.
  absorbed,      ///< Reached an absorbing guard (`guard`) at t_stop, at x (model.hpp, absorbs).
  event_cap,     ///< More than `max_events` guard crossings without the Zeno signature.
  failed,        ///< Numerical failure (non-finite value, ODE step limit/underflow).
};

/// Human-readable name of a `ForwardStatus`.
inline const char* forward_status_name(ForwardStatus s) {
  switch (s) {
    case ForwardStatus::ok:
      return "ok";
    case ForwardStatus::left_support:
      return "left the support";
    case ForwardStatus::zeno:
      return "Zeno accumulation";
    case ForwardStatus::absorbed:
      return "absorbed by a guard";
    case ForwardStatus::event_cap:
      return "too many guard crossings without Zeno signature (max_events; chattering?)";
    case ForwardStatus::failed:
      return "numerical failure";
  }
  return "?";
}

/// Outcome of a forward flow.
template <std::size_t N>
struct ForwardResult {
  ForwardStatus status = ForwardStatus::ok;  ///< How it ended.
  int mode = -1;                             ///< Mode at t_stop.
  /// State at t_stop: the final state (ok), the first state outside the support
  /// (left_support), the accumulation state (zeno), the point of the absorbing guard's surface
  /// (absorbed), the event state before the reset that exceeded the cap (event_cap), the last
  /// good state (failed).
  std::array<double, N> x{};
  double t_stop = 0.0;                  ///< Final time, or when the flow stopped (t_Z for zeno).
  int events = 0;                       ///< Guard crossings located.
  TraceError error = TraceError::none;  ///< For event_cap and failed: what.
  int guard = -1;                       ///< Guard of the last crossing (or of the failure), −1.
  double value = 0.0;  ///< For a grazing failure: |∇s·X|/(|∇s||X|) at x; else 0.
  /// Whether the flow reached the final time.
  bool ok() const { return status == ForwardStatus::ok; }
};

/// Per-thread workspace integrating the forward hybrid flow of M. No heap allocation.
template <HybridModel M>
class ForwardFlow {
 public:
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  /// Guards (≥ 1 for array sizes; model.hpp).
  static constexpr std::size_t kGuards = guard_capacity_v<M>;
  static constexpr std::size_t kZenoGaps = 3;             ///< Gaps in the Zeno signature.
  static constexpr std::size_t kHistory = kZenoGaps + 1;  ///< Event times/states kept.
  using State = std::array<double, N>;                    ///< A state.

  /// A workspace for parameters `par` (kept by pointer) and options `opt` (copied).
  ForwardFlow(const double* par, const ForwardOptions& opt) : par_(par), opt_(opt), ode_(opt.ode) {}

  /// Flow (mode, x) from time 0 through the sorted output times `times` (finite, ≥ 0; one
  /// trajectory for all); on_output(std::size_t k, int mode, const State& x) is called, in
  /// order of k, for every output time before the flow stopped (t_k ≤ t_stop for `ok`,
  /// t_k < t_stop otherwise; see the file doc for Zeno). `times` is assumed valid.
  template <class OnOutput>
  ForwardResult<N> run(int mode, const State& x0, std::span<const double> times,
                       OnOutput&& on_output) {
    return run(mode, x0, times, std::forward<OnOutput>(on_output),
               [](double, int, const State&, const State&) {});
  }

  /// As above; on_reset(double t, int g, const State& before, const State& after) is also
  /// called at every reset the flow applies, in time order: guard g fired at time t, at the
  /// located (projected) state `before`, and the flow continues from Δ_g(before) = `after`
  /// (budget/atom.hpp counts the resets that carry mass across the grid box's boundary).
  template <class OnOutput, class OnReset>
  ForwardResult<N> run(int mode, const State& x0, std::span<const double> times,
                       OnOutput&& on_output, OnReset&& on_reset) {
    ForwardResult<N> res;
    res.mode = mode;
    res.x = x0;
    nhist_ = 0;
    events_ = 0;
    bad_guard_ = -1;
    const std::size_t K = times.size();
    if (K == 0) return res;
    const double t_end = times[K - 1];
    if (!M::in_support(x0.data(), par_)) {
      res.status = ForwardStatus::left_support;
      return res;
    }
    std::size_t k = 0;
    double t0 = 0.0, h0 = 0.0;
    State y = x0;
    int m = mode;
    bool initial = true;
    int fixed_guard = -1;  // guard whose reset just mapped the state to itself (to == from)
    for (;;) {
      res.mode = m;
      res.events = events_;
      if (t0 >= t_end) {  // an event at t_end: the rest is the post-reset state
        for (; k < K; ++k) on_output(k, m, y);
        res.x = y;
        res.t_stop = t_end;
        return res;
      }
      setup_events(m);
      auto rhs = [this, m](double, const State& x, State& dx) {
        M::flow(m, x.data(), par_, dx.data());
      };
      auto gfun = [this](int e, const State& x) {
        const int g = guard_[static_cast<std::size_t>(e)];
        const double v = M::guard_surface(g, x.data(), par_);
        if (!std::isfinite(v) && bad_guard_ < 0) bad_guard_ = g;
        return v;
      };
      OdeStatus st = ode_.start(rhs, t0, y, t_end, h0);
      if (st != OdeStatus::ok) return fail_ode(res, st, y, t0);
      bool first = true, event = false;
      EventRoot root{};
      State xe{};
      auto on_root = [&](const EventRoot& r, const State& x) {
        root = r;
        xe = x;
        return true;
      };
      for (;;) {
        st = ode_.step(rhs);
        if (st != OdeStatus::ok) return fail_ode(res, st, ode_.y(), ode_.t());
        if (first) {
          first = false;
          std::array<bool, kGuards> at_start{};
          loc_.arm(ode_, gfun, nullptr, at_start.data());
          if (initial) event = fire_at_start(at_start, gfun, root, xe, -1);
          if (!initial && fixed_guard >= 0 &&
              fire_at_start(at_start, gfun, root, xe, fixed_guard)) {
            // At rest: the state is a fixed point of Δ_g on S_g and g fires again at once.
            res.status = ForwardStatus::zeno;
            res.x = ode_.y_prev();
            res.t_stop = t0;
            return res;
          }
        }
        if (!event) {
          double t_stop = 0.0;
          event = loc_.scan(ode_, gfun, on_root, t_stop);
        }
        if (bad_guard_ >= 0) {
          res.status = ForwardStatus::failed;
          res.error = TraceError::non_finite_flow;
          res.guard = bad_guard_;
          res.x = ode_.y_prev();
          res.t_stop = ode_.t_prev();
          return res;
        }
        const double t_hi = event ? root.t : ode_.t();
        while (k < K && (event ? times[k] < t_hi : times[k] <= t_hi)) {
          State xk;
          ode_.dense(std::max(times[k], ode_.t_prev()), xk);
          on_output(k, m, xk);
          ++k;
        }
        if (event) break;
        if (!M::in_support(ode_.y().data(), par_)) {
          res.status = ForwardStatus::left_support;
          res.x = ode_.y();
          res.t_stop = ode_.t();
          return res;
        }
        if (ode_.done()) {
          res.x = ode_.y();
          res.t_stop = t_end;
          return res;
        }
      }
      // A crossing of guard g at root.t from xe (pre-reset).
      const int g = guard_[static_cast<std::size_t>(root.event)];
      const GuardInfo gi = detail::guard_info<M>(static_cast<std::size_t>(g));
      project(g, xe);
      // A crossing outside the state space: the trajectory left the support inside this step,
      // before it met the guard (the support is checked at step ends), and its mass left with
      // it: no reset, no trap. (The density-level campaign's random model 3675: a trap beyond
      // the support's edge, x ≤ 1.2 against the trap at x = 1.242, took the mass that had left
      // through the edge, 0.028 in the budget's forward flows.)
      if (!detail::crossing_in_support<M>(g, m, xe, par_)) {
        res.status = ForwardStatus::left_support;
        res.x = xe;
        res.t_stop = root.t;
        return res;
      }
      ++events_;
      res.events = events_;
      res.guard = g;
      // The guard fires at a tangency (the pre-flight's criterion, `detail::grazing`).
      const double ratio = detail::grazing<M>(
          g, m, xe, par_, opt_.graze_tol, [t_end](double) { return detail::graze_delta(t_end); });
      if (ratio >= 0.0) {
        res.status = ForwardStatus::failed;
        res.error = TraceError::grazing;
        res.x = xe;
        res.t_stop = root.t;
        res.value = ratio;
        return res;
      }
      if (absorbs(gi)) {  // the trajectory ends on the guard's surface; its mass leaves
        res.status = ForwardStatus::absorbed;
        res.mode = m;
        res.x = xe;
        res.t_stop = root.t;
        return res;
      }
      push_history(root.t, xe);
      const bool capped = events_ > opt_.max_events;
      double tz = 0.0;
      State xz{};
      if (zeno(capped, t_end, tz, xz) && (!capped || tz <= t_end)) {
        for (; k < K && times[k] < tz; ++k) on_output(k, gi.to, xz);
        res.mode = gi.to;
        res.x = xz;
        res.status = tz <= t_end ? ForwardStatus::zeno : ForwardStatus::ok;
        res.t_stop = tz <= t_end ? tz : t_end;
        return res;
      }
      if (capped) {
        res.status = ForwardStatus::event_cap;
        res.error = TraceError::event_cap;
        res.x = xe;
        res.t_stop = root.t;
        return res;
      }
      M::reset(g, xe.data(), par_, y.data());
      if (!detail::all_finite(y)) {
        res.status = ForwardStatus::failed;
        res.error = TraceError::non_finite_reset;
        res.x = xe;
        res.t_stop = root.t;
        return res;
      }
      on_reset(root.t, g, static_cast<const State&>(xe), static_cast<const State&>(y));
      double xn = 0.0;
      for (double v : xe) xn = std::max(xn, std::fabs(v));
      fixed_guard = gi.to == gi.from && dist(y, xe) <= 1e-14 * (1.0 + xn) ? g : -1;
      m = gi.to;
      t0 = root.t;
      h0 = ode_.h_next();
      initial = false;
    }
  }

  /// The state at time t ≥ 0 (no intermediate outputs).
  ForwardResult<N> run(int mode, const State& x0, double t) {
    const std::array<double, 1> times{t};
    return run(mode, x0, std::span<const double>(times), [](std::size_t, int, const State&) {});
  }

 private:
  ForwardResult<N>& fail_ode(ForwardResult<N>& res, OdeStatus st, const State& x, double t) {
    res.status = ForwardStatus::failed;
    res.error = st == OdeStatus::step_limit       ? TraceError::step_limit
                : st == OdeStatus::step_underflow ? TraceError::step_underflow
                                                  : TraceError::non_finite_flow;
    res.x = x;
    res.t_stop = t;
    res.guard = -1;
    return res;
  }

  void setup_events(int mode) {
    std::array<int, kGuards> dirs{};
    int n = 0;
    for (std::size_t g = 0; g < static_cast<std::size_t>(M::n_guard); ++g) {
      const GuardInfo gi = detail::guard_info<M>(g);
      if (gi.from != mode) continue;
      guard_[static_cast<std::size_t>(n)] = static_cast<int>(g);
      dirs[static_cast<std::size_t>(n)] = gi.direction;
      ++n;
    }
    loc_.configure(n, dirs.data());
  }

  /// At the start of the flow: the first event (of guard `only`, if ≥ 0) with a root in the
  /// start window whose sign just after it is the firing direction fires at t₀ (from the
  /// start state).
  template <class G>
  bool fire_at_start(const std::array<bool, kGuards>& at_start, G& gfun, EventRoot& root, State& xe,
                     int only) {
    const double t0 = ode_.t_prev(), h = ode_.h_last();
    const double scale = std::max(std::fabs(t0), std::fabs(ode_.t_end()));
    const double delta = std::min(ode_.options().event_rearm * scale, 0.5 * h);
    State xd;
    ode_.dense_theta(delta / h, xd);
    for (int e = 0; e < loc_.size(); ++e) {
      const auto ei = static_cast<std::size_t>(e);
      if (!at_start[ei]) continue;
      const int g = guard_[ei];
      if (only >= 0 && g != only) continue;
      const int dir = detail::guard_info<M>(static_cast<std::size_t>(g)).direction;
      if (detail::sign_of(gfun(e, xd)) != dir) continue;
      root = EventRoot{e, t0, dir};
      xe = ode_.y_prev();
      return true;
    }
    return false;
  }

  /// Two Newton steps onto S_g along ∇s_g (see the file doc).
  void project(int g, State& z) const {
    State grad;
    for (int it = 0; it < 2; ++it) {
      M::guard_gradient(g, z.data(), par_, grad.data());
      const double gg = detail::dot<N>(grad.data(), grad.data());
      const double s = M::guard_surface(g, z.data(), par_);
      if (!(gg > 0.0) || !std::isfinite(gg) || !std::isfinite(s) || s == 0.0) break;
      for (std::size_t i = 0; i < N; ++i) z[i] -= s * grad[i] / gg;
    }
  }

  void push_history(double t, const State& x) {
    if (nhist_ == kHistory) {
      for (std::size_t i = 1; i < kHistory; ++i) {
        th_[i - 1] = th_[i];
        xh_[i - 1] = xh_[i];
      }
      --nhist_;
    }
    th_[nhist_] = t;
    xh_[nhist_] = x;
    ++nhist_;
  }

  static double dist(const State& a, const State& b) {
    double d = 0.0;
    for (std::size_t i = 0; i < N; ++i) d = std::max(d, std::fabs(a[i] - b[i]));
    return d;
  }

  /// The Zeno signature on the event history (file doc); on success t_Z and x_Z.
  bool zeno(bool capped, double t_end, double& tz, State& xz) const {
    if (nhist_ < kHistory) return false;
    std::array<double, kZenoGaps> d{}, dx{};
    for (std::size_t j = 0; j < kZenoGaps; ++j) {
      d[j] = th_[j + 1] - th_[j];
      dx[j] = dist(xh_[j + 1], xh_[j]);
      if (!(d[j] > 0.0)) return false;
    }
    double rmax = 0.0, rmin = std::numeric_limits<double>::infinity();
    for (std::size_t j = 1; j < kZenoGaps; ++j) {
      const double r = d[j] / d[j - 1];
      rmax = std::max(rmax, r);
      rmin = std::min(rmin, r);
      if (!(dx[j] <= dx[j - 1] * (1.0 + 1e-9))) return false;
    }
    if (!(rmax <= opt_.zeno_ratio) || !(rmax - rmin <= 0.1 * (1.0 - rmax))) return false;
    const double dn = d[kZenoGaps - 1];
    if (!capped && !(dn <= opt_.zeno_time * std::fabs(t_end))) return false;
    const double r = dn / d[kZenoGaps - 2];
    tz = th_[kHistory - 1] + dn * r / (1.0 - r);
    const State& xn = xh_[kHistory - 1];
    const State& xp = xh_[kHistory - 2];
    const double dprev = dx[kZenoGaps - 2];
    const double rho = dprev > 0.0 ? dx[kZenoGaps - 1] / dprev : 0.0;
    for (std::size_t i = 0; i < N; ++i)
      xz[i] = rho < 1.0 ? xn[i] + (xn[i] - xp[i]) * rho / (1.0 - rho) : xn[i];
    if (!detail::all_finite(xz)) xz = xn;
    return std::isfinite(tz);
  }

  const double* par_;
  ForwardOptions opt_;
  Dopri5<N> ode_;
  EventLocator<N, kGuards> loc_;
  std::array<int, kGuards> guard_{};
  int events_ = 0;
  int bad_guard_ = -1;
  std::array<double, kHistory> th_{};
  std::array<State, kHistory> xh_{};
  std::size_t nhist_ = 0;
};

/// The forward hybrid flow φ_t(mode, x) at time t ≥ 0 (see the file doc).
template <HybridModel M>
ForwardResult<state_dim_v<M>> forward_flow(int mode, const std::array<double, state_dim_v<M>>& x,
                                           double t, const double* par, const ForwardOptions& opt) {
  if (!std::isfinite(t) || t < 0.0)
    throw std::invalid_argument("forward_flow: the time must be finite and >= 0");
  ForwardFlow<M> flow(par, opt);
  return flow.run(mode, x, t);
}

/// The forward hybrid flow of (mode, x) through the sorted output times `times` (finite,
/// ≥ 0), one trajectory for all: on_output(std::size_t k, int mode, const std::array<double,
/// N>& x) for every output time reached (see `ForwardFlow::run`). Returns how it ended.
template <HybridModel M, class OnOutput>
ForwardResult<state_dim_v<M>> forward_flow(int mode, const std::array<double, state_dim_v<M>>& x,
                                           std::span<const double> times, const double* par,
                                           const ForwardOptions& opt, OnOutput&& on_output) {
  detail::validate_times(times);
  ForwardFlow<M> flow(par, opt);
  return flow.run(mode, x, times, on_output);
}

/// One-line description of a forward flow that ended in `event_cap` or `failed` (exit 3).
template <HybridModel M>
std::string describe(const ForwardResult<state_dim_v<M>>& r, int start_mode,
                     const std::array<double, state_dim_v<M>>& start) {
  constexpr std::size_t N = state_dim_v<M>;
  std::ostringstream os;
  os.precision(17);
  auto point = [&os](const std::array<double, N>& x) { write_state<M>(os, x); };
  os << "forward trajectory from ";
  point(start);
  os << " in mode '" << mode_name<M>(start_mode) << "': " << forward_status_name(r.status);
  if (r.error != TraceError::none) os << " (" << trace_error_name(r.error) << ")";
  if (r.guard >= 0 && r.guard < M::n_guard) os << " at guard '" << guard_name<M>(r.guard) << "'";
  os << " at time t = " << r.t_stop << ", state ";
  point(r.x);
  os << ", mode '" << mode_name<M>(r.mode) << "', after " << r.events << " guard crossings";
  if (r.error == TraceError::grazing) detail::describe_grazing(os, r.value);
  return os.str();
}

}  // namespace hybgen::rt
