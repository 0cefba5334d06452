// Tests of hybgen/rt/methods/preflight.hpp and of the failure reports of the characteristics:
// every numerical failure class (docs/hardening.md) provoked on hand-written models (variants of
// the bouncing ball of bouncing_ball_model.hpp), with the place (guard, mode, state) and the value
// of the report checked against hand computations.

#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/forward.hpp"
#include "hybgen/rt/methods/preflight.hpp"

namespace {

namespace rt = hybgen::rt;
using Ball = rt::testing::BouncingBall;
using P2 = std::array<double, 2>;
using E = rt::PreflightError;

/// The paper's box [0, 2] × [−2, 2] with n × n nodes; node (0, 0) exists for odd n.
rt::TensorGrid<2> box(int nx, int np) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.0, 2.0, nx}, rt::GridAxis{-2.0, 2.0, np}};
  return g;
}

constexpr std::array<double, 3> kElastic{1.0, 1.0, 1.0};  // m, g, e

// --- Variants of the ball, each breaking one thing. ---

/// u0 = x − 1: negative on x < 1.
struct NegativeInitialBall : Ball {
  /// u0 = x − 1.
  static double initial_density(int, const double* x, const double*) { return x[0] - 1.0; }
};
/// u0 = log(x): −inf at x = 0.
struct LogInitialBall : Ball {
  /// u0 = log x.
  static double initial_density(int, const double* x, const double*) { return std::log(x[0]); }
};
/// Support x ≥ 0, p ≤ 3/2: the elastic impact at p < −3/2 lands outside it.
struct LowCeilingBall : Ball {
  /// x ≥ 0 and p ≤ 3/2.
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0 && x[1] <= 1.5; }
};
/// Δ(x, p) = (x, −p/2 − 1/2): lands moving down (re-triggers) for −1 < p < 0;
/// J = ∇sᵀ adj(DΔ) X(Δx) / ∇s·X(x) = (−1/2)(−p/2 − 1/2)/p = (p + 1)/(2p).
struct HalfBall : Ball {
  /// Δ(x, p) = (x, −p/2 − 1/2).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = -0.5 * x[1] - 0.5;
  }
  /// Δ⁻¹(x, p) = (x, −2p − 1).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = -2.0 * x[1] - 1.0;
  }
  /// DΔ = diag(1, −1/2).
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = out[2] = 0.0;
    out[3] = -0.5;
  }
  /// J = (p + 1)/(2p) (m = 1).
  static double hybrid_jacobian(int, const double* x, const double*) {
    return (x[1] + 1.0) / (2.0 * x[1]);
  }
};
/// J not finite (NaN) where p < −3/2.
struct NaNJacobianBall : Ball {
  /// e² for p ≥ −3/2, NaN below.
  static double hybrid_jacobian(int, const double* x, const double* par) {
    return x[1] < -1.5 ? std::numeric_limits<double>::quiet_NaN() : par[2] * par[2];
  }
};
/// X not finite where p < −3/2.
struct NaNFlowBelowBall : Ball {
  /// (p, −1), NaN in p' for p < −3/2.
  static void flow(int m, const double* x, const double* par, double* out) {
    Ball::flow(m, x, par, out);
    if (x[1] < -1.5) out[1] = std::numeric_limits<double>::quiet_NaN();
  }
};
/// Δ(x, p) = (x, −(3/2) atan p), inverted by Newton (has_inverse = false), which diverges
/// from the start z = y for |y| ≳ 1.4 (Newton on atan).
struct AtanBall : Ball {
  /// Numeric inverse.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, -1, false}};
  /// Δ(x, p) = (x, −1.5 atan p).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = -1.5 * std::atan(x[1]);
  }
  /// DΔ = diag(1, −1.5/(1 + p²)).
  static void reset_jacobian(int, const double* x, const double*, double* out) {
    out[0] = 1.0;
    out[1] = out[2] = 0.0;
    out[3] = -1.5 / (1.0 + x[1] * x[1]);
  }
  /// J = (−1.5/(1 + p²))(−1.5 atan p)/p.
  static double hybrid_jacobian(int, const double* x, const double*) {
    return 2.25 * std::atan(x[1]) / ((1.0 + x[1] * x[1]) * x[1]);
  }
};
static_assert(rt::HybridModel<AtanBall>);

/// Grazing: x' = 1, y' = x² on [−1, 1] × [−3/2, 3/2]; guard s = y increasing, Δ = (x, y − 1).
/// Orbits y = x³/3 + c cross y = 0 upwards; at (0, 0) the flow (1, 0) is tangent (inflection).
struct Cubic : Ball {
  /// (x, y).
  static constexpr std::array<const char*, 2> state_names{"x", "y"};
  /// Increasing.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, true}};
  /// X = (1, x²).
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = 1.0;
    out[1] = x[0] * x[0];
  }
  /// s = y.
  static double guard_surface(int, const double* x, const double*) { return x[1]; }
  /// ∇s = (0, 1).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 0.0;
    out[1] = 1.0;
  }
  /// Δ = (x, y − 1).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1] - 1.0;
  }
  /// J = ∇s·X(Δx)/∇s·X(x) = 1.
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  /// Everywhere.
  static bool in_support(const double*, const double*) { return true; }
};
/// The harmonic oscillator x' = p, p' = −x with guard x = 1 decreasing, Δ = (x − 1, p): the
/// circle of radius 1 touches x = 1 at (1, 0) without crossing it (a legitimate tangency).
struct Oscillator : Ball {
  /// X = (p, −x).
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1];
    out[1] = -x[0];
  }
  /// s = x − 1.
  static double guard_surface(int, const double* x, const double*) { return x[0] - 1.0; }
  /// Δ = (x − 1, p).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0] - 1.0;
    out[1] = x[1];
  }
  /// J = ∇s·X(Δx)/∇s·X(x) = 1 on s = 0 (p⁺ = p).
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  /// Everywhere.
  static bool in_support(const double*, const double*) { return true; }
};

/// Grazing reached only mid-trace: x' = 1, y' = 3x², guard s = y increasing, Δ = (x, y + 1).
/// Orbits y = x³ + c; the one with c = 0 crosses y = 0 at the inflection (0, 0), where the
/// flow (1, 0) is tangent to the guard. The box [1/2, 3/2] × [−1/2, 3/2] meets the guard only
/// where it is crossed transversally (x ≥ 1/2: |∇s·X|/(|∇s||X|) ≥ 0.6), so the pre-flight scan
/// passes; but its node (1, 1) lies on that orbit: its backward characteristic x = 1 − τ,
/// y = (1 − τ)³ meets the guard at the tangency at τ = 1, outside the box. DΔ = I, so
/// J = ∇s·X(Δx)/∇s·X(x) = 1 (X does not depend on y); div X = 0.
struct Inflection : Ball {
  /// (x, y).
  static constexpr std::array<const char*, 2> state_names{"x", "y"};
  /// One mode `m`.
  static constexpr std::array<const char*, 1> mode_names{"m"};
  /// One guard `g`.
  static constexpr std::array<const char*, 1> guard_names{"g"};
  /// Increasing, closed-form inverse.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, true}};
  /// X = (1, 3x²).
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 3.0 * x[0] * x[0];
  }
  /// s = y.
  static double guard_surface(int, const double* x, const double*) { return x[1]; }
  /// ∇s = (0, 1).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 0.0;
    out[1] = 1.0;
  }
  /// Δ = (x, y + 1).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1] + 1.0;
  }
  /// Δ⁻¹ = (x, y − 1).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1] - 1.0;
  }
  /// DΔ = I.
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = out[3] = 1.0;
    out[1] = out[2] = 0.0;
  }
  /// J = 1.
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  /// u0 = exp(−x² − y²).
  static double initial_density(int, const double* x, const double*) {
    return std::exp(-x[0] * x[0] - x[1] * x[1]);
  }
  /// Everywhere.
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<Inflection>);

rt::TensorGrid<2> cubic_box(int n) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{-1.0, 1.0, n}, rt::GridAxis{-1.5, 1.5, n}};
  return g;
}

// ---------------------------------------------------------------------------------------
// Legitimate models pass.

TEST(Preflight, BouncingBallPassesIncludingItsZenoPoint) {
  // The node (0, 0) is on the guard with ∇s·X = 0 (the ball's Zeno point): a tangency the
  // orbit x = −t²/2 does not cross, so no grazing. The grids have that node.
  for (int n : {21, 75, 257}) {
    const auto g = box(n, n);
    ASSERT_EQ(rt::axis_node(g.axes[1], n / 2), 0.0);
    for (double e : {1.0, 0.8, 0.5}) {
      const std::array<double, 3> par{1.0, 1.0, e};
      const auto f = rt::preflight<Ball>(g, par.data());
      EXPECT_TRUE(f.ok()) << n << " " << e << ": " << rt::describe_preflight<Ball>(f);
    }
  }
}

TEST(Preflight, ATangencyWithoutCrossingPasses) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{-1.0, 1.5, 11}, rt::GridAxis{-1.0, 1.0, 11}};  // node (1, 0)
  ASSERT_EQ(rt::axis_node(g.axes[0], 8), 1.0);
  ASSERT_EQ(rt::axis_node(g.axes[1], 5), 0.0);
  const auto f = rt::preflight<Oscillator>(g, kElastic.data());
  EXPECT_TRUE(f.ok()) << rt::describe_preflight<Oscillator>(f);
}

TEST(Preflight, CostOnTheBouncingBall) {
  // Measured, not asserted tightly: the scan is O(nodes); the bound only catches a blow-up
  // (the characteristics solve of 75×75 to t = 10 takes ~10 ms on this machine).
  for (int n : {75, 257, 1025}) {
    const auto g = box(n, n);
    const auto t0 = std::chrono::steady_clock::now();
    const auto f = rt::preflight<Ball>(g, kElastic.data());
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(f.ok());
    std::printf("[ preflight ] bouncing ball %dx%d: %.3f ms\n", n, n, 1e3 * s);
    EXPECT_LT(s, 5.0);
  }
}

// ---------------------------------------------------------------------------------------
// Each failure class.

TEST(Preflight, NegativeInitialDensity) {
  const auto f = rt::preflight<NegativeInitialBall>(box(5, 5), kElastic.data());
  ASSERT_EQ(f.error, E::negative_density);
  EXPECT_EQ(f.guard, -1);
  EXPECT_EQ(f.mode, 0);
  EXPECT_EQ(f.node, 0u);  // the first node in C order, (0, −2): u0 = −1
  EXPECT_EQ(f.state, (P2{0.0, -2.0}));
  EXPECT_EQ(f.value, -1.0);
  const std::string msg = rt::describe_preflight<NegativeInitialBall>(f);
  EXPECT_EQ(msg,
            "pre-flight scan of the initial density at t = 0: negative initial density u0 = -1 at "
            "the grid node (x = 0, p = -2) in mode 'flight'");
}

TEST(Preflight, NonFiniteInitialDensity) {
  const auto f = rt::preflight<LogInitialBall>(box(5, 5), kElastic.data());
  ASSERT_EQ(f.error, E::non_finite_density);
  EXPECT_EQ(f.state, (P2{0.0, -2.0}));
  EXPECT_TRUE(std::isinf(f.value));
  EXPECT_NE(rt::describe_preflight<LogInitialBall>(f).find("non-finite initial density u0 = -inf"),
            std::string::npos);
}

TEST(Preflight, ResetOutsideTheBoxIsANoteNotAFailure) {
  // e = 3/2: Δ(0, −2) = (0, 3), above p = 2; the first ground node in C order. Its mass leaves
  // the box as outflow (the budget counts it: budget/atom.hpp), so the scan passes and keeps
  // the first such point as a note.
  const std::array<double, 3> par{1.0, 1.0, 1.5};
  std::vector<rt::PreflightFailure<2>> notes;
  const auto f = rt::preflight<Ball>(box(21, 21), par.data(), {}, nullptr, &notes);
  EXPECT_TRUE(f.ok()) << rt::describe_preflight<Ball>(f);
  ASSERT_EQ(notes.size(), 1u);
  const auto& n = notes.front();
  ASSERT_EQ(n.error, E::reset_outside_box);
  EXPECT_EQ(n.guard, 0);
  EXPECT_EQ(n.state, (P2{0.0, -2.0}));
  EXPECT_EQ(n.image, (P2{0.0, 3.0}));
  EXPECT_EQ(rt::describe_preflight<Ball>(n),
            "pre-flight scan of guard 'ground' at t = 0: the reset carries mass out of the domain "
            "(the grid box) at the point (x = 0, p = -2) of its surface in mode 'flight': Delta = "
            "(x = 0, p = 3)");
  // e = 1 fits exactly (p⁺ = 2 on the face): no note.
  notes.clear();
  EXPECT_TRUE(rt::preflight<Ball>(box(21, 21), kElastic.data(), {}, nullptr, &notes).ok());
  EXPECT_TRUE(notes.empty());
}

TEST(Preflight, ResetOutsideTheSupport) {
  const auto f = rt::preflight<LowCeilingBall>(box(21, 21), kElastic.data());
  ASSERT_EQ(f.error, E::reset_outside_support);
  EXPECT_EQ(f.state, (P2{0.0, -2.0}));
  EXPECT_EQ(f.image, (P2{0.0, 2.0}));
}

TEST(Preflight, ResetBackOnItsGuard) {
  // Ground nodes p_j = −2 + 4j/19; p⁺ = −p/2 − 1/2 < 0 iff p > −1: first p_5 = −18/19.
  const auto f = rt::preflight<HalfBall>(box(20, 20), kElastic.data());
  ASSERT_EQ(f.error, E::reset_retriggers);
  EXPECT_EQ(f.guard, 0);
  EXPECT_EQ(f.other_guard, 0);
  EXPECT_EQ(f.state[0], 0.0);
  EXPECT_NEAR(f.state[1], -18.0 / 19.0, 1e-15);
  EXPECT_NEAR(f.image[1], -1.0 / 38.0, 1e-15);
  EXPECT_NE(rt::describe_preflight<HalfBall>(f).find("is on guard 'ground' of mode 'flight', "
                                                     "which fires there at once"),
            std::string::npos);
}

/// Two water tanks (levels x1, x2 on [0, 1]², inflow w = 1 to one tank, outflows v = 0.6):
/// fill1: (0.4, −0.6), fill2: (−0.6, 0.4); `to2` fill1 → fill2 when x2 = 1/2 decreasing,
/// `to1` fill2 → fill1 when x1 = 1/2 decreasing; identity resets (J = X⁺·∇s/X⁻·∇s: 0.4/(−0.6)
/// or the mirror, ≠ 0). Only at the corner (1/2, 1/2) does a reset land on the other guard,
/// which fires there at once: a re-trigger at one isolated point.
struct WaterTank {
  static constexpr int n_state = 2, n_param = 0, n_mode = 2, n_guard = 2;    ///< Sizes.
  static constexpr const char* name = "water_tank";                          ///< Name.
  static constexpr std::array<const char*, 2> state_names{"x1", "x2"};       ///< States.
  static constexpr std::array<const char*, 0> param_names{};                 ///< None.
  static constexpr std::array<double, 0> param_defaults{};                   ///< None.
  static constexpr std::array<const char*, 2> mode_names{"fill1", "fill2"};  ///< Modes.
  static constexpr std::array<const char*, 2> guard_names{"to2", "to1"};     ///< Guards.
  /// to2: fill1 → fill2 decreasing; to1: fill2 → fill1 decreasing.
  static constexpr std::array<rt::GuardInfo, 2> guards{rt::GuardInfo{0, 1, -1, true},
                                                       rt::GuardInfo{1, 0, -1, true}};
  static constexpr double r1 = 0.5, r2 = 0.5;  ///< The levels of the guards.
  /// X_m.
  static void flow(int m, const double*, const double*, double* out) {
    out[0] = m == 0 ? 0.4 : -0.6;
    out[1] = m == 0 ? -0.6 : 0.4;
  }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// s_to2 = x2 − r2, s_to1 = x1 − r1.
  static double guard_surface(int g, const double* x, const double*) {
    return g == 0 ? x[1] - r2 : x[0] - r1;
  }
  /// ∇s.
  static void guard_gradient(int g, const double*, const double*, double* out) {
    out[0] = g == 0 ? 0.0 : 1.0;
    out[1] = g == 0 ? 1.0 : 0.0;
  }
  /// Identity.
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  /// Identity.
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  /// Identity.
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = out[3] = 1.0;
    out[1] = out[2] = 0.0;
  }
  /// ∇s·X_to / ∇s·X_from.
  static double hybrid_jacobian(int g, const double*, const double*) {
    (void)g;  // to2: 0.4/(−0.6); to1: the same by symmetry
    return 0.4 / -0.6;
  }
  /// u0 = 1 in fill1.
  static double initial_density(int m, const double*, const double*) { return m == 0 ? 1.0 : 0.0; }
  /// The unit square.
  static bool in_support(const double* x, const double*) {
    return x[0] >= 0.0 && x[0] <= 1.0 && x[1] >= 0.0 && x[1] <= 1.0;
  }
};

/// HalfBall's re-trigger is a stretch (−1 < p < 0 of the ground), a failure; the water tank's
/// is one point (the corner of the two guards, a grid node for odd n, else a few bisected
/// crossings next to it): a note, and the scan passes.
TEST(Preflight, ReTriggerAtAnIsolatedPointIsANote) {
  for (const int n : {21, 20}) {
    rt::TensorGrid<2> g;
    g.axes = {rt::GridAxis{0.0, 1.0, n}, rt::GridAxis{0.0, 1.0, n}};
    std::vector<rt::PreflightFailure<2>> notes;
    const auto f = rt::preflight<WaterTank>(g, nullptr, rt::PreflightOptions{}, nullptr, &notes);
    EXPECT_TRUE(f.ok()) << rt::describe_preflight<WaterTank>(f);
    if (n % 2 == 1) {
      ASSERT_EQ(notes.size(), 2u) << n;  // both guards, at the corner node
      for (const auto& note : notes) {
        EXPECT_EQ(note.error, E::reset_retriggers);
        EXPECT_EQ(note.state, (P2{0.5, 0.5}));
      }
      EXPECT_NE(rt::describe_preflight<WaterTank>(notes[0]).find("is on guard 'to1'"),
                std::string::npos);
    } else {
      EXPECT_TRUE(notes.empty());  // no grid point at the corner: nothing re-triggers
    }
  }
  std::vector<rt::PreflightFailure<2>> notes;
  const auto f = rt::preflight<HalfBall>(box(20, 20), kElastic.data(), rt::PreflightOptions{},
                                         nullptr, &notes);
  EXPECT_EQ(f.error, E::reset_retriggers);
  EXPECT_TRUE(notes.empty());
}

TEST(Preflight, ZeroAndNonFiniteHybridJacobian) {
  // 21 nodes: p = −1 is a ground node, where J = (p + 1)/(2p) = 0; the nodes before it
  // (p ≤ −1.2) have p⁺ = −p/2 − 1/2 > 0, J > 0 and no re-trigger.
  auto f = rt::preflight<HalfBall>(box(21, 21), kElastic.data());
  ASSERT_EQ(f.error, E::zero_jacobian);
  EXPECT_EQ(f.state, (P2{0.0, -1.0}));
  EXPECT_EQ(f.value, 0.0);
  // e = 0 (J = e² = 0 everywhere): the first ground node.
  const std::array<double, 3> par0{1.0, 1.0, 0.0};
  f = rt::preflight<Ball>(box(21, 21), par0.data());
  ASSERT_EQ(f.error, E::zero_jacobian);
  EXPECT_EQ(f.state, (P2{0.0, -2.0}));
  // J = NaN below p = −3/2.
  f = rt::preflight<NaNJacobianBall>(box(21, 21), kElastic.data());
  ASSERT_EQ(f.error, E::zero_jacobian);
  EXPECT_TRUE(std::isnan(f.value));
  EXPECT_NE(rt::describe_preflight<NaNJacobianBall>(f).find("zero or non-finite hybrid Jacobian "
                                                            "at the point (x = 0, p = -2)"),
            std::string::npos);
}

TEST(Preflight, NonFiniteFlowAtACrossing) {
  const auto f = rt::preflight<NaNFlowBelowBall>(box(21, 21), kElastic.data());
  ASSERT_EQ(f.error, E::non_finite_flow);
  EXPECT_EQ(f.state, (P2{0.0, -2.0}));
}

TEST(Preflight, Grazing) {
  const auto f = rt::preflight<Cubic>(cubic_box(11), kElastic.data());
  ASSERT_EQ(f.error, E::grazing) << rt::describe_preflight<Cubic>(f);
  EXPECT_EQ(f.state, (P2{0.0, 0.0}));
  EXPECT_EQ(f.value, 0.0);
  EXPECT_NE(rt::describe_preflight<Cubic>(f).find("grazing: the flow is tangent to the guard at "
                                                  "a crossing at the point (x = 0, y = 0)"),
            std::string::npos);
  // An even grid has no node on x = 0; the crossing points on the edges nearest to it have
  // |∇s·X|/(|∇s||X|) = x²/√(1 + x⁴) with |x| ≥ 1/9, far above graze_tol: no report there.
  EXPECT_TRUE(rt::preflight<Cubic>(cubic_box(10), kElastic.data()).ok());
}

TEST(Preflight, NewtonInverseDoesNotConverge) {
  const auto f = rt::preflight<AtanBall>(box(21, 21), kElastic.data());
  ASSERT_EQ(f.error, E::inverse_failed);
  EXPECT_EQ(f.state, (P2{0.0, -2.0}));
  EXPECT_NEAR(f.image[1], 1.5 * std::atan(2.0), 1e-15);
  // Where Newton converges (images 0 ≤ y ≤ 1.5 atan(1/2) ≈ 0.70 of the crossings
  // −1/2 ≤ p < 0) there is no failure: the box [0, 2] × [−1/2, 4/5] holds those images.
  rt::TensorGrid<2> small;
  small.axes = {rt::GridAxis{0.0, 2.0, 11}, rt::GridAxis{-0.5, 0.8, 11}};
  EXPECT_TRUE(rt::preflight<AtanBall>(small, kElastic.data()).ok());
}

// ---------------------------------------------------------------------------------------
// The characteristics name their failures with the state and the backward time.

rt::CharacteristicsOptions options() {
  rt::CharacteristicsOptions o;
  o.ode.rtol = 1e-10;
  o.ode.atol = 1e-12;
  return o;
}

TEST(TraceFailure, NewtonInverseOnACharacteristic) {
  // Backward from (1, 1.66): the incoming guard's event b = s∘Δ⁻¹ needs Δ⁻¹(y) at once, and
  // Newton from z = y diverges there (as in the pre-flight scan).
  const std::vector<double> times{0.0, 0.5, 1.0};
  std::vector<double> out(times.size());
  const auto st = rt::trace<AtanBall>(P2{1.0, 1.66}, 0, times, kElastic.data(), options(), out);
  ASSERT_EQ(st.error, rt::TraceError::inverse_failed);
  EXPECT_EQ(st.guard, 0);
  EXPECT_LT(st.tau, 0.01);  // within the first step
  EXPECT_NEAR(st.state[1], 1.66, 0.01);
  const std::string msg = rt::describe<AtanBall>(rt::TraceFailure<2>{st, 0, 0, P2{1.0, 1.66}});
  EXPECT_NE(msg.find("Newton iteration for the inverse reset did not converge at guard 'ground' at "
                     "backward time tau = "),
            std::string::npos)
      << msg;
}

TEST(TraceFailure, EventCapNamesTheState) {
  // Elastic ball at low energy: from (0.1, 0) the period is 2√0.2 ≈ 0.894, so the 4th
  // backward reset is at τ = 0.447 + 3·0.894 = 3.13 < 4, at the ground with p = −√0.2.
  const std::vector<double> times{0.0, 2.0, 4.0};
  std::vector<double> out(times.size());
  auto opt = options();
  opt.max_events = 3;
  const auto st = rt::trace<Ball>(P2{0.1, 0.0}, 0, times, kElastic.data(), opt, out);
  ASSERT_EQ(st.error, rt::TraceError::event_cap);
  EXPECT_EQ(st.events, 4);
  const double T = 2.0 * std::sqrt(0.2);
  EXPECT_NEAR(st.tau, T / 2 + 3 * T, 1e-8);
  EXPECT_NEAR(st.state[0], 0.0, 1e-12);
  EXPECT_NEAR(st.state[1], -std::sqrt(0.2), 1e-8);
  const std::string msg = rt::describe<Ball>(rt::TraceFailure<2>{st, 0, 0, P2{0.1, 0.0}});
  EXPECT_NE(msg.find("too many resets on one characteristic (max_events) at guard 'ground'"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("after 4 resets"), std::string::npos) << msg;
}

// ---------------------------------------------------------------------------------------
// Grazing met mid-trace, where the pre-flight scan cannot see it (outside the grid box).

/// The tangency criterion bounds the distance to the inflection: along y = x³ + c the ratio
/// |∇s·X|/(|∇s||X|) = 3x²/√(1 + 9x⁴) ≥ 3x²/√10 for |x| ≤ 1, so ratio ≤ kGrazeTol forces
/// |x| ≤ √(√10·1e-8/3) < 1.1e-4 (the locator itself gets |x| ~ (ε)^{1/3} ~ 1e-5 on x³).
constexpr double kNearInflection = 1.1e-4;

/// [1/2, 3/2] × [−1/2, 3/2], 5 × 5 nodes: y = 0 and (1, 1) are nodes.
rt::TensorGrid<2> inflection_box() {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.5, 1.5, 5}, rt::GridAxis{-0.5, 1.5, 5}};
  return g;
}

TEST(MidTraceGrazing, PreflightCannotSeeIt) {
  // The scan meets the guard on the nodes (x, 0), x ≥ 1/2, all transversal, Δ(x, 0) = (x, 1)
  // in the box: it passes and the run would start.
  const auto g = inflection_box();
  ASSERT_EQ(rt::axis_node(g.axes[1], 1), 0.0);
  ASSERT_EQ(g.node(13), (P2{1.0, 1.0}));
  const auto f = rt::preflight<Inflection>(g, kElastic.data());
  EXPECT_TRUE(f.ok()) << rt::describe_preflight<Inflection>(f);
}

TEST(MidTraceGrazing, OutgoingGuardOnTheBackwardCharacteristic) {
  const std::vector<double> times{0.0, 0.75, 1.5};
  std::vector<double> out(times.size());
  const auto st = rt::trace<Inflection>(P2{1.0, 1.0}, 0, times, kElastic.data(), options(), out);
  ASSERT_EQ(st.error, rt::TraceError::grazing);
  EXPECT_EQ(st.guard, 0);
  EXPECT_EQ(st.mode, 0);
  // x = 1 − τ along the characteristic (x' = −1 is integrated exactly): τ = 1 − x.
  EXPECT_NEAR(st.state[0], 0.0, kNearInflection);
  EXPECT_NEAR(st.tau, 1.0, kNearInflection);
  EXPECT_NEAR(st.tau + st.state[0], 1.0, 1e-12);
  EXPECT_NEAR(st.state[1], 0.0, 1e-12);  // on the guard: |y| ≤ |x|³ + rounding
  EXPECT_GE(st.value, 0.0);
  EXPECT_LE(st.value, rt::kGrazeTol);
  const std::string msg = rt::describe<Inflection>(rt::TraceFailure<2>{st, 0, 13, P2{1.0, 1.0}});
  EXPECT_NE(msg.find("characteristic from (x = 1, y = 1) in mode 'm' failed: grazing: the flow is "
                     "tangent to the guard at a crossing at guard 'g' at backward time tau = "),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("and the orbit crosses the surface"), std::string::npos) << msg;
  // The same node before it gets there (t_end = 1/2 < 1) is fine, and so is a neighbour
  // whose orbit y = x³ − 1/4 crosses transversally (at x = 4^(−1/3), ratio ≈ 0.76).
  const std::vector<double> early{0.0, 0.5};
  std::vector<double> out2(early.size());
  EXPECT_TRUE(rt::trace<Inflection>(P2{1.0, 1.0}, 0, early, kElastic.data(), options(), out2).ok());
  EXPECT_TRUE(rt::trace<Inflection>(P2{1.0, 0.75}, 0, times, kElastic.data(), options(), out).ok());
}

TEST(MidTraceGrazing, TheGridSolveNamesTheNode) {
  // Of the 25 nodes only (1, 1) is on y = x³ (and no node is on y = x³ + 1, whose reversed
  // reset would start at the tangency): the solve reports it (flat index 2·5 + 3).
  const std::vector<double> times{0.0, 0.5, 1.0, 1.5};
  const auto sol = rt::solve_grid<Inflection>(inflection_box(), times, kElastic.data(), options());
  ASSERT_FALSE(sol.ok());
  EXPECT_EQ(sol.failure.status.error, rt::TraceError::grazing);
  EXPECT_EQ(sol.failure.start_index, 13u);
  EXPECT_EQ(sol.failure.start, (P2{1.0, 1.0}));
}

TEST(MidTraceGrazing, IncomingGuardPreImageAtTheTangency) {
  // From (1/2, 9/8) on y = x³ + 1 the backward path meets Δ(S) = {y = 1} at (0, 1), whose
  // pre-image Δ⁻¹ = (0, 0) is the tangency: the reversed-reset branch would fire there.
  const std::vector<double> times{0.0, 1.0};
  std::vector<double> out(times.size());
  const auto st = rt::trace<Inflection>(P2{0.5, 1.125}, 0, times, kElastic.data(), options(), out);
  ASSERT_EQ(st.error, rt::TraceError::grazing);
  EXPECT_EQ(st.guard, 0);
  EXPECT_NEAR(st.tau, 0.5, kNearInflection);
  EXPECT_NEAR(st.state[0], 0.0, kNearInflection);
  EXPECT_EQ(st.state[1], 0.0);  // the pre-image, projected onto S: y = 0 exactly
}

rt::ForwardOptions forward_options() {
  rt::ForwardOptions o;
  o.ode.rtol = 1e-10;
  o.ode.atol = 1e-12;
  return o;
}

TEST(MidTraceGrazing, ForwardFlowThroughTheTangency) {
  // Forward from (−1/2, −1/8) on y = x³: the guard fires at the tangency at t = 1/2.
  const auto r =
      rt::forward_flow<Inflection>(0, P2{-0.5, -0.125}, 1.5, kElastic.data(), forward_options());
  ASSERT_EQ(r.status, rt::ForwardStatus::failed);
  EXPECT_EQ(r.error, rt::TraceError::grazing);
  EXPECT_EQ(r.guard, 0);
  EXPECT_NEAR(r.t_stop, 0.5, kNearInflection);
  EXPECT_NEAR(r.x[0], 0.0, kNearInflection);
  EXPECT_LE(r.value, rt::kGrazeTol);
  const std::string msg = rt::describe<Inflection>(r, 0, P2{-0.5, -0.125});
  EXPECT_NE(msg.find("numerical failure (grazing: the flow is tangent to the guard at a crossing) "
                     "at guard 'g' at time t = "),
            std::string::npos)
      << msg;
  // A transversal crossing (y = x³ − 3/8 crosses at x = 0.72) resets and goes on.
  const auto ok =
      rt::forward_flow<Inflection>(0, P2{-0.5, -0.5}, 1.5, kElastic.data(), forward_options());
  EXPECT_TRUE(ok.ok()) << rt::describe<Inflection>(ok, 0, P2{-0.5, -0.5});
  EXPECT_EQ(ok.events, 1);
}

TEST(MidTraceGrazing, TheBallsZenoBouncesAreNoGrazing) {
  // e = 1/2 from (10⁻⁴, 0), t_end = 1/10: impact speeds |p_k| = √(2·10⁻⁴)·2^{−k}; from k = 21
  // on |p| < 1e-8, so the flow is tangent to x = 0 to graze_tol there (ratio |p|/√(p² + 1))
  // before Zeno is declared (last gap 2|p⁺| ≤ zeno_time·t_end = 1e-8, i.e. |p| ≤ 1e-8). The
  // orbit x = p t − t²/2 does not cross x = 0 over ±δ = ±1e-4 (it would need δ < 2|p|): the
  // flow ends at the Zeno point, not in a grazing failure.
  const std::array<double, 3> par{1.0, 1.0, 0.5};
  const auto r = rt::forward_flow<Ball>(0, P2{1e-4, 0.0}, 0.1, par.data(), forward_options());
  EXPECT_EQ(r.status, rt::ForwardStatus::zeno) << rt::describe<Ball>(r, 0, P2{1e-4, 0.0});
  EXPECT_GE(r.events, 22);
}

}  // namespace
