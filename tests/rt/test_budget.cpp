// Tests of hybgen/rt/methods/budget.hpp: the adaptive mass budget against closed forms — the Zeno
// mass of the bouncing ball (e < 1), a zero atom (e = 1), an exactly Gaussian spiral, a 1-D
// two-mode switching system — plus failure propagation, the point cap and speed.

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/budget.hpp"
#include "support/ball_closed_form.hpp"
#include "support/rt_setup.hpp"

namespace {

namespace rt = hybgen::rt;
using hybgen::testing::output_times;
using hybgen::testing::paper_grid;
using hybgen::testing::seconds_since;
using hybgen::testing::tolerances;
using Ball = rt::testing::BouncingBall;
using hybgen::testing::ball_box_mass0;
using hybgen::testing::zeno_mass;

// ---------------------------------------------------------------------------------------
// The Zeno mass of the ball Z(t) (m = g = 1): `zeno_mass` of tests/support/ball_closed_form.hpp.
//
// The atom is measured by forward flows from the box to their Zeno points (budget.hpp,
// `adaptive_atom`), so atom(t) = the Zeno mass of the initial states in B = [0, 2] × [−2, 2].
// Z(t) counts the whole half plane; at t ≤ 10 with e = 0.8 every initial state with T_Z ≤ t
// lies in B (T_Z ≤ t needs v1 ≤ V = (t − p0)(1 − e)/(1 + e) ≤ 4/3 and |p0| < V, so |p0| <
// 4/3 and x0 ≤ V²/2 < 1), hence atom(t) = Z(t) exactly.
//
// The budget's own check, mass0 − mass − outflow − atom = 0: the ball's density has no other
// sink than the Zeno point — resets at the ground map B into B (|e p| < |p|) and `outflow`
// counts a reset across the face x = 0 only when it carries mass into or out of B — so the
// three independently measured terms must add up to mass0 within their estimated errors.
/// The estimated error of atom[k] (the forward cubature's estimate).
double atom_estimate(const rt::BudgetResult<2>& r, const rt::AdaptiveBudgetInfo&, std::size_t k) {
  return r.budget.atom_error[k];
}

/// Asserts |defect| ≤ 2·(its estimated error) + slack at every time, and returns the worst
/// |defect|/mass0.
double expect_budget_closes(const rt::MassBudget& b, double slack) {
  const std::vector<double> d = rt::budget_defect(b), bar = rt::budget_defect_error(b);
  double worst = 0.0;
  for (std::size_t k = 0; k < d.size(); ++k) {
    worst = std::max(worst, std::fabs(d[k]));
    EXPECT_LE(std::fabs(d[k]), 2.0 * bar[k] + slack) << "t = " << b.times[k];
  }
  std::printf("   worst |mass0 − mass − outflow − atom| = %.2e mass0\n", worst / b.mass0);
  return worst / b.mass0;
}

struct BallRun {
  rt::BudgetResult<2> res;
  rt::AdaptiveBudgetInfo info;
  double seconds = 0.0;
};

BallRun ball_budget(double e, const std::vector<double>& times, const rt::AdaptiveOptions& ao) {
  const std::array<double, 3> par{1.0, 1.0, e};
  BallRun r;
  const auto t0 = std::chrono::steady_clock::now();
  r.res = rt::adaptive_mass_budget<Ball>(paper_grid(), times, par.data(), tolerances(1e-10, 1e-12),
                                         ao, &r.info);
  r.seconds = seconds_since(t0);
  return r;
}

void print_run(const char* name, const BallRun& r) {
  const auto& i = r.info;
  std::printf(
      "[ %s ] %.3f s; volume: %zu points, %zu cells, %d batches, converged %d, est. %.2g; "
      "faces: %zu points, converged %d, est. %.2g\n",
      name, r.seconds, i.volume.points, i.volume.cells, i.volume.iterations,
      i.volume.converged ? 1 : 0, i.volume.error_estimate, i.surface.points,
      i.surface.converged ? 1 : 0, i.surface.error_estimate);
}

// ---------------------------------------------------------------------------------------

TEST(AdaptiveBudget, ZenoAtomIsTheZenoMass) {
  // e = 0.8 on the paper's box, t = 0, 0.5, …, 10. Tolerances: rel_tol = 1e-4 bounds the
  // estimated error of the atom's cubature by 2.6e-4; the estimates are ≈ 2σ estimates
  // (budget.hpp), so we assert |atom − Z| ≤ 2·estimate plus 2e-5 for what they do not
  // include (the extrapolated Zeno time T_Z, ODE and Z: < 1e-9), and 1e-3·mass0.
  const auto times = output_times(21, 0.5);
  const BallRun r = ball_budget(0.8, times, rt::AdaptiveOptions{});
  ASSERT_TRUE(r.res.ok()) << rt::describe<Ball>(r.res.failure);
  print_run("zeno e=0.8", r);
  const auto& b = r.res.budget;
  EXPECT_TRUE(r.info.volume.converged);
  EXPECT_TRUE(r.info.surface.converged);
  EXPECT_NEAR(b.mass0, ball_box_mass0(), 1e-6 * b.mass0);
  EXPECT_EQ(b.atom[0], 0.0);  // no trajectory is at rest at t = 0
  ASSERT_EQ(b.mass_error.size(), times.size());
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double Z = zeno_mass(times[k], 0.8), err = b.atom[k] - Z;
    const double est = atom_estimate(r.res, r.info, k);
    worst = std::max(worst, std::fabs(err));
    if (k % 4 == 0)
      std::printf(
          "   t %5.2f: mass %.6f outflow %+.6f atom %.6f, Zeno mass %.6f, error %+.2e "
          "(estimate %.2e)\n",
          times[k], b.mass[k], b.outflow[k], b.atom[k], Z, err, est);
    EXPECT_LE(std::fabs(err), 2.0 * est + 2e-5) << "t = " << times[k];
    EXPECT_LE(std::fabs(err), 1e-3 * b.mass0) << "t = " << times[k];
  }
  std::printf("   worst |atom − Z| = %.2e = %.2e mass0\n", worst, worst / b.mass0);
  EXPECT_LE(expect_budget_closes(b, 2e-5), 1e-3);
  // For contrast, the trapezoid budget on the grid nodes (what the runner reported).
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  const auto opt = tolerances(1e-10, 1e-12);
  const auto sol = rt::solve_grid<Ball>(paper_grid(), times, par.data(), opt);
  ASSERT_TRUE(sol.ok());
  const auto trap = rt::mass_budget<Ball>(paper_grid(), sol, times, par.data(), opt);
  std::printf("   trapezoid on the 75x75 nodes: atom(10) = %.4f vs Zeno mass %.4f\n",
              trap.budget.atom.back(), zeno_mass(10.0, 0.8));
}

TEST(AdaptiveBudget, ElasticBallHasNoAtom) {
  // e = 1: no Zeno point: the measured atom is exactly 0 and the budget must close.
  const auto times = output_times(21, 0.5);
  const BallRun r = ball_budget(1.0, times, rt::AdaptiveOptions{});
  ASSERT_TRUE(r.res.ok()) << rt::describe<Ball>(r.res.failure);
  print_run("elastic e=1", r);
  const auto& b = r.res.budget;
  EXPECT_TRUE(r.info.volume.converged);
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) EXPECT_EQ(b.atom[k], 0.0) << times[k];
  worst = expect_budget_closes(b, 2e-5);
  EXPECT_LE(worst, 1e-4);
  std::printf("   mass(10) %.6f, outflow(10) %+.6f\n", b.mass.back(), b.outflow.back());
}

// ---------------------------------------------------------------------------------------
// x' = a x − p, p' = x + a p (div = 2a): φ_t(y) = e^{at} R(t) y with R the rotation by t,
// so u0 = exp(−4|y − c|²) gives u(t, y) = e^{−2at} exp(−4 e^{−2at}|y − φ_t(c)|²) and
//   ∫_{[−1,1]²} u(t) = e^{−2at} Π_{i} (√π/(4s)) (erf(2s(1 − c_i(t))) + erf(2s(1 + c_i(t)))),
// s = e^{−at}, c(t) = φ_t(c). No atoms: outflow = mass0 − mass exactly.

using Spiral2D = rt::testing::Spiral2D;

double spiral_mass(double t, double a) {
  const double s = std::exp(-a * t);
  const std::array<double, 2> c{0.5 * std::cos(t) / s, 0.5 * std::sin(t) / s};
  double m = s * s;
  for (const double ci : c)
    m *= std::sqrt(std::numbers::pi) / (4.0 * s) *
         (std::erf(2.0 * s * (1.0 - ci)) + std::erf(2.0 * s * (1.0 + ci)));
  return m;
}

TEST(AdaptiveBudget, SmoothSpiralClosesTightly) {
  rt::TensorGrid<2> box;
  box.axes = {rt::GridAxis{-1.0, 1.0, 2}, rt::GridAxis{-1.0, 1.0, 2}};
  const std::array<double, 1> par{0.15};
  // Times not starting at 0: mass0 comes from an extra t = 0 slot.
  std::vector<double> times;
  for (int k = 1; k <= 12; ++k) times.push_back(0.25 * k);
  rt::AdaptiveOptions ao;
  ao.rel_tol = 1e-9;
  rt::AdaptiveBudgetInfo info;
  const auto t0 = std::chrono::steady_clock::now();
  const auto res = rt::adaptive_mass_budget<Spiral2D>(box, times, par.data(),
                                                      tolerances(1e-12, 1e-14), ao, &info);
  const double secs = seconds_since(t0);
  ASSERT_TRUE(res.ok());
  const auto& b = res.budget;
  double worst_mass = std::fabs(b.mass0 - spiral_mass(0.0, 0.15)), worst_atom = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    worst_mass = std::max(worst_mass, std::fabs(b.mass[k] - spiral_mass(times[k], 0.15)));
    worst_atom = std::max(worst_atom, std::fabs(rt::budget_defect(b)[k]));
  }
  std::printf(
      "[ spiral ] %.3f s, volume %zu points (converged %d), faces %zu points: mass0 %.12f, "
      "outflow(3) %.12f, max|mass − exact| %.2e, max|defect| %.2e\n",
      secs, info.volume.points, info.volume.converged ? 1 : 0, info.surface.points, b.mass0,
      b.outflow.back(), worst_mass, worst_atom);
  EXPECT_TRUE(info.volume.converged);
  EXPECT_TRUE(info.surface.converged);
  EXPECT_GT(b.outflow.back(), 0.1);  // a sizeable part of the mass has left the box
  EXPECT_LT(worst_mass, 1e-10 * b.mass0);
  EXPECT_LT(worst_atom, 1e-9 * b.mass0);
}

// ---------------------------------------------------------------------------------------
// Two modes on the line with identity resets (see test_characteristics.cpp):
//   A: x' = +1, guard "up" A → B at x = 1 (increasing); B: x' = −2, guard "down" B → A at
//   x = −1 (decreasing). u jumps where histories are cut; the faces are points (D = 0).

using TwoMode1D = rt::testing::TwoModeLine;

TEST(AdaptiveBudget, TwoModeLineCloses) {
  rt::TensorGrid<1> box;
  box.axes = {rt::GridAxis{-2.0, 2.0, 41}};
  const auto times = output_times(9, 0.5);
  rt::AdaptiveOptions ao;
  ao.rel_tol = 1e-8;
  rt::AdaptiveBudgetInfo info;
  const auto t0 = std::chrono::steady_clock::now();
  const auto res =
      rt::adaptive_mass_budget<TwoMode1D>(box, times, nullptr, tolerances(1e-11, 1e-13), ao, &info);
  const double secs = seconds_since(t0);
  ASSERT_TRUE(res.ok());
  const auto& b = res.budget;
  double worst = 0.0;
  for (const double a : b.atom) EXPECT_EQ(a, 0.0);  // no Zeno point: no forward flow stops
  for (const double d : rt::budget_defect(b)) worst = std::max(worst, std::fabs(d));
  std::printf(
      "[ two-mode ] %.3f s, %zu points, %zu cells (converged %d): mass0 %.10f mass(4) %.10f "
      "outflow(4) %.10f max|defect| %.2e\n",
      secs, info.volume.points, info.volume.cells, info.volume.converged ? 1 : 0, b.mass0,
      b.mass.back(), b.outflow.back(), worst);
  EXPECT_TRUE(info.volume.converged);
  EXPECT_GT(b.outflow.back(), 0.05);  // 0.0749 (test_characteristics)
  EXPECT_LT(worst, 1e-7 * b.mass0);
}

// ---------------------------------------------------------------------------------------
// A flux that starts and stops inside one output interval. The conveyor x' = 1 on [0, 1]
// carries u0(x) = b((x − c)/w) with b(s) = (1 − s²)² on |s| < 1 (c = 0.4, w = 0.1) out through
// x = 1 during t ∈ (0.5, 0.7), inside the first output interval [0, 0.75]. Exactly,
//   outflow(t) = ∫_{1−t}^{1} u0 = w·(B(1) − B(clamp((1 − t − c)/w, −1, 1))),
//   B(s) = s − 2s³/3 + s⁵/5,  mass0 = w·16/15,  mass(t) = mass0 − outflow(t),  atom = 0.
// A fixed 3-point Gauss rule per output interval (the budget's time rule before
// budget.hpp integrated along each characteristic) puts no node inside (0.5, 0.7) and
// reported outflow(0.75) = 0 with the whole mass as "atom".

/// The conveyor: one state, one mode, no guards.
struct Conveyor {
  static constexpr int n_state = 1, n_param = 0, n_mode = 1, n_guard = 0;  ///< Sizes.
  static constexpr const char* name = "conveyor";                          ///< Model name.
  static constexpr std::array<const char*, 1> state_names{"x"};            ///< State names.
  static constexpr std::array<const char*, 0> param_names{};               ///< None.
  static constexpr std::array<double, 0> param_defaults{};                 ///< None.
  static constexpr std::array<const char*, 1> mode_names{"belt"};          ///< Mode names.
  static constexpr std::array<const char*, 0> guard_names{};               ///< No guards.
  static constexpr std::array<rt::GuardInfo, 0> guards{};                  ///< No guards.
  static constexpr double c = 0.4, w = 0.1;                                ///< The bump.
  /// X = 1.
  static void flow(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// Unused (no guards).
  static double guard_surface(int, const double*, const double*) { return 1.0; }
  /// Unused (no guards).
  static void guard_gradient(int, const double*, const double*, double* out) { out[0] = 0.0; }
  /// Unused (no guards).
  static void reset(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  /// Unused (no guards).
  static void reset_inverse(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  /// Unused (no guards).
  static void reset_jacobian(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// Unused (no guards).
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  /// u0 = (1 − s²)², s = (x − c)/w, on |s| < 1.
  static double initial_density(int, const double* x, const double*) {
    const double s = (x[0] - c) / w;
    return std::fabs(s) < 1.0 ? (1.0 - s * s) * (1.0 - s * s) : 0.0;
  }
  /// The whole line.
  static bool in_support(const double*, const double*) { return true; }
};

/// ∫_{1−t}^{1} u0 in closed form (see above).
double conveyor_outflow(double t) {
  auto B = [](double s) { return s - 2.0 * s * s * s / 3.0 + s * s * s * s * s / 5.0; };
  const double s = std::clamp((1.0 - t - Conveyor::c) / Conveyor::w, -1.0, 1.0);
  return Conveyor::w * (B(1.0) - B(s));
}

TEST(AdaptiveBudget, PulseInsideAnOutputIntervalIsCounted) {
  rt::TensorGrid<1> box;
  box.axes = {rt::GridAxis{0.0, 1.0, 2}};
  const std::vector<double> times{0.0, 0.55, 0.75, 1.5};  // 0.55: in the middle of the pulse
  rt::AdaptiveBudgetInfo info;
  const auto res =
      rt::adaptive_mass_budget<Conveyor>(box, times, nullptr, tolerances(1e-10, 1e-12), {}, &info);
  ASSERT_TRUE(res.ok());
  const auto& b = res.budget;
  const double exact0 = Conveyor::w * 16.0 / 15.0;
  EXPECT_LE(std::fabs(b.mass0 - exact0), b.mass0_error + 1e-12);
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double exact = conveyor_outflow(times[k]);
    EXPECT_LE(std::fabs(b.mass[k] - (exact0 - exact)), b.mass_error[k] + 1e-12) << times[k];
    std::printf("   t %.2f: outflow %.10f exact %.10f (est. %.1e), mass %.10f, atom %.1e\n",
                times[k], b.outflow[k], exact, b.outflow_error[k], b.mass[k], b.atom[k]);
    EXPECT_EQ(b.atom[k], 0.0);  // no guard, no Zeno point: measured, not a remainder
    // The error estimate must cover the error, and both must be small.
    EXPECT_LE(std::fabs(b.outflow[k] - exact), b.outflow_error[k] + 1e-12) << times[k];
    EXPECT_LE(std::fabs(b.outflow[k] - exact), 1e-5 * b.mass0) << times[k];
  }
  EXPECT_NEAR(b.outflow.back(), exact0, 1e-8);  // everything has left by t = 1.5
  expect_budget_closes(b, 1e-12);
}

TEST(AdaptiveBudget, TheDropFromTheInitialMassIsMeasuredAsOneIntegral) {
  // mass0 − mass[k] is the cubature's integral of u(0) − u(t_k) (budget/volume.hpp): its
  // estimate `drop_error` covers its error against the closed form (the conveyor's outflow,
  // as nothing else leaves) and leaves out more than a tenth of the sum
  // mass0_error + mass_error[k] that the defect took before at some t > 0 (both can fail); it
  // is at most that sum and 0 where t_k = 0 (both by construction). With and without t = 0
  // among the times (an extra slot), on 2 nodes (no check points inside a cell) and on 41
  // (the grid's nodes check the cells, with the drops' values: volume_checks).
  for (const int nodes : {2, 41}) {
    rt::TensorGrid<1> box;
    box.axes = {rt::GridAxis{0.0, 1.0, nodes}};
    rt::AdaptiveOptions aopt;
    aopt.rel_tol = 1e-3;
    for (const std::vector<double>& times :
         {std::vector<double>{0.0, 0.3, 0.55, 0.75}, std::vector<double>{0.3, 0.55, 0.75}}) {
      const auto res =
          rt::adaptive_mass_budget<Conveyor>(box, times, nullptr, tolerances(1e-10, 1e-12), aopt);
      ASSERT_TRUE(res.ok());
      const auto& b = res.budget;
      ASSERT_EQ(b.drop_error.size(), times.size());
      double saved = 0.0;  // the largest share of the old sum the drop's estimate leaves out, t > 0
      for (std::size_t k = 0; k < times.size(); ++k) {
        const double drop = b.mass0 - b.mass[k], exact = conveyor_outflow(times[k]);
        const double sum = b.mass0_error + b.mass_error[k];
        std::printf("   t %.2f: drop %.10f exact %.10f (est. %.1e; the sum %.1e)\n", times[k], drop,
                    exact, b.drop_error[k], sum);
        EXPECT_LE(std::fabs(drop - exact), b.drop_error[k] + 1e-12) << times[k];
        EXPECT_LE(b.drop_error[k], sum) << times[k];
        if (times[k] == 0.0) {
          EXPECT_EQ(b.drop_error[k], 0.0);
        }
        if (times[k] > 0.0) saved = std::max(saved, 1.0 - b.drop_error[k] / sum);
      }
      // Not the old sum under another name.
      EXPECT_GT(saved, 0.1) << nodes << " nodes";
      expect_budget_closes(b, 1e-12);
    }
  }
}

// ---------------------------------------------------------------------------------------
// Integrable singularities that no cell boundary is aligned with: X = 0 (u(t) = u0, no
// flux), u0 = |x − c|^{−1/2} on [−1, 1] (∫ = 2(√(1 + c) + √(1 − c))) and, in 2-D,
// u0 = 1/|y − c| on [0, 1]² with c = (0.3, 0.7) (∫ by summing the closed form over the four
// rectangles with a corner at c: ∫_{[0,a]×[0,b]} 1/r = a asinh(b/a) + b asinh(a/b)).
// The 1-D case is the estimate's weak spot: Gauss misses the peak with one sign at every
// level and the errors of successive levels decay only by r = 2^{−1/2}, so the leaf's true
// error is ≈ r/(1 − r) = 2.4 times its last discrepancy (measured: up to 3.1×).

template <std::size_t N>
struct Static {
  static constexpr int n_state = static_cast<int>(N), n_param = 0, n_mode = 1, n_guard = 0;
  static constexpr const char* name = "static";
  static constexpr std::array<const char*, N> state_names{};
  static constexpr std::array<const char*, 0> param_names{};
  static constexpr std::array<double, 0> param_defaults{};
  static constexpr std::array<const char*, 1> mode_names{"only"};
  static constexpr std::array<const char*, 0> guard_names{};
  static constexpr std::array<rt::GuardInfo, 0> guards{};
  static inline std::array<double, 2> c{0.3, 0.7};  ///< Where u0 is singular.
  static void flow(int, const double*, const double*, double* out) {
    for (std::size_t i = 0; i < N; ++i) out[i] = 0.0;
  }
  static double divergence(int, const double*, const double*) { return 0.0; }
  static double guard_surface(int, const double*, const double*) { return 1.0; }
  static void guard_gradient(int, const double*, const double*, double* out) {
    for (std::size_t i = 0; i < N; ++i) out[i] = 0.0;
  }
  static void reset(int, const double* x, const double*, double* out) {
    for (std::size_t i = 0; i < N; ++i) out[i] = x[i];
  }
  static void reset_inverse(int, const double* x, const double*, double* out) {
    for (std::size_t i = 0; i < N; ++i) out[i] = x[i];
  }
  static void reset_jacobian(int, const double*, const double*, double* out) {
    for (std::size_t i = 0; i < N * N; ++i) out[i] = i % (N + 1) == 0 ? 1.0 : 0.0;
  }
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  static double initial_density(int, const double* x, const double*) {
    if constexpr (N == 1) {
      return 1.0 / std::sqrt(std::fabs(x[0] - c[0]));
    } else {
      return 1.0 / std::hypot(x[0] - c[0], x[1] - c[1]);
    }
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<Static<1>> && rt::HybridModel<Static<2>>);

double corner_integral(double a, double b) {
  return a * std::asinh(b / a) + b * std::asinh(a / b);
}

TEST(AdaptiveBudget, IntegrableSingularitiesConverge) {
  const auto times = output_times(3, 0.5);
  rt::AdaptiveOptions ao;
  ao.rel_tol = 1e-6;
  rt::TensorGrid<1> line;
  line.axes = {rt::GridAxis{-1.0, 1.0, 2}};
  double worst_ratio = 0.0;
  std::size_t most_points = 0;
  for (const double c : {0.3, 0.1, 0.123456, 0.5, 0.77, -0.4, -0.99}) {
    Static<1>::c[0] = c;
    rt::TraceFailure<1> f;
    const auto am =
        rt::adaptive_mass<Static<1>>(line, times, nullptr, tolerances(1e-10, 1e-12), ao, f);
    ASSERT_TRUE(f.ok());
    const double exact = 2.0 * (std::sqrt(1.0 + c) + std::sqrt(1.0 - c));
    EXPECT_TRUE(am.converged) << "c = " << c;
    EXPECT_LE(std::fabs(am.mass0 - exact), 4.0 * am.mass0_error) << "c = " << c;
    EXPECT_LE(std::fabs(am.mass0 - exact), 2e-5 * exact) << "c = " << c;
    EXPECT_EQ(am.mass.back(), am.mass0);  // u(t) = u0
    worst_ratio = std::max(worst_ratio, std::fabs(am.mass0 - exact) / am.mass0_error);
    most_points = std::max(most_points, am.points);
  }
  std::printf(
      "[ singular 1-D ] |x - c|^(-1/2), 7 positions c, rel_tol 1e-6: <= %zu points, "
      "worst |error|/estimate %.2f\n",
      most_points, worst_ratio);
  rt::TensorGrid<2> square;
  square.axes = {rt::GridAxis{0.0, 1.0, 2}, rt::GridAxis{0.0, 1.0, 2}};
  rt::TraceFailure<2> f;
  ao.rel_tol = 1e-5;
  const auto am =
      rt::adaptive_mass<Static<2>>(square, times, nullptr, tolerances(1e-10, 1e-12), ao, f);
  ASSERT_TRUE(f.ok());
  const double exact = corner_integral(0.3, 0.7) + corner_integral(0.7, 0.7) +
                       corner_integral(0.3, 0.3) + corner_integral(0.7, 0.3);
  std::printf(
      "[ singular 2-D ] 1/|y - c|: %zu points, %zu cells: mass %.10f, exact %.10f, "
      "error %.2e (estimate %.2e)\n",
      am.points, am.cells, am.mass0, exact, am.mass0 - exact, am.mass0_error);
  EXPECT_TRUE(am.converged);
  EXPECT_LE(std::fabs(am.mass0 - exact), am.mass0_error);
  EXPECT_LE(std::fabs(am.mass0 - exact), 2e-5 * exact);
}

/// Static<N> with u0 = 1 on the slab 0.045 ≤ x₀ ≤ 0.08 of [0, 1]^N (mass 0.035): between the
/// Gauss nodes of the cubature's first two levels (4 nodes per axis on cells of width 1/4,
/// then 1/8: x₀ = 0.0174, 0.0825, … and 0.0087, 0.0413, 0.0838, …), so every node the
/// cubature traces before it freezes an empty-looking cell reads 0; the grid nodes x₀ = 0.05,
/// 0.06, 0.07, 0.08 of a 101-node axis read 1.
template <std::size_t N>
struct Slab : Static<N> {
  static double initial_density(int, const double* x, const double*) {
    return x[0] >= 0.045 && x[0] <= 0.08 ? 1.0 : 0.0;
  }
};
static_assert(rt::HybridModel<Slab<1>> && rt::HybridModel<Slab<2>>);

/// The slab's mass by adaptive_mass on `grid`; returns |error| / exact after asserting that
/// the grid's nodes were its check points.
template <std::size_t N>
double slab_error(const rt::TensorGrid<N>& grid, double& estimate) {
  const std::vector<double> times{0.0, 1.0};
  rt::TraceFailure<N> f;
  const auto am = rt::adaptive_mass<Slab<N>>(grid, times, nullptr, tolerances(1e-10, 1e-12), {}, f);
  EXPECT_TRUE(f.ok());
  const double exact = 0.035;
  std::printf(
      "[ slab %zu-D ] %zu check points, %zu points: mass %.6f (exact %.3f), estimate %.1e, "
      "converged %d\n",
      N, am.check_points, am.points, am.mass0, exact, am.mass0_error, am.converged ? 1 : 0);
  EXPECT_EQ(am.check_points, grid.size());
  EXPECT_EQ(am.mass.back(), am.mass0);  // u(t) = u0
  estimate = am.mass0_error;
  return std::fabs(am.mass0 - exact) / exact;
}

TEST(AdaptiveBudget, GridNodesSeeWhatTheGaussNodesMiss) {
  // The cubature's blind spot (budget.hpp): a feature between the Gauss nodes of the first
  // levels looks empty and is frozen. Before the grid's nodes became check points both cases
  // gave mass 0 with an estimate of 0, against 0.035 (error 100 %). Now the cells' misfit at
  // the nodes x₀ = 0.05 … 0.08 makes the cubature refine there. Measured: 1-D exact (2e-16)
  // within its estimate 3e-6; 2-D 0.035156, error 0.45 %, with an estimate of 2e-10: the
  // slab's edges lie between Gauss nodes again in leaves narrower than the grid's spacing
  // (0.01), where the check points no longer apply (a leaf x₀ ∈ [0.0781, 0.0801] reads 1 at
  // all its nodes, ≤ 0.0799). That residual is bounded by the jump times the Gauss gap
  // x1[0]·(leaf width < spacing) on each edge: ≤ 2·0.069·0.01 = 1.4e-3 of the unit face, 4 %
  // of the mass; asserted with margin. In a run the closure check (methods.hpp) flags it.
  rt::TensorGrid<1> line;
  line.axes = {rt::GridAxis{0.0, 1.0, 101}};
  double est = 0.0;
  const double e1 = slab_error<1>(line, est);
  EXPECT_LE(e1 * 0.035, est + 1e-4 * 0.035);
  rt::TensorGrid<2> square;
  square.axes = {rt::GridAxis{0.0, 1.0, 101}, rt::GridAxis{0.0, 1.0, 11}};
  EXPECT_LE(slab_error<2>(square, est), 0.04);
}

// ---------------------------------------------------------------------------------------
// Failures, the point cap, zero integrands.

/// x' = a x (backward flow contracts towards 0) with X undefined (NaN) at |x| ≥ 3: interior
/// characteristics never meet it; those from the faces of [−3, 3] start on it.
struct EdgeNaN1D {
  static constexpr int n_state = 1, n_param = 1, n_mode = 1, n_guard = 0;
  static constexpr const char* name = "edge_nan";
  static constexpr std::array<const char*, 1> state_names{"x"};
  static constexpr std::array<const char*, 1> param_names{"a"};
  static constexpr std::array<double, 1> param_defaults{0.3};
  static constexpr std::array<const char*, 1> mode_names{"only"};
  static constexpr std::array<const char*, 0> guard_names{};
  static constexpr std::array<rt::GuardInfo, 0> guards{};
  static void flow(int, const double* x, const double* par, double* out) {
    out[0] = std::fabs(x[0]) >= 3.0 ? std::numeric_limits<double>::quiet_NaN() : par[0] * x[0];
  }
  static double divergence(int, const double*, const double* par) { return par[0]; }
  static double guard_surface(int, const double*, const double*) { return 1.0; }
  static void guard_gradient(int, const double*, const double*, double* out) { out[0] = 0.0; }
  static void reset(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  static void reset_inverse(int, const double* x, const double*, double* out) { out[0] = x[0]; }
  static void reset_jacobian(int, const double*, const double*, double* out) { out[0] = 1.0; }
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  static double initial_density(int, const double* x, const double*) {
    return std::exp(-x[0] * x[0]);
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<EdgeNaN1D>);

TEST(AdaptiveBudget, FailuresPropagate) {
  // (a) Volume: e = 0 has no finite Δ⁻¹; the first traced batch already fails.
  const auto times = output_times(21, 0.5);
  const std::array<double, 3> par0{1.0, 1.0, 0.0};
  const auto res =
      rt::adaptive_mass_budget<Ball>(paper_grid(), times, par0.data(), tolerances(1e-10, 1e-12));
  ASSERT_FALSE(res.ok());
  EXPECT_EQ(res.failure.status.error, rt::TraceError::non_finite_reset);
  EXPECT_EQ(res.failure.status.guard, 0);
  const std::string msg = rt::describe<Ball>(res.failure);
  std::printf("[ failure ] volume: %s\n", msg.c_str());
  EXPECT_NE(msg.find("non-finite inverse reset"), std::string::npos);
  EXPECT_EQ(res.budget.mass.size(), times.size());  // partial, but shaped
  // (b) Faces only: the volume integral succeeds, the outflow fails.
  rt::TensorGrid<1> box;
  box.axes = {rt::GridAxis{-3.0, 3.0, 61}};
  const std::array<double, 1> par{0.3};
  rt::TraceFailure<1> vf;
  const auto am = rt::adaptive_mass<EdgeNaN1D>(box, times, par.data(), tolerances(1e-10, 1e-12),
                                               rt::AdaptiveOptions{}, vf);
  EXPECT_TRUE(vf.ok());
  EXPECT_TRUE(am.converged);
  const auto res1 =
      rt::adaptive_mass_budget<EdgeNaN1D>(box, times, par.data(), tolerances(1e-10, 1e-12));
  ASSERT_FALSE(res1.ok());
  EXPECT_EQ(res1.failure.status.error, rt::TraceError::non_finite_flow);
  EXPECT_EQ(std::fabs(res1.failure.start[0]), 3.0);
  std::printf("[ failure ] faces: %s\n", rt::describe<EdgeNaN1D>(res1.failure).c_str());
}

TEST(AdaptiveBudget, PointCapIsReportedHonestly) {
  const auto times = output_times(21, 0.5);
  rt::AdaptiveOptions ao;
  ao.max_points = 3000;  // per cubature: volume, faces, atom
  const BallRun r = ball_budget(0.8, times, ao);
  ASSERT_TRUE(r.res.ok());
  print_run("capped", r);
  EXPECT_FALSE(r.info.volume.converged);
  EXPECT_LE(r.info.volume.points, ao.max_points);
  EXPECT_GT(r.info.volume.error_estimate, ao.rel_tol * r.res.budget.mass0);
  // At so coarse a level features may still be unseen: the estimates must still cover.
  double worst = 0.0, worst_ratio = 0.0;
  for (std::size_t k = 1; k < times.size(); ++k) {
    const double err = std::fabs(r.res.budget.atom[k] - zeno_mass(times[k], 0.8));
    worst = std::max(worst, err);
    worst_ratio = std::max(worst_ratio, err / atom_estimate(r.res, r.info, k));
  }
  std::printf("   worst |atom − Z| %.2e, worst |atom − Z|/estimate %.2f\n", worst, worst_ratio);
  // Capped, each time carries the largest estimate of any (budget.hpp, `detail::collect`):
  // the Zeno basin at t ≤ 1 (mass ≤ 3.5e-4) is seen by no node yet and still covered.
  EXPECT_FALSE(r.info.atom.converged);
  EXPECT_LE(worst_ratio, 1.0);
}

TEST(AdaptiveBudget, ZeroDensityIsNotRefined) {
  // A box outside the support x ≥ 0: u ≡ 0; only the initial cells and their halves.
  rt::TensorGrid<2> box;
  box.axes = {rt::GridAxis{-3.0, -1.0, 2}, rt::GridAxis{-2.0, 2.0, 2}};
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  rt::TraceFailure<2> f;
  const auto am = rt::adaptive_mass<Ball>(box, output_times(21, 0.5), par.data(),
                                          tolerances(1e-10, 1e-12), rt::AdaptiveOptions{}, f);
  ASSERT_TRUE(f.ok());
  EXPECT_TRUE(am.converged);
  EXPECT_EQ(am.mass0, 0.0);
  EXPECT_EQ(am.error_estimate, 0.0);
  EXPECT_EQ(am.iterations, 1);
  EXPECT_EQ(am.points, 3u * 16u * 16u);  // 16 initial cells of 4 × 4 nodes, 32 halves
}

TEST(AdaptiveBudget, RunnerConfigurationAtomWithinItsEstimate) {
  // The runner's set-up (models/bouncing_ball.model): 75×75 box, t = 0, 0.2, …, 10 (51
  // times), here with e = 0.8, at rel_tol 3e-4 (budget=full's). The default 1e-4 is
  // ZenoAtomIsTheZenoMass's, above, at 21 of these times. The time is printed, not asserted (the
  // budget's cost is benchmarked by bench/budget_cost.sh).
  const auto times = output_times(51, 0.2);
  rt::AdaptiveOptions ao;
  ao.rel_tol = 3e-4;
  const BallRun r = ball_budget(0.8, times, ao);
  ASSERT_TRUE(r.res.ok());
  double worst = 0.0, est = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    worst = std::max(worst, std::fabs(r.res.budget.atom[k] - zeno_mass(times[k], 0.8)));
    est = std::max(est, atom_estimate(r.res, r.info, k));
  }
  const double m0 = r.res.budget.mass0;
  std::printf(
      "[ timing ] 75x75 ball e=0.8, 51 times to 10, rel_tol %.0e, %d threads: budget %.3f s "
      "(%zu + %zu points); worst |atom − Z| %.2e mass0, estimate %.2e mass0\n",
      ao.rel_tol, omp_get_max_threads(), r.seconds, r.info.volume.points, r.info.surface.points,
      worst / m0, est / m0);
  EXPECT_LE(worst, 1e-3 * m0);
  EXPECT_LE(worst, est);
}

}  // namespace
