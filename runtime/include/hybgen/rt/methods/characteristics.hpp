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
///    Δ_g(z) = x from z = x); for a reset with a constant component i (GuardInfo::image_axis:
///    the sawtooth's x ↦ 0) b_g(x) = x_i − Δ_i, and the pre-image solves Δ_j(z) = x_j (j ≠ i)
///    with s_g(z) = 0 (newton_reset_solve): the mass crossing S_g enters at Δ(S_g) with the
///    flux ratio 1/|J| (J = ∇sᵀ adj(DΔ) X⁺ / ∇sᵀ X⁻ is finite where det DΔ = 0). At a root y*, z =
///    Δ_g⁻¹(y*) is a true pre-image only if the guard fires there: sign(∇s_g(z)·X_from(z)) =
///    guards[g].direction. Then a REVERSED-RESET BRANCH (state z, mode `from`, weight/|J_g(z)|,
///    same I) is spawned; it serves the output times after τ*. A reset with SEVERAL pre-images on
///    S_g (a fold; the pre-flight finds them and passes seeds,
///    CharacteristicsOptions::preimage_seeds) spawns one branch per pre-image, all enumerated by
///    Newton from the seeds: the paper's general theorem sums over them.
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
/// on the far side of the event surface (b_g has its post-crossing sign), or on it to rounding
/// (b_g = 0) and outside the support, where the continuing history has no value; so a point on
/// such a discontinuity gets one of its two one-sided values, never their sum or zero.
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
/// Size: the backward tracer (events, reversed-reset branches, ties, grazing, pre-images)
/// is one state machine; the grid, geometry and solutions it uses are in core/.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/core/ode.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/io/progress.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

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
  /// Cumulative mode: a density scale c_ref below which the time integral need not resolve
  /// u: a panel is also accepted when its error estimate is ≤ cumulative_tol·c_ref·(its
  /// length), so each output's error from it is ≤ cumulative_tol·c_ref·t_k. Without it (0)
  /// an integrand that is rounding noise (a compactly supported u0 whose zero is computed
  /// with cancellation) meets a purely relative test nowhere.
  double cumulative_floor = 0.0;
  /// Cumulative mode: out holds 2K values, out[K + k] the part of out[k]'s error that the
  /// time integral's work cap left unresolved (`detail::Tracer::accumulate`; 0 where the cap
  /// was not reached). `evaluate`'s solution then has 2K times.
  bool cumulative_errors = false;
  /// Guards whose reset has SEVERAL pre-images on the guard (the pre-flight's
  /// `find_preimage_seeds`): (*preimage_seeds)[g] holds start points on S_g, N doubles each,
  /// from which every incoming crossing enumerates all pre-images by Newton (each spawns a
  /// branch, weight 1/|J|, as the paper's general theorem sums them). Empty or null for a
  /// guard: its reset is taken as injective on S_g (one pre-image: Δ⁻¹ or Newton from y).
  const std::vector<std::vector<double>>* preimage_seeds = nullptr;
  /// The ranks sharing the points (null: this process alone). Each traces its block of the
  /// (mode, point) pairs and every rank receives every value: a characteristic does not
  /// depend on its neighbours, so the values are the same bits for any number of ranks.
  const Backend* backend = nullptr;
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
  /// opt.cumulative_tol > 0 (and its unresolved error into out[K + k] with
  /// opt.cumulative_errors); `times` is assumed valid.
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
      // A constant component i: Δ_g(S_g) lies in the plane x_i = Δ_i, whose signed distance
      // is the event (b_g = s_g∘Δ_g⁻¹ is not defined off the plane).
      if (const int axis = guard_info<M>(static_cast<std::size_t>(g)).image_axis; axis >= 0) {
        State d;
        M::reset(g, x.data(), par_, d.data());
        return x[static_cast<std::size_t>(axis)] - d[static_cast<std::size_t>(axis)];
      }
      State z;
      // A numeric Δ⁻¹ starts Newton from the pre-image of this event's last evaluation on
      // the branch (the points the ODE and the root finder ask for are close together), else
      // from x: 1–3 iterations instead of up to newton_max_iter, whichever start converges
      // gives the same b_g (below). On a random 4-D model whose backward characteristics
      // cross up to 68 resets, this was 90 % of the run (tests/validation/test_differential.cpp).
      const bool numeric = !guard_info<M>(static_cast<std::size_t>(g)).has_inverse;
      const auto ei_slot = static_cast<std::size_t>(e);
      bool ok = numeric && warm_ok_[ei_slot] &&
                newton_reset_solve<M>(g, x.data(), warm_[ei_slot].data(), par_,
                                      opt_.newton_max_iter, opt_.newton_tol, z) &&
                all_finite(z);
      if (!ok) ok = reset_inverse(g, x.data(), z);
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
      if (numeric) warm_[ei_slot] = z, warm_ok_[ei_slot] = true;
      return M::guard_surface(g, z.data(), par_);
    }
    return M::guard_surface(g, x.data(), par_);
  }

  void setup_events(int mode) {
    warm_ok_.fill(false);
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
  /// `dir` is the sign b_g takes after the crossing (0 for a root at the branch start).
  void try_spawn(int e, double tau, const Vec& x, const FaceContext<N>* face, bool at_start,
                 int dir) {
    const int g = guard_[static_cast<std::size_t>(e)];
    // The path meets the reset's image at x. Where x lies outside the state space just after
    // the reset (forward in time: the side the path comes from), the path left the support
    // before this crossing, between the step ends where the support is tested: nothing was
    // reset there, and no pre-image has mass to give. (The differential campaign's random
    // model 3733: a backward path left its support at τ = 0.42996 and met the image at
    // 0.43173, just outside; it took the pre-image's density, 2.7e-5 for 0.)
    {
      State y;
      for (std::size_t i = 0; i < N; ++i) y[i] = x[i];
      if (!leaves_into_support<M>(mode_, y, par_)) return;
    }
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
    // (tests/validation/test_support_pruning.cpp). Tested just before the crossing
    // (core/geometry.hpp).
    if (!reaches_from_support<M>(gi.from, z, par_)) return;
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
        // The continuing trajectory at t_k: past the image surface, or on it to rounding
        // (b_g = 0 exactly: s_g∘Δ_g⁻¹ can round a tiny distance away, x ↦ (x + 1) − 1) with
        // the continuing history outside the support, where it has no value (u0 = 0): either
        // way the reset's side holds t_k's value (tests/validation/models/wrap_decay.model,
        // whose column x = 0.5 met the image x = 0 at t = 0 and got 0 from both sides).
        Vec xc;
        dense_at(kb, xc);
        const int side = sign_of(event_value(e, xc));
        crossed = side == dir || (side == 0 && !M::in_support(xc.data(), par_));
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
  /// whole's, |I_L + I_R − I| ≤ tol·max(|I_L + I_R|, cmax·h, c_ref·h) (h: the panel's
  /// length; c_ref: `cumulative_floor`), else halved (to depth kMaxDepth: a jump of u0 along
  /// the path converges linearly). cmax is the largest |c| seen on this characteristic, so
  /// the error per unit time is ≲ tol·max(max|u|, c_ref).
  ///
  /// Bounded work, whatever c is: a branch halves at most kMaxSplits panels in all. A jump
  /// costs kMaxDepth halvings, a kink a few, so that allows several of each per branch; an
  /// integrand that fails the test almost everywhere (rounding noise without a floor, an
  /// oscillation finer than the panels) would otherwise halve every panel kMaxDepth times,
  /// 2^kMaxDepth pieces each. Beyond the cap a failing piece is accepted (I_L + I_R) and
  /// |I_L + I_R − I| added to unres_, the branch's unresolved error, which the outputs
  /// report with `cumulative_errors`. A base panel costs 3 panel rules (the whole and its
  /// halves), a halving 4 more (its two pieces' halves), so a branch costs at most
  /// 3·(its base panels) + 4·kMaxSplits rules of kPanelOrder evaluations of u0: with the
  /// horizon's kMinPanels base panels, about 6.3 times an integrand that needs no halving.
  void accumulate(double b) {
    const double a0 = cursor_;
    cursor_ = std::max(cursor_, b);
    if (!(b > a0)) return;
    const double tol = opt_.cumulative_tol, floor = opt_.cumulative_floor;
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
        const double err = std::fabs(L + R - p.whole), h = p.b - p.a;
        if (p.depth >= kMaxDepth ||
            err <= tol * std::max({std::fabs(L + R), cmax_ * h, floor * h})) {
          acc_ += L + R;
          continue;
        }
        if (splits_ >= kMaxSplits) {  // the work cap: accepted, its error booked
          acc_ += L + R;
          unres_ += err;
          continue;
        }
        ++splits_;
        stack[top++] = Piece{m, p.b, R, p.depth + 1};
        stack[top++] = Piece{p.a, m, L, p.depth + 1};
      }
    }
  }

  /// Cumulative mode: output k gets the branch's integral so far (and its unresolved error).
  void add_cumulative(std::size_t k) {
    out_[k] += acc_;
    if (opt_.cumulative_errors) out_[times_.size() + k] += unres_;
  }

  /// Cumulative mode: the branch ends at σ; every later output gets its whole integral.
  void finish_cumulative(std::size_t k) {
    for (; k < times_.size(); ++k) add_cumulative(k);
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
    unres_ = 0.0;
    splits_ = 0;
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
          add_cumulative(k);
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
  // Per event of the current branch: the last pre-image of a numeric Δ⁻¹ (event_value).
  std::array<State, kMaxEv> warm_{};
  std::array<bool, kMaxEv> warm_ok_{};
  std::array<Branch, kMaxPending> pend_{};
  std::array<std::size_t, 8> dense_k_{};  // output indices evaluated in the current step
  std::array<Vec, 8> dense_x_{};          // their states (dense_at)
  std::size_t n_dense_ = 0;
  std::size_t npend_ = 0;
  // Cumulative mode (opt_.cumulative_tol > 0): the current branch's ∫ c dσ from its start to
  // cursor_, and the largest |c| met on this characteristic.
  static constexpr int kPanelOrder = 5;              // Gauss–Legendre nodes per panel
  static constexpr int kMinPanels = 64;              // panels per horizon, at least
  static constexpr int kMaxDepth = 40;               // halvings of a panel
  static constexpr int kMaxSplits = 4 * kMinPanels;  // halvings per branch (accumulate)
  double acc_ = 0.0;
  double unres_ = 0.0;  // the part of acc_'s error left unresolved by the work cap
  int splits_ = 0;      // halvings on the current branch
  double cursor_ = 0.0;
  double cmax_ = 0.0;
};

}  // namespace detail

/// u(t_k, y) in `mode` for the sorted output times `times` (all ≥ 0) into out[k]
/// (out.size() == times.size(), twice that with opt.cumulative_errors in cumulative mode), by
/// one backward characteristic from y to τ = times.back(). y outside `M::in_support` gives 0.
/// With `face` (y on a face of a box), the value is the limit from inside that box (see
/// `FaceContext`). Returns the failure, if any.
template <HybridModel M>
TraceStatus<state_dim_v<M>> trace(const std::array<double, state_dim_v<M>>& y, int mode,
                                  std::span<const double> times, const double* par,
                                  const CharacteristicsOptions& opt, std::span<double> out,
                                  const FaceContext<state_dim_v<M>>* face = nullptr) {
  detail::validate_times(times);
  const bool with_errors = opt.cumulative_tol > 0.0 && opt.cumulative_errors;
  if (out.size() != times.size() * (with_errors ? 2 : 1))
    throw std::invalid_argument("characteristics: out.size() != times.size()");
  detail::Tracer<M> tracer(par, opt);
  return tracer.run(y, mode, times, out, face);
}

namespace detail {

/// Trace every (mode, point) in parallel. `point(i)` gives the coordinates, `face(i)` a
/// `const FaceContext<N>*` (or nullptr). Over several ranks each traces its block of the
/// (mode, point) pairs; `distributed`: each keeps its block (Solution::distributed), else
/// every rank gets every value.
template <HybridModel M, class PointFn, class FaceFn>
Solution<state_dim_v<M>> solve_points(std::size_t n_point, PointFn&& point, FaceFn&& face,
                                      std::span<const double> times, const double* par,
                                      const CharacteristicsOptions& opt, bool distributed = false) {
  constexpr std::size_t N = state_dim_v<M>;
  validate_times(times);
  Solution<N> sol;
  // Cumulative outputs with their unresolved errors: out[K + k] (CharacteristicsOptions).
  const bool with_errors = opt.cumulative_tol > 0.0 && opt.cumulative_errors;
  sol.n_time = times.size() * (with_errors ? 2 : 1);
  sol.n_mode = static_cast<std::size_t>(M::n_mode);
  sol.n_point = n_point;
  const auto total = static_cast<long long>(sol.n_mode * n_point);
  const auto np = static_cast<long long>(n_point);
  const Backend& backend = opt.backend ? *opt.backend : serial_backend();
  const Block mine = backend.block(static_cast<std::size_t>(total));
  if (distributed && backend.ranks() > 1) sol.distributed = true, sol.owned = mine;
  sol.u.assign(sol.n_time * sol.frame_size(), 0.0);
  if (sol.n_time == 0 || n_point == 0) return sol;
  std::atomic<long long> first_fail{total};
#pragma omp parallel
  {
    Tracer<M> tracer(par, opt);
    std::vector<double> buf(sol.n_time);
#pragma omp for schedule(dynamic, 16)
    for (auto idx = static_cast<long long>(mine.begin); idx < static_cast<long long>(mine.end);
         ++idx) {
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
  if (backend.ranks() > 1) {
    // Frame k holds the pairs in the order idx = m·n_point + i: each rank's block is one
    // contiguous piece of it, and the blocks tile it in rank order.
    const auto size = static_cast<std::size_t>(total);
    for (std::size_t k = 0; k < sol.n_time && !sol.distributed; ++k) {
      double* frame = sol.u.data() + k * size;
      const std::vector<double> all =
          backend.all_gather(std::span<const double>(frame + mine.begin, mine.size()));
      std::copy(all.begin(), all.end(), frame);
    }
    agree_first_failure(backend, first_fail.load(), sol.failure, total);
  }
  return sol;
}

}  // namespace detail

/// The characteristics solution on every node of `grid` for every mode and output time
/// (OpenMP over (mode, node), dynamic schedule). Nodes outside `M::in_support` are 0.
/// On failure, `failure` names the first failing (mode, node); other values are partial.
/// Over several ranks (opt.backend) each rank keeps its block of the (mode, node) pairs of
/// every frame (Solution::distributed): no rank holds a whole frame.
template <HybridModel M>
Solution<state_dim_v<M>> solve_grid(const TensorGrid<state_dim_v<M>>& grid,
                                    std::span<const double> times, const double* par,
                                    const CharacteristicsOptions& opt) {
  using Face = const FaceContext<state_dim_v<M>>*;
  return detail::solve_points<M>(
      grid.size(), [&grid](std::size_t i) { return grid.node(i); },
      [](std::size_t) -> Face { return nullptr; }, times, par, opt, true);
}

/// u at arbitrary points (all modes, all output times), same layout as `solve_grid` (2K
/// times with cumulative errors: CharacteristicsOptions::cumulative_errors).
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

}  // namespace hybgen::rt
