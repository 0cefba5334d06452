// Validation: mass that bounces once off an inelastic wall and then leaves the box, the
// whole flux starting and stopping inside ONE output interval, a model hybgen does not ship,
// against closed forms derived here (none of them comes from hybgen).
//
// A particle with linear drag, x' = p, p' = −γp (γ = 1/2), on the state space x ≥ 0, hits the
// wall x = 0 (guard `wall`, s = x decreasing) and rebounds with restitution e = 1/2: (x, p) ↦
// (x, −e p). div X = −γ, so the density grows like e^{γt} along the flow; DΔ = diag(1, −e),
// adj DΔ = diag(−e, 1), X⁺ = (−e p, γ e p), ∇s = (1, 0): J = (−e)(−e p)/p = e² = 1/4 (every
// impact concentrates the density fourfold). The box is [0, L] × [−3.1, 1.5], L = 1: mass leaves
// through the face x = L only (the face x = 0 is the wall, where mass is reset, not lost).
//
// Closed forms. In a flight p(t) = p0 e^{−γt}, x(t) = x0 + p0(1 − e^{−γt})/γ, so c = p + γx is
// constant (dp/dx = −γ). From (x0, p0 < 0) with c = p0 + γx0 < 0 the wall is reached at
// t1 = −ln(c/p0)/γ with speed |c|; the rebound leaves at q = −e c > 0 and reaches x = L (if q >
// γL) after s = −ln(1 − γL/q)/γ. The exit time T(x0, p0) = t1 + s increases with x0 and with
// p0 (farther from the wall, slower). Hence
//   outflow(t) = ∫ u0 [T ≤ t]  (`outflow`: for each p0 the x0 with T ≤ t are x0 ≤ X(p0, t), by
//                bisection, ∫ a by its antiderivative; Gauss–Legendre in p0 on panels broken
//                where X(p0, t) reaches the ends of a's support, so the integrand is smooth);
//   mass(t) = 1 − outflow(t) (nothing else leaves; no Zeno point is reached: one bounce).
// The density, backwards from (x, p): with p > 0 the flight meets the wall after τ1 = ln(1 +
// γx/p)/γ at the post-impact state (0, p + γx), whose pre-image is (0, −(p + γx)/e) with the
// factor 1/e²; then a flight back for the rest of the time. u(t, y) = u0(foot)·e^{γt}/e^{2n}
// (n = 0 or 1 impacts): `exact`, a closed-form backward map.
//
// u0 = a(x) b(p): a the unit sin² bump on [0.3, 0.7], b = (15/16w)(1 − ((p + 2.5)/w)²)² on
// |p + 2.5| < w = 1/2 (unit mass). Every state bounces within t1 ∈ [0.10, 0.39] and leaves
// within T ∈ [0.97, 2.25]: with the output times 0, 0.05, 2.5 the whole flux, the bounce
// included, lies inside the interval (0.05, 2.5).
//
// Compared:
//  * characteristics (solve_grid, 41 × 93 nodes, 6 times up to 2.5): error relative to
//    max(u, 1) below 100·rtol for rtol 1e-10 and 1e-12 (docs/methods.md: the error is the ODE
//    tolerance; measured 3.7e-9 and 4.6e-11).
//  * its mass budget (adaptive_mass_budget, what `hybgen run` reports) at the output times 0,
//    0.05, 2.5 (rel_tol 1e-4 and the runner's 3e-4): the outflow against outflow(t) within its
//    own estimate outflow_error, the mass against 1 − outflow(t) within mass_error plus the
//    target, atom 0, and the defect mass0 − mass − outflow − atom (rt::budget_defect) within
//    rt::kDefectFactor × rt::budget_defect_error (the run's closure check, methods.hpp); the
//    same at 11 output times through the exit window. On a taller box the 41 × 93 grid
//    does not resolve the post-impact strip and the volume cubature misses 0.9 % of the mass
//    with a small estimate (figures at the test; a fifth of it before the grid's nodes were
//    its check points): the closure check flags it as docs/outputs.md promises (asserted); on a
//    grid twice as fine the mass is within its estimate (asserted).
//  * transfer (hat, h = 0.25): outflow and density against the closed forms on two grids,
//    with the convergence ratios (docs/methods.md: O(Δx²/h) plus the error where mass crosses the
//    guard; figures at the test).
//  * particles (2·10⁵): mass and outflow within 5σ (σ² ≤ F·Σw²/Σw, the compound-Poisson
//    bound of test_outflow.cpp; measured |z| ≤ 0.93).

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/budget.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "hybgen/rt/methods/transfer.hpp"
#include "support/hand_models.hpp"

namespace {

namespace rt = hybgen::rt;
using P2 = std::array<double, 2>;

/// Drag γ, restitution e, exit face x = L.
constexpr double kGamma = 0.5, kE = 0.5, kL = 1.0;
/// a's support [kXa, kXb]; b's centre kPc and half-width kPw.
constexpr double kXa = 0.3, kXb = 0.7, kPc = -2.5, kPw = 0.5;
/// The box [0, L] × [kPlo, kPhi].
constexpr double kPlo = -3.1, kPhi = 1.5;

/// a(x): the unit sin² bump on [kXa, kXb].
double a_of(double x) {
  if (!(x > kXa && x < kXb)) return 0.0;
  const double s = std::sin(std::numbers::pi * (x - kXa) / (kXb - kXa));
  return 2.0 / (kXb - kXa) * s * s;
}

/// ∫_{kXa}^{x} a (0 below, 1 above the support).
double a_cdf(double x) {
  if (x <= kXa) return 0.0;
  if (x >= kXb) return 1.0;
  const double w = kXb - kXa, y = x - kXa;
  return 2.0 / w *
         (0.5 * y - w * std::sin(2.0 * std::numbers::pi * y / w) / (4.0 * std::numbers::pi));
}

/// b(p) = (15/16w)(1 − ((p − pc)/w)²)² on |p − pc| < w (unit mass).
double b_of(double p) {
  const double z = (p - kPc) / kPw;
  if (!(std::fabs(z) < 1.0)) return 0.0;
  const double q = 1.0 - z * z;
  return 15.0 / (16.0 * kPw) * q * q;
}

/// The particle with drag at an inelastic wall x = 0 (support/hand_models.hpp: the wall).
struct DragWall : hybgen::testing::PlanarWall<DragWall, -1> {
  static constexpr double wall = 0.0;                                 ///< x = 0
  static constexpr double restitution = kE;                           ///< e
  static constexpr const char* name = "drag_wall";                    ///< Model name.
  static constexpr std::array<const char*, 2> state_names{"x", "p"};  ///< State names.
  static constexpr std::array<const char*, 1> mode_names{"fly"};      ///< Mode names.
  /// X = (p, −γp).
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1];
    out[1] = -kGamma * x[1];
  }
  /// div X = −γ.
  static double divergence(int, const double*, const double*) { return -kGamma; }
  /// u0 = a(x) b(p) (0 outside the support x ≥ 0: a vanishes there).
  static double initial_density(int, const double* x, const double*) {
    return a_of(x[0]) * b_of(x[1]);
  }
  /// x ≥ 0.
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0; }
};
static_assert(rt::HybridModel<DragWall>);

/// The state a flight of duration τ backwards from (x, p): (x − p(e^{γτ} − 1)/γ, p e^{γτ}).
P2 back(const P2& y, double tau) {
  const double g = std::exp(kGamma * tau);
  return {y[0] - y[1] * (g - 1.0) / kGamma, y[1] * g};
}

/// The exact density by the closed-form backward map (file comment).
double exact(double t, const P2& y) {
  if (y[0] < 0.0) return 0.0;
  double factor = std::exp(kGamma * t);
  P2 foot = back(y, t);
  if (y[1] > 0.0) {
    const double tau1 = std::log1p(kGamma * y[0] / y[1]) / kGamma;
    if (tau1 < t) {
      const double pw = y[1] + kGamma * y[0];  // speed just after the impact
      factor /= kE * kE;
      foot = back({0.0, -pw / kE}, t - tau1);
    }
  }
  return factor * a_of(foot[0]) * b_of(foot[1]);
}

/// The exit time T(x0, p0) (HUGE_VAL if the state never reaches x = L).
double exit_time(double x0, double p0) {
  const double c = p0 + kGamma * x0;
  if (!(c < 0.0)) return HUGE_VAL;
  const double t1 = -std::log(c / p0) / kGamma, q = -kE * c;
  if (!(q > kGamma * kL)) return HUGE_VAL;
  return t1 - std::log1p(-kGamma * kL / q) / kGamma;
}

/// Largest x0 ∈ [kXa, kXb] with T(x0, p0) ≤ t (kXa if none: a vanishes below it).
double x_limit(double p0, double t) {
  if (exit_time(kXa, p0) > t) return kXa;
  if (exit_time(kXb, p0) <= t) return kXb;
  double lo = kXa, hi = kXb;
  for (int it = 0; it < 200 && hi - lo > 1e-15; ++it) {
    const double mid = 0.5 * (lo + hi);
    (exit_time(mid, p0) <= t ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// The p0 ∈ (pc − w, pc + w) where T(x0, p0) = t (T increases with p0), or an end.
double p_where(double x0, double t) {
  double lo = kPc - kPw, hi = kPc + kPw;
  if (exit_time(x0, lo) > t) return lo;
  if (exit_time(x0, hi) <= t) return hi;
  for (int it = 0; it < 200 && hi - lo > 1e-15; ++it) {
    const double mid = 0.5 * (lo + hi);
    (exit_time(x0, mid) <= t ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// outflow(t) = ∫ u0 [T ≤ t] (file comment), `panels` Gauss panels per smooth piece in p0.
double outflow(double t, int panels = 200) {
  std::vector<double> cut{kPc - kPw, p_where(kXb, t), p_where(kXa, t), kPc + kPw};
  std::sort(cut.begin(), cut.end());
  double f = 0.0;
  for (std::size_t j = 0; j + 1 < cut.size(); ++j) {
    if (!(cut[j + 1] > cut[j])) continue;
    const auto r = rt::gauss_legendre_rule(cut[j], cut[j + 1], panels, 6);
    for (std::size_t i = 0; i < r.nodes.size(); ++i)
      f += r.weights[i] * b_of(r.nodes[i]) * a_cdf(x_limit(r.nodes[i], t));
  }
  return f;
}

/// The grid of the box, nx × np nodes.
rt::TensorGrid<2> box(int nx, int np) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.0, kL, nx}, rt::GridAxis{kPlo, kPhi, np}};
  return g;
}

/// Output times with the whole flux inside the last interval.
const std::vector<double> kCoarse{0.0, 0.05, 2.5};
/// Output times through the exit window.
const std::vector<double> kFine{0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5};

TEST(BounceExit, ReferencesAreConsistent) {
  // The support's exit and bounce times; the outflow against a brute-force midpoint rule of
  // u0·[T ≤ t] and against itself at half the panels; the box mass of `exact` (midpoint rule)
  // against 1 − outflow(t).
  double tmin = HUGE_VAL, tmax = 0.0, t1max = 0.0;
  for (const double x0 : {kXa, kXb})
    for (const double p0 : {kPc - kPw, kPc + kPw}) {
      tmin = std::min(tmin, exit_time(x0, p0));
      tmax = std::max(tmax, exit_time(x0, p0));
      t1max = std::max(t1max, -std::log1p(kGamma * x0 / p0) / kGamma);
    }
  std::printf("[ bounce ] exit times in [%.4f, %.4f], impacts before %.4f\n", tmin, tmax, t1max);
  EXPECT_GT(tmin, 0.05);
  EXPECT_LT(tmax, 2.5);
  EXPECT_EQ(outflow(0.05), 0.0);
  EXPECT_NEAR(outflow(2.5), 1.0, 1e-13);
  for (const double t : {1.0, 1.25, 1.5, 2.0}) {
    const int n = 1200;
    double brute = 0.0;
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const double x0 = kXa + (kXb - kXa) * (i + 0.5) / n,
                     p0 = kPc - kPw + 2.0 * kPw * (j + 0.5) / n;
        if (exit_time(x0, p0) <= t) brute += a_of(x0) * b_of(p0) * (kXb - kXa) * 2.0 * kPw / n / n;
      }
    const int m = 1000;
    double mass = 0.0;
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < 2 * m; ++j) {
        const P2 y{kL * (i + 0.5) / m, kPlo + (kPhi - kPlo) * (j + 0.5) / (2 * m)};
        mass += exact(t, y) * kL * (kPhi - kPlo) / (2.0 * m * m);
      }
    std::printf(
        "[ bounce ] outflow(%.2f) = %.12f (100 panels %.12f, midpoint %.6f), box mass %.6f\n", t,
        outflow(t), outflow(t, 100), brute, mass);
    EXPECT_NEAR(outflow(t), outflow(t, 100), 1e-12);
    EXPECT_NEAR(outflow(t), brute, 2e-3);
    EXPECT_NEAR(mass, 1.0 - outflow(t), 3e-3);
  }
}

TEST(BounceExit, CharacteristicsMatchTheBackwardMap) {
  // The error is the ODE tolerance (docs/methods.md), amplified by the dynamics (the impact and the
  // drag compress the density, whose foot then lies on u0's steep flanks): measured 3.7e-9
  // with rtol 1e-10 and 4.6e-11 with rtol 1e-12 (ratio 81 for a 100 times finer tolerance).
  // Asserted: < 1e-8, and < 1e-10 with the finer tolerance.
  const auto grid = box(41, 93);
  const std::vector<double> times{0.0, 0.2, 0.5, 1.0, 1.7, 2.5};
  for (const double rtol : {1e-10, 1e-12}) {
    rt::CharacteristicsOptions co;
    co.ode.rtol = rtol;
    co.ode.atol = 1e-2 * rtol;
    const auto sol = rt::solve_grid<DragWall>(grid, times, nullptr, co);
    ASSERT_TRUE(sol.ok()) << rt::describe<DragWall>(sol.failure);
    double worst = 0.0, umax = 0.0;
    for (std::size_t k = 0; k < times.size(); ++k)
      for (std::size_t i = 0; i < grid.size(); ++i) {
        const auto y = grid.node(i);
        const double ue = exact(times[k], y);
        umax = std::max(umax, ue);
        worst = std::max(worst, std::fabs(sol.at(k, 0, i) - ue) / std::max(ue, 1.0));
      }
    std::printf(
        "[ bounce ] characteristics 41 x 93 rtol %.0e: max relative error %.2e (max u %.2f)\n",
        rtol, worst, umax);
    EXPECT_LT(worst, 100.0 * rtol);
  }
}

/// The characteristics budget at `times` on the box [0, L] × [plo, phi] against the closed
/// forms (file comment): the outflow within its estimate, atom 0; with `strict`, the mass within
/// its estimate plus the target and the defect within the closure bar, else (docs/outputs.md's
/// promise) a mass outside that must be flagged by the closure check. Returns the worst mass
/// error.
double check_budget(const std::vector<double>& times, double rel_tol, double plo, double phi,
                    bool strict, int nx = 41, int np = 93) {
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  rt::AdaptiveOptions ao;
  ao.rel_tol = rel_tol;
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.0, kL, nx}, rt::GridAxis{plo, phi, np}};
  const auto b = rt::adaptive_mass_budget<DragWall>(g, times, nullptr, co, ao);
  EXPECT_TRUE(b.ok()) << rt::describe<DragWall>(b.failure) << b.message;
  if (!b.ok()) return HUGE_VAL;
  const auto defect = rt::budget_defect(b.budget), bar = rt::budget_defect_error(b.budget);
  const double target = rel_tol * b.budget.mass0;
  double wo = 0.0, wm = 0.0, wd = 0.0, worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double F = outflow(times[k]);
    const double eo = std::fabs(b.budget.outflow[k] - F);
    const double em = std::fabs(b.budget.mass[k] - (1.0 - F));
    const double dbar = rt::kDefectFactor * bar[k] + rt::kDefectFloor * b.budget.mass0;
    std::printf(
        "[ bounce ] budget p in [%.1f, %.1f] rel_tol %.0e t = %.2f: outflow %.8f (exact %.8f, "
        "error %.1e, est %.1e), mass %.8f (error %.1e, est %.1e), atom %.1e, defect %.1e (bar "
        "%.1e)\n",
        plo, phi, rel_tol, times[k], b.budget.outflow[k], F, eo, b.budget.outflow_error[k],
        b.budget.mass[k], em, b.budget.mass_error[k], b.budget.atom[k], defect[k], dbar);
    wo = std::max(wo, eo / b.budget.outflow_error[k]);
    wm = std::max(wm, em / (b.budget.mass_error[k] + target));
    wd = std::max(wd, std::fabs(defect[k]) / dbar);
    worst = std::max(worst, em);
    EXPECT_LE(eo, b.budget.outflow_error[k]) << "t = " << times[k];
    EXPECT_EQ(b.budget.atom[k], 0.0) << "t = " << times[k];
    if (strict) {
      EXPECT_LE(em, b.budget.mass_error[k] + target) << "t = " << times[k];
      EXPECT_LE(std::fabs(defect[k]), dbar) << "t = " << times[k];
    } else {
      EXPECT_TRUE(em <= b.budget.mass_error[k] + target || std::fabs(defect[k]) > dbar)
          << "t = " << times[k] << ": a wrong mass that the closure check does not flag";
    }
  }
  std::printf(
      "[ bounce ] budget p in [%.1f, %.1f] rel_tol %.0e: worst error / estimate: outflow %.2f, "
      "mass %.2f (with the target); defect / bar %.2f\n",
      plo, phi, rel_tol, wo, wm, wd);
  EXPECT_LE(std::fabs(b.budget.mass0 - 1.0), b.budget.mass0_error + target);
  return worst;
}

TEST(BounceExit, BudgetCountsAFluxInsideOneOutputInterval) {
  // The case: the bounce and the whole exit inside (0.05, 2.5). Measured (rel_tol
  // 1e-4 / 3e-4, the runner's default): outflow at t = 2.5 low by 6.0e-6 / 5.1e-6 against
  // estimates 7.6e-5 / 2.7e-4; defect / bar 0.54 / 0.19.
  check_budget(kCoarse, 1e-4, kPlo, kPhi, true);
  check_budget(kCoarse, 3e-4, kPlo, kPhi, true);
}

TEST(BounceExit, BudgetFollowsTheExitWindow) {
  // 11 output times through the window. Measured: outflow errors ≤ 0.10 of their estimates,
  // masses ≤ 0.22 of estimate plus target, defect / bar ≤ 0.16.
  check_budget(kFine, 1e-4, kPlo, kPhi, true);
}

TEST(BounceExit, BudgetMassMissedByTheCubatureIsFlagged) {
  // The same budget on the taller box [0, 1] × [−3.5, 2] (the same mass: nothing reaches p <
  // −3.1 or p > 1.45). At t = 1.25 the density is the post-impact strip (area 0.054 of the
  // box's 5.5). Before the grid's nodes were the volume cubature's check points (budget.hpp):
  // mass 0.596 against 0.809 (−0.213) with an estimate of 9.4e-5, the same for rel_tol 1e-3
  // … 1e-5 — the 0.596 was the mass of ONE of the 4 × 4 initial cells; the two cells below it
  // held 0.213 of the strip, seen by 2 of the 80 Gauss nodes of each (the cell and all its
  // halves), and were frozen as empty. Now 26 grid nodes of the 41 × 93 grid read the strip
  // and the cells around them are refined: measured mass 0.80162, error −7.1e-3 (30× less),
  // estimate 9.3e-5. What is left is a piece of the strip that no grid node sees either
  // (5.7e-3 of it in the leaf x ∈ [0.875, 1] × p ∈ [−0.75, 0.625], all of whose 16 Gauss
  // nodes and ~130 grid nodes read 0): the cubature sees what the grid resolves, no more.
  // There docs/outputs.md's promise for "an error the estimates missed" is the closure check's
  // warning, |defect| > kDefectFactor × budget_defect_error: asserted, with the outflow
  // (independent of the volume cubature) within its estimate.
  const double worst = check_budget({0.0, 1.25}, 1e-4, -3.5, 2.0, false);
  std::printf("[ bounce ] box p in [-3.5, 2], 41 x 93: worst mass error %.3e\n", worst);
  EXPECT_LE(worst, 1e-2);
}

TEST(BounceExit, BudgetOnAGridThatResolvesTheStripIsWithinItsEstimate) {
  // The tall box again on a grid twice as fine (81 × 185), which resolves the strip: the
  // mass is within its estimate plus the target, the defect within its bar (strict).
  // Measured: error 1.1e-4 against estimate 1.0e-4 + target 1e-4; on 161 × 369 7.6e-5
  // against 8.4e-5 + 1e-4.
  const double worst = check_budget({0.0, 1.25}, 1e-4, -3.5, 2.0, true, 81, 185);
  std::printf("[ bounce ] box p in [-3.5, 2], 81 x 185: worst mass error %.3e\n", worst);
}

TEST(BounceExit, TransferBooksTheOutflow) {
  // h = 0.25 (hat smoothing is per step: O(Δx²/h), docs/methods.md), 81 × 185 and 161 × 369 nodes.
  // Measured: worst outflow error over the output times 4.69e-3 and 1.21e-3 (ratio 3.9, second
  // order); relative L1 of the density at t = 0.5 (after every impact) 4.6e-2 and 1.2e-2
  // (ratio 3.8), at t = 1 0.18 and 0.052 (3.5): the post-impact strip is 2–5 cells thick on
  // the coarse grid. (h = 0.05 gives 2.2e-2 and 6.0e-3 for the outflow: more steps, more
  // smoothing.) Asserted: outflow < 1e-2 and L1(0.5) < 0.1 on the coarse grid, then ratios
  // > 3, > 3 and > 2.5; the budget closed to rounding, no atom.
  const std::vector<double>& times = kFine;
  double prev_out = 0.0, prev_half = 0.0, prev_one = 0.0;
  for (const auto& [nx, np] : {std::pair{81, 185}, std::pair{161, 369}}) {
    const auto grid = box(nx, np);
    rt::TransferOptions o;
    o.step = 0.25;
    const auto op = rt::assemble_transfer<DragWall>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto run = rt::march(op, rt::initial_vector<DragWall>(grid, nullptr), times);
    ASSERT_TRUE(run.ok()) << run.failure;
    double wo = 0.0;
    std::vector<double> l1(times.size(), 0.0);
    for (std::size_t k = 0; k < times.size(); ++k) {
      const double F = outflow(times[k]);
      EXPECT_NEAR(run.budget.mass[k] + run.budget.outflow[k], run.budget.mass0, 1e-13);
      EXPECT_EQ(run.budget.atom[k], 0.0);
      wo = std::max(wo, std::fabs(run.budget.outflow[k] - F));
      double num = 0.0, den = 0.0;
      for (std::size_t i = 0; i < grid.size(); ++i) {
        const double ue = exact(times[k], grid.node(i)), u = run.solution.at(k, 0, i);
        ASSERT_GE(u, 0.0);
        num += op.weight[i] * std::fabs(u - ue);
        den += op.weight[i] * ue;
      }
      l1[k] = den > 0.0 ? num / den : 0.0;
      std::printf("[ bounce ] transfer %d x %d t = %.2f: outflow %.6f (exact %.6f), rel L1 %.3e\n",
                  nx, np, times[k], run.budget.outflow[k], F, l1[k]);
    }
    std::printf("[ bounce ] transfer %d x %d h=0.25 (assembly %.2f s): worst outflow error %.3e\n",
                nx, np, op.seconds, wo);
    if (prev_out == 0.0) {
      EXPECT_LT(wo, 1e-2);
      EXPECT_LT(l1[2], 0.1);
    } else {
      EXPECT_GT(prev_out / wo, 3.0);
      EXPECT_GT(prev_half / l1[2], 3.0);
      EXPECT_GT(prev_one / l1[4], 2.5);
    }
    prev_out = wo;
    prev_half = l1[2];
    prev_one = l1[4];
  }
}

TEST(BounceExit, ParticlesCountTheOutflow) {
  const auto grid = box(41, 93);
  rt::ParticleOptions po;
  po.particles = 200000;
  po.seed = 17;
  po.forward.ode.rtol = 1e-9;
  po.forward.ode.atol = 1e-11;
  const auto run = rt::solve_particles<DragWall>(grid, kFine, nullptr, po);
  ASSERT_TRUE(run.failure.ok()) << rt::describe<DragWall>(run.failure);
  const auto& b = run.budget;
  const double s2 = 0.25 * b.mass_error[0] * b.mass_error[0] +
                    b.mass0 * b.mass0 / static_cast<double>(po.particles);
  const double w2bar = s2 / b.mass0;
  double worst = 0.0;
  for (std::size_t k = 0; k < kFine.size(); ++k) {
    const double F = outflow(kFine[k]);
    // Floors: a mass or an outflow that is exactly 0 or 1 has no variance.
    const double sig_m =
        std::max({0.5 * b.mass_error[k], std::sqrt(std::max(1.0 - F, 0.0) * w2bar), 1e-12});
    const double sig_o = std::sqrt(F * w2bar) + 1e-12;
    const double zm = std::fabs(b.mass[k] - (1.0 - F)) / sig_m;
    const double zo = F > 0.0 ? std::fabs(b.outflow[k] - F) / sig_o : 0.0;
    worst = std::max({worst, zm, zo});
    std::printf(
        "[ bounce ] particles t = %.2f: mass %.5f (exact %.5f), outflow %.5f (exact %.5f), |z| "
        "%.2f %.2f\n",
        kFine[k], b.mass[k], 1.0 - F, b.outflow[k], F, zm, zo);
    EXPECT_LE(zm, 5.0) << "t = " << kFine[k];
    EXPECT_LE(zo, 5.0) << "t = " << kFine[k];
    EXPECT_EQ(b.atom[k], 0.0);
    if (F == 0.0) {
      EXPECT_EQ(b.outflow[k], 0.0);
    }
  }
  std::printf("[ bounce ] particles: worst |z| %.2f\n", worst);
}

}  // namespace
