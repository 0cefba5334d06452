// The table model (runtime/include/hybgen/rt/table_model.hpp): a generated model seen through
// function pointers, which the precompiled runtime library runs. It must be the same model:
// every kernel forwards, the run-time counts and names are the struct's, and a solve through
// the table equals the solve through the struct (the same arithmetic; only the calls are
// indirect). The model is the hand-written bouncing ball of tests, not generated code.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "ball_methods.hpp"
#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "hybgen/rt/table_model.hpp"

namespace {

namespace rt = hybgen::rt;
using Ball = rt::testing::BouncingBall;
using Table = rt::TableModel<2>;

/// The ball's table, installed as TableModel<2>'s model.
const rt::ModelTable& ball_table() {
  static const rt::ModelTable t = rt::make_table<Ball>();
  Table::install(t);
  return t;
}

TEST(TableModel, SatisfiesTheContractWithTheStructsCountsAndNames) {
  static_assert(rt::HybridModel<Table>);
  ball_table();
  EXPECT_EQ(Table::n_state, Ball::n_state);
  EXPECT_EQ(Table::n_param, Ball::n_param);
  EXPECT_EQ(Table::n_mode, Ball::n_mode);
  EXPECT_EQ(Table::n_guard, Ball::n_guard);
  EXPECT_STREQ(Table::name, Ball::name);
  ASSERT_EQ(Table::state_names.size(), Ball::state_names.size());
  for (std::size_t i = 0; i < Ball::state_names.size(); ++i)
    EXPECT_STREQ(Table::state_names[i], Ball::state_names[i]);
  ASSERT_EQ(Table::guards.size(), Ball::guards.size());
  EXPECT_EQ(Table::guards[0].direction, Ball::guards[0].direction);
  EXPECT_EQ(Table::param_defaults[1], Ball::param_defaults[1]);
  // The event arrays of a table model are sized by the capacity, not the count.
  EXPECT_EQ(rt::guard_capacity_v<Table>, static_cast<std::size_t>(rt::kTableMaxGuards));
  EXPECT_EQ(rt::guard_capacity_v<Ball>, static_cast<std::size_t>(Ball::n_guard));
}

TEST(TableModel, EveryKernelForwards) {
  ball_table();
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  const std::array<double, 3> par{1.0, 1.3, 0.7};
  for (int k = 0; k < 100; ++k) {
    const std::array<double, 2> x{u(rng), u(rng)};
    std::array<double, 2> a{}, b{};
    std::array<double, 4> ja{}, jb{};
    Ball::flow(0, x.data(), par.data(), a.data());
    Table::flow(0, x.data(), par.data(), b.data());
    EXPECT_EQ(a, b);
    Ball::reset(0, x.data(), par.data(), a.data());
    Table::reset(0, x.data(), par.data(), b.data());
    EXPECT_EQ(a, b);
    Ball::reset_inverse(0, x.data(), par.data(), a.data());
    Table::reset_inverse(0, x.data(), par.data(), b.data());
    EXPECT_EQ(a, b);
    Ball::guard_gradient(0, x.data(), par.data(), a.data());
    Table::guard_gradient(0, x.data(), par.data(), b.data());
    EXPECT_EQ(a, b);
    Ball::reset_jacobian(0, x.data(), par.data(), ja.data());
    Table::reset_jacobian(0, x.data(), par.data(), jb.data());
    EXPECT_EQ(ja, jb);
    EXPECT_EQ(Ball::divergence(0, x.data(), par.data()),
              Table::divergence(0, x.data(), par.data()));
    EXPECT_EQ(Ball::guard_surface(0, x.data(), par.data()),
              Table::guard_surface(0, x.data(), par.data()));
    EXPECT_EQ(Ball::hybrid_jacobian(0, x.data(), par.data()),
              Table::hybrid_jacobian(0, x.data(), par.data()));
    EXPECT_EQ(Ball::initial_density(0, x.data(), par.data()),
              Table::initial_density(0, x.data(), par.data()));
    EXPECT_EQ(Ball::in_support(x.data(), par.data()), Table::in_support(x.data(), par.data()));
    EXPECT_TRUE(Table::in_region(0, x.data(), par.data()));  // the ball has no regions
  }
}

// Every method through the table gives the struct's densities (to rounding: the compiler may
// contract a*b+c differently once a kernel is inlined) and the same budget.
TEST(TableModel, EveryMethodSolvesAsTheStructDoes) {
  ball_table();
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{0.0, 2.0, 31}, rt::GridAxis{-2.0, 2.0, 31}};
  const std::vector<double> times{0.0, 0.5, 1.0};
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  for (const char* method : {"characteristics", "transfer", "particles"}) {
    rt::MethodSettings s;
    s.quiet = true;
    s.set("method", method).set("particles", 20000).set("budget", "full");
    const auto a = rt::solve_method<Ball>(grid, times, 0.5, par.data(), s);
    const auto b = rt::solve_method<Table>(grid, times, 0.5, par.data(), s);
    ASSERT_TRUE(a.ok() && b.ok()) << method << ": " << a.failure << b.failure;
    ASSERT_EQ(a.solution.u.size(), b.solution.u.size());
    double peak = 0, diff = 0;
    for (std::size_t i = 0; i < a.solution.u.size(); ++i) {
      peak = std::max(peak, std::fabs(a.solution.u[i]));
      diff = std::max(diff, std::fabs(a.solution.u[i] - b.solution.u[i]));
    }
    EXPECT_GT(peak, 0.1) << method;
    EXPECT_LE(diff, 1e-9 * peak) << method;
    ASSERT_EQ(a.budget.mass.size(), b.budget.mass.size());
    for (std::size_t k = 0; k < a.budget.mass.size(); ++k)
      EXPECT_NEAR(a.budget.mass[k], b.budget.mass[k], 1e-9 * a.budget.mass0) << method;
  }
}

TEST(TableModel, LibraryShapes) {
  EXPECT_TRUE(rt::table_fits(1, 0));
  EXPECT_TRUE(rt::table_fits(rt::kTableMaxState, rt::kTableMaxGuards));
  EXPECT_FALSE(rt::table_fits(0, 1));
  EXPECT_FALSE(rt::table_fits(rt::kTableMaxState + 1, 1));
  EXPECT_FALSE(rt::table_fits(2, rt::kTableMaxGuards + 1));
}

}  // namespace
