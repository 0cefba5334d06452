// Tests of hybgen/rt/methods/forward.hpp (the forward hybrid flow) against closed forms derived by
// hand: the bouncing ball (elastic and e = 0.8 with its Zeno point), an oscillator with
// direction-filtered guards, a chattering model (event cap), a non-finite vector field, a
// model leaving its support, and a start on a guard surface.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/forward.hpp"

namespace {

namespace rt = hybgen::rt;
using Ball = rt::testing::BouncingBall;
using P2 = std::array<double, 2>;

// ---------------------------------------------------------------------------------------
// The ball's forward closed form (m = g = 1, restitution e). From (x0, p0), x0 ≥ 0:
// flight x(t) = x0 + p0 t − t²/2, p(t) = p0 − t, reaching the ground x = 0 at the positive
// root t1 = p0 + v1, v1 = sqrt(p0² + 2 x0), with p = −v1. The k-th impact (k ≥ 1) leaves
// with speed w_k = e^k v1, and the flight after it lasts 2 w_k (x = w s − s²/2 returns to 0
// at s = 2w). Hence impact k+1 is at t_{k+1} = t1 + 2 v1 (e + … + e^k), and for e < 1 the
// impacts accumulate at the ZENO TIME
//   t_Z = t1 + Σ_{k≥1} 2 e^k v1 = t1 + 2 e v1/(1 − e) = p0 + v1 (1 + e)/(1 − e),
// where the ball comes to rest at the Zeno point (0, 0).

struct BallState {
  P2 x{};
  int impacts = 0;
};

BallState ball_forward(double x0, double p0, double t, double e) {
  const double v1 = std::sqrt(p0 * p0 + 2.0 * x0);
  const double t1 = p0 + v1;
  if (t < t1) return {{x0 + p0 * t - 0.5 * t * t, p0 - t}, 0};
  double s = t - t1, w = e * v1;
  int n = 1;
  while (s >= 2.0 * w && w > 0.0) {
    s -= 2.0 * w;
    w *= e;
    ++n;
  }
  return {{w * s - 0.5 * s * s, w - s}, n};
}

double zeno_time(double x0, double p0, double e) {
  const double v1 = std::sqrt(p0 * p0 + 2.0 * x0);
  return p0 + v1 * (1.0 + e) / (1.0 - e);
}

/// Distance from t to the nearest impact (to avoid asserting impact counts at ties).
double distance_to_impact(double x0, double p0, double t, double e) {
  const double v1 = std::sqrt(p0 * p0 + 2.0 * x0);
  double ti = p0 + v1, w = e * v1, d = std::fabs(t - ti);
  for (int k = 0; k < 100000 && ti < t + 1.0; ++k) {
    ti += 2.0 * w;
    w *= e;
    d = std::min(d, std::fabs(t - ti));
  }
  return d;
}

rt::ForwardOptions options() {
  rt::ForwardOptions o;
  o.ode.rtol = 1e-10;
  o.ode.atol = 1e-12;
  return o;
}

// ---------------------------------------------------------------------------------------
// Small test models (boilerplate shared by a base).

struct NoReset {
  static double divergence(int, const double*, const double*) { return 0.0; }
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = out[3] = 1.0;
    out[1] = out[2] = 0.0;
  }
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  static double initial_density(int, const double*, const double*) { return 1.0; }
};

/// Harmonic oscillator x' = p, p' = −x, two modes with the same flow; guard g0 (0 → 1) and
/// g1 (1 → 0) both on s = x with direction Dir, identity reset. From (1, 0): x = cos t, so x
/// decreases through 0 at π/2 + 2πk and increases through 0 at 3π/2 + 2πk. After g0 fires
/// (p = −1: moving to the firing side of g1 too) g1 must NOT re-trigger at once.
template <int Dir>
struct Oscillator : NoReset {
  static constexpr int n_state = 2, n_param = 0, n_mode = 2, n_guard = 2;
  static constexpr const char* name = "oscillator";
  static constexpr std::array<const char*, 2> state_names{"x", "p"};
  static constexpr std::array<const char*, 0> param_names{};
  static constexpr std::array<double, 0> param_defaults{};
  static constexpr std::array<const char*, 2> mode_names{"a", "b"};
  static constexpr std::array<const char*, 2> guard_names{"ab", "ba"};
  static constexpr std::array<rt::GuardInfo, 2> guards{rt::GuardInfo{0, 1, Dir, true},
                                                       rt::GuardInfo{1, 0, Dir, true}};
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1];
    out[1] = -x[0];
  }
  static double guard_surface(int, const double* x, const double*) { return x[0]; }
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<Oscillator<-1>>);

/// Chattering: x' = −1, y' = 1; guard s = x decreasing, reset (x, y) → (x + c, y), c = par[0].
/// From (x0 > 0, 0): events at x0 + j c, j = 0, 1, …: constant gaps, no accumulation.
struct Chatter : NoReset {
  static constexpr int n_state = 2, n_param = 1, n_mode = 1, n_guard = 1;
  static constexpr const char* name = "chatter";
  static constexpr std::array<const char*, 2> state_names{"x", "y"};
  static constexpr std::array<const char*, 1> param_names{"c"};
  static constexpr std::array<double, 1> param_defaults{1e-3};
  static constexpr std::array<const char*, 1> mode_names{"only"};
  static constexpr std::array<const char*, 1> guard_names{"wall"};
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, -1, true}};
  static void flow(int, const double*, const double*, double* out) {
    out[0] = -1.0;
    out[1] = 1.0;
  }
  static double guard_surface(int, const double* x, const double*) { return x[0]; }
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  static void reset(int, const double* x, const double* par, double* out) {
    out[0] = x[0] + par[0];
    out[1] = x[1];
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<Chatter>);

/// x' = 1, y' = 0 for x < 2; the vector field is NaN for x ≥ 2. No guards.
struct Poisoned : NoReset {
  static constexpr int n_state = 2, n_param = 0, n_mode = 1, n_guard = 0;
  static constexpr const char* name = "poisoned";
  static constexpr std::array<const char*, 2> state_names{"x", "y"};
  static constexpr std::array<const char*, 0> param_names{};
  static constexpr std::array<double, 0> param_defaults{};
  static constexpr std::array<const char*, 1> mode_names{"only"};
  static constexpr std::array<const char*, 0> guard_names{};
  static constexpr std::array<rt::GuardInfo, 0> guards{};
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[0] < 2.0 ? 1.0 : std::numeric_limits<double>::quiet_NaN();
    out[1] = 0.0;
  }
  static double guard_surface(int, const double*, const double*) { return 1.0; }
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = out[1] = 0.0;
  }
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<Poisoned>);

/// The ball's flight with support x ≥ 0 but without the ground guard.
struct FreeFall : Poisoned {
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1];
    out[1] = -1.0;
  }
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0; }
};
static_assert(rt::HybridModel<FreeFall>);

// ---------------------------------------------------------------------------------------

TEST(ForwardFlow, ElasticBallMatchesClosedForm) {
  // e = 1 (m = g = 1): random starts in [0, 2] × [−2, 2], random t ≤ 20. DP5 integrates the
  // quadratic flight exactly and its dense output (order 4) is exact on it, so the only
  // errors are rounding and Brent's root to ~1e-16 relative: states agree to 1e-9 after up
  // to ~10 impacts (each impact time enters every later state with slope ≤ |p| ≤ 3).
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(0.0, 2.0), up(-2.0, 2.0), ut(0.0, 20.0);
  for (int i = 0; i < 300; ++i) {
    const double x0 = ux(rng), p0 = up(rng), t = ut(rng);
    const auto r = rt::forward_flow<Ball>(0, P2{x0, p0}, t, par.data(), options());
    ASSERT_EQ(r.status, rt::ForwardStatus::ok) << rt::describe<Ball>(r, 0, P2{x0, p0});
    const BallState ex = ball_forward(x0, p0, t, 1.0);
    EXPECT_NEAR(r.x[0], ex.x[0], 1e-9) << x0 << " " << p0 << " " << t;
    EXPECT_NEAR(r.x[1], ex.x[1], 1e-9) << x0 << " " << p0 << " " << t;
    EXPECT_EQ(r.mode, 0);
    EXPECT_EQ(r.t_stop, t);
    if (distance_to_impact(x0, p0, t, 1.0) > 1e-6) {
      EXPECT_EQ(r.events, ex.impacts);
    }
  }
}

TEST(ForwardFlow, ImpactTimesAndOutputTimes) {
  // One trajectory for many output times: from (1, 0), v1 = √2, impacts at √2 (2k + 1).
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  std::vector<double> times;
  for (int k = 0; k <= 100; ++k) times.push_back(0.2 * k);
  std::vector<int> seen;
  const auto r = rt::forward_flow<Ball>(
      0, P2{1.0, 0.0}, times, par.data(), options(), [&](std::size_t k, int mode, const P2& x) {
        seen.push_back(static_cast<int>(k));
        EXPECT_EQ(mode, 0);
        const BallState ex = ball_forward(1.0, 0.0, times[k], 1.0);
        EXPECT_NEAR(x[0], ex.x[0], 1e-9) << "t = " << times[k];
        EXPECT_NEAR(x[1], ex.x[1], 1e-9) << "t = " << times[k];
      });
  ASSERT_EQ(r.status, rt::ForwardStatus::ok);
  ASSERT_EQ(seen.size(), times.size());
  for (std::size_t k = 0; k < seen.size(); ++k) EXPECT_EQ(seen[k], static_cast<int>(k));
  // Impacts at √2·(2k + 1) ≤ 20: k = 0..6.
  EXPECT_EQ(r.events, 7);
  // Just before and after the third impact √2·5.
  const double t3 = 5.0 * std::numbers::sqrt2;
  EXPECT_EQ(rt::forward_flow<Ball>(0, P2{1.0, 0.0}, t3 - 1e-7, par.data(), options()).events, 2);
  EXPECT_EQ(rt::forward_flow<Ball>(0, P2{1.0, 0.0}, t3 + 1e-7, par.data(), options()).events, 3);
}

TEST(ForwardFlow, ZenoBallReachesTheZenoPoint) {
  // e = 0.8 from (1, 0): t_Z = √2·(1 + 0.8)/(1 − 0.8) = 9√2 ≈ 12.728. The gaps 2·0.8ᵏ√2 are
  // exactly geometric and the flights exact (see above), so the extrapolated t_Z and x_Z are
  // exact up to rounding amplified by r/(1 − r)² = 20: asserted to 1e-9.
  const double e = 0.8;
  const std::array<double, 3> par{1.0, 1.0, e};
  const double tz = zeno_time(1.0, 0.0, e);
  EXPECT_NEAR(tz, 9.0 * std::numbers::sqrt2, 1e-12);
  const auto r = rt::forward_flow<Ball>(0, P2{1.0, 0.0}, 20.0, par.data(), options());
  ASSERT_EQ(r.status, rt::ForwardStatus::zeno) << rt::describe<Ball>(r, 0, P2{1.0, 0.0});
  EXPECT_NEAR(r.t_stop, tz, 1e-9);
  EXPECT_NEAR(r.x[0], 0.0, 1e-9);
  EXPECT_NEAR(r.x[1], 0.0, 1e-9);
  EXPECT_EQ(r.error, rt::TraceError::none);
  // Declared once the gap 2·0.8ᵏ√2 ≤ zeno_time·t_end = 2e-6: k ≥ 62.
  EXPECT_GE(r.events, 60);
  EXPECT_LE(r.events, 70);
  // Before t_Z: ok and on the closed form; the impact count too.
  for (const double t : {tz - 2.0, tz - 0.5, tz - 0.01}) {
    const auto q = rt::forward_flow<Ball>(0, P2{1.0, 0.0}, t, par.data(), options());
    ASSERT_EQ(q.status, rt::ForwardStatus::ok) << t;
    const BallState ex = ball_forward(1.0, 0.0, t, e);
    EXPECT_NEAR(q.x[0], ex.x[0], 1e-9) << t;
    EXPECT_NEAR(q.x[1], ex.x[1], 1e-9) << t;
    EXPECT_EQ(q.events, ex.impacts) << t;
  }
  // Many output times: exactly those before t_Z are delivered, on the closed form.
  std::vector<double> times;
  for (int k = 0; k <= 100; ++k) times.push_back(0.2 * k);
  std::size_t n = 0;
  const auto m = rt::forward_flow<Ball>(0, P2{1.0, 0.0}, times, par.data(), options(),
                                        [&](std::size_t k, int, const P2& x) {
                                          EXPECT_EQ(k, n);
                                          ++n;
                                          const BallState ex = ball_forward(1.0, 0.0, times[k], e);
                                          EXPECT_NEAR(x[0], ex.x[0], 1e-9);
                                          EXPECT_NEAR(x[1], ex.x[1], 1e-9);
                                        });
  EXPECT_EQ(m.status, rt::ForwardStatus::zeno);
  EXPECT_EQ(n, static_cast<std::size_t>(std::ceil(tz / 0.2)));
}

TEST(ForwardFlow, ZenoTimeOverRandomStarts) {
  // The closed-form t_Z = p0 + v1 (1 + e)/(1 − e) for random starts and several e, down to
  // e = 0.001, where the third flight (2e-9·v1) is the last one resolvable above the re-arm
  // window δ = 1e-12·t_end: the signature (3 gaps) must be complete by then.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> ux(0.0, 2.0), up(-2.0, 2.0);
  for (const double e : {0.001, 0.01, 0.5, 0.8, 0.9}) {
    const std::array<double, 3> par{1.0, 1.0, e};
    for (int i = 0; i < 50; ++i) {
      const double x0 = ux(rng), p0 = up(rng);
      const double tz = zeno_time(x0, p0, e);
      const auto r = rt::forward_flow<Ball>(0, P2{x0, p0}, tz + 1.0, par.data(), options());
      ASSERT_EQ(r.status, rt::ForwardStatus::zeno) << e << " " << x0 << " " << p0;
      EXPECT_NEAR(r.t_stop, tz, 1e-9 * (1.0 + tz));
      EXPECT_NEAR(r.x[0], 0.0, 1e-9);
      EXPECT_NEAR(r.x[1], 0.0, 1e-9);
    }
  }
}

TEST(ForwardFlow, RestartFromTheZenoPointStaysThere) {
  // (0, 0) with e = 0.8: the ground fires at once (x'' < 0) and Δ(0, 0) = (0, 0) fires again:
  // at rest from t = 0 (zeno, t_stop = 0). Restarting from a returned Zeno state is the same.
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  const auto r = rt::forward_flow<Ball>(0, P2{0.0, 0.0}, 1.0, par.data(), options());
  ASSERT_EQ(r.status, rt::ForwardStatus::zeno) << rt::describe<Ball>(r, 0, P2{0.0, 0.0});
  EXPECT_EQ(r.t_stop, 0.0);
  EXPECT_EQ(r.x, (P2{0.0, 0.0}));
  const auto z = rt::forward_flow<Ball>(0, P2{1.0, 0.0}, 20.0, par.data(), options());
  ASSERT_EQ(z.status, rt::ForwardStatus::zeno);
  const auto again = rt::forward_flow<Ball>(0, z.x, 0.5, par.data(), options());
  EXPECT_EQ(again.status, rt::ForwardStatus::zeno);
  EXPECT_EQ(again.t_stop, 0.0);
  EXPECT_NEAR(again.x[0], 0.0, 1e-9);
  EXPECT_NEAR(again.x[1], 0.0, 1e-9);
}

TEST(ForwardFlow, EventCapWithZenoSignatureIsZeno) {
  // e = 0.95: gaps shrink by 0.95 per impact; with max_events = 100 the cap is hit long before
  // the gap reaches zeno_time, but the signature holds and t_Z ≤ t_end: Zeno, with the
  // extrapolated (exact for geometric gaps) t_Z. With t_end < t_Z the same cap is an error.
  const double e = 0.95;
  const std::array<double, 3> par{1.0, 1.0, e};
  auto o = options();
  o.max_events = 100;
  const double tz = zeno_time(1.0, 0.0, e);
  const auto r = rt::forward_flow<Ball>(0, P2{1.0, 0.0}, tz + 1.0, par.data(), o);
  ASSERT_EQ(r.status, rt::ForwardStatus::zeno);
  EXPECT_EQ(r.events, 101);
  EXPECT_NEAR(r.t_stop, tz, 1e-8 * tz);
  EXPECT_NEAR(r.x[1], 0.0, 1e-8);
  const auto c = rt::forward_flow<Ball>(0, P2{1.0, 0.0}, tz - 0.01, par.data(), o);
  EXPECT_EQ(c.status, rt::ForwardStatus::event_cap);
  EXPECT_EQ(c.error, rt::TraceError::event_cap);
}

TEST(ForwardFlow, DirectionIsFiltered) {
  // Oscillator from (1, 0): decreasing crossings at π/2 + 2πk, increasing at 3π/2 + 2πk.
  const double pi = std::numbers::pi;
  std::vector<double> times;
  for (int k = 0; k <= 200; ++k) times.push_back(0.1 * k);
  auto count = [&](double t, double first) {
    int n = 0;
    for (double c = first; c <= t; c += 2.0 * pi) ++n;
    return n;
  };
  auto check = [&](auto model_tag, double first) {
    using Model = decltype(model_tag);
    int seen = 0;
    const auto r = rt::forward_flow<Model>(0, P2{1.0, 0.0}, times, nullptr, options(),
                                           [&](std::size_t k, int mode, const P2& x) {
                                             ++seen;
                                             const double t = times[k];
                                             EXPECT_EQ(mode, count(t, first) % 2) << "t = " << t;
                                             // Identity resets: the state is the oscillator's;
                                             // error ≲ rtol·t·(#steps) ≪ 1e-7.
                                             EXPECT_NEAR(x[0], std::cos(t), 1e-7) << "t = " << t;
                                             EXPECT_NEAR(x[1], -std::sin(t), 1e-7) << "t = " << t;
                                           });
    EXPECT_EQ(r.status, rt::ForwardStatus::ok);
    EXPECT_EQ(seen, static_cast<int>(times.size()));
    EXPECT_EQ(r.events, count(20.0, first));
  };
  check(Oscillator<-1>{}, pi / 2.0);        // π/2, 5π/2, 9π/2, 13π/2: 4 events by t = 20
  check(Oscillator<+1>{}, 3.0 * pi / 2.0);  // 3π/2, 7π/2, 11π/2: 3 events
}

TEST(ForwardFlow, ChatteringHitsTheEventCap) {
  // Events at 0.5 + j·1e-3: constant gaps (ratio 1), so no Zeno signature. With
  // max_events = 50 the 51st crossing (j = 50, t = 0.55) is the error, reported with state.
  const std::array<double, 1> par{1e-3};
  auto o = options();
  o.max_events = 50;
  const auto r = rt::forward_flow<Chatter>(0, P2{0.5, 0.0}, 1.0, par.data(), o);
  ASSERT_EQ(r.status, rt::ForwardStatus::event_cap);
  EXPECT_EQ(r.error, rt::TraceError::event_cap);
  EXPECT_EQ(r.events, 51);
  EXPECT_EQ(r.guard, 0);
  EXPECT_NEAR(r.t_stop, 0.55, 1e-12);
  EXPECT_NEAR(r.x[0], 0.0, 1e-12);
  EXPECT_NEAR(r.x[1], 0.55, 1e-12);
  const std::string msg = rt::describe<Chatter>(r, 0, P2{0.5, 0.0});
  EXPECT_NE(msg.find("wall"), std::string::npos) << msg;
  EXPECT_NE(msg.find("max_events"), std::string::npos) << msg;
  // Below the cap: 101 events (j = 0..100) by t = 0.6005, state (1e-3 − 5e-4, 0.6005).
  o.max_events = 1000;
  const auto q = rt::forward_flow<Chatter>(0, P2{0.5, 0.0}, 0.6005, par.data(), o);
  ASSERT_EQ(q.status, rt::ForwardStatus::ok);
  EXPECT_EQ(q.events, 101);
  EXPECT_NEAR(q.x[0], 5e-4, 1e-12);
  EXPECT_NEAR(q.x[1], 0.6005, 1e-12);
}

TEST(ForwardFlow, NonFiniteFlowFails) {
  // x' = 1 until x = 2, then NaN: the ODE cannot pass x = 2.
  const auto r = rt::forward_flow<Poisoned>(0, P2{0.0, 0.0}, 5.0, nullptr, options());
  ASSERT_EQ(r.status, rt::ForwardStatus::failed);
  EXPECT_EQ(r.error, rt::TraceError::non_finite_flow);
  EXPECT_LE(r.t_stop, 2.0);
  EXPECT_GE(r.t_stop, 1.0);
  EXPECT_NEAR(r.x[0], r.t_stop, 1e-12);
  EXPECT_TRUE(std::isfinite(r.x[0]));
}

TEST(ForwardFlow, LeavingTheSupport) {
  // Free fall from (1, 0) crosses x = 0 at √2 and nothing stops it: left_support at the first
  // step end after √2, with x < 0 there; outputs before that are on the parabola.
  std::vector<double> times{0.0, 0.5, 1.0, 1.4, 3.0, 4.0};
  std::size_t n = 0;
  const auto r = rt::forward_flow<FreeFall>(0, P2{1.0, 0.0}, times, nullptr, options(),
                                            [&](std::size_t k, int, const P2& x) {
                                              ++n;
                                              const double t = times[k];
                                              EXPECT_NEAR(x[0], 1.0 - 0.5 * t * t, 1e-9);
                                            });
  ASSERT_EQ(r.status, rt::ForwardStatus::left_support);
  EXPECT_GE(r.t_stop, std::numbers::sqrt2);
  EXPECT_LT(r.x[0], 0.0);
  EXPECT_GE(n, 4u);
  // A start outside the support stops at once.
  const auto s = rt::forward_flow<FreeFall>(0, P2{-1.0, 0.0}, 1.0, nullptr, options());
  EXPECT_EQ(s.status, rt::ForwardStatus::left_support);
  EXPECT_EQ(s.t_stop, 0.0);
}

TEST(ForwardFlow, StartOnTheGuardFiresAtOnce) {
  // (0, −1) is on the ground moving down: the guard fires at t = 0 → (0, e). With e = 0.5 at
  // t = 0.5: x = 0.5·0.5 − 0.125 = 0.125, p = 0. (0, +1) moves up: no event at the start.
  const std::array<double, 3> par{1.0, 1.0, 0.5};
  const auto r = rt::forward_flow<Ball>(0, P2{0.0, -1.0}, 0.5, par.data(), options());
  ASSERT_EQ(r.status, rt::ForwardStatus::ok);
  EXPECT_EQ(r.events, 1);
  EXPECT_NEAR(r.x[0], 0.125, 1e-12);
  EXPECT_NEAR(r.x[1], 0.0, 1e-12);
  const auto u = rt::forward_flow<Ball>(0, P2{0.0, 1.0}, 0.5, par.data(), options());
  ASSERT_EQ(u.status, rt::ForwardStatus::ok);
  EXPECT_EQ(u.events, 0);
  EXPECT_NEAR(u.x[0], 0.375, 1e-12);
  // t = 0: nothing happens, the start state is returned.
  const auto z = rt::forward_flow<Ball>(0, P2{0.3, -1.0}, 0.0, par.data(), options());
  EXPECT_EQ(z.status, rt::ForwardStatus::ok);
  EXPECT_EQ(z.x[0], 0.3);
}

}  // namespace
