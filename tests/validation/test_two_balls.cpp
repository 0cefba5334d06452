// Validation in 4-D: two independent balls bouncing with different restitutions, each through
// its own guard, with a Zeno accumulation on either, a model hybgen does not ship, against
// closed forms derived here (none of them comes from hybgen).
//
// State (x1, p1, x2, p2), one mode x_i' = p_i, p_i' = −1 on x_i ≥ 0. Guard `wall_i`: s = x_i
// decreasing, reset p_i ↦ −e_i p_i (the other ball unchanged), e1 = 1/2, e2 = 3/5. div X = 0;
// DΔ_i = I − (1 + e_i) e_{p_i} e_{p_i}ᵀ, adj DΔ_i = −e_i DΔ_i⁻¹, X⁺ = (p1, −1, p2, −1) with
// p_i ↦ −e_i p_i, ∇s = e_{x_i}: J_i = (−e_i)(−e_i p_i)/p_i = e_i² (1/4 and 9/25).
//
// Zeno. Ball i alone comes to rest at (0, 0) at t_Z,i = p0 + k_i v, v = √(p0² + 2x0), k_i =
// (1 + e_i)/(1 − e_i) (3 and 4; test_zeno_wall.cpp derives it), and Z_i(t) = ∫ u0_i [t_Z,i ≤
// t] is the 1-D quadrature of that test (`zeno_mass`). The hybrid execution of the pair ends
// at the FIRST accumulation, min(t_Z,1, t_Z,2) (the forward flow declares Zeno there; the
// other ball is still moving, and the Zeno set is {x1 = p1 = 0} ∪ {x2 = p2 = 0}). With a
// product initial density u0 = u0_1(x1, p1)·u0_2(x2, p2) the two Zeno times are independent,
//   atom(t) = ∫ u0 [min(t_Z,1, t_Z,2) ≤ t] = 1 − (1 − Z_1(t))(1 − Z_2(t)),
//   mass(t) = (1 − Z_1(t))(1 − Z_2(t))      (the absolutely continuous part, in the box),
// and the density is the product of the two balls' densities, each by its closed-form
// backward map (`exact_ball`: backwards the impacts spread out, finitely many in finite time,
// each with the factor 1/e_i²). Nothing leaves the box [0, 1] × [−1.4, 1.4] × [0, 0.7] ×
// [−1.2, 1.2] (energies ≤ 0.925 and 0.625).
//
// u0_1 = a(x1; 0.2, 0.8) b(p1; 0, 0.5), u0_2 = a(x2; 0.1, 0.5) b(p2; 0.1, 0.4): a the unit sin²
// bump on an interval, b(p; c, w) = (15/16w)(1 − ((p − c)/w)²)² (unit mass). Zeno times lie
// in [1.79, 4.58] (ball 1) and [1.73, 4.97] (ball 2); output times 0, 1.5, 2.5, 3.5, 5.
// Compared:
//  * the forward flow's Zeno detection (what the atoms of the budget and of the particles rest
//    on) against min(t_Z,1, t_Z,2) from 20000 initial states.
//  * characteristics (evaluate, 600 points, every output time) against the product of the
//    closed-form backward maps: error relative to max(u, 1) below 1e-8 (docs/methods.md: the ODE
//    tolerance; measured 4.7e-12 where u reaches 2·10⁵ in the Zeno stripes).
//  * its mass budget (adaptive_mass_budget: the box mass by backward characteristics, the atom
//    by forward flows to a Zeno point, measured independently): the atom against 1 − (1 −
//    Z_1)(1 − Z_2) within kDefectFactor × its estimate plus the target (the estimates are ≈ 2σ,
//    budget.hpp), the mass against (1 − Z_1)(1 − Z_2) likewise or flagged by the closure check
//    (docs/outputs.md's promise). With the runner's default `budget=fast` the atom is wrong by up
//    to 0.97 with estimates below 1e-2 and no flag: a hybgen bug, asserted (and failing).
//  * particles (10⁵): the atom and the mass within 5σ (measured |z| ≤ 0.81).
//  * transfer: not run, measured instead. In 4-D the default 2⁴ samples per cell and h = 1
//    (the atom lags less with a long step: transfer.hpp, "Zeno points") on 9 × 23 × 7 × 19
//    and 13 × 33 × 9 × 25 nodes (assembly 1.4 s and 7.6 s) give atoms at t = 3 of 0.442 and
//    0.455 (exact 0.611), at t = 4 of 0.881 and 0.925 (exact 1.000), with 1.6 % and 2.6 % of
//    the mass smoothed out of the box: no convergence to assert at affordable grids (at h =
//    0.5, 17 × 45 × 13 × 35 nodes take 14 s and reach 0.907 at t = 5). The 2-D Zeno wall
//    (test_zeno_wall.cpp) covers the transfer's atom.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/budget.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "hybgen/rt/methods/transfer.hpp"

namespace {

namespace rt = hybgen::rt;
using P2 = std::array<double, 2>;
using P4 = std::array<double, 4>;

/// One ball's data: restitution, u0's support in x and p.
struct Ball {
  double e;       ///< Restitution.
  double xa, xb;  ///< a's support [xa, xb].
  double pc, pw;  ///< b's centre and half-width.
  /// k = (1 + e)/(1 − e): t_Z = p0 + k v.
  double k() const { return (1.0 + e) / (1.0 - e); }
};
/// The two balls.
constexpr std::array<Ball, 2> kBalls{Ball{0.5, 0.2, 0.8, 0.0, 0.5}, Ball{0.6, 0.1, 0.5, 0.1, 0.4}};
/// The box.
constexpr std::array<double, 4> kLo{0.0, -1.4, 0.0, -1.2}, kHi{1.0, 1.4, 0.7, 1.2};

/// a(x): the unit sin² bump on [xa, xb].
double a_of(const Ball& b, double x) {
  if (!(x > b.xa && x < b.xb)) return 0.0;
  const double s = std::sin(std::numbers::pi * (x - b.xa) / (b.xb - b.xa));
  return 2.0 / (b.xb - b.xa) * s * s;
}

/// b(p) = (15/16w)(1 − ((p − c)/w)²)² (unit mass).
double b_of(const Ball& b, double p) {
  const double z = (p - b.pc) / b.pw;
  if (!(std::fabs(z) < 1.0)) return 0.0;
  const double q = 1.0 - z * z;
  return 15.0 / (16.0 * b.pw) * q * q;
}

/// ∫_{−∞}^{p} b.
double b_cdf(const Ball& b, double p) {
  const double z = std::clamp((p - b.pc) / b.pw, -1.0, 1.0);
  return 15.0 / 16.0 * (z - 2.0 * z * z * z / 3.0 + z * z * z * z * z / 5.0 + 8.0 / 15.0);
}

/// Ball i's initial density.
double u0_ball(std::size_t i, double x, double p) {
  return a_of(kBalls[i], x) * b_of(kBalls[i], p);
}

/// The two balls.
struct TwoBalls {
  static constexpr int n_state = 4;                 ///< x1 p1 x2 p2
  static constexpr int n_param = 0;                 ///< none
  static constexpr int n_mode = 1;                  ///< one mode
  static constexpr int n_guard = 2;                 ///< wall_1, wall_2
  static constexpr const char* name = "two_balls";  ///< Model name.
  static constexpr std::array<const char*, 4> state_names{"x1", "p1", "x2", "p2"};  ///< States.
  static constexpr std::array<const char*, 0> param_names{};                        ///< None.
  static constexpr std::array<double, 0> param_defaults{};                          ///< None.
  static constexpr std::array<const char*, 1> mode_names{"fly"};                    ///< Modes.
  static constexpr std::array<const char*, 2> guard_names{"wall_1", "wall_2"};      ///< Guards.
  /// Both decreasing, closed-form inverses.
  static constexpr std::array<rt::GuardInfo, 2> guards{rt::GuardInfo{0, 0, -1, true},
                                                       rt::GuardInfo{0, 0, -1, true}};
  /// X = (p1, −1, p2, −1).
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1];
    out[1] = -1.0;
    out[2] = x[3];
    out[3] = -1.0;
  }
  /// div X = 0.
  static double divergence(int, const double*, const double*) { return 0.0; }
  /// s_i = x_i.
  static double guard_surface(int g, const double* x, const double*) { return x[2 * g]; }
  /// ∇s_i = e_{x_i}.
  static void guard_gradient(int g, const double*, const double*, double* out) {
    for (int a = 0; a < 4; ++a) out[a] = a == 2 * g ? 1.0 : 0.0;
  }
  /// Δ_i: p_i ↦ −e_i p_i.
  static void reset(int g, const double* x, const double*, double* out) {
    for (int a = 0; a < 4; ++a) out[a] = x[a];
    out[2 * g + 1] = -kBalls[static_cast<std::size_t>(g)].e * x[2 * g + 1];
  }
  /// Δ_i⁻¹: p_i ↦ −p_i/e_i.
  static void reset_inverse(int g, const double* x, const double*, double* out) {
    for (int a = 0; a < 4; ++a) out[a] = x[a];
    out[2 * g + 1] = -x[2 * g + 1] / kBalls[static_cast<std::size_t>(g)].e;
  }
  /// DΔ_i = diag(1, …, −e_i, …, 1).
  static void reset_jacobian(int g, const double*, const double*, double* out) {
    for (int a = 0; a < 16; ++a) out[a] = a % 5 == 0 ? 1.0 : 0.0;
    out[5 * (2 * g + 1)] = -kBalls[static_cast<std::size_t>(g)].e;
  }
  /// J_i = e_i².
  static double hybrid_jacobian(int g, const double*, const double*) {
    const double e = kBalls[static_cast<std::size_t>(g)].e;
    return e * e;
  }
  /// u0 = u0_1(x1, p1) u0_2(x2, p2) (0 outside the support: a vanishes at x < 0).
  static double initial_density(int, const double* x, const double*) {
    return u0_ball(0, x[0], x[1]) * u0_ball(1, x[2], x[3]);
  }
  /// x1 ≥ 0 and x2 ≥ 0.
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0 && x[2] >= 0.0; }
};
static_assert(rt::HybridModel<TwoBalls>);

/// Ball i's density at time t and (x, p), by the closed-form backward map (test_zeno_wall.cpp):
/// backwards from (x, p) the flight reaches the wall after s = w − p, w = √(p² + 2x), at the
/// post-impact state (0, w), whose pre-image is (0, −w/e) with the factor 1/e².
double exact_ball(std::size_t i, double t, double x, double p) {
  const double e = kBalls[i].e;
  double left = t, factor = 1.0;
  for (int impacts = 0; impacts < 400; ++impacts) {
    const double w = std::sqrt(p * p + 2.0 * x);
    const double s = w - p;
    if (s >= left) return factor * u0_ball(i, x - p * left - 0.5 * left * left, p + left);
    left -= s;
    x = 0.0;
    p = -w / e;
    factor /= e * e;
  }
  return HUGE_VAL;
}

/// The exact density of the pair.
double exact(double t, const P4& y) {
  if (y[0] < 0.0 || y[2] < 0.0) return 0.0;
  return exact_ball(0, t, y[0], y[1]) * exact_ball(1, t, y[2], y[3]);
}

/// Z_i(t) = ∫ u0_i [t_Z,i ≤ t]: for x0 ≤ X* = t²/(2(k² − 1)), p0 between the roots p± = (−t ±
/// k√(t² − 2(k² − 1)x0))/(k² − 1) (test_zeno_wall.cpp), by composite Gauss–Legendre in
/// σ = √(X* − x0) with `panels` panels.
double zeno_mass(std::size_t i, double t, int panels = 4000) {
  const Ball& b = kBalls[i];
  if (t <= 0.0) return 0.0;
  const double k = b.k(), k2 = k * k;
  const double xs = t * t / (2.0 * (k2 - 1.0));
  if (xs <= b.xa) return 0.0;
  const double s_lo = std::sqrt(std::max(0.0, xs - b.xb)), s_hi = std::sqrt(xs - b.xa);
  const auto rule = rt::gauss_legendre_rule(s_lo, s_hi, panels, 4);
  double z = 0.0;
  for (std::size_t q = 0; q < rule.nodes.size(); ++q) {
    const double sg = rule.nodes[q], x0 = xs - sg * sg;
    const double root = k * std::sqrt(2.0 * (k2 - 1.0)) * sg;
    const double pm = (-t - root) / (k2 - 1.0), pp = (-t + root) / (k2 - 1.0);
    z += rule.weights[q] * 2.0 * sg * a_of(b, x0) * (b_cdf(b, pp) - b_cdf(b, pm));
  }
  return z;
}

/// The atom of the pair, 1 − (1 − Z_1)(1 − Z_2).
double atom_of(double t) {
  return 1.0 - (1.0 - zeno_mass(0, t)) * (1.0 - zeno_mass(1, t));
}

/// t_Z of ball i from (x0, p0).
double zeno_time(std::size_t i, double x0, double p0) {
  return p0 + kBalls[i].k() * std::sqrt(p0 * p0 + 2.0 * x0);
}

/// The grid of the box with n nodes per axis.
rt::TensorGrid<4> box(int n) {
  rt::TensorGrid<4> g;
  for (std::size_t a = 0; a < 4; ++a) g.axes[a] = rt::GridAxis{kLo[a], kHi[a], n};
  return g;
}

/// The output times.
const std::vector<double> kTimes{0.0, 1.5, 2.5, 3.5, 5.0};

TEST(TwoBalls, ReferencesAreConsistent) {
  // Each Z_i against a brute-force midpoint rule of u0_i·[t_Z,i ≤ t] (1000², its error O(1e-3)
  // at the discontinuity) and against itself at half the panels; Z_i = 0 before the first and
  // 1 after the last Zeno time.
  for (std::size_t i = 0; i < 2; ++i) {
    const Ball& b = kBalls[i];
    for (const double t : {2.5, 3.5}) {
      const int n = 1000;
      double z = 0.0;
      for (int r = 0; r < n; ++r)
        for (int c = 0; c < n; ++c) {
          const double x0 = b.xa + (b.xb - b.xa) * (r + 0.5) / n;
          const double p0 = b.pc - b.pw + 2.0 * b.pw * (c + 0.5) / n;
          if (zeno_time(i, x0, p0) <= t)
            z += u0_ball(i, x0, p0) * (b.xb - b.xa) * 2.0 * b.pw / n / n;
        }
      std::printf("[ two balls ] Z_%zu(%.1f) = %.9f (2000 panels %.9f, midpoint 1000^2 %.6f)\n",
                  i + 1, t, zeno_mass(i, t), zeno_mass(i, t, 2000), z);
      EXPECT_NEAR(zeno_mass(i, t), zeno_mass(i, t, 2000), 1e-10);
      EXPECT_NEAR(zeno_mass(i, t), z, 2e-3);
    }
    EXPECT_EQ(zeno_mass(i, 1.5), 0.0);
    EXPECT_NEAR(zeno_mass(i, 5.0), 1.0, 1e-12);
  }
}

TEST(TwoBalls, ForwardFlowStopsAtTheFirstZenoTime) {
  // What the atom of the budget and of the particles rests on: the forward flow's Zeno
  // detection (forward.hpp) with the two balls' bounces interleaved (gap ratios e1 and e2
  // alternate until one cascade dominates). 20000 initial states in u0's support: every flow
  // ends `zeno` at min(t_Z,1, t_Z,2) (closed form). Measured: worst |t_stop − t_Z| 2.6e-14
  // over 2·10⁵ states (29 events per flow on average). Asserted: ≤ 1e-9, no other ending.
  const std::vector<double> times{0.0, 5.0};
  const long long n = 20000;
  double worst = 0.0;
  long long other = 0;
#pragma omp parallel reduction(max : worst) reduction(+ : other)
  {
    rt::ForwardFlow<TwoBalls> flow(nullptr, rt::ForwardOptions{});
#pragma omp for schedule(dynamic, 64)
    for (long long q = 0; q < n; ++q) {
      std::uint64_t s = 0x9E3779B97F4A7C15ULL * static_cast<std::uint64_t>(q + 1);
      auto uni = [&s]() {
        s = s * 6364136223846793005ULL + 1442695040888963407ULL;
        return static_cast<double>(s >> 11) * 0x1.0p-53;
      };
      P4 x{};
      for (std::size_t i = 0; i < 2; ++i) {
        x[2 * i] = kBalls[i].xa + (kBalls[i].xb - kBalls[i].xa) * uni();
        x[2 * i + 1] = kBalls[i].pc - kBalls[i].pw + 2.0 * kBalls[i].pw * uni();
      }
      const double tz = std::min(zeno_time(0, x[0], x[1]), zeno_time(1, x[2], x[3]));
      const auto r = flow.run(0, x, times, [](std::size_t, int, const P4&) {});
      if (r.status != rt::ForwardStatus::zeno) {
        ++other;
      } else {
        worst = std::max(worst, std::fabs(r.t_stop - tz));
      }
    }
  }
  std::printf("[ two balls ] forward flows: worst |t_stop - t_Z| %.2e, %lld not at rest\n", worst,
              other);
  EXPECT_EQ(other, 0);
  EXPECT_LT(worst, 1e-9);
}

TEST(TwoBalls, CharacteristicsMatchTheProductOfBackwardMaps) {
  // 600 points (x1, p1, x2, p2) whose two halves lie where each ball's density is positive at
  // one of t = 0, 1.5, 2.5, 3.5 (150 pairs each, drawn from 200² lattices of the balls' boxes by
  // a linear congruential sequence), evaluated at every output time. Measured: worst error
  // relative to max(u, 1) 2e-14 (u up to ~400: a few impacts back). Asserted: < 1e-8.
  std::uint64_t s = 12345;
  auto pick = [&s](std::size_t n) {
    s = s * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<std::size_t>((s >> 11) % n);
  };
  std::vector<P4> pts;
  for (const double t : {0.0, 1.5, 2.5, 3.5}) {
    std::array<std::vector<P2>, 2> cand;
    for (std::size_t i = 0; i < 2; ++i) {
      const int n = 200;
      for (int r = 0; r < n; ++r)
        for (int c = 0; c < n; ++c) {
          const P2 y{kLo[2 * i] + (kHi[2 * i] - kLo[2 * i]) * (r + 0.5) / n,
                     kLo[2 * i + 1] + (kHi[2 * i + 1] - kLo[2 * i + 1]) * (c + 0.5) / n};
          if (exact_ball(i, t, y[0], y[1]) > 0.0) cand[i].push_back(y);
        }
      ASSERT_FALSE(cand[i].empty());
    }
    for (int q = 0; q < 150; ++q) {
      const P2 a = cand[0][pick(cand[0].size())], b = cand[1][pick(cand[1].size())];
      pts.push_back({a[0], a[1], b[0], b[1]});
    }
  }
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const auto sol = rt::evaluate<TwoBalls>(pts, kTimes, nullptr, co);
  ASSERT_TRUE(sol.ok()) << rt::describe<TwoBalls>(sol.failure);
  double worst = 0.0, umax = 0.0;
  std::size_t nonzero = 0;
  for (std::size_t k = 0; k < kTimes.size(); ++k)
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const double ue = exact(kTimes[k], pts[i]), u = sol.at(k, 0, i);
      umax = std::max(umax, ue);
      if (ue > 0.0) ++nonzero;
      worst = std::max(worst, std::fabs(u - ue) / std::max(ue, 1.0));
    }
  std::printf(
      "[ two balls ] characteristics, 600 points x 5 times: max relative error %.2e (max u %.1f, "
      "%zu nonzero values)\n",
      worst, umax, nonzero);
  EXPECT_LT(worst, 1e-8);
  EXPECT_GE(nonzero, 600u);
}

/// The characteristics budget with `rel_tol` and `max_points` against the closed forms; with
/// `strict`, the atom within kDefectFactor × its estimate plus the target (the estimates are
/// ≈ 2σ: budget.hpp, methods.hpp), the mass likewise or flagged by the closure check.
void check_budget(double rel_tol, std::size_t max_points) {
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  rt::AdaptiveOptions ao;
  ao.rel_tol = rel_tol;
  ao.max_points = max_points;
  rt::AdaptiveBudgetInfo info;
  const auto b = rt::adaptive_mass_budget<TwoBalls>(box(9), kTimes, nullptr, co, ao, &info);
  ASSERT_TRUE(b.ok()) << rt::describe<TwoBalls>(b.failure) << b.message;
  const auto defect = rt::budget_defect(b.budget), bar = rt::budget_defect_error(b.budget);
  const double target = rel_tol * b.budget.mass0;
  double worst_a = 0.0, worst_m = 0.0;
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    const double A = atom_of(kTimes[k]);
    const double ea = std::fabs(b.budget.atom[k] - A), em = std::fabs(b.budget.mass[k] - (1.0 - A));
    const double dbar = rt::kDefectFactor * bar[k] + rt::kDefectFloor * b.budget.mass0;
    const double bar_a = rt::kDefectFactor * b.budget.atom_error[k] + target;
    const double bar_m = rt::kDefectFactor * b.budget.mass_error[k] + target;
    worst_a = std::max(worst_a, ea / bar_a);
    worst_m = std::max(worst_m, em / bar_m);
    std::printf(
        "[ two balls ] budget rel_tol %.0e, %zu points: t = %.1f: mass %.6f +- %.1e (exact %.6f), "
        "atom %.6f +- %.1e (exact %.6f), outflow %.1e, defect %.1e (bar %.1e)\n",
        rel_tol, max_points, kTimes[k], b.budget.mass[k], b.budget.mass_error[k], 1.0 - A,
        b.budget.atom[k], b.budget.atom_error[k], A, b.budget.outflow[k], defect[k], dbar);
    EXPECT_LE(ea, bar_a) << "t = " << kTimes[k];
    EXPECT_TRUE(em <= bar_m || std::fabs(defect[k]) > dbar)
        << "t = " << kTimes[k] << ": a wrong mass that the closure check does not flag";
  }
  std::printf(
      "[ two balls ] budget rel_tol %.0e: worst error / (2 estimate + target): atom %.2f, mass "
      "%.2f; points: volume %zu (%s), atom %zu (%s)\n",
      rel_tol, worst_a, worst_m, info.volume.points, info.volume.converged ? "converged" : "capped",
      info.atom.points, info.atom.converged ? "converged" : "capped");
}

TEST(TwoBalls, BudgetAtomIsTheFirstZenoMass) {
  // rel_tol 1e-3 with 10⁵ points per cubature (2 s; both 4-D cubatures reach the cap).
  // Measured: atom errors 7.8e-4, 3.7e-3, 3.3e-3 at t = 2.5, 3.5, 5 against an estimate of
  // 7.9e-3 (0.22 of the bar below); the box mass is low by 0.32 at t = 2.5 (0.548 against
  // 0.871) with an estimate of 0.17 (0.93 of the bar), and the defect 0.27 stays inside the
  // closure bar 0.43: the capped volume cubature of the striped 4-D density is poor, and only
  // its large estimate covers it.
  check_budget(1e-3, 100000);
}

TEST(TwoBalls, FastBudgetAtomWithinItsEstimate) {
  // The runner's default budget (`budget=fast`: rel_tol kFastBudgetTol = 1e-2, at most
  // kFastBudgetPoints = 20000 points per cubature; methods.hpp). In 4-D its atom cubature
  // started from ONE cell of 4⁴ Gauss nodes over the whole box, where u0's support is 4 % of
  // the volume, and declared convergence having seen almost none of it: atom 0.0064, 0.023,
  // 0.025 at t = 2.5, 3.5, 5 (exact 0.129, 0.966, 1.000) with estimates 5.2e-3 … 8.4e-3, and
  // the closure check did not flag it (defect 0.86 against a bar of 3.6, swamped by the
  // capped volume's estimate 1.6). Fixed: the atom's cubature covers only the box of the
  // nodes where u0 > 0 (budget.hpp, `adaptive_atom`); measured now: atom 0.103, 0.981, 1.009
  // with a (capped) estimate of 9.7e-3, worst error / (2 estimate + target) 0.92. The mass
  // stays poor (0.35 against 0.87 at t = 2.5) and says so: its estimate is 1.6.
  check_budget(rt::kFastBudgetTol, rt::kFastBudgetPoints);
}

TEST(TwoBalls, ParticleAtomIsTheFirstZenoMass) {
  const auto grid = box(9);
  rt::ParticleOptions po;
  po.particles = 100000;
  po.seed = 41;
  const auto run = rt::solve_particles<TwoBalls>(grid, kTimes, nullptr, po);
  ASSERT_TRUE(run.failure.ok()) << rt::describe<TwoBalls>(run.failure);
  const auto& b = run.budget;
  const double s2 = 0.25 * b.mass_error[0] * b.mass_error[0] +
                    b.mass0 * b.mass0 / static_cast<double>(po.particles);
  double worst = 0.0;
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    const double A = atom_of(kTimes[k]);
    // σ: the atom's own 2σ̂, floored by the compound-Poisson bound (as test_zeno_wall.cpp).
    const double sa = std::max({0.5 * run.atom_error[k], std::sqrt(A * s2 / b.mass0), 1e-12});
    const double sm =
        std::max({0.5 * b.mass_error[k], std::sqrt(std::max(1.0 - A, 0.0) * s2 / b.mass0), 1e-12});
    const double za = std::fabs(b.atom[k] - A) / sa, zm = std::fabs(b.mass[k] - (1.0 - A)) / sm;
    worst = std::max({worst, za, zm});
    std::printf(
        "[ two balls ] particles t = %.1f: atom %.5f +- %.5f (exact %.5f), mass %.5f (exact "
        "%.5f), outflow %.1e\n",
        kTimes[k], b.atom[k], run.atom_error[k], A, b.mass[k], 1.0 - A, b.outflow[k]);
    EXPECT_LE(za, 5.0) << "t = " << kTimes[k];
    EXPECT_LE(zm, 5.0) << "t = " << kTimes[k];
    EXPECT_EQ(b.outflow[k], 0.0);
  }
  std::printf("[ two balls ] particles: worst |z| %.2f\n", worst);
}

}  // namespace
