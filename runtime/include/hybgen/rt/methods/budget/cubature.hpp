#pragma once
/// \file cubature.hpp
/// The adaptive cubature of the mass budget (budget.hpp): K integrals at once over a union of
/// D-dimensional boxes, by tensor Gauss rules on cells refined where the integrand is not
/// resolved. The runtime does not know where the density jumps or blows up, so the cubature
/// finds it.
///
/// The cubature (dimension D: N for the volume, N − 1 for the faces). Cells are boxes; on a
/// cell C the rule is tensor Gauss–Legendre with q = `order` nodes per axis, exact for degree
/// 2q − 1; I_C = |C| Σ_n W_n U_n, U_n the integrand at node n for every slot k. The nodes
/// define the tensor interpolant 𝓘_C of degree q − 1, and I_C = ∫_C 𝓘_C exactly.
///  * Split axis: the one with the largest null-rule indicator T_a = ∫_C |degree-(q − 1)
///    Legendre component of 𝓘_C along a| (what the rule does not resolve along a); so cells
///    become as anisotropic as the integrand (near the ball's Zeno point the stripes are thin
///    in x and long in p: aspect ratios ~1e-3 occur).
///  * Discrepancy: when C is split into halves C_s along a, the parent's prediction for half s
///    is Ĩ_s = ∫_{C_s} 𝓘_C (stored with C), Σ_s Ĩ_s = I_C, and d_s = I_{C_s} − Ĩ_s: Σ_s d_s is
///    the classical two-level error estimate of I_C, attributed to the half where the
///    parent's polynomial failed. It measures the error along a only; the error along the
///    other axes is estimated as o_s = ρ Σ_{b≠a} T_b(C_s), with ρ = Σ_s max_k|d_s| / T_a(C) ≤ 1
///    calibrating null rules against the measured error.
///  * Error model per slot k: E_k = |Σ d| + 2·sqrt(Σ d² + Σ o²) over the leaves. At jumps and
///    singularities the cell errors have erratic signs and largely cancel (Σ|d| is ~100×
///    pessimistic for the striped ball density); |Σ d| is the systematic part (smooth
///    integrands, one-signed singularities). E_k is an estimate (≈ 2σ under a random-sign
///    model), not a bound; the value returned is the leaf-level sum, usually more accurate.
///    Measured on the bouncing ball (e ∈ {0.6, 0.8, 1}, dt ∈ {0.2, 0.5}, rel_tol ∈ {1e-3,
///    3e-4, 1e-4}; 630 (run, time) pairs): |atom − Zeno mass| ≤ the atom's summed estimate
///    in 99.8 % of the pairs (median ratio 0.09, largest 1.03). Weak spot: a point
///    singularity with one-signed errors decaying slowly between levels (ratio r; r = 2^{−1/2}
///    for |x − c|^{−1/2} in 1-D): the leaf's error is ≈ r/(1 − r) times its last
///    discrepancy, so E_k can be low by that factor (measured up to 3.1×). Blind spot: a
///    jump of the density that crosses a cell between its Gauss nodes, all on one side, is
///    not seen by the nodes. The check points (the grid's nodes, with the values the run
///    solved there: `CheckPoints`) see it down to the grid's spacing: a leaf's misfit there
///    enters E_k like a discrepancy (before them, a strip after an impact on a tall box,
///    tests/validation/test_bounce_exit.cpp, was missed by 0.21 of the mass with an estimate
///    of 9.4e-5). Below the grid's spacing it remains (test_shear_reset.cpp at rel_tol 1e-5:
///    mass low by 3.8e-5, estimate 1e-6); the budget's closure check (the defect against the
///    sum of the estimates, methods.hpp) flags it when the other terms are right.
///  * Refinement: Dörfler marking — the leaves with the largest indicators e = max_k(|d_k| +
///    o_k) whose sum reaches half of the live total are split together and all their
///    halves' nodes traced in one `evaluate` call (OpenMP over the points). Stop when
///    E_k ≤ rel_tol·scale_k for every slot, or when `max_points` would be exceeded
///    (`converged` = false; E_k is still the estimate).
///  * Bounded work: at most `max_points` integrand points in all, whatever the integrand —
///    the initial cells with their halves take at most a quarter of them (fewer cells per
///    root if needed), and no batch is traced that would exceed the cap. But where a quarter
///    would leave one cell per root and two per axis fit in three quarters, two: the
///    discrepancies are only as good as the first level of nodes, and in 4-D a cap of 20000
///    (budget=fast) left ONE cell of 4⁴ nodes over the box, from which a plain Gaussian (the
///    differential campaign's model 2531) was refined on the wrong axes and declared
///    converged at 0.3005 for 0.3357 with an estimate of 4.3e-3; from 2⁴ cells it is
///    0.33579 ± 1.5e-2 (tests/rt/test_cubature.cpp). (Three quarters always, 4³ cells in
///    3-D, left too little for the refinement of a contracting density:
///    tests/validation/test_cell_averages.cpp's 3-D clock lost 7 % of its mass at t = 4.) A point's
///    cost is its integrand's: one backward characteristic (volume; bounded by the ODE's step limit
///    and `max_events`), one with a time integral under its own work cap (faces: Tracer::accumulate
///    in characteristics.hpp), or one forward flow (atom; `max_events`). A cubature stopped by the
///    cap says so (`converged` = false) and widens its estimate (`error`).
///  * Frozen leaves: leaves with e ≤ rel_tol·scale/(max cells) can never be marked before the
///    stop test holds (all of them together are below the target), so they are frozen:
///    their values stay in the sums, their storage is freed. Cells where the integrand is 0
///    (outside the support) freeze at once. Cells narrower than 2⁻⁴⁰ of the box are frozen
///    too (an unresolvable singularity keeps its honest share of E_k).
///  * Memory: 8·5K bytes per live leaf (K slots, the passive ones included: the volume's
///    2·(times) − 1 with its drops, budget/volume.hpp), at most max_points/q^D leaves, plus one
///    batch of ≤ 2²¹ (point, time, mode) values (the initial cells are traced in batches of
///    that size too).
///  * Per-root integrals (`per_root`): the integral and the error model above are also kept
///    for every root box on its own (8·5K bytes per root), and the stop test holds the sum
///    over the roots of their estimated errors, Σ_r E_{r,k} ≤ rel_tol·scale_k: the L1 error
///    of the roots' integrals, not the error of their sum. The cell averages of
///    characteristics (budget/cell_averages.hpp) take every dual cell of the grid as a root.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <queue>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/methods/budget/check_points.hpp"
#include "hybgen/rt/methods/budget/cubature_rule.hpp"

namespace hybgen::rt {

/// Options of the adaptive volume (and face) integrals.
struct AdaptiveOptions {
  double rel_tol = 1e-4;            ///< Target: estimated error ≤ rel_tol·max(mass0, mass_k).
  std::size_t max_points = 400000;  ///< Cap on traced points per integral (volume; faces).
  int order = 4;                    ///< Gauss–Legendre nodes per axis in a cell (≥ 1).
  /// Initial cells per axis of each root box (fewer where they and their halves would take
  /// more than a quarter of max_points, but 2 rather than 1 within three quarters; ≥ 1).
  int root_parts = 4;
};

/// What an adaptive cubature did (shared by `AdaptiveMass` and `AdaptiveOutflow`).
struct CubatureStats {
  std::vector<double> error;    ///< Estimated |error| of each time's integral (see above).
  double error_estimate = 0.0;  ///< The largest estimated error.
  std::size_t points = 0;       ///< Points traced (each for all modes and times).
  std::size_t cells = 0;        ///< Leaf cells of the final partition.
  int iterations = 0;           ///< Refinement batches.
  bool converged = false;       ///< Whether the rel_tol target was met within max_points.
  bool capped = false;          ///< Whether the cubature stopped at its point cap.
};

namespace detail {

/// Copy integrals `first`..`first + n − 1` of a finished cubature into `values`, their
/// error estimates and the statistics into `stats` (error_estimate is raised, not reset).
template <class Cubature>
void collect(const Cubature& cub, bool ok, std::size_t first, std::size_t n,
             std::vector<double>& values, CubatureStats& stats) {
  values.assign(n, 0.0);
  stats.error.assign(n, 0.0);
  for (std::size_t k = 0; k < n; ++k) {
    values[k] = cub.integral(first + k);
    stats.error[k] = cub.error(first + k);
    stats.error_estimate = std::max(stats.error_estimate, stats.error[k]);
  }
  stats.points = cub.points();
  stats.cells = cub.cells();
  stats.iterations = cub.iterations();
  stats.converged = ok && cub.converged();
  stats.capped = ok && !cub.converged();
  // Stopped by the point cap: a feature no node has seen yet at one time (the Zeno basin at
  // early times) has no estimate of its own, so every time gets the largest estimate of any.
  if (!stats.converged)
    for (double& e : stats.error) e = std::max(e, stats.error_estimate);
}

/// The adaptive cubature of K integrals at once over a union of D-dimensional root boxes
/// (see the file comment). `Values` fills U[i·K + k] for a batch of cells' nodes:
/// bool values(std::span<const Cell<D>> cells, std::span<const std::array<double, D>> pts,
/// std::size_t nodes_per_cell, std::vector<double>& U) — false on a failed characteristic.
///
/// Check points (optional, `CheckPoints`): each belongs to the one leaf that contains it
/// (cells are half-open, closed at the roots' upper faces) and moves to a half when its leaf
/// is split. A leaf C with check points y_j (n of them) has the misfit
///   c_k = |C|·(1/n) Σ_j (v_jk − 𝓘_C(y_j)) ≈ ∫_C (u − 𝓘_C) = ∫_C u − I_C,
/// the points taken as samples of the interpolant's error: a signed estimate of I_C's error
/// with d's sign convention. Where |c| > 4|d| (kMisfitOverDiscrepancy: where the Gauss nodes
/// see the feature too, d is the sharper estimate) c stands for d in the error model (Σ d in
/// the systematic part, Σ d² in the random part) and in the leaf's indicator. It sees what
/// the Gauss nodes are blind to — a jump between them, a thin strip, a feature inside a cell whose
/// nodes all read 0 — to the resolution of the check points: such a leaf is refined instead
/// of frozen as empty or accurate. Signed, because near a Zeno point the misfits of the
/// striped density cancel as the discrepancies do; |c| summed would never converge there.
/// The points are a sample of the leaf only while it is at least as wide as their spacing
/// on every axis: a narrower leaf takes no misfit (a node at a singularity, the ball's Zeno
/// point (0, 0), would otherwise hold its shrinking leaf at a large misfit for ever). Below
/// the spacing the blind spot remains (file comment).
template <std::size_t D, class Values>
class AdaptiveCubature {
 public:
  using Box = Cell<D>;  ///< A cell.

  /// Integrals over `roots` (roots[i].tag = i) of K slots; `values_per_point` (≥ K) sizes the
  /// batches; the target is rel_tol·scale if scale > 0, else rel_tol·max(|I_0|, |I_k|) per slot k.
  /// `checks` (may be null; must outlive the cubature): known values inside the roots.
  /// `targeted` (0: all K): only the slots k < targeted steer the refinement (split axes,
  /// indicators) and the stop test; the others are integrated on the same cells, passively
  /// (the faces' unresolved time-integral errors, budget/faces.hpp).
  /// `per_root`: keep each root's integral and error too, and stop on their L1 sum (file
  /// comment).
  AdaptiveCubature(std::vector<Box> roots, std::size_t K, std::size_t values_per_point,
                   const AdaptiveOptions& aopt, double scale, Values& values,
                   const CheckPoints<D>* checks = nullptr, std::size_t targeted = 0,
                   bool per_root = false)
      : rule_(aopt.order),
        roots_(std::move(roots)),
        K_(K),
        KT_(targeted > 0 && targeted < K ? targeted : K),
        aopt_(aopt),
        scale_(scale),
        values_(values),
        checks_(checks != nullptr && !checks->x.empty() ? checks : nullptr),
        per_root_(per_root) {
    for (std::size_t i = 0; i < roots_.size(); ++i) roots_[i].tag = i;
    // The misfit reads K values per check point (CheckPoints::v): a mismatch would read past
    // them (the cell averages' observables' slots once did; ASan found it).
    if (checks_ != nullptr && checks_->v.size() != checks_->x.size() * K_)
      throw std::logic_error("AdaptiveCubature: the check points carry " +
                             std::to_string(checks_->v.size()) + " values for " +
                             std::to_string(checks_->x.size()) + " points, not " +
                             std::to_string(K_) + " each");
    if (per_root_)
      for (std::vector<double>* v : {&rtotal_, &rD1_, &rD2_, &rO2_, &rA1_})
        v->assign(roots_.size() * K_, 0.0);
    stride_ = 5 * K_;
    total_.assign(K_, 0.0);
    D1_.assign(K_, 0.0);
    D2_.assign(K_, 0.0);
    O2_.assign(K_, 0.0);
    A1_.assign(K_, 0.0);
    for (Analysis& an : an_) {
      an.I.resize(K_);
      an.C.resize(K_);
      an.pred.resize(2 * K_);
      for (auto& t : an.Tk) t.resize(K_);
    }
    line_.resize(K_);
    d_.resize(K_);
    o_.resize(K_);
    const std::size_t per_batch = kBatchValues / std::max<std::size_t>(values_per_point, 1);
    batch_cap_ = std::max<std::size_t>(per_batch / (2 * rule_.Q), 1);
  }

  /// Run to the target or to the point budget; false if a characteristic failed.
  bool run() {
    const std::size_t Q = rule_.Q;
    // Initial cells: each root box cut into n_r parts per axis (root_parts; fewer if the
    // initial cells and their halves would take more than a quarter of the budget, the rest
    // being the refinement's; but 2 where 1 would be the answer and 2 fit in three quarters:
    // the file comment).
    const std::size_t want = static_cast<std::size_t>(std::max(aopt_.root_parts, 1));
    const auto initial_cells = [&](std::size_t parts) {
      std::size_t per_root = 1;
      for (std::size_t a = 0; a < D; ++a) per_root *= parts;
      return per_root * roots_.size();
    };
    std::size_t n_r = want, n_init = 0;
    for (;; --n_r) {
      n_init = initial_cells(n_r);
      if (n_r == 1 || 3 * n_init * Q <= aopt_.max_points / 4) break;
    }
    if (n_r == 1 && want >= 2 && 4 * initial_cells(2) * Q <= aopt_.max_points) {
      n_r = 2;
      n_init = initial_cells(2);
    }
    std::vector<Box> init;
    init.reserve(n_init);
    for (const Box& root : roots_) {
      std::size_t per_root = 1;
      for (std::size_t a = 0; a < D; ++a) per_root *= n_r;
      for (std::size_t r = 0; r < per_root; ++r) {
        Box c = root;
        std::size_t rem = r;
        for (std::size_t a = 0; a < D; ++a) {
          const std::size_t i = rem % n_r;
          rem /= n_r;
          const double w = root.hi[a] - root.lo[a], nr = static_cast<double>(n_r);
          if (i > 0) c.lo[a] = root.lo[a] + w * static_cast<double>(i) / nr;
          if (i + 1 < n_r) c.hi[a] = root.lo[a] + w * static_cast<double>(i + 1) / nr;
        }
        init.push_back(c);
      }
    }
    // Traced in batches of a split's size (the same sums, in the same order, as one batch).
    const std::size_t chunk = 2 * batch_cap_;
    std::vector<bool> assigned(checks_ != nullptr ? checks_->x.size() : 0, false);
    std::fill(d_.begin(), d_.end(), 0.0);
    std::fill(o_.begin(), o_.end(), 0.0);
    for (std::size_t first = 0; first < init.size(); first += chunk) {
      const std::size_t last = std::min(first + chunk, init.size());
      batch_.assign(init.begin() + static_cast<std::ptrdiff_t>(first),
                    init.begin() + static_cast<std::ptrdiff_t>(last));
      assign_checks(n_r == 1 ? first : kNoHint, assigned);
      if (!eval()) return false;
      for (std::size_t c = 0; c < batch_.size(); ++c) {
        analyse(c, an_[0]);
        for (std::size_t k = 0; k < K_; ++k) total_[k] += an_[0].I[k];
        if (per_root_)
          for (std::size_t k = 0; k < K_; ++k) rtotal_[batch_[c].tag * K_ + k] += an_[0].I[k];
        if constexpr (D > 0) store(c, an_[0], true);
      }
    }
    if constexpr (D == 0) {
      converged_ = true;  // points: the "integral" is exact
      return true;
    } else {
      // All initial cells are split once (they have no discrepancy yet).
      marked_.clear();
      while (!heap_.empty()) {
        marked_.push_back(heap_.top().second);
        heap_.pop();
      }
      live_ = 0.0;
      if (!split()) return false;
      // Leaves below freeze_tol_ can never be marked before the stop test holds.
      const std::size_t max_cells = std::max<std::size_t>(aopt_.max_points / Q, 1);
      const double s0 = scale_ > 0.0 ? scale_ : std::fabs(total_[0]);
      freeze_tol_ = aopt_.rel_tol * s0 / static_cast<double>(max_cells);
      const std::size_t cost = 2 * Q;
      for (;;) {
        const double excess = worst_excess();  // max_k E_k / target_k
        if (excess <= 1.0) {
          converged_ = done_ = true;
          return true;
        }
        if (heap_.empty() || points_ + cost > aopt_.max_points) {
          capped_ = done_ = true;
          return true;
        }
        if (half_.empty() && 2 * points_ >= aopt_.max_points) half_ = total_;
        const std::size_t cap = std::min((aopt_.max_points - points_) / cost, batch_cap_);
        // Dörfler marking: the largest indicators until the fraction θ of the live total;
        // θ = 1/2 far from the target, less when close (E ~ sqrt(Σ e²): marking the share
        // 1 − 1/excess² would suffice if marked errors vanished), to not overshoot.
        marked_.clear();
        const double theta = std::clamp(1.0 - 1.0 / (excess * excess), 0.2, 0.5);
        const double goal = theta * std::max(live_, 0.0);
        double acc = 0.0;
        while (!heap_.empty() && marked_.size() < cap && (marked_.empty() || acc < goal)) {
          acc += heap_.top().first;
          live_ -= heap_.top().first;
          marked_.push_back(heap_.top().second);
          heap_.pop();
        }
        if (!split()) return false;
      }
    }
  }

  /// Estimated |error| of slot k: |Σ d| + 2·sqrt(Σ d² + Σ o²), and once the run is over:
  ///  * if it spent more than half its point cap, at least the change of the integral over the
  ///    rest (an integral still moving that much is not closer to its limit than that; the
  ///    capped 4-D volume of tests/validation/test_two_balls.cpp, mass 0.498 against 0.871
  ///    at t = 2.5, had an estimate of 0.17 without this floor and 0.22 with it);
  ///  * if stopped by the cap, at least Σ |c| (the leaves' check-point misfits taken
  ///    one-signed: a cubature that could not refine to its target cannot count on their
  ///    cancelling).
  /// Neither floor catches a cubature that converges on a wrong value without moving (the
  /// same file's 4-D atom at rel_tol 1e-2 and 32768 points: 0.1015 against 0.1288 with an
  /// estimate of 8.5e-3, unchanged over its second half).
  double error(std::size_t k) const {
    const double e =
        std::fabs(D1_[k]) + 2.0 * std::sqrt(std::max(D2_[k], 0.0) + std::max(O2_[k], 0.0));
    if (!done_) return e;
    const double moved = half_.empty() ? 0.0 : std::fabs(total_[k] - half_[k]);
    return std::max({e, capped_ ? A1_[k] : 0.0, moved});
  }
  /// Integral of slot k.
  double integral(std::size_t k) const { return total_[k]; }
  /// Integral of slot k over root r alone (`per_root`).
  double root_integral(std::size_t r, std::size_t k) const { return rtotal_[r * K_ + k]; }
  /// Estimated |error| of root_integral(r, k) (`per_root`): |Σ d| + 2·sqrt(Σ d² + Σ o²) over
  /// the root's leaves, and once a capped run is over at least Σ |c| of its leaves.
  double root_error(std::size_t r, std::size_t k) const {
    const std::size_t i = r * K_ + k;
    const double e =
        std::fabs(rD1_[i]) + 2.0 * std::sqrt(std::max(rD2_[i], 0.0) + std::max(rO2_[i], 0.0));
    return done_ && capped_ ? std::max(e, rA1_[i]) : e;
  }
  /// Σ_r root_error(r, k): the estimated L1 error of the roots' integrals (`per_root`).
  double l1_error(std::size_t k) const {
    double s = 0.0;
    for (std::size_t r = 0; r < roots_.size(); ++r) s += root_error(r, k);
    return s;
  }
  /// Points traced.
  std::size_t points() const { return points_; }
  /// Leaves (live and frozen).
  std::size_t cells() const {
    return cells_.size() - free_.size() + frozen_ + (D == 0 ? roots_.size() : 0);
  }
  /// Refinement batches.
  int iterations() const { return iterations_; }
  /// Whether the target was met.
  bool converged() const { return converged_; }

 private:
  /// A cell's node values condensed: integral I[k], null-rule indicators Tk[a][k] and their
  /// maxima over k T[a], the split axis ax, the predictions pred[s·K + k] of its halves and
  /// the check-point misfit C[k] (0 without check points).
  struct Analysis {
    std::vector<double> I, C, pred;
    std::array<std::vector<double>, D> Tk;
    std::array<double, D> T{};
    std::size_t ax = 0;
  };

  /// max_k E_k / (rel_tol·scale_k) (∞ if a target is 0 and E_k is not); E_k is the L1 sum
  /// over the roots with `per_root`.
  double worst_excess() const {
    double w = 0.0;
    for (std::size_t k = 0; k < KT_; ++k) {
      const double s = scale_ > 0.0 ? scale_ : std::max(std::fabs(total_[0]), std::fabs(total_[k]));
      const double target = aopt_.rel_tol * s, e = per_root_ ? l1_error(k) : error(k);
      if (e > target)
        w = std::max(w, target > 0.0 ? e / target : std::numeric_limits<double>::infinity());
    }
    return w;
  }

  /// Values at the nodes of batch_ (one call: OpenMP over all the points).
  bool eval() {
    const std::size_t Q = rule_.Q;
    pts_.resize(batch_.size() * Q);
    for (std::size_t c = 0; c < batch_.size(); ++c)
      for (std::size_t n = 0; n < Q; ++n)
        for (std::size_t a = 0; a < D; ++a)
          pts_[c * Q + n][a] =
              batch_[c].lo[a] + (batch_[c].hi[a] - batch_[c].lo[a]) * rule_.xi[n][a];
    points_ += pts_.size();
    U_.assign(pts_.size() * K_, 0.0);
    return values_(std::span<const Box>(batch_), std::span<const std::array<double, D>>(pts_), Q,
                   U_);
  }

  /// Whether `y` lies in `cell`: lo ≤ y < hi on every axis, or y = hi at its root's upper
  /// face (so that every point of a root belongs to exactly one of its leaves).
  bool contains(const Box& cell, const std::array<double, D>& y) const {
    const Box& root = roots_[cell.tag];
    for (std::size_t a = 0; a < D; ++a) {
      const bool in = (cell.lo[a] <= y[a] && y[a] < cell.hi[a]) ||
                      (y[a] == cell.hi[a] && cell.hi[a] == root.hi[a]);
      if (!in) return false;
    }
    return true;
  }

  /// The check points of a batch_ of initial cells: each not yet `assigned` to the first cell
  /// that contains it. With uncut roots (`first`: the batch's first root), a point's
  /// `CheckPoints::root` hint is tried first, so that a grid's dual cells as roots do not
  /// cost a scan of every root per point.
  void assign_checks(std::size_t first, std::vector<bool>& assigned) {
    batch_own_.assign(batch_.size(), {});
    if (checks_ == nullptr) return;
    const bool hinted = first != kNoHint && checks_->root.size() == checks_->x.size();
    for (std::size_t j = 0; j < checks_->x.size(); ++j) {
      if (assigned[j]) continue;
      if (hinted) {
        const std::size_t r = checks_->root[j];
        if (r >= first && r - first < batch_.size() && contains(batch_[r - first], checks_->x[j])) {
          batch_own_[r - first].push_back(static_cast<std::uint32_t>(j));
          assigned[j] = true;
        }
        continue;
      }
      for (std::size_t c = 0; c < batch_.size(); ++c)
        if (contains(batch_[c], checks_->x[j])) {
          batch_own_[c].push_back(static_cast<std::uint32_t>(j));
          assigned[j] = true;
          break;
        }
    }
  }

  /// C[k] of cell c of the last batch (see the class comment).
  void misfit(std::size_t c, Analysis& an) {
    std::fill(an.C.begin(), an.C.end(), 0.0);
    if constexpr (D > 0) {
      const std::vector<std::uint32_t>& own = batch_own_[c];
      if (own.empty()) return;
      const std::size_t Q = rule_.Q, q = rule_.q, K = K_;
      const Box& cell = batch_[c];
      for (std::size_t a = 0; a < D; ++a)
        if (cell.hi[a] - cell.lo[a] < (1.0 - 1e-9) * checks_->spacing[a]) return;
      const double* u = &U_[c * Q * K];
      lag_.resize(D * q);
      diff_.resize(K);
      sum_.assign(K, 0.0);
      for (const std::uint32_t j : own) {
        const std::array<double, D>& y = checks_->x[j];
        for (std::size_t a = 0; a < D; ++a) {
          const double w = cell.hi[a] - cell.lo[a];
          const double xi = w > 0.0 ? (y[a] - cell.lo[a]) / w : 0.5;
          for (std::size_t i = 0; i < q; ++i) lag_[a * q + i] = rule_.lagrange(i, xi);
        }
        for (std::size_t k = 0; k < K; ++k) diff_[k] = -checks_->v[j * K + k];
        for (std::size_t n = 0; n < Q; ++n) {
          double w = 1.0;
          std::size_t rem = n;
          for (std::size_t a = 0; a < D; ++a) {
            w *= lag_[a * q + rem % q];
            rem /= q;
          }
          for (std::size_t k = 0; k < K; ++k) diff_[k] += w * u[n * K + k];
        }
        for (std::size_t k = 0; k < K; ++k) sum_[k] -= diff_[k];
      }
      const double f = cell.volume() / static_cast<double>(own.size());
      for (std::size_t k = 0; k < K; ++k) an.C[k] = f * sum_[k];
    }
  }

  /// Analyse cell c of the last batch. The split axis has the largest null-rule indicator;
  /// ties (e.g. all 0) go to the axis widest relative to its root box.
  void analyse(std::size_t c, Analysis& an) {
    const std::size_t Q = rule_.Q, q = rule_.q, K = K_;
    const Box& cell = batch_[c];
    const double vol = cell.volume();
    const double* u = &U_[c * Q * K];
    std::fill(an.I.begin(), an.I.end(), 0.0);
    for (std::size_t n = 0; n < Q; ++n)
      for (std::size_t k = 0; k < K; ++k) an.I[k] += rule_.W[n] * u[n * K + k];
    for (double& v : an.I) v *= vol;
    misfit(c, an);
    if constexpr (D > 0) {
      std::size_t step = 1;  // flat-index stride of axis a
      for (std::size_t a = 0; a < D; ++a) {
        std::vector<double>& t = an.Tk[a];
        std::fill(t.begin(), t.end(), 0.0);
        if (q > 1) {
          for (std::size_t n = 0; n < Q; ++n) {
            if ((n / step) % q != 0) continue;  // lines along a start at n_a = 0
            std::fill(line_.begin(), line_.end(), 0.0);
            for (std::size_t i = 0; i < q; ++i)
              for (std::size_t k = 0; k < K; ++k)
                line_[k] += rule_.nu[i] * u[(n + i * step) * K + k];
            const double wl = vol * rule_.W[n] / rule_.w1[0];  // weight of the line
            for (std::size_t k = 0; k < K; ++k) t[k] += wl * std::fabs(line_[k]);
          }
        }
        an.T[a] = *std::max_element(t.begin(), t.begin() + static_cast<std::ptrdiff_t>(KT_));
        step *= q;
      }
      const Box& root = roots_[cell.tag];
      an.ax = 0;
      double best_w = -1.0;
      for (std::size_t a = 0; a < D; ++a) {
        const double rw = root.hi[a] - root.lo[a];
        const double w = rw > 0.0 ? (cell.hi[a] - cell.lo[a]) / rw : 0.0;
        if (an.T[a] > an.T[an.ax] || (an.T[a] == an.T[an.ax] && w > best_w)) {
          an.ax = a;
          best_w = w;
        }
      }
      std::fill(an.pred.begin(), an.pred.end(), 0.0);
      for (std::size_t s = 0; s < 2; ++s) {
        const double* h = &rule_.half[(an.ax * 2 + s) * Q];
        for (std::size_t n = 0; n < Q; ++n)
          for (std::size_t k = 0; k < K; ++k) an.pred[s * K + k] += h[n] * u[n * K + k];
      }
      for (double& v : an.pred) v *= vol;
    }
  }

  /// Keep cell c of the last batch as a live leaf with discrepancy d_ and other-axes estimate
  /// o_ (both already in the running sums) and its check points, or freeze it (it stays in
  /// the sums only).
  void store(std::size_t c, const Analysis& an, bool force) {
    const Box& cell = batch_[c];
    double e = 0.0;
    for (std::size_t k = 0; k < KT_; ++k) e = std::max(e, std::fabs(d_[k]) + o_[k]);
    const Box& root = roots_[cell.tag];
    bool narrow = false;
    for (std::size_t a = 0; a < D; ++a)
      narrow = narrow || cell.hi[a] - cell.lo[a] <= kMinWidth * (root.hi[a] - root.lo[a]);
    if (!force && (e <= freeze_tol_ || narrow)) {
      ++frozen_;
      batch_own_[c].clear();
      return;
    }
    std::size_t slot;
    if (!free_.empty()) {
      slot = free_.back();
      free_.pop_back();
    } else {
      slot = cells_.size();
      cells_.emplace_back();
      own_.emplace_back();
      axis_.push_back(0);
      tsplit_.push_back(0.0);
      data_.resize(data_.size() + stride_);
    }
    cells_[slot] = cell;
    own_[slot] = std::move(batch_own_[c]);
    axis_[slot] = an.ax;
    tsplit_[slot] = an.T[an.ax];
    double* dst = &data_[slot * stride_];
    std::copy(an.pred.begin(), an.pred.end(), dst);
    std::copy(d_.begin(), d_.end(), dst + 2 * K_);
    std::copy(o_.begin(), o_.end(), dst + 3 * K_);
    if (force)
      std::fill(dst + 4 * K_, dst + 5 * K_, 0.0);  // an initial cell: its c is in no sum
    else
      std::copy(an.C.begin(), an.C.end(), dst + 4 * K_);
    heap_.emplace(force ? std::numeric_limits<double>::infinity() : e, slot);
    if (!force) live_ += e;
  }

  /// Split the leaves marked_ into their halves along their axes (one traced batch).
  bool split() {
    const std::size_t K = K_;
    batch_.clear();
    for (std::size_t s : marked_)
      for (std::size_t h = 0; h < 2; ++h) batch_.push_back(cells_[s].half(axis_[s], h));
    // The parent's check points go to the half that contains them (y < mid: the lower one).
    batch_own_.resize(batch_.size());
    for (std::size_t b = 0; b < marked_.size(); ++b) {
      const std::size_t s = marked_[b], a = axis_[s];
      batch_own_[2 * b].clear();
      batch_own_[2 * b + 1].clear();
      const double mid = batch_[2 * b].hi[a];
      for (const std::uint32_t j : own_[s])
        batch_own_[2 * b + (checks_->x[j][a] < mid ? 0 : 1)].push_back(j);
      own_[s].clear();
    }
    if (!eval()) return false;
    for (std::size_t b = 0; b < marked_.size(); ++b) {
      const std::size_t s = marked_[b];
      // A copy: storing the halves may reallocate data_.
      parent_.assign(data_.begin() + static_cast<std::ptrdiff_t>(s * stride_),
                     data_.begin() + static_cast<std::ptrdiff_t>((s + 1) * stride_));
      const double* pd = &parent_[2 * K];
      const double* po = &parent_[3 * K];
      const double* pc = &parent_[4 * K];
      for (std::size_t k = 0; k < K; ++k) {
        D1_[k] -= pd[k];
        D2_[k] -= pd[k] * pd[k];
        O2_[k] -= po[k] * po[k];
        A1_[k] -= std::fabs(pc[k]);
      }
      const std::size_t root = batch_[2 * b].tag;  // slot s may be reused below
      if (per_root_)
        for (std::size_t k = 0, i = root * K; k < K; ++k, ++i) {
          rD1_[i] -= pd[k];
          rD2_[i] -= pd[k] * pd[k];
          rO2_[i] -= po[k] * po[k];
          rA1_[i] -= std::fabs(pc[k]);
        }
      // ρ = (measured error along the split axis) / (its null-rule indicator), ≤ 1.
      double dsum = 0.0;
      for (std::size_t h = 0; h < 2; ++h) {
        analyse(2 * b + h, an_[h]);
        double m = 0.0;
        for (std::size_t k = 0; k < KT_; ++k)
          m = std::max(m, std::fabs(an_[h].I[k] - parent_[h * K + k]));
        dsum += m;
      }
      const double rho = tsplit_[s] > 0.0 ? std::min(1.0, dsum / tsplit_[s]) : 1.0;
      const std::size_t ax = axis_[s];
      free_.push_back(s);
      for (std::size_t h = 0; h < 2; ++h) {
        const Analysis& an = an_[h];
        for (std::size_t k = 0; k < K; ++k) {
          // The value moves by the discrepancy; the error model takes the discrepancy or,
          // where the check points see more, their misfit (class comment).
          const double dk = an.I[k] - parent_[h * K + k];
          total_[k] += dk;
          d_[k] = std::fabs(an.C[k]) > kMisfitOverDiscrepancy * std::fabs(dk) ? an.C[k] : dk;
          double o = 0.0;
          for (std::size_t a = 0; a < D; ++a)
            if (a != ax) o += an.Tk[a][k];
          o_[k] = rho * o;
          D1_[k] += d_[k];
          D2_[k] += d_[k] * d_[k];
          A1_[k] += std::fabs(an.C[k]);
          O2_[k] += o_[k] * o_[k];
          if (per_root_) {
            const std::size_t i = root * K + k;
            rtotal_[i] += dk;
            rD1_[i] += d_[k];
            rD2_[i] += d_[k] * d_[k];
            rA1_[i] += std::fabs(an.C[k]);
            rO2_[i] += o_[k] * o_[k];
          }
        }
        store(2 * b + h, an, false);
      }
    }
    ++iterations_;
    return true;
  }

  static constexpr double kMinWidth = 0x1p-40;           // relative width below which cells freeze
  static constexpr double kMisfitOverDiscrepancy = 4.0;  // c stands for d beyond this ratio
  static constexpr std::size_t kBatchValues = std::size_t{1} << 21;  // values per batch
  static constexpr std::size_t kNoHint = ~std::size_t{0};            // assign_checks: roots are cut

  CubatureRule<D> rule_;
  std::vector<Box> roots_;
  std::size_t K_;
  std::size_t KT_;  // the targeted slots: k < KT_
  AdaptiveOptions aopt_;
  double scale_;
  Values& values_;
  const CheckPoints<D>* checks_;
  bool per_root_ = false;
  std::size_t stride_ = 0, batch_cap_ = 1;
  // Live leaves: cell, split axis, T of the split axis; data_ per leaf: the halves'
  // predictions (2K), d (K), o (K), c (K). Freed slots are reused.
  std::vector<Box> cells_;
  std::vector<std::vector<std::uint32_t>> own_;  // the check points of each live leaf
  std::vector<std::size_t> axis_;
  std::vector<double> tsplit_, data_;
  std::vector<std::size_t> free_;
  std::priority_queue<std::pair<double, std::size_t>> heap_;  // (indicator, leaf)
  // Running sums over all leaves, frozen ones included.
  std::vector<double> total_, D1_, D2_, O2_, A1_;
  std::vector<double> half_;  // total_ when half of the points were spent (empty before)
  // per_root_: the running sums of each root r at [r·K + k].
  std::vector<double> rtotal_, rD1_, rD2_, rO2_, rA1_;
  double live_ = 0.0;  // Σ of the indicators in the heap
  double freeze_tol_ = 0.0;
  std::size_t frozen_ = 0, points_ = 0;
  int iterations_ = 0;
  bool converged_ = false, capped_ = false, done_ = false;
  // Work space.
  std::vector<Box> batch_;
  std::vector<std::vector<std::uint32_t>> batch_own_;  // the check points of each batch cell
  std::vector<std::array<double, D>> pts_;
  std::vector<double> U_, line_, d_, o_, parent_, lag_, diff_, sum_;
  std::vector<std::size_t> marked_;
  std::array<Analysis, 2> an_{};
};

}  // namespace detail

}  // namespace hybgen::rt
