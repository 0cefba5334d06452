// Tests of the mass budget's bound on work in time (the time integral of a face point's flux,
// Tracer::accumulate in hybgen/rt/methods/characteristics.hpp, and its use in
// hybgen/rt/methods/budget/faces.hpp): whatever the integrand, a characteristic's time
// integral costs a bounded number of evaluations of u0; a density that is 0 only up to
// rounding costs what 0 costs (the floor); a capped integral reports what it left
// unresolved, and the outflow widens its error by it and is not `converged`.
//
// Two models, both drifting at speed 1 (x' = 1), with the exact outflow through x = 1 known:
//  * Bump2D: the C¹ bump b(x)·b(y), b(s) = ((0.04 − (s − 1/2)²)₊)², evaluated as hybgen emits
//    tests/validation/drift_bump.model (abs expanded: 100·|t²/4 − 1/25| − 25·t² + 4, t = 2s − 1),
//    so rounding noise of ~1e-15 (before squaring) where b is 0;
//  * Square1D: on [0, 1], u0 = 1 + q(x), q = +1 where ⌊2²⁰x⌋ is even and −1 where it is odd:
//    2²⁰ jumps, more than any adaptive rule in time can resolve. Through x = 1 the outflow
//    by time t ≤ 1 is ∫_{1−t}^{1} u0 = t + ∫_{1−t}^{1} q, and ∫ q = 0 over the whole periods
//    of length 2⁻¹⁹ that [1 − t, 1] is made of for t = 1/2 and 1.
// Measured: see each test's comment.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "hybgen/rt/methods/budget.hpp"
#include "support/rt_setup.hpp"

namespace {

namespace rt = hybgen::rt;
using hybgen::testing::tolerances;

/// Evaluations of u0 (the work of a time integral: kPanelOrder = 5 per panel rule).
std::atomic<long> g_evaluations{0};

/// What a model of `n` states without guards needs besides its flow and density.
template <int n>
struct NoGuards {
  static constexpr int n_param = 0;                             ///< none
  static constexpr int n_mode = 1;                              ///< one mode
  static constexpr int n_guard = 0;                             ///< none
  static constexpr std::array<const char*, 0> param_names{};    ///< none
  static constexpr std::array<double, 0> param_defaults{};      ///< none
  static constexpr std::array<const char*, 1> mode_names{"m"};  ///< the mode
  static constexpr std::array<const char*, 0> guard_names{};    ///< none
  static constexpr std::array<rt::GuardInfo, 0> guards{};       ///< none
  /// No guard: never called.
  static double guard_surface(int, const double*, const double*) { return 0.0; }
  /// No guard: never called (0).
  static void guard_gradient(int, const double*, const double*, double* out) {
    std::fill_n(out, n, 0.0);
  }
  /// No guard: never called (the identity).
  static void reset(int, const double* x, const double*, double* out) { std::copy_n(x, n, out); }
  /// No guard: never called (the identity).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    std::copy_n(x, n, out);
  }
  /// No guard: never called (0).
  static void reset_jacobian(int, const double*, const double*, double* out) {
    std::fill_n(out, n * n, 0.0);
  }
  /// No guard: never called.
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// One region: everywhere.
  static bool in_region(int, const double*, const double*) { return true; }
};

/// The bump drifting out of the unit square (file comment).
struct Bump2D : NoGuards<2> {
  static constexpr int n_state = 2;                                   ///< x, y
  static constexpr const char* name = "bump2d";                       ///< Model name.
  static constexpr std::array<const char*, 2> state_names{"x", "y"};  ///< State names.
  /// x' = 1, y' = 0.
  static void flow(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  /// As hybgen emits drift_bump.model's initial density.
  static double initial_density(int, const double* s, const double*) {
    g_evaluations.fetch_add(1, std::memory_order_relaxed);
    const double t0 = 2.0 * s[0] - 1.0, t1 = t0 * t0;
    const double t2 = 100.0 * std::fabs((1.0 / 4.0) * t1 - (1.0 / 25.0)) - 25.0 * t1 + 4.0;
    const double t3 = 2.0 * s[1] - 1.0, t4 = t3 * t3;
    const double t5 = 100.0 * std::fabs((1.0 / 4.0) * t4 - (1.0 / 25.0)) - 25.0 * t4 + 4.0;
    return (1.0 / 1600000000.0) * (t2 * t2) * (t5 * t5);
  }
  /// The whole plane.
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<Bump2D>);

/// 1 + the square wave of 2²⁰ periods on [0, 1] (file comment).
struct Square1D : NoGuards<1> {
  static constexpr int n_state = 1;                              ///< x
  static constexpr const char* name = "square1d";                ///< Model name.
  static constexpr std::array<const char*, 1> state_names{"x"};  ///< State names.
  /// x' = 1.
  static void flow(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// 1 ± 1 on alternate intervals of length 2⁻²⁰ of [0, 1]; 0 outside (model.hpp's contract).
  static double initial_density(int, const double* x, const double*) {
    g_evaluations.fetch_add(1, std::memory_order_relaxed);
    if (!(x[0] >= 0.0 && x[0] <= 1.0)) return 0.0;
    const auto j = static_cast<long long>(std::floor(std::ldexp(x[0], 20)));
    return j % 2 == 0 ? 2.0 : 0.0;
  }
  /// [0, 1].
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0 && x[0] <= 1.0; }
};
static_assert(rt::HybridModel<Square1D>);

/// The bound on u0's evaluations by one branch's time integral over a horizon of 64 base
/// panels (characteristics.hpp: at most 3 panel rules per base panel and 4 per halving, at
/// most kMaxSplits = 256 halvings, 5 evaluations per rule), with base panels to spare for the
/// ODE's steps and the output times (each may start a new one).
constexpr long kBranchEvaluations = 5 * (3 * (64 + 64) + 4 * 256);

// Rounding noise below the floor: the time integral along the face x = 1 at y = 0.1, where
// u0 is noise (b(y) = 0 up to rounding), costs what an integrand that is 0 costs: 64 base
// panels of 3 rules (measured: 960 evaluations). Without the floor it stops at its cap
// (measured: 6080 evaluations, unresolved 5e-62) instead of halving every panel 40 times.
TEST(BudgetWorkCap, RoundingNoiseIsAcceptedBelowTheFloor) {
  const std::vector<double> times{0.0, 0.5, 1.0, 2.0};
  rt::CharacteristicsOptions opt = tolerances(1e-10, 1e-12);
  opt.cumulative_tol = 1e-3;
  opt.cumulative_errors = true;
  rt::FaceContext<2> face;
  face.inward = {-1.0, 0.0};
  face.hi = {1.0, 1.0};
  std::vector<double> out(2 * times.size());
  for (const double floor : {1e-10, 0.0}) {
    opt.cumulative_floor = floor;
    g_evaluations = 0;
    const rt::TraceStatus<2> st = rt::trace<Bump2D>({1.0, 0.1}, 0, times, nullptr, opt, out, &face);
    ASSERT_TRUE(st.ok());
    const long n = g_evaluations.load();
    std::printf("floor %g: %ld evaluations, integral %.2e, unresolved %.2e\n", floor, n,
                out[times.size() - 1], out[2 * times.size() - 1]);
    EXPECT_LE(n, kBranchEvaluations);
    for (std::size_t k = 0; k < times.size(); ++k) {
      EXPECT_LE(std::fabs(out[k]), 1e-30);  // noise, not mass (the box holds 1.2e-7)
      if (floor > 0.0) {
        EXPECT_EQ(out[times.size() + k], 0.0);
      }
    }
    if (floor > 0.0) {
      EXPECT_LE(n, 5 * 3 * 64 + 5 * 3 * 8);
    }
  }
}

// 2²⁰ jumps along the characteristic: the time integral stops at its cap and reports what it
// left (measured: see the printout). The face cubature's outflow includes it in its error,
// counts the capped points and is not `converged`; through the whole budget, the run is told
// which bound it reached.
TEST(BudgetWorkCap, JumpsBeyondResolutionAreCappedAndSaySo) {
  const std::vector<double> times{0.0, 0.5, 1.0};
  rt::TensorGrid<1> grid;
  grid.axes[0] = {0.0, 1.0, 33};
  const rt::CharacteristicsOptions opt = tolerances(1e-10, 1e-12);
  rt::AdaptiveOptions aopt;
  aopt.rel_tol = 1e-2;
  aopt.max_points = 20000;
  const double time_tol = 1e-3, scale = 1.0;
  g_evaluations = 0;
  rt::TraceFailure<1> failure;
  const rt::AdaptiveOutflow ao =
      rt::adaptive_outflow<Square1D>(grid, times, nullptr, opt, aopt, scale, time_tol, failure);
  ASSERT_TRUE(failure.ok());
  const long n = g_evaluations.load();
  std::printf("square wave: %ld evaluations of u0 on %zu face points, %zu capped\n", n, ao.points,
              ao.time_capped);
  EXPECT_LE(n, 2 * kBranchEvaluations);  // x = 0 leaves the support at once
  EXPECT_EQ(ao.time_capped, 1u);         // x = 1
  EXPECT_FALSE(ao.converged);
  for (std::size_t k = 1; k < times.size(); ++k) {
    const double bar = ao.error[k] + time_tol * scale + ao.time_error[k];
    std::printf("  t = %.1f: outflow %.6f, exact %.6f, error bar %.1e (unresolved %.1e)\n",
                times[k], ao.outflow[k], times[k], bar, ao.time_error[k]);
    EXPECT_GT(ao.time_error[k], 0.0);
    EXPECT_LE(std::fabs(ao.outflow[k] - times[k]), bar);
  }
  rt::AdaptiveBudgetInfo info;
  const rt::BudgetResult<1> r =
      rt::adaptive_mass_budget<Square1D>(grid, times, nullptr, opt, aopt, &info);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(info.surface.time_capped, 1u);
  EXPECT_NE(rt::budget_bounds_reached(info).find("time integral"), std::string::npos)
      << rt::budget_bounds_reached(info);
  for (std::size_t k = 1; k < times.size(); ++k)
    EXPECT_LE(std::fabs(r.budget.outflow[k] - times[k]), r.budget.outflow_error[k]);
}

}  // namespace
