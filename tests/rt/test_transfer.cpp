// Tests of hybgen/rt/transfer.hpp: the interpolating (semi-Lagrangian) transfer operator on
// the elastic bouncing ball against its closed-form density, its structure (positivity, row
// sums), mass accounting, step/time validation and failure reporting.

#include <gtest/gtest.h>

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
#include "hybgen/rt/transfer.hpp"
#include "support/ball_closed_form.hpp"
#include "support/rt_setup.hpp"

namespace {

namespace rt = hybgen::rt;
using hybgen::testing::seconds_since;
using Ball = rt::testing::BouncingBall;

// ---------------------------------------------------------------------------------------
// The bouncing ball with a smooth, compactly supported initial density.
//
// A box-limited operator has no inflow from outside the box, so its error against the
// whole-space density does not vanish under refinement once mass enters the box (the
// paper's Gaussian has ~9 % of its mass at x > 2). The energy E = p²/2 + x (m = g = 1) is
// invariant under the elastic flow and {E ≤ 1.8} ⊂ [0, 1.8] × [−1.9, 1.9] lies inside the box
// [0, 2] × [−2, 2]: with u0 supported there no mass ever meets the box faces, and the exact
// density u(t) = u0 ∘ φ₋ₜ is the reference for the discretisation error alone.
// u0 = exp(−(x−1)² − p²)·χ(E), χ = 1 for E ≤ 1, 0 for E ≥ 1.8, quintic smoothstep (C²)
// between. u0(0, p) = u0(0, −p), so u(t) is continuous across the reset line (it has a kink
// there: only Lipschitz, which linear interpolation still resolves at second order in L1).

double chi(double E) {
  const double s = std::clamp((1.8 - E) / 0.8, 0.0, 1.0);
  return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
}

double compact_u0(double x, double p) {
  if (x < 0.0) return 0.0;
  return std::exp(-(x - 1.0) * (x - 1.0) - p * p) * chi(0.5 * p * p + x);
}

/// The ball of bouncing_ball_model.hpp with the compact u0 (static members inherited).
struct CompactBall : Ball {
  /// u0 = exp(−(x−1)² − p²)·χ(p²/2 + x) on x ≥ 0.
  static double initial_density(int, const double* x, const double*) {
    return compact_u0(x[0], x[1]);
  }
};
static_assert(rt::HybridModel<CompactBall>);

/// Elastic ball, m = g = 1: u(t, x, p) = u0(φ₋ₜ(x, p)) (tests/support/ball_closed_form.hpp).
template <class U0>
double exact_elastic(double x, double p, double t, U0&& u0) {
  return hybgen::testing::ball_pullback_elastic(x, p, t, u0);
}

rt::TensorGrid<2> ball_grid(int n) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.0, 2.0, n}, rt::GridAxis{-2.0, 2.0, n}};
  return g;
}

rt::TransferOptions interp_options(double h) {
  rt::TransferOptions o;
  o.step = h;
  o.trace.ode.rtol = 1e-10;
  o.trace.ode.atol = 1e-12;
  return o;
}

/// Relative L1 error Σ w|u − u_exact| / Σ w|u_exact| (trapezoid weights) at output k.
template <std::size_t N, class Exact>
double rel_l1(const rt::TensorGrid<N>& grid, const rt::Solution<N>& sol, std::size_t k,
              Exact&& exact) {
  std::array<rt::AxisRule, N> rules;
  for (std::size_t a = 0; a < N; ++a) rules[a] = rt::trapezoid_rule(grid.axes[a]);
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    std::size_t rem = i;
    double w = 1.0;
    for (std::size_t a = N; a-- > 0;) {
      w *= rules[a].weights[rem % rules[a].weights.size()];
      rem /= rules[a].weights.size();
    }
    const auto y = grid.node(i);
    const double ue = exact(y);
    num += w * std::fabs(sol.at(k, 0, i) - ue);
    den += w * std::fabs(ue);
  }
  return num / den;
}

// ---------------------------------------------------------------------------------------

TEST(Transfer, HatWeightsReproduceLinearFunctions) {
  // Multilinear interpolation is exact for affine functions and its weights are a partition
  // of unity with non-negative entries; points outside the box are rejected.
  const auto grid = ball_grid(9);
  std::array<std::size_t, 4> idx{};
  std::array<double, 4> wt{};
  for (const auto& x : std::vector<std::array<double, 2>>{
           {0.3, -1.1}, {0.0, -2.0}, {2.0, 2.0}, {1.75, 0.5}, {1.0, 0.0}}) {
    ASSERT_TRUE(rt::detail::hat_weights<2>(grid, x.data(), idx, wt));
    double s = 0.0, f = 0.0;
    for (std::size_t c = 0; c < 4; ++c) {
      EXPECT_GE(wt[c], 0.0);
      const auto y = grid.node(idx[c]);
      s += wt[c];
      f += wt[c] * (3.0 * y[0] - 2.0 * y[1] + 1.0);
    }
    EXPECT_NEAR(s, 1.0, 1e-15);
    EXPECT_NEAR(f, 3.0 * x[0] - 2.0 * x[1] + 1.0, 1e-13);
  }
  const std::array<double, 2> out{2.01, 0.0}, out2{1.0, -2.5};
  EXPECT_FALSE(rt::detail::hat_weights<2>(grid, out.data(), idx, wt));
  EXPECT_FALSE(rt::detail::hat_weights<2>(grid, out2.data(), idx, wt));
}

TEST(Transfer, BallOperatorStructure) {
  // Elastic ball: div X = 0 and |J| = e² = 1, so each row is Σ_k φ_k(foot) = 1 when its single
  // foot is in the box and empty when the foot left it; entries are > 0. With e = 0.8 the
  // rows reached through a reversed reset carry 1/e² (the density jump of Thm 3.11).
  const auto grid = ball_grid(41);
  for (const double e : {1.0, 0.8}) {
    const std::array<double, 3> par{1.0, 1.0, e};
    const auto op = rt::assemble_transfer<Ball>(grid, par.data(), interp_options(0.05));
    ASSERT_TRUE(op.ok()) << rt::describe<Ball>(op.failure);
    ASSERT_EQ(op.P.rows(), static_cast<Eigen::Index>(grid.size()));
    int n_one = 0, n_reset = 0, n_empty = 0;
    for (Eigen::Index r = 0; r < op.P.rows(); ++r) {
      double s = 0.0;
      for (rt::CsrMatrix::InnerIterator it(op.P, r); it; ++it) {
        EXPECT_GT(it.value(), 0.0);
        s += it.value();
      }
      if (s == 0.0)
        ++n_empty;
      else if (std::fabs(s - 1.0) < 1e-12)
        ++n_one;
      else if (std::fabs(s - 1.0 / (e * e)) < 1e-12)
        ++n_reset;
      else
        ADD_FAILURE() << "row " << r << " sums to " << s;
    }
    EXPECT_GT(n_one, 1000);
    EXPECT_GT(n_empty, 0);  // feet beyond x = 2 or |p| = 2
    if (e < 1.0) {
      EXPECT_GT(n_reset, 0);
    }
    // Nodes near the ground with p > 0 came through a bounce within h: a foot on the other side.
    const std::size_t near_ground = 1 * 41 + 30;  // x = 0.05, p = 1
    const auto yg = grid.node(near_ground);
    ASSERT_NEAR(yg[0], 0.05, 1e-15);
    bool has_lower = false;
    for (rt::CsrMatrix::InnerIterator it(op.P, static_cast<Eigen::Index>(near_ground)); it; ++it)
      has_lower = has_lower || grid.node(static_cast<std::size_t>(it.col()))[1] < 0.0;
    EXPECT_TRUE(has_lower);
  }
}

TEST(Transfer, BallConvergesAtSecondOrder) {
  // L1 error against the closed form on grids 65² … 513². The trace is exact to the ODE
  // tolerance (1e-10), so the error is the interpolation error: each step's multilinear
  // interpolation errs by θ(1−θ)(Δx²/2)|∂²u| (θ: the fractional cell shift of the foot),
  // accumulated over t/h steps: order 2 in Δx at fixed h.
  //
  // h = 1/16: the momentum shift per step, g·h = 1/16, is a whole number of cells (1, 2, 4,
  // 8) on every grid, so θ = 0 along p and the error constant is the same on every grid. (At
  // h = 0.05 the p-shift is 0.8, 1.6, 3.2, 6.4 … cells: θ(1−θ) alternates 0.16, 0.24, which
  // moves the observed order by ±log₂1.5 = ±0.58 from level to level; the benchmark
  // BM_TransferGrid shows both.)
  //
  // Measured (h = 1/16): t = 1: 1.50e-2, 3.74e-3, 9.37e-4, 2.42e-4: orders 2.00, 2.00, 1.95
  // — second order. t = 10: 3.26e-1, 1.44e-1, 5.55e-2, 1.98e-2: orders 1.17, 1.38, 1.49,
  // rising towards 2 (1.52 at 1025²): pre-asymptotic, because the shear of the flow (the
  // period 2√(2E) depends on the energy) grows the density's second derivatives like t², so
  // Δx²|∂²u| ≪ |u| needs finer grids at t = 10. Asserted: every refinement reduces both errors;
  // the t = 1 orders lie in [1.85, 2.1] (second order; the band's width is the measured drift
  // plus 0.05) and the t = 10 orders in [1.0, 1.7] (the measured 1.17–1.49 ± 0.2).
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const double h = 1.0 / 16.0;
  const std::vector<double> times{0.0, 1.0, 10.0};
  std::vector<double> err1, err10;
  for (const int n : {65, 129, 257, 513}) {
    const auto grid = ball_grid(n);
    const auto t0 = std::chrono::steady_clock::now();
    const auto op = rt::assemble_transfer<CompactBall>(grid, par.data(), interp_options(h));
    ASSERT_TRUE(op.ok()) << rt::describe<CompactBall>(op.failure);
    const auto u0 = rt::initial_vector<CompactBall>(grid, par.data());
    const auto run = rt::march(op, u0, times);
    const double secs = seconds_since(t0);
    EXPECT_EQ(run.n_steps, 160);
    // t = 0 is the initial vector itself.
    EXPECT_EQ(rel_l1(grid, run.solution, 0, [](const auto& y) { return compact_u0(y[0], y[1]); }),
              0.0);
    err1.push_back(rel_l1(grid, run.solution, 1, [](const auto& y) {
      return exact_elastic(y[0], y[1], 1.0, compact_u0);
    }));
    err10.push_back(rel_l1(grid, run.solution, 2, [](const auto& y) {
      return exact_elastic(y[0], y[1], 10.0, compact_u0);
    }));
    const double loss = run.budget.mass0 - run.budget.mass[2];
    std::printf(
        "[ transfer ball ] %4d^2: assembly %.3f s, total %.3f s, nnz %ld, rel L1 "
        "t=1 %.3e t=10 %.3e, mass loss %.2e\n",
        n, op.seconds, secs, static_cast<long>(op.P.nonZeros()), err1.back(), err10.back(), loss);
    // No mass reaches the faces, so the loss is the scheme's conservation error alone:
    // |Σ w(u − u_ex)| ≤ Σ w|u − u_ex|, and Σ w u_ex(10) = mass0 up to the trapezoid rule's
    // O(Δx²) error (far below the L1 error), hence |loss| ≤ 1.5·(L1 error)·mass0.
    EXPECT_LT(std::fabs(loss), 1.5 * err10.back() * run.budget.mass0);
  }
  for (std::size_t j = 1; j < err1.size(); ++j) {
    EXPECT_LT(err1[j], err1[j - 1]);
    EXPECT_LT(err10[j], err10[j - 1]);
    const double o1 = std::log2(err1[j - 1] / err1[j]), o10 = std::log2(err10[j - 1] / err10[j]);
    std::printf("[ transfer ball ] observed order t=1 %.3f, t=10 %.3f\n", o1, o10);
    EXPECT_GE(o1, 1.85);
    EXPECT_LE(o1, 2.1);
    EXPECT_GE(o10, 1.0);
    EXPECT_LE(o10, 1.7);
  }
}

TEST(Transfer, MassBudgetIsReportedNotRenormalised) {
  // The paper's Gaussian leaves the box: the mass must fall (never renormalised), the per-step
  // losses must add up to the total loss, and mass + outflow + atom = mass0 by definition.
  const auto grid = ball_grid(65);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const auto op = rt::assemble_transfer<Ball>(grid, par.data(), interp_options(0.2));
  ASSERT_TRUE(op.ok());
  const auto u0 = rt::initial_vector<Ball>(grid, par.data());
  std::vector<double> times;
  for (int k = 0; k <= 10; ++k) times.push_back(0.4 * k);
  const auto run = rt::march(op, u0, times);
  ASSERT_EQ(run.step_mass.size(), 21U);
  ASSERT_EQ(run.step_outflow.size(), 20U);
  double sum = 0.0;
  for (const double l : run.step_outflow) sum += l;
  EXPECT_NEAR(sum, run.step_mass.front() - run.step_mass.back(), 1e-13);
  // Mass at t = 4 well below mass0: E > 2 orbits (≈ 10 % of the mass in the box) leave it.
  EXPECT_LT(run.budget.mass.back(), 0.97 * run.budget.mass0);
  for (std::size_t k = 0; k < times.size(); ++k) {
    EXPECT_DOUBLE_EQ(run.budget.mass[k], run.step_mass[2 * k]);
    EXPECT_NEAR(run.budget.mass[k] + run.budget.outflow[k] + run.budget.atom[k], run.budget.mass0,
                1e-14);
  }
  // Discrete mass at t = 0 is the trapezoid rule of u0.
  double m0 = 0.0;
  for (std::size_t r = 0; r < u0.size(); ++r) m0 += op.weight[r] * u0[r];
  EXPECT_NEAR(run.budget.mass0, m0, 1e-14 * m0);  // summation order differs
}

TEST(Transfer, OutputTimesMustBeMultiplesOfTheStep) {
  const auto grid = ball_grid(9);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const auto op = rt::assemble_transfer<Ball>(grid, par.data(), interp_options(0.05));
  const auto u0 = rt::initial_vector<Ball>(grid, par.data());
  const std::vector<double> good{0.0, 0.1, 0.5}, bad{0.0, 0.12};
  EXPECT_NO_THROW(rt::march(op, u0, good));
  EXPECT_THROW(rt::march(op, u0, bad), std::invalid_argument);
  EXPECT_THROW(rt::assemble_transfer<Ball>(grid, par.data(), interp_options(0.0)),
               std::invalid_argument);
  auto g1 = grid;
  g1.axes[0].n = 1;
  EXPECT_THROW(rt::assemble_transfer<Ball>(g1, par.data(), interp_options(0.05)),
               std::invalid_argument);
}

/// The ball with a vector field that is NaN for p > 1.5 (a broken kernel).
struct BrokenBall : Ball {
  /// X = (p, −1), NaN above p = 1.5.
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1] > 1.5 ? std::numeric_limits<double>::quiet_NaN() : x[1];
    out[1] = -1.0;
  }
};

TEST(Transfer, FailureNamesThePlace) {
  const auto grid = ball_grid(17);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const auto op = rt::assemble_transfer<BrokenBall>(grid, par.data(), interp_options(0.05));
  ASSERT_FALSE(op.ok());
  // A backward step of 0.05 moves p by 0.05 and a reversed reset maps p to −p, so the failing
  // state is within 0.05 of the NaN region |p| > 1.5 (here: the pre-image (0, 2) of (0, −2)).
  EXPECT_GT(std::fabs(op.failure.status.state[1]), 1.45);
  EXPECT_EQ(op.failure.status.error, rt::TraceError::non_finite_flow);
  const std::string msg = rt::describe<BrokenBall>(op.failure);
  EXPECT_NE(msg.find("characteristic from"), std::string::npos) << msg;
  EXPECT_NE(msg.find("flight"), std::string::npos) << msg;
}

}  // namespace

namespace {

// ---------------------------------------------------------------------------------------
// The conservative (Ulam) operator.

rt::TransferOptions ulam_options(double h, int samples) {
  rt::TransferOptions o;
  o.step = h;
  o.scheme = rt::TransferScheme::conservative;
  o.samples_per_axis = samples;
  o.forward.ode.rtol = 1e-10;
  o.forward.ode.atol = 1e-12;
  return o;
}

/// Every column: entries ≥ 0, Σ_j P_ji + outflow_i + atom_i = 1 to 1e-14, Σ_j P_ji ≤ 1 + 1e-14.
void check_columns(const rt::TransferOperator<2>& op) {
  std::vector<double> col(op.size(), 0.0);
  for (Eigen::Index r = 0; r < op.P.rows(); ++r)
    for (rt::CsrMatrix::InnerIterator it(op.P, r); it; ++it) {
      ASSERT_GT(it.value(), 0.0);
      col[static_cast<std::size_t>(it.col())] += it.value();
    }
  for (std::size_t i = 0; i < col.size(); ++i) {
    ASSERT_LE(col[i], 1.0 + 1e-14) << i;
    ASSERT_GE(op.outflow[i], 0.0);
    ASSERT_GE(op.atom[i], 0.0);
    ASSERT_NEAR(col[i] + op.outflow[i] + op.atom[i], 1.0, 1e-14) << i;
  }
}

TEST(TransferConservative, BudgetClosesAtEveryStep) {
  // Elastic ball, the paper's Gaussian on 65², h = 0.1 to t = 10: mass + outflow + atom =
  // mass0 to 1e-12 after every step (each column distributes exactly its mass: the identity
  // holds to rounding, ~1e-16 per step and entry), no atom (no Zeno point for e = 1 but the
  // measure-zero grazing point), outflow > 0 (orbits with E > 2 leave the box), u ≥ 0.
  const auto grid = ball_grid(65);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const auto op = rt::assemble_transfer<Ball>(grid, par.data(), ulam_options(0.1, 4));
  ASSERT_TRUE(op.ok()) << op.failure_message;
  check_columns(op);
  const auto u0 = rt::initial_vector<Ball>(grid, par.data());
  std::vector<double> times;
  for (int k = 0; k <= 20; ++k) times.push_back(0.5 * k);
  const auto run = rt::march(op, u0, times);
  ASSERT_EQ(run.step_mass.size(), 101U);
  double out = 0.0, atom = 0.0;
  for (std::size_t n = 0; n < run.step_outflow.size(); ++n) {
    out += run.step_outflow[n];
    atom += run.step_atom[n];
    EXPECT_GE(run.step_outflow[n], 0.0);
    EXPECT_NEAR(run.step_mass[n + 1] + out + atom, run.budget.mass0, 1e-12) << n;
  }
  EXPECT_EQ(atom, 0.0);
  EXPECT_GT(out, 0.05 * run.budget.mass0);
  for (std::size_t k = 0; k < times.size(); ++k)
    EXPECT_NEAR(run.budget.mass[k] + run.budget.outflow[k] + run.budget.atom[k], run.budget.mass0,
                1e-12);
  EXPECT_GE(*std::min_element(run.solution.u.begin(), run.solution.u.end()), 0.0);
  std::printf(
      "[ ulam ball e=1 ] 65^2 h=0.1: assembly %.3f s, nnz %ld, mass(10) %.6f of %.6f, "
      "outflow %.6f\n",
      op.seconds, static_cast<long>(op.P.nonZeros()), run.budget.mass.back(), run.budget.mass0,
      run.budget.outflow.back());
}

TEST(TransferConservative, ZenoMassBecomesAnAtom) {
  // e = 0.8: samples whose forward flow reaches the Zeno point (0, 0) within the step
  // (t_Z ≤ h) are atoms. The atom must grow monotonically (atoms never return) and the
  // budget still close to 1e-12. Reference: the closed-form mass of the initial states with
  // T_Z ≤ t (0.43415 at t = 10; ≈ all of it starts inside the box).
  // Ulam's limitation at a Zeno point: every step spreads the mass of the Zeno point's own
  // cell uniformly over it again, and only its samples with T_Z ≤ h drain into the atom.
  // T_Z = p0 + v1(1+e)/(1−e) with v1 = √(p0² + 2x0) ~ √Δx in that cell, so for h below
  // ~9√(2Δx) the cell never drains (measured: 129² or 257² at h = 0.1 or 0.25 give atom 0,
  // the mass sits in the corner cell as density) and for larger h the atom lags the truth
  // by the cell's Zeno times, converging like √Δx. Measured at h = 0.5: atom(10) = 0.251
  // (129²), 0.367 (257²); at h = 0.25: 0.329 (513²). Asserted on 257², h = 0.5: atom(10)
  // within [0.6, 1.0] of the closed form (measured 0.845).
  const auto grid = ball_grid(257);
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  const auto op = rt::assemble_transfer<Ball>(grid, par.data(), ulam_options(0.5, 4));
  ASSERT_TRUE(op.ok()) << op.failure_message;
  check_columns(op);
  const auto u0 = rt::initial_vector<Ball>(grid, par.data());
  const std::vector<double> times{0.0, 2.0, 5.0, 10.0};
  const auto run = rt::march(op, u0, times);
  double out = 0.0, atom = 0.0;
  for (std::size_t n = 0; n < run.step_atom.size(); ++n) {
    out += run.step_outflow[n];
    atom += run.step_atom[n];
    EXPECT_GE(run.step_atom[n], 0.0);
    EXPECT_NEAR(run.step_mass[n + 1] + out + atom, run.budget.mass0, 1e-12) << n;
  }
  const double zm = hybgen::testing::zeno_mass(10.0, 0.8);
  std::printf(
      "[ ulam ball e=0.8 ] 257^2 h=0.5: assembly %.3f s, atom(2, 5, 10) = %.5f %.5f "
      "%.5f, closed form at 10: %.5f, outflow(10) %.5f, mass0 %.5f\n",
      op.seconds, run.budget.atom[1], run.budget.atom[2], run.budget.atom[3], zm,
      run.budget.outflow[3], run.budget.mass0);
  EXPECT_GT(run.budget.atom[1], 0.0);
  EXPECT_LT(run.budget.atom[1], run.budget.atom[2]);
  EXPECT_LT(run.budget.atom[2], run.budget.atom[3]);
  EXPECT_GE(run.budget.atom[3], 0.6 * zm);
  EXPECT_LE(run.budget.atom[3], zm);
}

}  // namespace
