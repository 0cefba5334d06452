// Tests of hybgen/rt/core/ode.hpp: Dormand–Prince 5(4) with dense output and event location.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "hybgen/rt/core/ode.hpp"

namespace {

using hybgen::rt::Dopri5;
using hybgen::rt::EventRoot;
using hybgen::rt::integrate;
using hybgen::rt::OdeOptions;
using hybgen::rt::OdeStatus;
using V1 = std::array<double, 1>;
using V2 = std::array<double, 2>;

constexpr double kPi = std::numbers::pi;

OdeOptions tol(double rtol, double atol) {
  OdeOptions o;
  o.rtol = rtol;
  o.atol = atol;
  return o;
}

TEST(Ode, ExponentialDecay) {
  // y' = −λ y, y(0) = (1, 2): y(t) = y(0) e^{−λt}, two rates at once.
  auto f = [](double, const V2& y, V2& dy) {
    dy[0] = -y[0];
    dy[1] = -3.0 * y[1];
  };
  const auto res = integrate(f, 0.0, V2{1.0, 2.0}, 5.0, tol(1e-10, 1e-14));
  ASSERT_EQ(res.status, OdeStatus::ok);
  EXPECT_EQ(res.t, 5.0);
  EXPECT_NEAR(res.y[0], std::exp(-5.0), 1e-10 * std::exp(-5.0) * 50);
  EXPECT_NEAR(res.y[1], 2.0 * std::exp(-15.0), 1e-9 * 2.0 * std::exp(-15.0) + 1e-13);
  // Tighter tolerance, smaller error (convergence of the controller).
  const auto loose = integrate(f, 0.0, V2{1.0, 2.0}, 5.0, tol(1e-6, 1e-12));
  EXPECT_LT(std::fabs(res.y[0] - std::exp(-5.0)), std::fabs(loose.y[0] - std::exp(-5.0)));
  EXPECT_GT(res.steps, loose.steps);
}

TEST(Ode, HarmonicOscillatorEnergyOver100Periods) {
  // x' = v, v' = −x; E = (x² + v²)/2 is conserved. DP5 is not symplectic, so the drift
  // is the global error: it must stay < 1e-9 over 100 periods at rtol 1e-11.
  auto f = [](double, const V2& y, V2& dy) {
    dy[0] = y[1];
    dy[1] = -y[0];
  };
  Dopri5<2> ode(tol(1e-11, 1e-13));
  const double t_end = 200.0 * kPi;
  ASSERT_EQ(ode.start(f, 0.0, V2{1.0, 0.0}, t_end), OdeStatus::ok);
  double max_drift = 0.0;
  while (!ode.done()) {
    ASSERT_EQ(ode.step(f), OdeStatus::ok);
    const double e = 0.5 * (ode.y()[0] * ode.y()[0] + ode.y()[1] * ode.y()[1]);
    max_drift = std::max(max_drift, std::fabs(e - 0.5));
  }
  EXPECT_LT(max_drift, 1e-9);
  EXPECT_NEAR(ode.y()[0], 1.0, 1e-8);
  EXPECT_NEAR(ode.y()[1], 0.0, 1e-8);
  std::printf("[ harmonic ] 100 periods: %ld steps, %ld rejected, max |E - E0| = %.3g\n",
              ode.accepted_steps(), ode.rejected_steps(), max_drift);
}

TEST(Ode, DenseOutputAccuracy) {
  // Inside every step the continuous extension must be as accurate as the step ends.
  auto f = [](double, const V2& y, V2& dy) {
    dy[0] = y[1];
    dy[1] = -y[0];
  };
  Dopri5<2> ode(tol(1e-9, 1e-12));
  ASSERT_EQ(ode.start(f, 0.0, V2{1.0, 0.0}, 20.0), OdeStatus::ok);
  double max_dense = 0.0, max_node = 0.0;
  V2 x;
  while (!ode.done()) {
    ASSERT_EQ(ode.step(f), OdeStatus::ok);
    max_node = std::max(max_node, std::fabs(ode.y()[0] - std::cos(ode.t())));
    for (int j = 1; j < 10; ++j) {
      const double t = ode.t_prev() + 0.1 * j * ode.h_last();
      ode.dense(t, x);
      max_dense = std::max(max_dense, std::fabs(x[0] - std::cos(t)));
      max_dense = std::max(max_dense, std::fabs(x[1] + std::sin(t)));
    }
  }
  EXPECT_LT(max_dense, 1e-7);
  EXPECT_LT(max_dense, 20.0 * max_node + 1e-12);

  // The extension has order 4: exact (to rounding) on a degree-4 polynomial solution.
  auto fp = [](double t, const V1&, V1& dy) { dy[0] = 4.0 * t * t * t; };
  Dopri5<1> pode(tol(1e-6, 1e-6));
  ASSERT_EQ(pode.start(fp, 0.0, V1{0.0}, 3.0, 3.0), OdeStatus::ok);
  ASSERT_EQ(pode.step(fp), OdeStatus::ok);
  EXPECT_EQ(pode.t(), 3.0);
  V1 z;
  for (int j = 0; j <= 30; ++j) {
    const double t = 0.1 * j;
    pode.dense(t, z);
    EXPECT_NEAR(z[0], t * t * t * t, 1e-12 * 81.0) << "t = " << t;
  }
}

TEST(Ode, FallingBodyHitsGround) {
  // x' = v, v' = −g from x0 = 10, v0 = 2: x(t*) = 0 at t* = (v0 + sqrt(v0² + 2 g x0)) / g.
  const double g = 9.81, x0 = 10.0, v0 = 2.0;
  const double t_star = (v0 + std::sqrt(v0 * v0 + 2.0 * g * x0)) / g;
  auto f = [g](double, const V2& y, V2& dy) {
    dy[0] = y[1];
    dy[1] = -g;
  };
  auto ev = [](int, const V2& y) { return y[0]; };
  const int dir = -1;
  const auto res = integrate(f, 0.0, V2{x0, v0}, 10.0, tol(1e-12, 1e-12), 1, &dir, ev,
                             [](const EventRoot&, const V2&) { return true; });
  ASSERT_EQ(res.status, OdeStatus::ok);
  ASSERT_EQ(res.event, 0);
  EXPECT_NEAR(res.t, t_star, 1e-12);
  EXPECT_NEAR(res.y[0], 0.0, 1e-12);
  EXPECT_NEAR(res.y[1], v0 - g * t_star, 1e-11);
}

TEST(Ode, DirectionFiltering) {
  // x = cos t: decreasing root at π/2, increasing at 3π/2.
  auto f = [](double, const V2& y, V2& dy) {
    dy[0] = y[1];
    dy[1] = -y[0];
  };
  auto ev = [](int, const V2& y) { return y[0]; };
  auto stop = [](const EventRoot&, const V2&) { return true; };
  for (int dir : {-1, 0, 1}) {
    const auto res = integrate(f, 0.0, V2{1.0, 0.0}, 10.0, tol(1e-12, 1e-13), 1, &dir, ev, stop);
    ASSERT_EQ(res.event, 0);
    EXPECT_NEAR(res.t, dir == 1 ? 1.5 * kPi : 0.5 * kPi, 1e-11) << "direction " << dir;
  }
}

TEST(Ode, TwoRootsInsideOneStep) {
  // x' = 1 is integrated exactly, so one step covers [0, 10]; g = (x − 3)(x − 4.5) is
  // positive at both step ends: only the interior sign checks can see its two roots.
  auto f = [](double, const V1&, V1& dy) { dy[0] = 1.0; };
  auto ev = [](int, const V1& y) { return (y[0] - 3.0) * (y[0] - 4.5); };
  OdeOptions o = tol(1e-10, 1e-10);
  o.h_init = 10.0;
  std::vector<EventRoot> roots;
  const int both = 0;
  const auto res =
      integrate(f, 0.0, V1{0.0}, 10.0, o, 1, &both, ev, [&](const EventRoot& r, const V1&) {
        roots.push_back(r);
        return false;
      });
  ASSERT_EQ(res.status, OdeStatus::ok);
  EXPECT_EQ(res.steps, 1);
  ASSERT_EQ(roots.size(), 2u);
  EXPECT_NEAR(roots[0].t, 3.0, 1e-13);
  EXPECT_EQ(roots[0].direction, -1);
  EXPECT_NEAR(roots[1].t, 4.5, 1e-13);
  EXPECT_EQ(roots[1].direction, 1);
  // Only the increasing one when asked for.
  const int up = 1;
  const auto r2 = integrate(f, 0.0, V1{0.0}, 10.0, o, 1, &up, ev,
                            [](const EventRoot&, const V1&) { return true; });
  EXPECT_NEAR(r2.t, 4.5, 1e-13);
}

TEST(Ode, NoTriggerAtTheStartingPoint) {
  // Starting exactly on g = 0 (as right after a reset) must not report a root at t0,
  // whichever direction is required; the next genuine root is still found.
  auto f = [](double, const V2& y, V2& dy) {
    dy[0] = y[1];
    dy[1] = -1.0;
  };
  auto ev = [](int, const V2& y) { return y[0]; };
  std::vector<double> ts;
  for (int dir : {-1, 0, 1}) {
    ts.clear();
    const auto res = integrate(f, 0.0, V2{0.0, 1.0}, 5.0, tol(1e-12, 1e-12), 1, &dir, ev,
                               [&](const EventRoot& r, const V2&) {
                                 ts.push_back(r.t);
                                 return false;
                               });
    ASSERT_EQ(res.status, OdeStatus::ok);
    if (dir == 1) {
      EXPECT_TRUE(ts.empty());
    } else {
      ASSERT_EQ(ts.size(), 1u) << "direction " << dir;
      EXPECT_NEAR(ts[0], 2.0, 1e-12);  // x = t − t²/2
    }
  }
  // The locator flags the start root for the caller and arms with the side being entered.
  Dopri5<2> ode(tol(1e-12, 1e-12));
  hybgen::rt::EventLocator<2, 1> loc;
  const int both = 0;
  loc.configure(1, &both);
  ASSERT_EQ(ode.start(f, 0.0, V2{0.0, 1.0}, 5.0), OdeStatus::ok);
  ASSERT_EQ(ode.step(f), OdeStatus::ok);
  bool at_start = false;
  loc.arm(ode, ev, nullptr, &at_start);
  EXPECT_TRUE(at_start);
}

TEST(Ode, NonFiniteVectorFieldIsReported) {
  // y' = −1/(2y), y(0) = 1: y = sqrt(1 − t) ends at t = 1; past it f is NaN.
  auto f = [](double, const V1& y, V1& dy) { dy[0] = -0.5 / std::sqrt(y[0]) / std::sqrt(y[0]); };
  auto g = [](double, const V1& y, V1& dy) { dy[0] = std::sqrt(y[0] - 2.0); };
  const auto res = integrate(f, 0.0, V1{1.0}, 2.0, tol(1e-10, 1e-12));
  EXPECT_NE(res.status, OdeStatus::ok);
  EXPECT_LT(res.t, 1.0 + 1e-6);
  const auto res2 = integrate(g, 0.0, V1{1.0}, 2.0, tol(1e-10, 1e-12));
  EXPECT_EQ(res2.status, OdeStatus::non_finite);
  EXPECT_EQ(res2.t, 0.0);
}

}  // namespace
