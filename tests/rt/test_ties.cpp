// Ties in the backward-characteristics tracer (characteristics.hpp): an output time at
// which the backward characteristic meets a reset image exactly. The node then has two
// one-sided values (the straight history and the reset one); it must get exactly one of
// them, never their sum or 0.
//
// This file is compiled like a runner (-march=native, see tests/CMakeLists.txt) and uses the
// committed generated kernel of the ball, because that is where the tie once went wrong:
// with FMA contraction two inlined copies of the same dense-output evaluation rounded
// differently, and the tie was decided both ways (the relative L1 error of the ball on this
// grid was 1.5e-4 instead of 5e-15: some nodes doubled, some 0).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

#include "bouncing_ball/bouncing_ball.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "support/ball_closed_form.hpp"

namespace {

namespace rt = hybgen::rt;
using Ball = hybgen_model::bouncing_ball;

TEST(Ties, DyadicGridOfTheGeneratedBallMatchesTheClosedForm) {
  // h = 1/32 in x and 1/16 in p, outputs every 1/2: x(τ) = x + p τ − τ²/2 (backward from
  // (x, p)) has dyadic roots, so hundreds of characteristics reach the ground exactly at an
  // output time.
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{0.0, 2.0, 65}, rt::GridAxis{-2.0, 2.0, 65}};
  std::vector<double> times;
  for (int k = 0; k <= 20; ++k) times.push_back(0.5 * k);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  rt::CharacteristicsOptions opt;
  opt.ode.rtol = 1e-10;
  opt.ode.atol = 1e-12;
  const auto sol = rt::solve_grid<Ball>(grid, times, par.data(), opt);
  ASSERT_TRUE(sol.ok());
  // Node by node: a doubled or dropped value is off by u itself (≥ 1e-3 where it matters),
  // a correct one by the ODE tolerance (≤ 1e-9 here). The Zeno node (0, 0), where the
  // density has no limit, is left out.
  int bad = 0;
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const auto y = grid.node(i);
      if (y[0] == 0.0 && y[1] == 0.0) continue;
      const double ue = hybgen::testing::ball_exact_elastic(y[0], y[1], times[k]);
      if (std::fabs(sol.at(k, 0, i) - ue) > 1e-8 && bad++ < 5)
        ADD_FAILURE() << "t = " << times[k] << ", (x, p) = (" << y[0] << ", " << y[1]
                      << "): u = " << sol.at(k, 0, i) << ", exact " << ue;
    }
  EXPECT_EQ(bad, 0);
  const double rel = hybgen::testing::ball_relative_l1(grid, sol, times);
  std::printf("[ ties ] 65x65 dyadic grid, 21 outputs: relative L1 %.3g, %d bad nodes\n", rel, bad);
  EXPECT_LE(rel, 1e-10);
}

}  // namespace
