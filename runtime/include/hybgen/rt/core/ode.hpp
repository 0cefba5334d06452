#pragma once
/// \file ode.hpp
/// Adaptive Dormand–Prince 5(4) integration with dense output and event location.
///
/// The integrator advances y' = f(t, y), y ∈ ℝᴰ (std::array<double, D>), forward in t
/// with the embedded 5(4) pair of Dormand & Prince, FSAL, the PI (Lund-stabilised)
/// step-size controller of Hairer–Nørsett–Wanner (II.4, `dopri5`) and the standard
/// 4th-order continuous extension. Everything is allocation-free and templated: the
/// right-hand side and event functions are plain callables, never std::function.
///
/// Event location (`EventLocator`): for scalar event functions g_k(y), each accepted step
/// is sampled at `event_samples` equally spaced points of its dense output, so two roots
/// inside one step are found as long as they are further apart than h/event_samples. A
/// sign change is refined by Brent's method on θ ↦ g_k(dense(θ)) to machine precision in
/// θ (|Δt| ≲ 1e-16·h). Each event may require a crossing direction. Right after a (re)start
/// at t₀ (the starting point of an integration, typically a reset image), an event's
/// reference sign is taken at t₀ + δ, δ = event_rearm·max(|t₀|, |t_end|) (clamped to half
/// the first step): a root in [t₀, t₀ + δ] is never reported as a crossing — it is flagged
/// as "at the start" for the caller to decide — so an event cannot re-trigger at its own
/// starting point; the caller may in addition prescribe the side the trajectory must leave to.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>

namespace hybgen::rt {

/// Options of the Dormand–Prince 5(4) integrator and of its event location.
struct OdeOptions {
  double rtol = 1e-10;         ///< Relative tolerance (mixed error test atol + rtol·|y|).
  double atol = 1e-12;         ///< Absolute tolerance.
  double h_init = 0.0;         ///< First step size; 0 picks one automatically (Hairer's hinit).
  double h_max = 0.0;          ///< Largest step size; 0 means only the span limits it.
  long max_steps = 200000;     ///< Attempted steps allowed between `start` and the end.
  double safety = 0.9;         ///< Safety factor of the step-size controller.
  double fac_min = 0.2;        ///< Smallest step-size ratio h_new/h.
  double fac_max = 10.0;       ///< Largest step-size ratio h_new/h.
  double beta = 0.04;          ///< PI (Lund) stabilisation exponent; 0 gives the I controller.
  int event_samples = 8;       ///< Sign checks of every event inside each accepted step (≥ 1).
  double event_rearm = 1e-12;  ///< Start window δ relative to max(|t₀|, |t_end|) (see file doc).
};

/// Outcome of a step or of an integration.
enum class OdeStatus {
  ok,              ///< Success.
  step_limit,      ///< `max_steps` exceeded.
  step_underflow,  ///< The step size fell below the resolution of t.
  non_finite,      ///< f returned NaN/Inf at an accepted state, or every retry did.
};

/// Name of an `OdeStatus` for messages.
inline const char* ode_status_name(OdeStatus s) {
  switch (s) {
    case OdeStatus::ok:
      return "ok";
    case OdeStatus::step_limit:
      return "step limit exceeded";
    case OdeStatus::step_underflow:
      return "step size underflow";
    case OdeStatus::non_finite:
      return "non-finite value in the vector field";
  }
  return "?";
}

namespace detail {

/// Dormand–Prince 5(4) tableau (Hairer–Nørsett–Wanner, Table II.5.2) and the dense
/// output coefficients d_i of `dopri5`'s continuous extension.
struct Dp5 {
  static constexpr double c2 = 1.0 / 5.0, c3 = 3.0 / 10.0, c4 = 4.0 / 5.0, c5 = 8.0 / 9.0;
  static constexpr double a21 = 1.0 / 5.0;
  static constexpr double a31 = 3.0 / 40.0, a32 = 9.0 / 40.0;
  static constexpr double a41 = 44.0 / 45.0, a42 = -56.0 / 15.0, a43 = 32.0 / 9.0;
  static constexpr double a51 = 19372.0 / 6561.0, a52 = -25360.0 / 2187.0, a53 = 64448.0 / 6561.0,
                          a54 = -212.0 / 729.0;
  static constexpr double a61 = 9017.0 / 3168.0, a62 = -355.0 / 33.0, a63 = 46732.0 / 5247.0,
                          a64 = 49.0 / 176.0, a65 = -5103.0 / 18656.0;
  static constexpr double a71 = 35.0 / 384.0, a73 = 500.0 / 1113.0, a74 = 125.0 / 192.0,
                          a75 = -2187.0 / 6784.0, a76 = 11.0 / 84.0;
  // Error weights e_i = b_i − b̂_i.
  static constexpr double e1 = 71.0 / 57600.0, e3 = -71.0 / 16695.0, e4 = 71.0 / 1920.0,
                          e5 = -17253.0 / 339200.0, e6 = 22.0 / 525.0, e7 = -1.0 / 40.0;
  // Dense output.
  static constexpr double d1 = -12715105075.0 / 11282082432.0, d3 = 87487479700.0 / 32700410799.0,
                          d4 = -10690763975.0 / 1880347072.0, d5 = 701980252875.0 / 199316789632.0,
                          d6 = -1453857185.0 / 822651844.0, d7 = 69997945.0 / 29380423.0;
};

/// sign(v) ∈ {−1, 0, +1}; NaN counts as 0 (no information).
inline int sign_of(double v) {
  return v > 0.0 ? 1 : (v < 0.0 ? -1 : 0);
}

/// Whether every entry is finite.
template <std::size_t D>
inline bool all_finite(const std::array<double, D>& v) {
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

}  // namespace detail

/// Brent's root finder (Forsythe–Malcolm–Moler `zeroin`) on a bracket [a, b] with
/// f(a)·f(b) ≤ 0, given fa = f(a), fb = f(b). Returns b with |b − root| ≤ 2ε|b| + tol/2.
template <class F>
double brent_root(F&& f, double a, double b, double fa, double fb, double tol) {
  constexpr double eps = std::numeric_limits<double>::epsilon();
  if (fa == 0.0) return a;
  if (fb == 0.0) return b;
  double c = a, fc = fa, d = b - a, e = d;
  for (int it = 0; it < 400; ++it) {
    // Invariant: the root lies between b and c; b is the best estimate.
    if ((fb > 0.0 && fc > 0.0) || (fb < 0.0 && fc < 0.0)) {
      c = a;
      fc = fa;
      d = b - a;
      e = d;
    }
    if (std::fabs(fc) < std::fabs(fb)) {
      a = b;
      b = c;
      c = a;
      fa = fb;
      fb = fc;
      fc = fa;
    }
    const double tol1 = 2.0 * eps * std::fabs(b) + 0.5 * tol;
    const double xm = 0.5 * (c - b);
    if (std::fabs(xm) <= tol1 || fb == 0.0) return b;
    if (std::fabs(e) >= tol1 && std::fabs(fa) > std::fabs(fb)) {
      // Inverse quadratic interpolation (secant when a == c).
      const double s = fb / fa;
      double p, q;
      if (a == c) {
        p = 2.0 * xm * s;
        q = 1.0 - s;
      } else {
        const double qq = fa / fc, r = fb / fc;
        p = s * (2.0 * xm * qq * (qq - r) - (b - a) * (r - 1.0));
        q = (qq - 1.0) * (r - 1.0) * (s - 1.0);
      }
      if (p > 0.0) q = -q;
      p = std::fabs(p);
      if (2.0 * p < 3.0 * xm * q - std::fabs(tol1 * q) && p < std::fabs(0.5 * e * q)) {
        e = d;
        d = p / q;
      } else {
        d = xm;
        e = d;
      }
    } else {
      d = xm;
      e = d;
    }
    a = b;
    fa = fb;
    b += std::fabs(d) > tol1 ? d : std::copysign(tol1, xm);
    fb = f(b);
  }
  return b;
}

/// Dormand–Prince 5(4) stepper over y ∈ ℝᴰ, forward in time, with FSAL and dense output.
/// The right-hand side is a callable `f(double t, const std::array<double, D>& y,
/// std::array<double, D>& dydt)`. After each successful `step`, the dense output
/// `dense(t, out)` is valid on [t_prev(), t()].
template <std::size_t D>
class Dopri5 {
 public:
  /// State vector type.
  using Vec = std::array<double, D>;

  /// A stepper with the given options (copied).
  explicit Dopri5(const OdeOptions& opt) : opt_(opt) {}

  /// Start at (t0, y0) towards t_end ≥ t0; h0 > 0 is the first trial step (else `h_init`,
  /// else automatic). Evaluates f(t0, y0) (the FSAL stage). Fails with `non_finite` if that
  /// value is not finite.
  template <class Rhs>
  OdeStatus start(Rhs& f, double t0, const Vec& y0, double t_end, double h0 = 0.0) {
    t_ = t_prev_ = t0;
    t_end_ = t_end;
    y_ = y_prev_ = y0;
    h_last_ = 0.0;
    facold_ = 1e-4;
    last_rejected_ = false;
    n_attempts_ = 0;
    f(t_, y_, k1_);
    ++n_rhs_;
    if (!detail::all_finite(k1_) || !detail::all_finite(y_)) return OdeStatus::non_finite;
    double h = h0 > 0.0 ? h0 : opt_.h_init;
    if (!(h > 0.0)) h = initial_step(f);
    h_ = limit_step(h);
    return OdeStatus::ok;
  }

  /// Take one accepted step (retrying rejected ones). Precondition: t() < t_end.
  template <class Rhs>
  OdeStatus step(Rhs& f) {
    using C = detail::Dp5;
    bool failed_non_finite = false;
    for (;;) {
      if (n_attempts_ >= opt_.max_steps) return OdeStatus::step_limit;
      ++n_attempts_;
      double h = limit_step(h_);
      bool last = false;
      // Land exactly on t_end instead of leaving a sliver (< 1 % of h) behind.
      if (t_ + 1.01 * h >= t_end_) {
        h = t_end_ - t_;
        last = true;
      }
      // A sliver to t_end below the resolution of t (e.g. an event that fell on t_end up to
      // rounding) is not an underflow: the last step is taken with the tiny h and lands on
      // t_end exactly.
      if (!(h > 0.0) || (!last && !(0.1 * std::fabs(h) >
                                    std::fabs(t_) * std::numeric_limits<double>::epsilon()))) {
        return failed_non_finite ? OdeStatus::non_finite : OdeStatus::step_underflow;
      }
      Vec yt;
      for (std::size_t i = 0; i < D; ++i) yt[i] = y_[i] + h * C::a21 * k1_[i];
      f(t_ + C::c2 * h, yt, k2_);
      for (std::size_t i = 0; i < D; ++i) yt[i] = y_[i] + h * (C::a31 * k1_[i] + C::a32 * k2_[i]);
      f(t_ + C::c3 * h, yt, k3_);
      for (std::size_t i = 0; i < D; ++i)
        yt[i] = y_[i] + h * (C::a41 * k1_[i] + C::a42 * k2_[i] + C::a43 * k3_[i]);
      f(t_ + C::c4 * h, yt, k4_);
      for (std::size_t i = 0; i < D; ++i)
        yt[i] = y_[i] + h * (C::a51 * k1_[i] + C::a52 * k2_[i] + C::a53 * k3_[i] + C::a54 * k4_[i]);
      f(t_ + C::c5 * h, yt, k5_);
      for (std::size_t i = 0; i < D; ++i)
        yt[i] = y_[i] + h * (C::a61 * k1_[i] + C::a62 * k2_[i] + C::a63 * k3_[i] + C::a64 * k4_[i] +
                             C::a65 * k5_[i]);
      const double t_new = last ? t_end_ : t_ + h;
      f(t_new, yt, k6_);
      Vec y1;
      for (std::size_t i = 0; i < D; ++i)
        y1[i] = y_[i] + h * (C::a71 * k1_[i] + C::a73 * k3_[i] + C::a74 * k4_[i] + C::a75 * k5_[i] +
                             C::a76 * k6_[i]);
      f(t_new, y1, k7_);
      n_rhs_ += 6;
      // err = RMS_i( h Σ e_j k_j,i / (atol + rtol·max(|y_i|, |y1_i|)) ).
      double err = 0.0;
      for (std::size_t i = 0; i < D; ++i) {
        const double sk = opt_.atol + opt_.rtol * std::max(std::fabs(y_[i]), std::fabs(y1[i]));
        const double ei = h * (C::e1 * k1_[i] + C::e3 * k3_[i] + C::e4 * k4_[i] + C::e5 * k5_[i] +
                               C::e6 * k6_[i] + C::e7 * k7_[i]);
        err += (ei / sk) * (ei / sk);
      }
      err = std::sqrt(err / static_cast<double>(D));
      if (!std::isfinite(err) || !detail::all_finite(y1) || !detail::all_finite(k7_)) {
        // A stage left the domain of f: shrink hard and retry.
        failed_non_finite = true;
        last_rejected_ = true;
        h_ = h * opt_.fac_min;
        continue;
      }
      // PI controller: h_new = h · safety · err^(−(0.2 − 0.75β)) · err_old^β.
      const double expo1 = 0.2 - opt_.beta * 0.75;
      const double fac11 = std::pow(err, expo1);
      if (err <= 1.0) {
        double fac = fac11 / std::pow(facold_, opt_.beta);
        fac = std::clamp(fac / opt_.safety, 1.0 / opt_.fac_max, 1.0 / opt_.fac_min);
        double h_new = h / fac;
        if (last_rejected_) h_new = std::min(h_new, h);
        facold_ = std::max(err, 1e-4);
        // Dense output: y(t_prev + θh) = r1 + θ(r2 + (1−θ)(r3 + θ(r4 + (1−θ) r5))).
        for (std::size_t i = 0; i < D; ++i) {
          const double ydiff = y1[i] - y_[i];
          const double bspl = h * k1_[i] - ydiff;
          r1_[i] = y_[i];
          r2_[i] = ydiff;
          r3_[i] = bspl;
          r4_[i] = ydiff - h * k7_[i] - bspl;
          r5_[i] = h * (C::d1 * k1_[i] + C::d3 * k3_[i] + C::d4 * k4_[i] + C::d5 * k5_[i] +
                        C::d6 * k6_[i] + C::d7 * k7_[i]);
        }
        y_prev_ = y_;
        y_ = y1;
        k1_ = k7_;  // FSAL
        t_prev_ = t_;
        t_ = t_new;
        h_last_ = t_ - t_prev_;
        h_ = h_new;
        last_rejected_ = false;
        ++n_accepted_;
        return OdeStatus::ok;
      }
      h_ = h / std::min(1.0 / opt_.fac_min, fac11 / opt_.safety);
      last_rejected_ = true;
      ++n_rejected_;
    }
  }

  /// Dense output at θ ∈ [0, 1] of the last accepted step (θ = 1 gives y() exactly).
  void dense_theta(double theta, Vec& out) const {
    if (theta >= 1.0) {
      out = y_;
      return;
    }
    const double th1 = 1.0 - theta;
    for (std::size_t i = 0; i < D; ++i)
      out[i] = r1_[i] + theta * (r2_[i] + th1 * (r3_[i] + theta * (r4_[i] + th1 * r5_[i])));
  }

  /// Dense output at t ∈ [t_prev(), t()] of the last accepted step.
  void dense(double t, Vec& out) const {
    if (t >= t_) {
      out = y_;
      return;
    }
    dense_theta((t - t_prev_) / h_last_, out);
  }

  /// Time reached.
  double t() const { return t_; }
  /// Start of the last accepted step.
  double t_prev() const { return t_prev_; }
  /// End of the integration interval.
  double t_end() const { return t_end_; }
  /// Length of the last accepted step.
  double h_last() const { return h_last_; }
  /// Proposed size of the next step.
  double h_next() const { return h_; }
  /// State at t().
  const Vec& y() const { return y_; }
  /// State at t_prev().
  const Vec& y_prev() const { return y_prev_; }
  /// f(t(), y()) (the FSAL stage).
  const Vec& f_current() const { return k1_; }
  /// Whether t() has reached t_end.
  bool done() const { return t_ >= t_end_; }
  /// Accepted steps since construction.
  long accepted_steps() const { return n_accepted_; }
  /// Rejected steps since construction.
  long rejected_steps() const { return n_rejected_; }
  /// Right-hand-side evaluations since construction.
  long rhs_evaluations() const { return n_rhs_; }
  /// The options in use.
  const OdeOptions& options() const { return opt_; }

 private:
  double limit_step(double h) const {
    if (opt_.h_max > 0.0) h = std::min(h, opt_.h_max);
    return std::min(h, t_end_ - t_);
  }

  /// Hairer's starting step: h ≈ (0.01 / max(‖f'‖, ‖f‖))^(1/5) with norms scaled by the
  /// tolerances, from one explicit Euler trial step.
  template <class Rhs>
  double initial_step(Rhs& f) {
    double dnf = 0.0, dny = 0.0;
    for (std::size_t i = 0; i < D; ++i) {
      const double sk = opt_.atol + opt_.rtol * std::fabs(y_[i]);
      dnf += (k1_[i] / sk) * (k1_[i] / sk);
      dny += (y_[i] / sk) * (y_[i] / sk);
    }
    double h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : std::sqrt(dny / dnf) * 0.01;
    h = limit_step(h);
    Vec y1, f1;
    for (std::size_t i = 0; i < D; ++i) y1[i] = y_[i] + h * k1_[i];
    f(t_ + h, y1, f1);
    ++n_rhs_;
    double der2 = 0.0;
    for (std::size_t i = 0; i < D; ++i) {
      const double sk = opt_.atol + opt_.rtol * std::fabs(y_[i]);
      der2 += ((f1[i] - k1_[i]) / sk) * ((f1[i] - k1_[i]) / sk);
    }
    der2 = std::sqrt(der2) / h;
    const double der12 = std::max(std::fabs(der2), std::sqrt(dnf));
    const double h1 = der12 <= 1e-15 || !std::isfinite(der12) ? std::max(1e-6, h * 1e-3)
                                                              : std::pow(0.01 / der12, 0.2);
    return std::min(100.0 * h, h1);
  }

  OdeOptions opt_;
  double t_ = 0.0, t_prev_ = 0.0, t_end_ = 0.0, h_ = 0.0, h_last_ = 0.0, facold_ = 1e-4;
  bool last_rejected_ = false;
  long n_attempts_ = 0, n_accepted_ = 0, n_rejected_ = 0, n_rhs_ = 0;
  Vec y_{}, y_prev_{}, k1_{}, k2_{}, k3_{}, k4_{}, k5_{}, k6_{}, k7_{};
  Vec r1_{}, r2_{}, r3_{}, r4_{}, r5_{};
};

/// A located root of event function `event` at time `t`, crossing in `direction`
/// (+1: g increases through 0, −1: g decreases through 0).
struct EventRoot {
  int event;      ///< Index of the event function.
  double t;       ///< Time of the root.
  int direction;  ///< Crossing direction, ±1.
};

/// Event location on the steps of a `Dopri5<D>` for up to `MaxEvents` scalar event
/// functions g(k, y) (k = 0..n−1). Per event: a reference sign (the last nonzero sign
/// seen) and the sample where it was seen (the left end of the next bracket).
/// Invariant between scans: ref_[k] is the sign of g_k at the end of the last step
/// (or 0 while unarmed), g_ref_[k] its value there.
template <std::size_t D, std::size_t MaxEvents>
class EventLocator {
 public:
  /// State vector type.
  using Vec = std::array<double, D>;

  /// Use events 0..n−1 (n ≤ MaxEvents) with required directions (−1, 0 = both, +1).
  void configure(int n, const int* directions) {
    n_ = std::min(n, static_cast<int>(MaxEvents));
    for (int k = 0; k < n_; ++k) dir_[idx(k)] = directions != nullptr ? directions[k] : 0;
  }

  /// Number of events in use.
  int size() const { return n_; }

  /// Arm the events after the FIRST accepted step from the start point (ode.t_prev(),
  /// ode.y_prev()). The reference sign of g_k is its sign at t₀ + δ (see file doc);
  /// `at_start[k]` (if given) is set when g_k has a root in [t₀, t₀ + δ] (g_k(y₀) = 0 or a
  /// sign change). If `expected` is given and expected[k] ≠ 0 while the sign at t₀ + δ
  /// differs, the event stays unarmed until its first nonzero sample (no crossing is
  /// reported before the trajectory has visibly left to the expected side).
  template <class G>
  void arm(const Dopri5<D>& ode, G& g, const int* expected = nullptr, bool* at_start = nullptr) {
    if (n_ == 0) return;
    const double t0 = ode.t_prev();
    const double h = ode.h_last();
    const double scale = std::max(std::fabs(t0), std::fabs(ode.t_end()));
    const double delta = std::min(ode.options().event_rearm * scale, 0.5 * h);
    const double th = delta / h;
    Vec x;
    ode.dense_theta(th, x);
    for (int k = 0; k < n_; ++k) {
      const double v0 = g(k, ode.y_prev());
      const double vd = g(k, x);
      const int s0 = detail::sign_of(v0), sd = detail::sign_of(vd);
      if (at_start != nullptr) at_start[k] = (s0 == 0) || (sd != 0 && s0 != sd);
      int ref = sd;
      if (expected != nullptr && expected[k] != 0 && sd != expected[k]) ref = 0;
      ref_[idx(k)] = ref;
      th_ref_[idx(k)] = th;
      g_ref_[idx(k)] = vd;
    }
    theta_begin_ = th;
  }

  /// Scan the last accepted step for sign changes; for each root whose direction is
  /// allowed, in time order, call on_root(const EventRoot&, const Vec& y_at_root) -> bool.
  /// If it returns true, stop: returns true and sets t_stop to the root's time.
  template <class G, class OnRoot>
  bool scan(const Dopri5<D>& ode, G& g, OnRoot& on_root, double& t_stop) {
    if (n_ == 0) return false;
    const int ns = std::max(1, ode.options().event_samples);
    const double ta = ode.t_prev(), h = ode.h_last();
    std::array<Candidate, MaxEvents> cand;
    Vec x;
    for (int j = 1; j <= ns; ++j) {
      const double th = j == ns ? 1.0 : static_cast<double>(j) / static_cast<double>(ns);
      if (th <= theta_begin_) continue;
      ode.dense_theta(th, x);
      std::size_t nc = 0;
      for (int k = 0; k < n_; ++k) {
        const std::size_t kk = idx(k);
        const double v = g(k, x);
        if (j == ns) g_last_[kk] = v;
        const int s = detail::sign_of(v);
        if (s == 0) continue;
        if (ref_[kk] != 0 && s != ref_[kk] && (dir_[kk] == 0 || dir_[kk] == s)) {
          cand[nc++] = Candidate{k, th_ref_[kk], g_ref_[kk], th, v, s, 0.0};
        }
        ref_[kk] = s;
        th_ref_[kk] = th;
        g_ref_[kk] = v;
      }
      if (nc == 0) continue;
      // Refine each bracket on the dense-output polynomial, then report in time order.
      for (std::size_t c = 0; c < nc; ++c) {
        Candidate& cd = cand[c];
        Vec xr;
        auto phi = [&](double theta) {
          ode.dense_theta(theta, xr);
          return g(cd.k, xr);
        };
        cd.root = brent_root(phi, cd.a, cd.b, cd.ga, cd.gb, 1e-16);
      }
      // Insertion sort by (root, k): nc ≤ MaxEvents is a handful (and GCC 12 at -O3 reads
      // std::sort's introsort on this short std::array as out of bounds, -Warray-bounds).
      const auto before = [](const Candidate& l, const Candidate& r) {
        return l.root < r.root || (l.root == r.root && l.k < r.k);
      };
      for (std::size_t c = 1; c < nc; ++c)
        for (std::size_t d = c; d > 0 && before(cand[d], cand[d - 1]); --d)
          std::swap(cand[d], cand[d - 1]);
      for (std::size_t c = 0; c < nc; ++c) {
        Vec xr;
        ode.dense_theta(cand[c].root, xr);
        const double tr = cand[c].root >= 1.0 ? ode.t() : ta + cand[c].root * h;
        if (on_root(EventRoot{cand[c].k, tr, cand[c].dir}, xr)) {
          t_stop = tr;
          return true;
        }
      }
    }
    // The next step starts where this one ended: brackets restart at θ = 0.
    for (int k = 0; k < n_; ++k) {
      th_ref_[idx(k)] = 0.0;
      g_ref_[idx(k)] = g_last_[idx(k)];
    }
    theta_begin_ = 0.0;
    return false;
  }

 private:
  struct Candidate {
    int k;
    double a, ga, b, gb;
    int dir;
    double root;
  };
  static std::size_t idx(int k) { return static_cast<std::size_t>(k); }

  int n_ = 0;
  double theta_begin_ = 0.0;
  std::array<int, MaxEvents> dir_{}, ref_{};
  std::array<double, MaxEvents> th_ref_{}, g_ref_{}, g_last_{};
};

/// Result of `integrate`.
template <std::size_t D>
struct OdeResult {
  OdeStatus status = OdeStatus::ok;  ///< Success or what failed.
  double t = 0.0;                    ///< Time reached (t_end, or the stopping event's time).
  std::array<double, D> y{};         ///< State at t.
  int event = -1;                    ///< Event that stopped the integration, or −1.
  long steps = 0;                    ///< Accepted steps.
};

/// Integrate y' = f(t, y) from (t0, y0) to t_end without events.
template <std::size_t D, class Rhs>
OdeResult<D> integrate(Rhs&& f, double t0, const std::array<double, D>& y0, double t_end,
                       const OdeOptions& opt) {
  Dopri5<D> ode(opt);
  OdeResult<D> res;
  res.status = ode.start(f, t0, y0, t_end);
  while (res.status == OdeStatus::ok && !ode.done()) res.status = ode.step(f);
  res.t = ode.t();
  res.y = ode.y();
  res.steps = ode.accepted_steps();
  return res;
}

/// Integrate y' = f(t, y) from (t0, y0) to t_end with `n_events` event functions
/// g(int k, const std::array<double, D>&) -> double and required `directions`.
/// At every located root (in time order), on_event(const EventRoot&, const state&) -> bool
/// is called; returning true stops the integration there (res.event, res.t, res.y).
/// Roots in the start window [t0, t0 + δ] are not reported (no trigger at the start).
template <std::size_t MaxEvents = 8, std::size_t D, class Rhs, class G, class OnEvent>
OdeResult<D> integrate(Rhs&& f, double t0, const std::array<double, D>& y0, double t_end,
                       const OdeOptions& opt, int n_events, const int* directions, G&& g,
                       OnEvent&& on_event) {
  Dopri5<D> ode(opt);
  EventLocator<D, MaxEvents> loc;
  loc.configure(n_events, directions);
  OdeResult<D> res;
  res.status = ode.start(f, t0, y0, t_end);
  bool first = true;
  auto on_root = [&](const EventRoot& r, const std::array<double, D>& x) {
    if (on_event(r, x)) {
      res.event = r.event;
      res.y = x;
      return true;
    }
    return false;
  };
  while (res.status == OdeStatus::ok && !ode.done()) {
    res.status = ode.step(f);
    if (res.status != OdeStatus::ok) break;
    if (first) {
      loc.arm(ode, g);
      first = false;
    }
    double t_stop = 0.0;
    if (loc.scan(ode, g, on_root, t_stop)) {
      res.t = t_stop;
      res.steps = ode.accepted_steps();
      return res;
    }
  }
  res.t = ode.t();
  res.y = ode.y();
  res.steps = ode.accepted_steps();
  return res;
}

}  // namespace hybgen::rt
