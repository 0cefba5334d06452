// The runner's method interface (runtime/include/hybgen/rt/methods/methods.hpp): every method on
// the same problem (the paper's bouncing ball on a small grid) returns frames, times and a
// budget that obey the interface's invariants, and the densities of the four methods agree
// with the closed form within each method's own accuracy.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "ball_methods.hpp"
#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "support/ball_closed_form.hpp"

namespace {

namespace rt = hybgen::rt;
using Ball = rt::testing::BouncingBall;

rt::TensorGrid<2> grid(int n) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.0, 2.0, n}, rt::GridAxis{-2.0, 2.0, n}};
  return g;
}

const std::vector<double> kTimes{0.0, 0.5, 1.0, 1.5, 2.0};
const std::array<double, 3> kPar{1.0, 1.0, 1.0};

rt::MethodResult<2> solve(const std::string& method, int n, const std::string& scheme = "") {
  rt::MethodSettings s;
  s.set("method", method);
  s.quiet = true;
  s.set("step", 0.05);
  s.set("particles", 200000);
  s.set("eigenvalues", 3);
  s.set("budget", "full");
  if (!scheme.empty()) s.set("scheme", scheme);
  return rt::solve_method<Ball>(grid(n), kTimes, 0.5, kPar.data(), s);
}

// Frames, times and the budget identity mass + outflow + atom = mass0 to budget_tol·mass0.
void expect_time_series(const rt::MethodResult<2>& r, double budget_tol) {
  ASSERT_TRUE(r.ok()) << r.failure;
  EXPECT_EQ(r.solution.n_time, kTimes.size());
  EXPECT_EQ(r.frame_names.size(), kTimes.size());
  EXPECT_EQ(r.frame_names.front(), "u_0000");
  EXPECT_EQ(r.frame_times, kTimes);
  ASSERT_EQ(r.budget.mass.size(), kTimes.size());
  for (std::size_t k = 0; k < kTimes.size(); ++k)
    EXPECT_NEAR(r.budget.mass[k] + r.budget.outflow[k] + r.budget.atom[k], r.budget.mass0,
                budget_tol * r.budget.mass0)
        << "t = " << kTimes[k];
}

// Relative L1 error over all frames against the elastic closed form.
double series_error(const rt::MethodResult<2>& r, int n) {
  const rt::TensorGrid<2> g = grid(n);
  return hybgen::testing::ball_relative_l1(g, r.solution, kTimes);
}

TEST(Methods, CharacteristicsAreExactToTheOdeTolerance) {
  const auto r = solve("characteristics", 41);
  // The budget's terms are measured independently (budget.hpp): mass + outflow + atom =
  // mass0 within the sum of their estimated errors, the criterion of the run's warning.
  expect_time_series(r, 1.0);
  const std::vector<double> d = rt::budget_defect(r.budget),
                            bar = rt::budget_defect_error(r.budget);
  for (std::size_t k = 0; k < d.size(); ++k)
    EXPECT_LE(std::fabs(d[k]), bar[k] + rt::kDefectFloor * r.budget.mass0) << kTimes[k];
  EXPECT_EQ(r.summary["budget"]["closes"], true);
  EXPECT_LT(series_error(r, 41), 1e-8);
  EXPECT_TRUE(r.summary.contains("budget"));
  EXPECT_EQ(r.atom_error.size(), kTimes.size());
}

// The budget setting: `off` computes none (empty series, no cost), `fast` a looser one whose
// terms still close within their (larger) estimates, and agrees with `full` within them.
TEST(Methods, CharacteristicsBudgetSetting) {
  rt::MethodSettings s;
  s.set("method", "characteristics");
  s.quiet = true;
  s.set("budget", "off");
  EXPECT_EQ(rt::MethodSettings{}.settings.word<"budget">(), "fast");  // the default
  const auto off = rt::solve_method<Ball>(grid(41), kTimes, 0.5, kPar.data(), s);
  ASSERT_TRUE(off.ok()) << off.failure;
  EXPECT_TRUE(off.budget.mass.empty());
  EXPECT_EQ(off.budget_s, 0.0);
  EXPECT_EQ(off.summary["budget"]["kind"], "off");
  s.set("budget", "fast");
  const auto fast = rt::solve_method<Ball>(grid(41), kTimes, 0.5, kPar.data(), s);
  ASSERT_TRUE(fast.ok()) << fast.failure;
  EXPECT_EQ(fast.summary["budget"]["kind"], "fast");
  EXPECT_GE(fast.summary["budget"]["rel_tol"].get<double>(), rt::kFastBudgetTol);
  EXPECT_EQ(fast.summary["budget"]["closes"], true);
  const auto full = solve("characteristics", 41);
  for (std::size_t k = 0; k < kTimes.size(); ++k)
    EXPECT_LE(std::fabs(fast.budget.mass[k] - full.budget.mass[k]),
              fast.budget.mass_error[k] + full.budget.mass_error[k])
        << kTimes[k];
  // Off, the solution is the same: the budget only measures it.
  EXPECT_EQ(off.solution.u, full.solution.u);
}

// The scheme moves mass column by column (transfer.hpp); on 81² with h = 0.05 to t = 2 its
// L1 error is O(Δx²/h); the budget closes (mass + outflow +
// atom = mass0, checked here from the reported series) and summary.json names the scheme
// and carries the conservation defects.
TEST(Methods, TransferOperatorSchemes) {
  for (const std::string scheme : {"hat"}) {
    const auto r = solve("transfer", 81, scheme);
    expect_time_series(r, 1e-12);
    const double err = series_error(r, 81);
    std::printf("[ methods ] transfer %s 81^2: series L1 %.3f\n", scheme.c_str(), err);
    EXPECT_LT(err, 0.15);
    EXPECT_EQ(r.summary["transfer"]["steps"], 40);
    EXPECT_EQ(r.summary["transfer"]["scheme"], scheme);
    EXPECT_LE(r.summary["transfer"]["column_defect"].get<double>(), 1e-12);
    EXPECT_LE(r.summary["transfer"]["budget_defect"].get<double>(), 1e-12);
  }
  rt::MethodSettings s;
  s.set("method", "transfer");
  // Withdrawn: the settings table (settings.hpp) refuses it before any solver sees it.
  EXPECT_THROW(s.set("scheme", "interpolate"), std::invalid_argument);
  EXPECT_EQ(s.settings.word<"scheme">(), "auto");  // hat for transfer (transfer.hpp)
}

TEST(Methods, ParticlesAgreeWithinMonteCarloNoise) {
  const auto r = solve("particles", 41);
  expect_time_series(r, 1e-12);
  EXPECT_LT(series_error(r, 41), 0.1);
  EXPECT_EQ(r.summary["particles"]["particles"], 200000);
}

// The elastic ball conserves mass in the box only up to outflow through p = ±2: the
// invariant density is a leading eigenvector with |λ₁| ≤ 1, one frame named `invariant`.
TEST(Methods, InvariantIsOneFrameWithASpectrum) {
  const auto r = solve("invariant", 41);
  ASSERT_TRUE(r.ok()) << r.failure;
  EXPECT_EQ(r.frame_names, std::vector<std::string>{"invariant"});
  EXPECT_TRUE(r.frame_times.empty());
  EXPECT_EQ(r.solution.n_time, 1u);
  const auto& eig = r.summary["invariant"]["eigenvalues"];
  ASSERT_GE(eig.size(), 2u);
  EXPECT_LE(eig[0]["abs"].get<double>(), 1.0 + 1e-9);
  EXPECT_GE(eig[0]["abs"].get<double>(), eig[1]["abs"].get<double>());
}

TEST(Methods, UnknownMethodAndStepMismatchAreErrors) {
  rt::MethodSettings s;
  EXPECT_THROW(s.set("method", "magic"), std::invalid_argument);  // not in the table
  s.set("method", "transfer");
  s.set("step", 0.3);  // 0.5 is not a multiple of 0.3
  EXPECT_THROW(rt::solve_method<Ball>(grid(5), kTimes, 0.5, kPar.data(), s), std::invalid_argument);
}

}  // namespace
