#pragma once
/// \file budget.hpp
/// Accurate mass budgets by adaptive cubature: the box mass Σ_modes ∫_box u(t_k) and the
/// cumulative outflow through the box faces, for all output times at once, with u evaluated
/// exactly (to ODE tolerance) by backward characteristics at the cubature nodes.
///
/// Why adaptive. Near a Zeno point the density is unbounded and striped (bouncing ball,
/// e < 1: u ~ 1/(p² + 2x) near (0, 0), with jumps by 1/e² across curves winding into the
/// origin); elsewhere it jumps across the images of the reset surface. Fixed rules
/// (trapezoid on the grid nodes, uniform Gauss) miss O(1) of the mass near the Zeno point,
/// and the face fluxes jump at fixed places (e.g. where the reset image of a box edge meets a
/// face), which uniform face rules integrate with an O(h) error that accumulates over time.
/// The runtime does not know where any of this is, so the cubature finds it.
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
///  * Bounded work: leaves with e ≤ rel_tol·scale/(max cells) can never be marked before the
///    stop test holds (all of them together are below the target), so they are frozen:
///    their values stay in the sums, their storage is freed. Cells where the integrand is 0
///    (outside the support) freeze at once. Cells narrower than 2⁻⁴⁰ of the box are frozen
///    too (an unresolvable singularity keeps its honest share of E_k).
///  * Memory: 8·5K bytes per live leaf (K slots), at most max_points/q^D leaves, plus one
///    batch of ≤ 2²¹ (point, time, mode) values.
///
/// Faces: one cubature over all 2N faces together (cells tagged with their face), of the
/// cumulative outflow density at each output time (see `detail::FaceValues`); in time the
/// integral ∫₀^{t_k} u dt is taken along each face point's characteristic by adaptive
/// Gauss–Legendre on the ODE's dense output (CharacteristicsOptions::cumulative_tol), so a
/// flux that starts or stops inside an output interval costs a few more panels, not accuracy.
/// A face point costs one characteristic for all times, so the faces are cheap.
///
/// Atom: a third cubature, over the box, of the initial density of the points whose FORWARD
/// flow (forward.hpp) comes to rest at a Zeno point by each output time (`adaptive_atom`).
/// The three terms are measured independently, so mass0 − mass − outflow − atom (the defect)
/// tests them: within the sum of their estimates it says the budget is closed; beyond, it
/// is mass no term measures (a reset carrying mass across the box boundary, or an error
/// the estimates missed).
/// Size: the adaptive cubatures in space (box mass) and on the faces over time (outflow),
/// their error estimates and the atom's forward flow share the refinement machinery.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <queue>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/core/ode.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/forward.hpp"
#include "hybgen/rt/methods/mass_budget.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Options of the adaptive volume (and face) integrals.
struct AdaptiveOptions {
  double rel_tol = 1e-4;            ///< Target: estimated error ≤ rel_tol·max(mass0, mass_k).
  std::size_t max_points = 400000;  ///< Cap on traced points per integral (volume; faces).
  int order = 4;                    ///< Gauss–Legendre nodes per axis in a cell (≥ 1).
};

/// Result of `adaptive_mass`: masses per output time with estimated errors.
/// What an adaptive cubature did (shared by `AdaptiveMass` and `AdaptiveOutflow`).
struct CubatureStats {
  std::vector<double> error;    ///< Estimated |error| of each time's integral (see above).
  double error_estimate = 0.0;  ///< The largest estimated error.
  std::size_t points = 0;       ///< Points traced (each for all modes and times).
  std::size_t cells = 0;        ///< Leaf cells of the final partition.
  int iterations = 0;           ///< Refinement batches.
  bool converged = false;       ///< Whether the rel_tol target was met within max_points.
};

/// Result of `adaptive_mass` (`error[k]` is the estimated |error| of mass[k]).
struct AdaptiveMass : CubatureStats {
  std::vector<double> mass;      ///< Σ_modes ∫_box u(t_k), per output time.
  double mass0 = 0.0;            ///< Σ_modes ∫_box u0 by the same cubature.
  double mass0_error = 0.0;      ///< Estimated |error| of mass0 (also in error_estimate).
  std::size_t check_points = 0;  ///< Grid nodes the cubature checked itself against.
};

/// Result of `adaptive_outflow`: cumulative net outflow through the box faces
/// (`error[k]`: the space part of outflow[k]'s error; points are face points).
struct AdaptiveOutflow : CubatureStats {
  std::vector<double> outflow;  ///< ∫₀^{t_k} Σ_modes ∮_∂box u X·n_out, per output time.
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
  // Stopped by the point cap: a feature no node has seen yet at one time (the Zeno basin at
  // early times) has no estimate of its own, so every time gets the largest estimate of any.
  if (!stats.converged)
    for (double& e : stats.error) e = std::max(e, stats.error_estimate);
}

}  // namespace detail

/// Diagnostics of `adaptive_mass_budget`.
struct AdaptiveBudgetInfo {
  AdaptiveMass volume;      ///< The volume integral (masses).
  AdaptiveOutflow surface;  ///< The face integral (outflow).
  AdaptiveOutflow atom;     ///< The atom's integral (`outflow` holds the atom).
};

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

/// Points where the integrand is already known (the grid nodes the run solved): x[j] and
/// its K slot values v[j·K + k]. The cubature compares every leaf's interpolant with the
/// check points inside it (see `AdaptiveCubature`), so a feature the grid resolves cannot
/// hide between a cell's Gauss nodes.
template <std::size_t D>
struct CheckPoints {
  std::vector<std::array<double, D>> x;  ///< Coordinates.
  std::vector<double> v;                 ///< Values, K per point.
  std::array<double, D> spacing{};       ///< Their lattice's spacing per axis.
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
  AdaptiveCubature(std::vector<Box> roots, std::size_t K, std::size_t values_per_point,
                   const AdaptiveOptions& aopt, double scale, Values& values,
                   const CheckPoints<D>* checks = nullptr)
      : rule_(aopt.order),
        roots_(std::move(roots)),
        K_(K),
        aopt_(aopt),
        scale_(scale),
        values_(values),
        checks_(checks != nullptr && !checks->x.empty() ? checks : nullptr) {
    for (std::size_t i = 0; i < roots_.size(); ++i) roots_[i].tag = i;
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
    // Initial cells: each root box cut into n_r parts per axis (4; fewer if the initial
    // cells and their halves would take more than a quarter of the budget).
    std::size_t n_r = 4, n_init = 0;
    for (;; --n_r) {
      std::size_t per_root = 1;
      for (std::size_t a = 0; a < D; ++a) per_root *= n_r;
      n_init = per_root * roots_.size();
      if (n_r == 1 || 3 * n_init * Q <= aopt_.max_points / 4) break;
    }
    batch_.clear();
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
        batch_.push_back(c);
      }
    }
    assign_checks();
    if (!eval()) return false;
    std::fill(d_.begin(), d_.end(), 0.0);
    std::fill(o_.begin(), o_.end(), 0.0);
    for (std::size_t c = 0; c < batch_.size(); ++c) {
      analyse(c, an_[0]);
      for (std::size_t k = 0; k < K_; ++k) total_[k] += an_[0].I[k];
      if constexpr (D > 0) store(c, an_[0], true);
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

  /// max_k E_k / (rel_tol·scale_k) (∞ if a target is 0 and E_k is not).
  double worst_excess() const {
    double w = 0.0;
    for (std::size_t k = 0; k < K_; ++k) {
      const double s = scale_ > 0.0 ? scale_ : std::max(std::fabs(total_[0]), std::fabs(total_[k]));
      const double target = aopt_.rel_tol * s, e = error(k);
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

  /// The check points of the initial batch_: each to the first cell that contains it.
  void assign_checks() {
    batch_own_.assign(batch_.size(), {});
    if (checks_ == nullptr) return;
    for (std::size_t j = 0; j < checks_->x.size(); ++j)
      for (std::size_t c = 0; c < batch_.size(); ++c)
        if (contains(batch_[c], checks_->x[j])) {
          batch_own_[c].push_back(static_cast<std::uint32_t>(j));
          break;
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
        an.T[a] = *std::max_element(t.begin(), t.end());
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
    for (std::size_t k = 0; k < K_; ++k) e = std::max(e, std::fabs(d_[k]) + o_[k]);
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
      // ρ = (measured error along the split axis) / (its null-rule indicator), ≤ 1.
      double dsum = 0.0;
      for (std::size_t h = 0; h < 2; ++h) {
        analyse(2 * b + h, an_[h]);
        double m = 0.0;
        for (std::size_t k = 0; k < K; ++k)
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

  CubatureRule<D> rule_;
  std::vector<Box> roots_;
  std::size_t K_;
  AdaptiveOptions aopt_;
  double scale_;
  Values& values_;
  const CheckPoints<D>* checks_;
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
  double live_ = 0.0;         // Σ of the indicators in the heap
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

/// Volume integrand: Σ_modes u(t_k) at the points, for the time slots `slots`.
template <HybridModel M>
struct VolumeValues {
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  std::span<const double> slots;                    ///< Times (slots[0] = 0).
  const double* par = nullptr;                      ///< Parameters.
  const CharacteristicsOptions* opt = nullptr;      ///< Characteristics options.
  TraceFailure<N> failure{};                        ///< First failure.

  /// U[i·K + k] = Σ_m u(slots[k], m, pts[i]).
  bool operator()(std::span<const Cell<N>>, std::span<const std::array<double, N>> pts, std::size_t,
                  std::vector<double>& U) {
    const Solution<N> sol = evaluate<M>(pts, slots, par, *opt);
    if (!sol.ok()) {
      failure = sol.failure;
      return false;
    }
    const std::size_t K = slots.size();
    for (std::size_t k = 0; k < K; ++k)
      for (std::size_t m = 0; m < sol.n_mode; ++m)
        for (std::size_t i = 0; i < pts.size(); ++i) U[i * K + k] += sol.at(k, m, i);
    return true;
  }
};

/// Face integrand: the cumulative net outflow density at a face point,
///   g_k(y) = Σ_m fw_m(y) ∫₀^{t_k} u(t, m, y) dt,
/// the time integral taken along the characteristic from y to the tolerance `time_tol`
/// (CharacteristicsOptions::cumulative_tol: adaptive in time, so a flux that starts or stops
/// inside an output interval is integrated as accurately as one that does not), u the limit
/// from inside the box (FaceContext) and the flux weight fw_m = X_m·n_out, except at a point
/// of a guard surface S_h where h fires: the mass crossing there is reset to Δ_h(y) and
/// counts only if it leaves the box (outwards, Δ_h(y) outside) or enters it (inwards, Δ_h(y)
/// inside) — the rule of `detail::outflow`. Face f = 2a + side is normal to axis a at lo[a]
/// (side 0) or hi[a] (side 1); its D = N − 1 coordinates are the other axes in order; a
/// cell's tag indexes `face`.
template <HybridModel M>
struct FaceValues {
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  static constexpr std::size_t D = N - 1;           ///< Face dimension.
  std::span<const double> times;                    ///< Output times.
  std::array<double, N> lo{}, hi{};                 ///< The box.
  double diam = 0.0;                                ///< Largest box side.
  const double* par = nullptr;                      ///< Parameters.
  CharacteristicsOptions opt{};                     ///< Options, cumulative_tol > 0.
  TraceFailure<N> failure{};                        ///< First failure.
  std::vector<std::size_t> face;                    ///< Face 2a + side of each root box.
  std::vector<std::array<double, N>> y;             ///< Work: the points in ℝᴺ.
  std::vector<FaceContext<N>> ctx;                  ///< Work: their faces.

  /// U[i·K + k] = g_k(point i) for the face of each point's cell.
  bool operator()(std::span<const Cell<D>> cells, std::span<const std::array<double, D>> pts,
                  std::size_t per_cell, std::vector<double>& U) {
    const std::size_t P = pts.size(), K = times.size();
    y.resize(P);
    ctx.resize(P);
    for (std::size_t i = 0; i < P; ++i) {
      const std::size_t f = face[cells[i / per_cell].tag], a = f / 2;
      if constexpr (D > 0) {
        for (std::size_t b = 0, j = 0; b < N; ++b)
          if (b != a) y[i][b] = pts[i][j++];
      }
      y[i][a] = f % 2 == 0 ? lo[a] : hi[a];
      ctx[i] = FaceContext<N>{};
      ctx[i].inward[a] = f % 2 == 0 ? 1.0 : -1.0;
      ctx[i].lo = lo;
      ctx[i].hi = hi;
    }
    const Solution<N> sol = evaluate<M>(std::span<const std::array<double, N>>(y), times, par, opt,
                                        std::span<const FaceContext<N>>(ctx));
    if (!sol.ok()) {
      failure = sol.failure;
      return false;
    }
    for (std::size_t i = 0; i < P; ++i) {
      const std::size_t a = face[cells[i / per_cell].tag] / 2;
      const double sign = ctx[i].inward[a] > 0.0 ? -1.0 : 1.0;  // n_out along a
      const double* yi = y[i].data();
      if (!M::in_support(yi, par)) continue;
      for (std::size_t m = 0; m < sol.n_mode; ++m) {
        const double xn = face_flux<M>(static_cast<int>(m), yi, a, sign, lo, hi, diam, par);
        if (xn == 0.0) continue;
        for (std::size_t k = 0; k < K; ++k) U[i * K + k] += xn * sol.at(k, m, i);
      }
    }
    return true;
  }
};

}  // namespace detail

/// Largest number of check points of the volume cubature: their values come with the run's
/// solution (`detail::volume_checks`), so all the nodes of most grids.
inline std::size_t max_volume_checks(const AdaptiveOptions& aopt) {
  return std::max<std::size_t>(aopt.max_points, std::size_t{1} << 14);
}

/// Largest number of check points of the atom's cubature: each costs a forward flow, so a
/// quarter of the cubature's own point cap (`adaptive_atom`).
inline std::size_t max_atom_checks(const AdaptiveOptions& aopt) {
  return std::max<std::size_t>(aopt.max_points / 4, 1);
}

namespace detail {

/// The grid's nodes in the box [lo, hi], every s-th per axis (node indices divisible by s)
/// with the smallest s that keeps them to `cap`: their flat indices, in C order;
/// `checks.x` and `checks.spacing` (s times the grid's) are set.
template <std::size_t N>
std::vector<std::size_t> check_lattice(const TensorGrid<N>& grid, std::size_t cap,
                                       const std::array<double, N>& lo,
                                       const std::array<double, N>& hi, CheckPoints<N>& checks) {
  std::array<std::size_t, N> first{}, last{};  // node index range in [lo, hi] per axis
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    const auto n = static_cast<std::size_t>(std::max(ax.n, 1));
    first[a] = n;
    last[a] = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double x = axis_node(ax, static_cast<int>(i));
      if (x < lo[a] || x > hi[a]) continue;
      first[a] = std::min(first[a], i);
      last[a] = std::max(last[a], i);
    }
    if (first[a] > last[a]) return {};
  }
  std::size_t stride = 1;
  for (;; ++stride) {
    std::size_t count = 1;
    for (std::size_t a = 0; a < N; ++a)
      count *= last[a] / stride - (first[a] + stride - 1) / stride + 1;
    if (count <= cap) break;
  }
  std::vector<std::size_t> flat;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    std::size_t rem = i;
    bool keep = true;
    for (std::size_t a = N; a-- > 0 && keep;) {
      const auto n = static_cast<std::size_t>(std::max(grid.axes[a].n, 1));
      const std::size_t ia = rem % n;
      keep = ia % stride == 0 && ia >= first[a] && ia <= last[a];
      rem /= n;
    }
    if (keep) flat.push_back(i);
  }
  checks.x.resize(flat.size());
  for (std::size_t j = 0; j < flat.size(); ++j) checks.x[j] = grid.node(flat[j]);
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = grid.axes[a];
    checks.spacing[a] =
        ax.n > 1 ? static_cast<double>(stride) * (ax.max - ax.min) / (ax.n - 1) : ax.max - ax.min;
  }
  return flat;
}

/// Whether x lies on the boundary of M's support, to the resolution `h`: one of the probes
/// x ± 1e-6·h_a e_a is on the other side of it.
template <HybridModel M>
bool on_support_boundary(const std::array<double, state_dim_v<M>>& x,
                         const std::array<double, state_dim_v<M>>& h, const double* par) {
  const bool in = M::in_support(x.data(), par);
  for (std::size_t a = 0; a < x.size(); ++a) {
    for (const double sign : {-1.0, 1.0}) {
      std::array<double, state_dim_v<M>> y = x;
      y[a] += sign * 1e-6 * h[a];
      if (M::in_support(y.data(), par) != in) return true;
    }
  }
  return false;
}

/// Set checks.v = v (K values per point of checks.x), leaving out the points with a
/// non-finite value (a node at a singularity) and the points on the support's boundary:
/// the density jumps to 0 there, and a node on the jump holds one side's value, no sample of
/// the cell around it (a support aligned with the grid, sir's s + i ≤ 1 or the ball's
/// x ≥ 0, puts a whole row of nodes on it, and their misfits would all have one sign).
template <HybridModel M>
void keep_samples(CheckPoints<state_dim_v<M>>& checks, std::vector<double> v, std::size_t K,
                  const double* par) {
  std::size_t kept = 0;
  for (std::size_t j = 0; j < checks.x.size(); ++j) {
    bool finite = true;
    for (std::size_t k = 0; k < K; ++k) finite = finite && std::isfinite(v[j * K + k]);
    if (!finite || on_support_boundary<M>(checks.x[j], checks.spacing, par)) continue;
    checks.x[kept] = checks.x[j];
    std::copy_n(v.begin() + static_cast<std::ptrdiff_t>(j * K), K,
                v.begin() + static_cast<std::ptrdiff_t>(kept * K));
    ++kept;
  }
  checks.x.resize(kept);
  v.resize(kept * K);
  checks.v = std::move(v);
}

/// The volume cubature's check points: the grid's nodes (`check_lattice` to
/// `max_volume_checks`: all of them on the grids of the shipped models), each with Σ_modes u at the
/// cubature's slots. `nodes` (may be null) is the run's solution at all grid nodes for the times
/// slots[off..] (solve_grid); without it, or for the t = 0 slot that `times` lacks, the values are
/// computed here (characteristics; u0). A characteristic traced here that fails (a flow that
/// is singular on the box's boundary, which the cubature's interior nodes never touch)
/// leaves the cubature without check points: its own nodes report the failures that matter.
template <HybridModel M>
void volume_checks(const TensorGrid<state_dim_v<M>>& grid, std::span<const double> slots,
                   std::size_t off, const Solution<state_dim_v<M>>* nodes, const double* par,
                   const CharacteristicsOptions& opt, const AdaptiveOptions& aopt,
                   CheckPoints<state_dim_v<M>>& checks) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::size_t K = slots.size();
  if (nodes != nullptr &&
      (nodes->n_point != grid.size() || nodes->n_time + off != K || !nodes->ok()))
    nodes = nullptr;
  std::array<double, N> lo{}, hi{};
  for (std::size_t a = 0; a < N; ++a) {
    lo[a] = grid.axes[a].min;
    hi[a] = grid.axes[a].max;
  }
  const std::vector<std::size_t> flat =
      check_lattice(grid, max_volume_checks(aopt), lo, hi, checks);
  std::vector<double> v(flat.size() * K, 0.0);
  if (nodes != nullptr) {
    // A distributed solution (several ranks) holds each (mode, node) on one rank: the values
    // at the check points are summed over the ranks per mode (0 + u: exact), then over the
    // modes in order, as here in one process: the same bits on every rank and as one process.
    const std::size_t n_mode = nodes->n_mode;
    std::vector<double> u(flat.size() * K * n_mode, 0.0);
    const Block own = nodes->distributed ? nodes->owned : Block{0, n_mode * nodes->n_point};
    for (std::size_t j = 0; j < flat.size(); ++j)
      for (std::size_t k = 0; k + off < K; ++k)
        for (std::size_t m = 0; m < n_mode; ++m)
          if (const std::size_t pair = m * nodes->n_point + flat[j];
              pair >= own.begin && pair < own.end)
            u[(j * K + k + off) * n_mode + m] = nodes->at(k, m, flat[j]);
    if (nodes->distributed && opt.backend != nullptr)
      opt.backend->sum_disjoint(std::span<double>(u));
    for (std::size_t jk = 0; jk < flat.size() * K; ++jk)
      for (std::size_t m = 0; m < n_mode; ++m) v[jk] += u[jk * n_mode + m];
    for (std::size_t j = 0; j < flat.size(); ++j) {
      if (off == 1 && M::in_support(checks.x[j].data(), par))
        for (int m = 0; m < M::n_mode; ++m)
          v[j * K] += M::initial_density(m, checks.x[j].data(), par);
    }
  } else {
    const Solution<N> sol =
        evaluate<M>(std::span<const std::array<double, N>>(checks.x), slots, par, opt);
    if (!sol.ok()) {
      checks = {};
      return;
    }
    for (std::size_t j = 0; j < flat.size(); ++j)
      for (std::size_t k = 0; k < K; ++k)
        for (std::size_t m = 0; m < sol.n_mode; ++m) v[j * K + k] += sol.at(k, m, j);
  }
  keep_samples<M>(checks, std::move(v), K, par);
}

}  // namespace detail

/// Adaptive cubature of Σ_modes ∫_box u(t_k) for every output time at once (one
/// characteristics evaluation per node serves all times), `box` = the box of the grid's
/// axes. mass0 is the same cubature at t = 0 (the t = 0 slot of `times`, or an extra slot),
/// so atom(0) = 0 exactly when times[0] = 0. The grid's nodes are the cubature's check
/// points (`detail::volume_checks`; `nodes`: the run's solution there, or null to compute
/// it), so its estimate sees what the grid resolves. On a failed characteristic `failure` is
/// set and the partial result returned (converged = false).
template <HybridModel M>
AdaptiveMass adaptive_mass(const TensorGrid<state_dim_v<M>>& box, std::span<const double> times,
                           const double* par, const CharacteristicsOptions& opt,
                           const AdaptiveOptions& aopt, TraceFailure<state_dim_v<M>>& failure,
                           const Solution<state_dim_v<M>>* nodes = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  detail::validate_times(times);
  const std::size_t off = !times.empty() && times.front() == 0.0 ? 0 : 1;
  std::vector<double> slots(times.size() + off, 0.0);
  for (std::size_t k = 0; k < times.size(); ++k) slots[k + off] = times[k];
  detail::Cell<N> root;
  for (std::size_t a = 0; a < N; ++a) {
    root.lo[a] = box.axes[a].min;
    root.hi[a] = box.axes[a].max;
  }
  detail::CheckPoints<N> checks;
  detail::volume_checks<M>(box, slots, off, nodes, par, opt, aopt, checks);
  detail::VolumeValues<M> values{slots, par, &opt, {}};
  const std::size_t per_point = slots.size() * static_cast<std::size_t>(M::n_mode);
  detail::AdaptiveCubature<N, detail::VolumeValues<M>> cub({root}, slots.size(), per_point, aopt,
                                                           0.0, values, &checks);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  AdaptiveMass res;
  res.check_points = checks.x.size();
  res.mass0 = cub.integral(0);
  res.mass0_error = cub.error(0);
  res.error_estimate = res.mass0_error;
  detail::collect(cub, ok, off, times.size(), res.mass, res);
  return res;
}

/// Adaptive cubature of the cumulative net outflow through the faces of `box` (the rule of
/// `detail::outflow`, see `detail::FaceValues`), all faces in one cubature; in time the
/// integral along each face point's characteristic to the relative tolerance `time_tol`. The
/// target is rel_tol·scale per output time (scale: e.g. the box mass; ≤ 0: the largest
/// |outflow|).
template <HybridModel M>
AdaptiveOutflow adaptive_outflow(const TensorGrid<state_dim_v<M>>& box,
                                 std::span<const double> times, const double* par,
                                 const CharacteristicsOptions& opt, const AdaptiveOptions& aopt,
                                 double scale, double time_tol,
                                 TraceFailure<state_dim_v<M>>& failure) {
  constexpr std::size_t N = state_dim_v<M>;
  constexpr std::size_t D = N - 1;
  detail::validate_times(times);
  AdaptiveOutflow res;
  res.outflow.assign(times.size(), 0.0);
  res.error.assign(times.size(), 0.0);
  detail::FaceValues<M> values;
  values.times = times;
  values.par = par;
  values.opt = opt;
  values.opt.cumulative_tol = time_tol > 0.0 ? time_tol : detail::kFluxTimeTol;
  if (times.empty() || times.back() <= 0.0) {
    res.converged = true;
    return res;
  }
  std::vector<detail::Cell<D>> faces;
  for (std::size_t a = 0; a < N; ++a) {
    values.lo[a] = box.axes[a].min;
    values.hi[a] = box.axes[a].max;
    values.diam = std::max(values.diam, values.hi[a] - values.lo[a]);
  }
  for (std::size_t a = 0; a < N; ++a) {
    for (std::size_t side = 0; side < 2; ++side) {
      if (side == 1 && values.hi[a] == values.lo[a]) continue;
      detail::Cell<D> f;
      for (std::size_t b = 0, j = 0; b < N; ++b) {
        if (b == a) continue;
        f.lo[j] = values.lo[b];
        f.hi[j] = values.hi[b];
        ++j;
      }
      f.tag = faces.size();
      faces.push_back(f);
      values.face.push_back(2 * a + side);
    }
  }
  const std::size_t per_point = times.size() * (1 + static_cast<std::size_t>(M::n_mode));
  detail::AdaptiveCubature<D, detail::FaceValues<M>> cub(faces, times.size(), per_point, aopt,
                                                         scale, values);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  detail::collect(cub, ok, 0, times.size(), res.outflow, res);
  return res;
}

namespace detail {

/// Atom integrand: the initial density of the points whose FORWARD flow has come to rest at a
/// Zeno accumulation point by each output time (forward.hpp's Zeno signature),
///   U[i·K + k] = Σ_m u0(m, x_i)·[t_Z(m, x_i) ≤ t_k].
/// The atom is thereby MEASURED where resets accumulate, independently of the backward
/// characteristics that give the mass and the outflow, so mass0 − mass − outflow − atom is a
/// real check of the budget. A forward flow that hits its event cap without the Zeno
/// signature (chattering) or fails numerically is a failure of the budget (`failure`).
template <HybridModel M>
struct ZenoValues {
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  std::span<const double> times;                    ///< Output times.
  const double* par = nullptr;                      ///< Parameters.
  ForwardOptions fopt{};                            ///< Options of the forward flows.
  const Backend* backend = nullptr;  ///< Ranks sharing the points (null: this process).
  std::string failure;               ///< First failure (describe), or empty.

  /// U[i·K + k] as above, OpenMP over the points.
  bool operator()(std::span<const Cell<N>>, std::span<const std::array<double, N>> pts, std::size_t,
                  std::vector<double>& U) {
    const std::size_t K = times.size();
    const auto P = static_cast<long long>(pts.size());
    const Backend& b = backend ? *backend : serial_backend();
    const Block mine = b.block(pts.size());
    std::atomic<long long> first_fail{P};
    std::string msg;
#pragma omp parallel
    {
      ForwardFlow<M> flow(par, fopt);
#pragma omp for schedule(dynamic, 8)
      for (auto ii = static_cast<long long>(mine.begin); ii < static_cast<long long>(mine.end);
           ++ii) {
        if (ii > first_fail.load(std::memory_order_relaxed)) continue;
        const auto i = static_cast<std::size_t>(ii);
        const std::array<double, N>& x = pts[i];
        if (!M::in_support(x.data(), par)) continue;
        for (int m = 0; m < M::n_mode; ++m) {
          const double u0 = M::initial_density(m, x.data(), par);
          if (u0 == 0.0) continue;  // no mass: its fate does not matter
          const ForwardResult<N> r =
              flow.run(m, x, times, [](std::size_t, int, const std::array<double, N>&) {});
          if (r.status == ForwardStatus::event_cap || r.status == ForwardStatus::failed) {
#pragma omp critical(hybgen_rt_budget_zeno_failure)
            {
              if (ii < first_fail.load()) {
                first_fail.store(ii);
                msg = describe<M>(r, m, x);
              }
            }
            break;
          }
          if (r.status != ForwardStatus::zeno) continue;
          for (std::size_t k = 0; k < K; ++k)
            if (times[k] >= r.t_stop) U[i * K + k] += u0;
        }
      }
    }
    if (b.ranks() > 1) {
      // Point i's K values are U[i·K, (i + 1)·K): the blocks of points tile U in rank order.
      const std::vector<double> all =
          b.all_gather(std::span<const double>(U.data() + mine.begin * K, mine.size() * K));
      std::copy(all.begin(), all.end(), U.begin());
      const std::int64_t first = b.min(std::int64_t{first_fail.load()});
      if (first < P) {
        const std::int64_t owner =
            b.min(first_fail.load() == first ? std::int64_t{b.rank()} : b.ranks());
        msg = b.broadcast(msg, static_cast<int>(owner));
        first_fail.store(first);
      }
    }
    if (first_fail.load() < P) {
      failure = msg;
      return false;
    }
    return true;
  }
};

/// Root cells per axis of the atom's cubature (each cut into 4 per axis by the cubature, with
/// 4 Gauss nodes per axis per cell): 32 nodes per axis up to 2-D, so that a small basin of
/// Zeno points is not missed by the first level of nodes; 16 above.
inline constexpr std::size_t zeno_roots_per_axis(std::size_t n) {
  return n <= 2 ? 2 : 1;
}

}  // namespace detail

/// Adaptive cubature of the Zeno atom: atom[k] = Σ_m ∫_box u0·[t_Z ≤ t_k] (see
/// `detail::ZenoValues`), all times at once, target rel_tol·scale, over the part of the box
/// where the grid's nodes see u0 > 0 (widened by a cell), with the grid's nodes there as
/// check points. Models without guards have no atom (0, exactly, without a flow). On a
/// failed forward flow `failure` is set.
template <HybridModel M>
AdaptiveOutflow adaptive_atom(const TensorGrid<state_dim_v<M>>& box, std::span<const double> times,
                              const double* par, const CharacteristicsOptions& opt,
                              const AdaptiveOptions& aopt, double scale, std::string& failure) {
  constexpr std::size_t N = state_dim_v<M>;
  detail::validate_times(times);
  AdaptiveOutflow res;  // `outflow` holds the atom
  res.outflow.assign(times.size(), 0.0);
  res.error.assign(times.size(), 0.0);
  if (M::n_guard == 0 || times.empty() || times.back() <= 0.0) {
    res.converged = true;
    return res;
  }
  detail::ZenoValues<M> values;
  values.times = times;
  values.par = par;
  values.backend = opt.backend;
  values.fopt.ode = opt.ode;
  values.fopt.graze_tol = opt.graze_tol;
  // The run's event cap (`max_events`, 100000 by default), not the forward flow's 1000: a
  // model that switches often over a long horizon without Zeno (a spiking neuron) must not
  // fail its budget where its characteristics pass.
  values.fopt.max_events = opt.max_events;
  // The integrand is 0 where u0 is: the cubature covers the box of the grid nodes with
  // u0 > 0, widened by one grid cell (u0 between nodes), clipped to the grid's box. A
  // localized initial density then gets the cubature's whole resolution (a 4-D density on
  // 4 % of the box, tests/validation/test_two_balls.cpp, was otherwise seen by a handful of
  // nodes and its atom underestimated 40-fold under budget=fast's point cap).
  std::array<double, N> slo{}, shi{};
  slo.fill(std::numeric_limits<double>::infinity());
  shi.fill(-std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < box.size(); ++i) {
    const std::array<double, N> y = box.node(i);
    if (!M::in_support(y.data(), par)) continue;
    bool mass = false;
    for (int m = 0; m < M::n_mode && !mass; ++m) mass = M::initial_density(m, y.data(), par) > 0.0;
    if (!mass) continue;
    for (std::size_t a = 0; a < N; ++a) {
      slo[a] = std::min(slo[a], y[a]);
      shi[a] = std::max(shi[a], y[a]);
    }
  }
  if (!(slo[0] <= shi[0])) {  // no node carries mass: none reaches a Zeno point either
    res.converged = true;
    return res;
  }
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = box.axes[a];
    const double h = ax.n > 1 ? (ax.max - ax.min) / (ax.n - 1) : 0.0;
    slo[a] = std::max(ax.min, slo[a] - h);
    shi[a] = std::min(ax.max, shi[a] + h);
  }
  const std::size_t R = detail::zeno_roots_per_axis(N);
  std::vector<detail::Cell<N>> roots;
  std::size_t total = 1;
  for (std::size_t a = 0; a < N; ++a) total *= R;
  for (std::size_t flat = 0; flat < total; ++flat) {
    detail::Cell<N> c;
    std::size_t rem = flat;
    for (std::size_t a = 0; a < N; ++a) {
      const std::size_t j = rem % R;
      rem /= R;
      const double lo = slo[a], hi = shi[a];
      c.lo[a] = lo + (hi - lo) * static_cast<double>(j) / static_cast<double>(R);
      c.hi[a] =
          j + 1 == R ? hi : lo + (hi - lo) * static_cast<double>(j + 1) / static_cast<double>(R);
    }
    roots.push_back(c);
  }
  // Check points: the grid's nodes in the cubature's box, with their atom integrand from the
  // same forward flows, so that a Zeno basin the grid resolves is not missed between Gauss
  // nodes (tests/validation/test_two_balls.cpp at budget=fast: 0.103 against 0.129 with an
  // estimate of 4.5e-3 without them, 0.1015 with 1.0e-2 with them — the basin's edge is
  // finer than that test's 9 nodes per axis). A failed flow there leaves the cubature
  // without check points; its own nodes report the failures that matter.
  detail::CheckPoints<N> checks;
  {
    detail::check_lattice(box, max_atom_checks(aopt), slo, shi, checks);
    std::vector<double> v(checks.x.size() * times.size(), 0.0);
    if (values(std::span<const detail::Cell<N>>{}, std::span<const std::array<double, N>>(checks.x),
               1, v)) {
      detail::keep_samples<M>(checks, std::move(v), times.size(), par);
    } else {
      checks = {};
      values.failure.clear();
    }
  }
  detail::AdaptiveCubature<N, detail::ZenoValues<M>> cub(
      std::move(roots), times.size(), times.size(), aopt, scale, values, &checks);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  detail::collect(cub, ok, 0, times.size(), res.outflow, res);
  return res;
}

/// The mass budget by adaptive cubature, every term measured on its own:
///  * mass and mass0: `adaptive_mass` (backward characteristics in the box);
///  * outflow: `adaptive_outflow` (backward characteristics on the faces, integrated in time
///    along each to rel_tol/10), target rel_tol·max(mass0, max_k mass_k);
///  * atom: `adaptive_atom` (forward flows from the box to their Zeno points), same target.
/// Each has its estimated error (mass_error, outflow_error, atom_error); the DEFECT
/// mass0 − mass − outflow − atom (`budget_defect`) checks them against each other: it is what
/// no term accounts for (inflow of mass that started outside the box, mass reset out of the
/// box from inside it, or an error the estimates missed). `grid` gives the box and the
/// volume cubature's check points (`nodes`: the run's solution at its nodes, or null).
/// A failed characteristic is reported in `failure` (volume first), a failed forward flow in
/// `message`.
template <HybridModel M>
BudgetResult<state_dim_v<M>> adaptive_mass_budget(const TensorGrid<state_dim_v<M>>& grid,
                                                  std::span<const double> times, const double* par,
                                                  const CharacteristicsOptions& opt,
                                                  const AdaptiveOptions& aopt = {},
                                                  AdaptiveBudgetInfo* info = nullptr,
                                                  const Solution<state_dim_v<M>>* nodes = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  BudgetResult<N> res;
  MassBudget& mb = res.budget;
  mb.times.assign(times.begin(), times.end());
  AdaptiveMass am = adaptive_mass<M>(grid, times, par, opt, aopt, res.failure, nodes);
  double scale = std::fabs(am.mass0);
  for (const double m : am.mass) scale = std::max(scale, std::fabs(m));
  TraceFailure<N> flux_failure;
  const double time_tol = 0.1 * aopt.rel_tol;
  AdaptiveOutflow ao =
      adaptive_outflow<M>(grid, times, par, opt, aopt, scale, time_tol, flux_failure);
  if (res.failure.ok()) res.failure = flux_failure;
  AdaptiveOutflow az = adaptive_atom<M>(grid, times, par, opt, aopt, scale, res.message);
  mb.mass0 = am.mass0;
  mb.mass = am.mass;
  mb.mass_error = am.error;
  mb.mass0_error = am.mass0_error;
  mb.outflow = ao.outflow;
  mb.atom = az.outflow;
  mb.outflow_error.resize(times.size());
  mb.atom_error = az.error;
  // The time integral's tolerance is relative to max|u| along each face characteristic:
  // ≤ time_tol·scale over the run (scale ≥ the mass that can cross).
  for (std::size_t k = 0; k < times.size(); ++k)
    mb.outflow_error[k] = ao.error[k] + time_tol * scale;
  if (info != nullptr) {
    info->volume = std::move(am);
    info->surface = std::move(ao);
    info->atom = std::move(az);
  }
  return res;
}

}  // namespace hybgen::rt
