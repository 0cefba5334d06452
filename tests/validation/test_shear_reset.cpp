// Validation: a linear flow with a reset that shears and scales (|det DΔ| = 0.4, not a
// reflection), with outflow, a model hybgen does not ship, in the weak form against an RK4
// push-forward of the initial density written here (as tests/validation/test_moments.cpp):
//   ∫_box φ u(t) dz = E[φ(Z_t); Z_t ∈ box],  Z_0 ~ u0.
//
// State z = (x, y) ∈ ℝ², one mode, X = A z with A = [[0.5, 0.2], [0.3, −1]] (div X = −0.5; a
// saddle: eigenvalues 0.539, −1.039, the stable direction nearly vertical). Guard `kick`: s =
// x − 1 increasing, reset Δz = B z with B = [[0.5, 0.25], [0, 0.8]] (scale x by ½ and y by 0.8,
// shear x by y/4; det B = 0.4), closed-form inverse B⁻¹ = [[2, −0.625], [0, 1.25]]. On the
// guard x = 1 in the box (|y| ≤ 1.5) the image is x = 0.5 + 0.25y ∈ [0.125, 0.875], |y| ≤ 1.2:
// inside the box, away from the guard. J = ∇sᵀ adj(B) X(Δz) / ∇sᵀ X(z), adj B = [[0.8, −0.25],
// [0, 0.5]]: J = (0.1625 + 0.409y)/(0.5 + 0.2y) on the guard, which vanishes at y ≈ −0.397
// (the image of the guard is tangent to the flow there: a fold, an integrable caustic of the
// density; the pre-flight samples J at nodes and passes) — less than 3e-6 of the mass is
// kicked below y = −0.2 by t = 3. States right of the saddle's stable manifold run to x = 1,
// are kicked back to x ≈ 0.5 and cycle; states left of it run off through the face x = −1:
// outflow. Box [−1, 1] × [−1.5, 1.5]; u0 = exp(−8|z − (0, 0.2)|²) (mass π/8, 6e-5 of it outside
// the box).
//
// Reference (nothing from hybgen but the model's functions, written here too): u0 pushed
// forward by classical RK4 (step 1e-2; a crossing of x = 1 located by bisection on the step,
// the reset applied), integrated over the initial states row by row with the jumps of the
// integrand (where the number of kicks or the box indicator changes) located by bisection,
// so that the quadrature is piecewise smooth (`reference_at`). Converged to ~1e-9 (RK4 step
// 2e-3, twice the scan, twice the rows change nothing above 1e-9; a plain tensor Gauss rule
// of 160² nodes per unit is still off by 1e-5 at such jumps). For transfer the reference is
// box-limited, as the operator (no mass enters from outside the box; a state counts only if
// it starts in the box and is in it at every multiple of the step).
// Compared (worst difference of the mass and the first moments ∫x u, ∫y u at t = 1, 2, 3,
// relative to the initial mass π/8 and the box scale 3):
//  * characteristics (docs/methods.md: no interpolation error, ODE tolerance): u at the midpoints
//    of 240² cells, < 1.5e-3 (the bound of a midpoint rule across the jump; measured 6.1e-4);
//    its adaptive budget: the outflow within rel_tol·mass0 at rel_tol 3e-4 and 1e-5 (measured
//    1.3e-6 and 2.9e-8), the mass within it at 3e-4 (measured 5.6e-5 against 1.2e-4) — at
//    1e-5 it does NOT converge (a known failure, skipped test with the figures; the
//    runner's closure check flags it, which is asserted).
//  * transfer (hat, h = 0.05, box-limited reference), 81 × 121, 161 × 241: docs/methods.md O(Δx²)
//    per step plus the switching error. Measured 4.8e-3 and 1.25e-3 (ratio 3.9: second
//    order); asserted < 8e-3, then a ratio > 3.
//  * particles (2·10⁵): the mass and first moments in the box (the cloud-in-cell deposit keeps
//    linear moments exactly) within 5σ, σ² ≤ max φ²·mass·Σw²/Σw (measured |z| ≤ 0.4).

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/budget.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/mass_budget.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "hybgen/rt/methods/transfer.hpp"

namespace {

namespace rt = hybgen::rt;
using P2 = std::array<double, 2>;

/// The flow's matrix A.
constexpr double kA[2][2] = {{0.5, 0.2}, {0.3, -1.0}};
/// The reset's matrix B.
constexpr double kB[2][2] = {{0.5, 0.25}, {0.0, 0.8}};
/// B⁻¹.
constexpr double kBinv[2][2] = {{2.0, -0.625}, {0.0, 1.25}};
/// The box's corners.
constexpr P2 kLo{-1.0, -1.5}, kHi{1.0, 1.5};

/// M z for a 2 × 2 matrix M.
P2 apply(const double (&m)[2][2], const double* z) {
  return {m[0][0] * z[0] + m[0][1] * z[1], m[1][0] * z[0] + m[1][1] * z[1]};
}

/// The sheared kick.
struct ShearKick {
  static constexpr int n_state = 2;                                   ///< x, y
  static constexpr int n_param = 0;                                   ///< none
  static constexpr int n_mode = 1;                                    ///< one mode
  static constexpr int n_guard = 1;                                   ///< kick
  static constexpr const char* name = "shear_kick";                   ///< Model name.
  static constexpr std::array<const char*, 2> state_names{"x", "y"};  ///< State names.
  static constexpr std::array<const char*, 0> param_names{};          ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};            ///< No parameters.
  static constexpr std::array<const char*, 1> mode_names{"run"};      ///< Mode names.
  static constexpr std::array<const char*, 1> guard_names{"kick"};    ///< Guard names.
  /// kick: increasing, closed-form inverse.
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, true}};
  /// X = A z.
  static void flow(int, const double* z, const double*, double* out) {
    const P2 v = apply(kA, z);
    out[0] = v[0];
    out[1] = v[1];
  }
  /// div X = tr A.
  static double divergence(int, const double*, const double*) { return kA[0][0] + kA[1][1]; }
  /// s = x − 1.
  static double guard_surface(int, const double* z, const double*) { return z[0] - 1.0; }
  /// ∇s = (1, 0).
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  /// Δz = B z.
  static void reset(int, const double* z, const double*, double* out) {
    const P2 v = apply(kB, z);
    out[0] = v[0];
    out[1] = v[1];
  }
  /// Δ⁻¹w = B⁻¹ w.
  static void reset_inverse(int, const double* z, const double*, double* out) {
    const P2 v = apply(kBinv, z);
    out[0] = v[0];
    out[1] = v[1];
  }
  /// DΔ = B.
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = kB[0][0];
    out[1] = kB[0][1];
    out[2] = kB[1][0];
    out[3] = kB[1][1];
  }
  /// J = ∇sᵀ adj(B) X(Bz) / ∇sᵀ X(z), adj B = [[B11, −B01], [−B10, B00]].
  static double hybrid_jacobian(int, const double* z, const double*) {
    const P2 w = apply(kB, z);
    const P2 xp = apply(kA, w.data()), xm = apply(kA, z);
    return (kB[1][1] * xp[0] - kB[0][1] * xp[1]) / xm[0];
  }
  /// u0 = exp(−8|z − (0, 0.2)|²).
  static double initial_density(int, const double* z, const double*) {
    return std::exp(-8.0 * (z[0] * z[0] + (z[1] - 0.2) * (z[1] - 0.2)));
  }
  /// The whole plane.
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<ShearKick>);

/// Whether z is in the (closed) box.
bool in_box(const P2& z) {
  return z[0] >= kLo[0] && z[0] <= kHi[0] && z[1] >= kLo[1] && z[1] <= kHi[1];
}

/// One classical RK4 step of z' = A z.
P2 rk4(const P2& z, double h) {
  auto f = [](const P2& v) { return apply(kA, v.data()); };
  const P2 k1 = f(z);
  const P2 k2 = f({z[0] + 0.5 * h * k1[0], z[1] + 0.5 * h * k1[1]});
  const P2 k3 = f({z[0] + 0.5 * h * k2[0], z[1] + 0.5 * h * k2[1]});
  const P2 k4 = f({z[0] + h * k3[0], z[1] + h * k3[1]});
  return {z[0] + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
          z[1] + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])};
}

/// Where z0 is at time t: the number of kicks, the state, and whether it was in the box at
/// every multiple of `check` (for the box-limited reference).
struct Fate {
  int kicks = 0;        ///< Resets on the way.
  P2 z{};               ///< State at t.
  bool stayed = false;  ///< In the box at 0 and at every multiple of `check`.
  /// What the integrand's indicator depends on (piecewise constant in z0).
  int key(bool box_limited) const {
    return 4 * kicks + (in_box(z) ? 2 : 0) + (box_limited && stayed ? 1 : 0);
  }
};

/// RK4 (step h) from z0 over [0, t], kicking at x = 1 (crossing located by bisection on the
/// step, the rest of the step taken from the reset state).
Fate push(const P2& z0, double t, double h, double check) {
  Fate f;
  f.z = z0;
  f.stayed = in_box(z0);
  const auto steps = std::lround(t / h), every = std::lround(check / h);
  for (long n = 0; n < steps; ++n) {
    const P2 y = rk4(f.z, h);
    if (f.z[0] < 1.0 && y[0] >= 1.0) {
      double a = 0.0, b = h;
      for (int it = 0; it < 60; ++it) {
        const double c = 0.5 * (a + b);
        (rk4(f.z, c)[0] < 1.0 ? a : b) = c;
      }
      f.z = rk4(apply(kB, rk4(f.z, b).data()), h - b);
      ++f.kicks;
    } else {
      f.z = y;
    }
    if ((n + 1) % every == 0 && !in_box(f.z)) f.stayed = false;
  }
  return f;
}

/// Mass and first moments in the box.
using Moments = std::array<double, 3>;

/// The reference moments at time t, by rows: for each y0 of a composite Gauss rule (40 panels
/// × 4 nodes on [−1.8, 2.2]), the integrand u0·φ(Z_t)·[Z_t in the box (and stayed)] is
/// piecewise smooth in x0, with jumps where the number of kicks by t or the box indicators
/// change. They are found on a scan of [−2, 2] (100 cells) and located by bisection to 1e-13,
/// and every piece between scan points and jumps gets 4-node Gauss–Legendre: the jumps then
/// cost nothing, and the row integral is continuous in y0 (u0 < e^{−32} off this square).
/// RK4 step 2e-3 (its error, ~1e-10, is far below the comparisons).
Moments reference_at(double t, bool box_limited, double check, double kH = 1e-2, int kScan = 100,
                     int y_panels = 40) {
  constexpr double kX0 = -2.0, kX1 = 2.0;
  const auto ry = rt::gauss_legendre_rule(-1.8, 2.2, y_panels, 4);
  const auto g4 = rt::gauss_legendre(4);
  Moments out{};
  const auto rows = static_cast<long long>(ry.nodes.size());
#pragma omp parallel
  {
    Moments loc{};
#pragma omp for schedule(dynamic, 1)
    for (long long r = 0; r < rows; ++r) {
      const double y0 = ry.nodes[static_cast<std::size_t>(r)];
      const double wy = ry.weights[static_cast<std::size_t>(r)];
      auto key = [&](double x0) { return push({x0, y0}, t, kH, check).key(box_limited); };
      std::vector<double> bp;
      int prev = key(kX0);
      for (int i = 1; i <= kScan; ++i) {
        const double xa = kX0 + (kX1 - kX0) * (i - 1) / kScan, xb = kX0 + (kX1 - kX0) * i / kScan;
        const int kb = key(xb);
        if (kb != prev) {
          double a = xa, b = xb;
          while (b - a > 1e-13) {
            const double c = 0.5 * (a + b);
            (key(c) == prev ? a : b) = c;
          }
          bp.push_back(0.5 * (a + b));
        }
        bp.push_back(xb);
        prev = kb;
      }
      double left = kX0;
      for (const double right : bp) {
        for (std::size_t q = 0; q < g4.nodes.size(); ++q) {
          const P2 z0{0.5 * (left + right) + 0.5 * (right - left) * g4.nodes[q], y0};
          const double m = wy * 0.5 * (right - left) * g4.weights[q] *
                           ShearKick::initial_density(0, z0.data(), nullptr);
          if (m < 1e-300) continue;
          const Fate f = push(z0, t, kH, check);
          if (!in_box(f.z) || (box_limited && !f.stayed)) continue;
          loc[0] += m;
          loc[1] += m * f.z[0];
          loc[2] += m * f.z[1];
        }
        left = right;
      }
    }
#pragma omp critical(validation_shear_reset)
    for (std::size_t a = 0; a < 3; ++a) out[a] += loc[a];
  }
  return out;
}

/// The output times.
const std::vector<double> kTimes{0.0, 1.0, 2.0, 3.0};

/// The reference at every output time, computed once: full (characteristics, particles) or
/// box-limited with the transfer step 0.05.
const std::vector<Moments>& reference(bool box_limited) {
  static std::vector<Moments> full, limited;
  std::vector<Moments>& r = box_limited ? limited : full;
  if (r.empty())
    for (const double t : kTimes) r.push_back(reference_at(t, box_limited, 0.05));
  return r;
}

/// Worst difference of the mass and first moments relative to `mass0` (and the box scale 3).
double worst_difference(const Moments& got, const Moments& ref, double mass0) {
  return std::max({std::fabs(got[0] - ref[0]) / mass0, std::fabs(got[1] - ref[1]) / (3.0 * mass0),
                   std::fabs(got[2] - ref[2]) / (3.0 * mass0)});
}

/// The grid of the box, nx × (3(nx − 1)/2 + 1) nodes.
rt::TensorGrid<2> box(int nx) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{kLo[0], kHi[0], nx}, rt::GridAxis{kLo[1], kHi[1], (3 * (nx - 1)) / 2 + 1}};
  return g;
}

/// The initial mass ∫u0 = π/8 (for the relative differences).
const double kMass0 = std::numbers::pi / 8.0;

TEST(ShearReset, CharacteristicsMoments) {
  // u at the midpoints of 240² cells. The density jumps (by up to 3) across the reset's image
  // of the guard, so the midpoint rule is first order there: measured worst 6.1e-4 (t = 3);
  // at 480² and 960² cells the mass errors at t = 2 are 5.3e-5 and 4.5e-6 of the mass
  // 0.39 (the density itself agrees with the reference; the bound is the quadrature's).
  // Asserted: < 1.5e-3.
  const auto& ref = reference(false);
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const int cells = 240;
  std::vector<P2> pts;
  for (int i = 0; i < cells; ++i)
    for (int j = 0; j < cells; ++j)
      pts.push_back({kLo[0] + (i + 0.5) * (kHi[0] - kLo[0]) / cells,
                     kLo[1] + (j + 0.5) * (kHi[1] - kLo[1]) / cells});
  const auto sol = rt::evaluate<ShearKick>(pts, kTimes, nullptr, co);
  ASSERT_TRUE(sol.ok()) << rt::describe<ShearKick>(sol.failure);
  const double cell = (kHi[0] - kLo[0]) * (kHi[1] - kLo[1]) / (cells * cells);
  double worst = 0.0;
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    Moments got{};
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const double m = cell * sol.at(k, 0, i);
      got[0] += m;
      got[1] += m * pts[i][0];
      got[2] += m * pts[i][1];
    }
    const double d = worst_difference(got, ref[k], kMass0);
    worst = std::max(worst, d);
    std::printf(
        "[ shear ] characteristics t = %.0f: mass %.6f (ref %.6f), <x> %.6f (%.6f), <y> "
        "%.6f (%.6f): worst %.2e\n",
        kTimes[k], got[0], ref[k][0], got[1], ref[k][1], got[2], ref[k][2], d);
  }
  EXPECT_LT(worst, 1.5e-3);
}

/// The adaptive budget of the characteristics (what `hybgen run` reports) at rel_tol.
rt::BudgetResult<2> budget(double rel_tol) {
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  rt::AdaptiveOptions ao;
  ao.rel_tol = rel_tol;
  ao.max_points = 4000000;
  return rt::adaptive_mass_budget<ShearKick>(box(41), kTimes, nullptr, co, ao);
}

TEST(ShearReset, CharacteristicsBudget) {
  // The budget's mass and outflow against the reference (outflow: its net outflow ∫_box u0 −
  // ∫_box u(t)). At the runner's default budget_tol 3e-4 both within the target rel_tol·mass0
  // = 1.2e-4: measured mass 5.6e-5, outflow 1.3e-6. At rel_tol 1e-5 the outflow converges
  // (measured 2.9e-8 against a target of 3.9e-6) but the mass does not: at t = 2 it is low by
  // 4.6e-5, 3.8e-5, 6.4e-5 for rel_tol 1e-4, 1e-5, 1e-6 while its estimate falls to 1.5e-5,
  // 1.1e-6, 2.9e-7, although the density is right (960² midpoints agree to 4.5e-6). The
  // missing mass is at the density's jump across the reset image of the guard in
  // [0.5, 1] × [0, 0.5]: a cell whose Gauss nodes all lie on one side of a jump sees no error
  // (one root cell there is low by 6.3e-5 with an estimate of 8e-8; 25 root cells agree to
  // 3e-6) — the adaptive cubature's blind spot (budget.hpp), in leaves narrower than the
  // 41-node grid's spacing, where the grid's nodes no longer serve as check points (with
  // them: t = 2 low by 3.8e-5, estimate 1.2e-6, flagged 5.2×). So there it must be within its
  // target or
  // flagged by the runner's closure check, |defect| > kDefectFactor·budget_defect_error
  // (methods.hpp: the warning "the mass budget does not close"). Measured: t = 1 within
  // target, t = 2 and 3 flagged (7.3× and 1.5× the bar; 6.1× and 1.4× before the defect took
  // the drop mass0 − mass as one integral, budget/volume.hpp, 2026-12-02).
  const auto& ref = reference(false);
  for (const double tol : {3e-4, 1e-5}) {
    const auto b = budget(tol);
    ASSERT_TRUE(b.ok()) << rt::describe<ShearKick>(b.failure) << b.message;
    const auto defect = rt::budget_defect(b.budget), bar = rt::budget_defect_error(b.budget);
    const double target = tol * b.budget.mass0;
    for (std::size_t k = 0; k < kTimes.size(); ++k) {
      const double em = b.budget.mass[k] - ref[k][0];
      const double eo = b.budget.outflow[k] - (ref[0][0] - ref[k][0]);
      const double ratio = std::fabs(defect[k]) / (rt::kDefectFactor * bar[k]);
      std::printf(
          "[ shear ] characteristics budget rel_tol %.0e t = %.0f: mass error %.2e (est "
          "%.1e), outflow error %.2e (est %.1e), target %.1e, defect / its bar %.2f\n",
          tol, kTimes[k], em, b.budget.mass_error[k], eo, b.budget.outflow_error[k], target, ratio);
      EXPECT_LE(std::fabs(eo), target) << "t = " << kTimes[k];
      if (tol > 1e-4) {
        EXPECT_LE(std::fabs(em), target) << "t = " << kTimes[k];
      } else {
        EXPECT_TRUE(std::fabs(em) <= target || ratio > 1.0)
            << "t = " << kTimes[k] << ": a wrong mass that the closure check does not flag";
      }
    }
  }
}

TEST(ShearReset, TransferMomentsAgainstTheBoxLimitedReference) {
  const auto& ref = reference(true);
  double prev = 0.0;
  for (const int nx : {81, 161}) {
    const auto grid = box(nx);
    rt::TransferOptions o;
    o.step = 0.05;
    const auto op = rt::assemble_transfer<ShearKick>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto run = rt::march(op, rt::initial_vector<ShearKick>(grid, nullptr), kTimes);
    ASSERT_TRUE(run.ok()) << run.failure;
    double worst = 0.0;
    for (std::size_t k = 0; k < kTimes.size(); ++k) {
      Moments got{};
      for (std::size_t i = 0; i < grid.size(); ++i) {
        const auto y = grid.node(i);
        const double m = op.weight[i] * run.solution.at(k, 0, i);
        got[0] += m;
        got[1] += m * y[0];
        got[2] += m * y[1];
      }
      const double d = worst_difference(got, ref[k], kMass0);
      worst = std::max(worst, d);
      std::printf(
          "[ shear ] transfer %d x %d t = %.0f: mass %.6f (ref %.6f), outflow %.6f (ref "
          "%.6f), <x> %.6f (%.6f), <y> %.6f (%.6f): worst %.2e\n",
          nx, grid.axes[1].n, kTimes[k], got[0], ref[k][0], run.budget.outflow[k],
          ref[0][0] - ref[k][0], got[1], ref[k][1], got[2], ref[k][2], d);
      EXPECT_NEAR(run.budget.mass[k] + run.budget.outflow[k], run.budget.mass0, 1e-12);
    }
    std::printf("[ shear ] transfer %d x %d: worst %.2e\n", nx, grid.axes[1].n, worst);
    if (prev == 0.0) {
      EXPECT_LT(worst, 8e-3);
    } else {
      EXPECT_GT(prev / worst, 3.0);
    }
    prev = worst;
  }
}

TEST(ShearReset, ParticleMoments) {
  const auto& ref = reference(false);
  const auto grid = box(41);
  rt::ParticleOptions po;
  po.particles = 200000;
  po.seed = 13;
  po.forward.ode.rtol = 1e-9;
  po.forward.ode.atol = 1e-11;
  const auto run = rt::solve_particles<ShearKick>(grid, kTimes, nullptr, po);
  ASSERT_TRUE(run.failure.ok()) << rt::describe<ShearKick>(run.failure);
  const auto& b = run.budget;
  const double s2 = 0.25 * b.mass_error[0] * b.mass_error[0] +
                    b.mass0 * b.mass0 / static_cast<double>(po.particles);
  const double w2bar = s2 / b.mass0;
  const auto w = rt::detail::trapezoid_weights(grid, 1);
  double worst = 0.0;
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    Moments got{};
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const auto y = grid.node(i);
      const double m = w[i] * run.solution.at(k, 0, i);
      got[0] += m;
      got[1] += m * y[0];
      got[2] += m * y[1];
    }
    // σ² ≤ E[φ²]·Σw²/Σw with |φ| ≤ 1, 1, 1.5 on the box.
    for (std::size_t a = 0; a < 3; ++a) {
      const double bound = a == 2 ? 1.5 : 1.0;
      const double sigma = bound * std::sqrt(ref[k][0] * w2bar);
      const double z = std::fabs(got[a] - ref[k][a]) / sigma;
      worst = std::max(worst, z);
      EXPECT_LE(z, 5.0) << "t = " << kTimes[k] << ", moment " << a;
    }
    std::printf(
        "[ shear ] particles t = %.0f: mass %.6f (ref %.6f), <x> %.6f (%.6f), <y> %.6f "
        "(%.6f)\n",
        kTimes[k], got[0], ref[k][0], got[1], ref[k][1], got[2], ref[k][2]);
  }
  std::printf("[ shear ] particles: worst |z| %.2f\n", worst);
}

}  // namespace
