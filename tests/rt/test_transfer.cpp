// Tests of hybgen/rt/methods/transfer.hpp: the mass-moving transfer operator (`hat`) on
// the bouncing ball — conservation column by column and step by step (checked against quantities
// computed here, not by the code under test), accuracy against the closed-form elastic
// density, the restitution case that the withdrawn interpolating scheme blew up, Zeno atoms,
// the detection of a broken budget, step/time validation and failure reporting.

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
#include "hybgen/rt/methods/transfer.hpp"
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

rt::TransferOptions options(double h, rt::TransferScheme scheme = rt::TransferScheme::hat,
                            int samples = 0) {
  rt::TransferOptions o;
  o.step = h;
  o.scheme = scheme;
  o.samples_per_axis = samples;
  o.forward.ode.rtol = 1e-10;
  o.forward.ode.atol = 1e-12;
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

TEST(Transfer, HatDepositIsAPartitionOfUnityThatKeepsTheCentre) {
  // The `hat` deposit of a sample's box [c − δ/2, c + δ/2] (per axis: axis_box_weights, exact
  // integrals of the hats; a tensor product in `deposit`): weights ≥ 0 summing to 1 (no mass
  // lost or made), and Σ_j w_j x_j = the centre of the box clipped to the grid (the hats
  // reproduce linear functions, so ∫_I Σ φ_j x_j = ∫_I x), for boxes inside, at the faces,
  // wider than a cell, and points (δ = 0). A point outside the box is refused.
  const auto grid = ball_grid(9);  // [0, 2] × [−2, 2], Δ = 0.25, 0.5
  const std::array<double, 2> dx{0.25, 0.5};
  const std::vector<char> all(grid.size(), 1);
  std::vector<std::pair<std::size_t, double>> out;
  for (const auto& [x, delta] :
       std::vector<std::pair<std::array<double, 2>, std::array<double, 2>>>{
           {{0.3, -1.1}, {0.1, 0.2}},
           {{0.0, -2.0}, {0.0625, 0.125}},
           {{2.0, 2.0}, {0.0, 0.0}},
           {{1.75, 0.5}, {0.6, 1.3}},
           {{1.0, 0.0}, {0.25, 0.5}},
           {{0.05, 1.97}, {0.2, 0.2}}}) {
    out.clear();
    ASSERT_TRUE(rt::detail::deposit<2>(grid, dx, delta, all.data(), x, out));
    double sum = 0.0;
    std::array<double, 2> centre{}, mean{};
    for (std::size_t a = 0; a < 2; ++a) {
      const double lo = std::max(grid.axes[a].min, x[a] - 0.5 * delta[a]);
      const double hi = std::min(grid.axes[a].max, x[a] + 0.5 * delta[a]);
      centre[a] = 0.5 * (lo + hi);
    }
    for (const auto& [node, w] : out) {
      EXPECT_GE(w, 0.0);
      sum += w;
      const auto y = grid.node(node);
      for (std::size_t a = 0; a < 2; ++a) mean[a] += w * y[a];
    }
    EXPECT_NEAR(sum, 1.0, 1e-15);
    EXPECT_NEAR(mean[0], centre[0], 1e-13);
    EXPECT_NEAR(mean[1], centre[1], 1e-13);
  }
  for (const auto& x : std::vector<std::array<double, 2>>{{2.01, 0.0}, {1.0, -2.5}}) {
    out.clear();
    EXPECT_FALSE(rt::detail::deposit<2>(grid, dx, {0.1, 0.1}, all.data(), x, out));
    EXPECT_TRUE(out.empty());
  }
}

/// Column sums of P computed here from the CSR arrays (independently of check_columns).
std::vector<double> column_sums(const rt::TransferOperator<2>& op) {
  std::vector<double> col(op.size(), 0.0);
  for (Eigen::Index r = 0; r < op.P.rows(); ++r)
    for (rt::CsrMatrix::InnerIterator it(op.P, r); it; ++it)
      col[static_cast<std::size_t>(it.col())] += it.value();
  return col;
}

TEST(Transfer, EveryColumnMovesExactlyItsMass) {
  // For both schemes, e = 1 and e = 0.8 (|J| = e² ≠ 1 at the ground, the case where the
  // withdrawn interpolating scheme created mass): entries > 0, and every column's entries
  // plus its outflow and atom sum to 1 to 1e-14. The outflow is counted independently here:
  // a column whose dual cell lies at distance > h·max|X| from the box faces x = 2 and
  // |p| = 2 cannot lose mass (|X| = |(p, −1)| ≤ √5 in the box).
  const auto grid = ball_grid(41);
  for (const auto scheme : {rt::TransferScheme::hat})
    for (const double e : {1.0, 0.8}) {
      SCOPED_TRACE(std::string(rt::scheme_name(scheme)) + " e=" + std::to_string(e));
      const std::array<double, 3> par{1.0, 1.0, e};
      const double h = 0.05;
      const auto op = rt::assemble_transfer<Ball>(grid, par.data(), options(h, scheme));
      ASSERT_TRUE(op.ok()) << op.failure_message;
      EXPECT_LE(op.column_defect, 1e-14);
      const auto col = column_sums(op);
      int interior = 0;
      for (std::size_t i = 0; i < col.size(); ++i) {
        EXPECT_GE(op.outflow[i], 0.0);
        EXPECT_GE(op.atom[i], 0.0);
        ASSERT_NEAR(col[i] + op.outflow[i] + op.atom[i], 1.0, 1e-14) << i;
        const auto y = grid.node(i);
        const double reach = h * std::sqrt(5.0) + 0.5 * 0.1;  // + half a cell
        if (y[0] < 2.0 - reach && std::fabs(y[1]) < 2.0 - reach && y[0] > 0.3) {
          ++interior;
          EXPECT_EQ(op.outflow[i], 0.0) << i;
          EXPECT_EQ(op.atom[i], 0.0) << i;
          EXPECT_NEAR(col[i], 1.0, 1e-14) << i;
        }
      }
      EXPECT_GT(interior, 800);
      for (Eigen::Index r = 0; r < op.P.rows(); ++r)
        for (rt::CsrMatrix::InnerIterator it(op.P, r); it; ++it) ASSERT_GT(it.value(), 0.0);
    }
}

TEST(Transfer, GalerkinCarriesItsMassExactlyAndTheIdentityIsItsMassMatrix) {
  // scheme=galerkin (transfer.hpp): x = P u, M u' = x. Checked on the ball with e = 0.8 (|J| =
  // 0.64 at the ground), 33², step 0.5 to t = 2:
  //  * P and M have no negative entry, and every column of P plus its outflow and atom sums to
  //    the column of M (column_mass, to 1e-13 relative), counted here from the matrices;
  //  * the march's budget closes at every step to 1e-12 of the initial mass (the solve made
  //    exact in the mass), and the mass is M u's sum;
  //  * a step of 1e-9 moves nothing: P equals M to 1e-6 of M's largest entry (each sample's
  //    sub-cell, moved or not, goes to the same hats).
  const auto grid = ball_grid(33);
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  const auto op =
      rt::assemble_transfer<Ball>(grid, par.data(), options(0.5, rt::TransferScheme::galerkin));
  ASSERT_TRUE(op.ok()) << op.failure_message;
  EXPECT_EQ(std::string(rt::scheme_name(op.scheme)), "galerkin");
  EXPECT_EQ(op.samples_per_axis, 8);
  EXPECT_LE(op.column_defect, 1e-13);
  ASSERT_EQ(op.column_mass.size(), op.size());
  const auto col = column_sums(op);
  std::vector<double> mcol(op.size(), 0.0);
  for (Eigen::Index r = 0; r < op.mass.rows(); ++r)
    for (rt::CsrMatrix::InnerIterator it(op.mass, r); it; ++it) {
      ASSERT_GE(it.value(), 0.0);
      mcol[static_cast<std::size_t>(it.col())] += it.value();
    }
  for (Eigen::Index r = 0; r < op.P.rows(); ++r)
    for (rt::CsrMatrix::InnerIterator it(op.P, r); it; ++it) ASSERT_GE(it.value(), 0.0);
  for (std::size_t i = 0; i < col.size(); ++i) {
    EXPECT_NEAR(col[i] + op.outflow[i] + op.atom[i], mcol[i], 1e-13 * std::max(mcol[i], 1e-3)) << i;
    EXPECT_NEAR(mcol[i], op.column_mass[i], 1e-13 * std::max(mcol[i], 1e-3)) << i;
  }
  std::vector<double> times;
  for (int k = 0; k <= 4; ++k) times.push_back(0.5 * k);
  const auto run = rt::march(op, rt::initial_vector<Ball>(grid, par.data()), times);
  ASSERT_TRUE(run.ok()) << run.failure;
  EXPECT_LE(run.budget_defect, 1e-12);
  EXPECT_NEAR(run.budget.mass.back() + run.budget.outflow.back() + run.budget.atom.back(),
              run.budget.mass0, 1e-12 * run.budget.mass0);

  const auto still =
      rt::assemble_transfer<Ball>(grid, par.data(), options(1e-9, rt::TransferScheme::galerkin));
  ASSERT_TRUE(still.ok()) << still.failure_message;
  const Eigen::SparseMatrix<double> diff = still.P - still.mass;
  double top = 0.0;
  for (Eigen::Index k = 0; k < still.mass.nonZeros(); ++k)
    top = std::max(top, still.mass.valuePtr()[k]);
  double worst = 0.0;
  for (Eigen::Index k = 0; k < diff.nonZeros(); ++k)
    worst = std::max(worst, std::fabs(diff.valuePtr()[k]));
  EXPECT_LE(worst, 1e-6 * top);
}

/// Elastic ball, m = g = 1: u(t, x, p) = u0(φ₋ₜ(x, p)) (tests/support/ball_closed_form.hpp).
TEST(Transfer, BallConvergesUnderRefinement) {
  // L1 error of the `hat` scheme against the closed form on grids 65² … 513², h = 1/16. Per
  // step the scheme smooths by (Δx²/8)∂²u per axis (transfer.hpp), so the error is O(Δx²) at
  // t = 1 and O(Δx²·t/h) later, pre-asymptotic at t = 10 where the shear of the flow (the
  // period depends on the energy) grows ∂²u like t².
  // Measured (hat, 4×4 samples): t = 1: 5.23e-2, 1.43e-2, 3.80e-3, 1.01e-3 (orders 1.88, 1.91,
  // 1.90); t = 10: 5.31e-1, 3.45e-1, 1.55e-1, 5.54e-2 (0.62, 1.15, 1.49). The withdrawn
  // interpolating scheme measured 1.50e-2 … 2.42e-4 and 3.26e-1 … 1.98e-2 here, 3–4× less, at
  // an h chosen in its favour (g·h a whole number of cells: no interpolation along p): the
  // price of moving mass instead of values; on the paper's configuration (h = 0.2) the two
  // differ by 6 % (docs/benchmarks.md). Smoothing carries mass past E = 1.8 to the faces on coarse
  // grids (outflow 4.7e-2, 1.9e-3, 1.0e-5, 6e-10 of 2.3): it is booked as outflow, never lost.
  // Asserted: both errors fall at every refinement; the t = 1 orders lie in [1.8, 2.1]; the
  // t = 10 orders of the two finer refinements in [1.0, 1.7]; mass + outflow = mass0 to 1e-12.
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const double h = 1.0 / 16.0;
  const std::vector<double> times{0.0, 1.0, 10.0};
  std::vector<double> err1, err10;
  for (const int n : {65, 129, 257, 513}) {
    const auto grid = ball_grid(n);
    const auto t0 = std::chrono::steady_clock::now();
    const auto op = rt::assemble_transfer<CompactBall>(grid, par.data(), options(h));
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto u0 = rt::initial_vector<CompactBall>(grid, par.data());
    const auto run = rt::march(op, u0, times);
    ASSERT_TRUE(run.ok()) << run.failure;
    const double secs = seconds_since(t0);
    EXPECT_EQ(run.n_steps, 160);
    EXPECT_EQ(rel_l1(grid, run.solution, 0, [](const auto& y) { return compact_u0(y[0], y[1]); }),
              0.0);
    err1.push_back(rel_l1(grid, run.solution, 1, [](const auto& y) {
      return exact_elastic(y[0], y[1], 1.0, compact_u0);
    }));
    err10.push_back(rel_l1(grid, run.solution, 2, [](const auto& y) {
      return exact_elastic(y[0], y[1], 10.0, compact_u0);
    }));
    std::printf(
        "[ transfer ball ] %4d^2: assembly %.3f s, total %.3f s, nnz %ld, rel L1 "
        "t=1 %.3e t=10 %.3e, mass change %.2e\n",
        n, op.seconds, secs, static_cast<long>(op.P.nonZeros()), err1.back(), err10.back(),
        run.budget.mass[2] - run.budget.mass0);
    // No Zeno point (e = 1): what the grid loses went through the faces, counted per column.
    EXPECT_EQ(run.budget.atom[2], 0.0);
    EXPECT_NEAR(run.budget.mass[2] + run.budget.outflow[2], run.budget.mass0,
                1e-12 * run.budget.mass0);
  }
  for (std::size_t j = 1; j < err1.size(); ++j) {
    EXPECT_LT(err1[j], err1[j - 1]);
    EXPECT_LT(err10[j], err10[j - 1]);
    const double o1 = std::log2(err1[j - 1] / err1[j]), o10 = std::log2(err10[j - 1] / err10[j]);
    std::printf("[ transfer ball ] observed order t=1 %.3f, t=10 %.3f\n", o1, o10);
    EXPECT_GE(o1, 1.8);
    EXPECT_LE(o1, 2.1);
    if (j >= 2) {
      EXPECT_GE(o10, 1.0);
      EXPECT_LE(o10, 1.7);
    }
  }
  EXPECT_LT(err1.back(), 1.5e-3);
  EXPECT_LT(err10.back(), 7e-2);
}

TEST(Transfer, RestitutionNeverCreatesMass) {
  // The run that exposed the interpolating scheme: e = 0.8, 301², step 0.2 to t = 10 (its grid
  // mass went from 2.6 to 3e14). Now, for both schemes, the grid mass never grows (to the
  // rounding of a 90601-term sum) and the budget closes at every step. At h = 0.2 the Zeno
  // cell does not drain into the atom (see ZenoMassBecomesAnAtom), so the mass that has come
  // to rest sits near (0, 0) as density; it is bracketed by closed forms independent of
  // hybgen (tests/support/ball_closed_form.hpp): every state with T_Z ≤ 10 is at (0, 0), so
  // mass(E ≤ 0.05) + atom ≥ zeno_mass(10) = 0.434; a state with E ≤ 0.05 has v = √(2E) ≤
  // √0.1 and reaches the Zeno point within p + v(1+e)/(1−e) ≤ 10v ≤ 3.17, so that mass ≤
  // zeno_mass(13.17) = 1.085. Measured: 1.0046; asserted with 5 % margin
  // for the schemes' smoothing across E = 0.05.
  const auto grid = ball_grid(301);
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  std::vector<double> times;
  for (int k = 0; k <= 50; ++k) times.push_back(0.2 * k);
  for (const auto scheme : {rt::TransferScheme::hat}) {
    SCOPED_TRACE(rt::scheme_name(scheme));
    const auto op = rt::assemble_transfer<Ball>(grid, par.data(), options(0.2, scheme));
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto run = rt::march(op, rt::initial_vector<Ball>(grid, par.data()), times);
    ASSERT_TRUE(run.ok()) << run.failure;
    double out = 0.0, atom = 0.0;
    for (std::size_t n = 0; n < run.step_outflow.size(); ++n) {
      EXPECT_LE(run.step_mass[n + 1], run.step_mass[n] * (1.0 + 1e-13)) << n;
      out += run.step_outflow[n];
      atom += run.step_atom[n];
      EXPECT_NEAR(run.step_mass[n + 1] + out + atom, run.budget.mass0, 1e-12) << n;
    }
    EXPECT_GE(*std::min_element(run.solution.u.begin(), run.solution.u.end()), 0.0);
    // Mass within E = p²/2 + x ≤ 0.05 at t = 10 (by the trapezoid weights) plus the atom.
    const auto w = rt::detail::trapezoid_weights(grid, 1);
    double low = 0.0;
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const auto y = grid.node(i);
      if (0.5 * y[1] * y[1] + y[0] <= 0.05) low += w[i] * run.solution.at(50, 0, i);
    }
    const double zm = hybgen::testing::zeno_mass(10.0, 0.8);
    std::printf(
        "[ transfer e=0.8 ] %s 301^2 h=0.2: mass %.5f -> %.5f, outflow %.5f, atom %.5f, "
        "near-Zeno density %.5f; closed-form Zeno mass %.5f\n",
        rt::scheme_name(scheme), run.budget.mass0, run.budget.mass.back(),
        run.budget.outflow.back(), run.budget.atom.back(), low, zm);
    EXPECT_LE(run.budget.mass.back(), run.budget.mass0);
    EXPECT_GE(run.budget.atom.back() + low, 0.95 * zm);
    EXPECT_LE(run.budget.atom.back() + low, 1.05 * hybgen::testing::zeno_mass(13.17, 0.8));
  }
}

TEST(Transfer, ZenoMassBecomesAnAtom) {
  // e = 0.8: samples whose forward flow reaches the Zeno point (0, 0) within the step
  // (t_Z ≤ h) are atoms. The atom must grow monotonically (atoms never return) and the
  // budget still close to 1e-12. Reference: the closed-form mass of the initial states with
  // T_Z ≤ t (0.43415 at t = 10; ≈ all of it starts inside the box).
  // The limitation at a Zeno point: every step spreads the mass of the Zeno point's own
  // cell uniformly over it again, and only its samples with T_Z ≤ h drain into the atom.
  // T_Z = p0 + v1(1+e)/(1−e) with v1 = √(p0² + 2x0) ~ √Δx in that cell, so for h below
  // ~9√(2Δx) the cell never drains and for larger h the atom lags the truth by the cell's
  // Zeno times. Asserted on 257², h = 0.5: atom(10) within [0.6, 1.0] of the closed form.
  const auto grid = ball_grid(257);
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  for (const auto scheme : {rt::TransferScheme::hat}) {
    SCOPED_TRACE(rt::scheme_name(scheme));
    const auto op = rt::assemble_transfer<Ball>(grid, par.data(), options(0.5, scheme));
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto u0 = rt::initial_vector<Ball>(grid, par.data());
    const std::vector<double> times{0.0, 2.0, 5.0, 10.0};
    const auto run = rt::march(op, u0, times);
    ASSERT_TRUE(run.ok()) << run.failure;
    double out = 0.0, atom = 0.0;
    for (std::size_t n = 0; n < run.step_atom.size(); ++n) {
      out += run.step_outflow[n];
      atom += run.step_atom[n];
      EXPECT_GE(run.step_atom[n], 0.0);
      EXPECT_NEAR(run.step_mass[n + 1] + out + atom, run.budget.mass0, 1e-12) << n;
    }
    const double zm = hybgen::testing::zeno_mass(10.0, 0.8);
    std::printf(
        "[ transfer e=0.8 ] %s 257^2 h=0.5: assembly %.3f s, atom(2, 5, 10) = %.5f %.5f "
        "%.5f, closed form at 10: %.5f, outflow(10) %.5f, mass0 %.5f\n",
        rt::scheme_name(scheme), op.seconds, run.budget.atom[1], run.budget.atom[2],
        run.budget.atom[3], zm, run.budget.outflow[3], run.budget.mass0);
    EXPECT_GT(run.budget.atom[1], 0.0);
    EXPECT_LT(run.budget.atom[1], run.budget.atom[2]);
    EXPECT_LT(run.budget.atom[2], run.budget.atom[3]);
    EXPECT_GE(run.budget.atom[3], 0.6 * zm);
    EXPECT_LE(run.budget.atom[3], zm);
  }
}

/// The ball mirrored (x ≤ 0, gravity +1, guard x = 0 increasing): its out-of-support samples
/// come AFTER its Zeno samples in C order within a thread's columns.
struct CeilingBall : Ball {
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, true}};
  /// X = (p/m, m g).
  static void flow(int, const double* x, const double* par, double* out) {
    out[0] = x[1] / par[0];
    out[1] = par[0] * par[1];
  }
  /// u0 = exp(−(x+1)² − p²) on x ≤ 0.
  static double initial_density(int, const double* x, const double*) {
    return x[0] <= 0.0 ? std::exp(-(x[0] + 1.0) * (x[0] + 1.0) - x[1] * x[1]) : 0.0;
  }
  /// x ≤ 0.
  static bool in_support(const double* x, const double*) { return x[0] <= 0.0; }
};

TEST(Transfer, SamplesOutsideTheSupportAreNeverBookedFromAnotherColumn) {
  // A review found that a sample outside the support was booked as an atom when the same
  // thread's previous column had left a Zeno result in that sample's slot: columns summed to
  // 2 (caught by check_columns, but a valid model failed, depending on the schedule). Grid
  // cells straddling x = 0 on both mirror images of the ball, e = 0.8, h = 2 (every sample
  // near the Zeno point reaches it): every column must sum to 1 and the assembly succeed.
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  for (const auto scheme : {rt::TransferScheme::hat}) {
    rt::TransferOptions o = options(2.0, scheme);
    rt::TensorGrid<2> g;
    g.axes = {rt::GridAxis{-0.03, 2.0, 204}, rt::GridAxis{-0.02, 0.02, 5}};
    const auto a = rt::assemble_transfer<Ball>(g, par.data(), o);
    EXPECT_TRUE(a.ok()) << a.failure_message;
    g.axes = {rt::GridAxis{-2.0, 0.03, 204}, rt::GridAxis{-0.02, 0.02, 5}};
    const auto b = rt::assemble_transfer<CeilingBall>(g, par.data(), o);
    EXPECT_TRUE(b.ok()) << b.failure_message;
    double atoms = 0.0;
    for (const double v : b.atom) atoms += v;
    EXPECT_GT(atoms, 0.0);  // the Zeno samples exist: the case is not vacuous
  }
}

TEST(Transfer, ABrokenColumnOrStepIsAFailureNeverAResult) {
  // The conservation checks are able to fail: an operator whose column gains 10 % is refused
  // at assembly (check_columns names the node), and a march over an operator corrupted after
  // the check stops at the first step with the step and its time.
  const auto grid = ball_grid(33);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  auto op = rt::assemble_transfer<Ball>(grid, par.data(), options(0.1));
  ASSERT_TRUE(op.ok()) << op.failure_message;
  // Find an interior node's column and scale its entries by 1.1.
  const std::size_t target = 16 * 33 + 16;  // (x, p) = (1, 0)
  for (Eigen::Index r = 0; r < op.P.rows(); ++r)
    for (rt::CsrMatrix::InnerIterator it(op.P, r); it; ++it)
      if (static_cast<std::size_t>(it.col()) == target) it.valueRef() *= 1.1;
  rt::detail::check_columns<Ball>(op);
  EXPECT_FALSE(op.ok());
  EXPECT_NEAR(op.column_defect, 0.1, 1e-12);
  EXPECT_NE(op.failure_message.find("(x = 1, p = 0)"), std::string::npos) << op.failure_message;
  EXPECT_NE(op.failure_message.find("instead of 1"), std::string::npos) << op.failure_message;
  op.failure_message.clear();  // as if the check had not run
  const auto u0 = rt::initial_vector<Ball>(grid, par.data());
  const std::vector<double> times{0.0, 0.5};
  const auto run = rt::march(op, u0, times);
  EXPECT_FALSE(run.ok());
  EXPECT_NE(run.failure.find("at step 1 (t = 0.1)"), std::string::npos) << run.failure;
  // The defect of step 1 is the 10 % gain of that column's mass, w·u0(1, 0) = Δx·Δp·1.
  const double dm = 0.1 * op.weight[target] * u0[target];
  EXPECT_NEAR(run.budget_defect, dm / run.budget.mass0, 1e-9);
}

TEST(Transfer, OutputTimesMustBeMultiplesOfTheStep) {
  const auto grid = ball_grid(9);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const auto op = rt::assemble_transfer<Ball>(grid, par.data(), options(0.05));
  const auto u0 = rt::initial_vector<Ball>(grid, par.data());
  const std::vector<double> good{0.0, 0.1, 0.5}, bad{0.0, 0.12};
  EXPECT_NO_THROW(rt::march(op, u0, good));
  EXPECT_THROW(rt::march(op, u0, bad), std::invalid_argument);
  EXPECT_THROW(rt::assemble_transfer<Ball>(grid, par.data(), options(0.0)), std::invalid_argument);
  EXPECT_THROW(
      rt::assemble_transfer<Ball>(grid, par.data(), options(0.05, rt::TransferScheme::hat, -1)),
      std::invalid_argument);
  auto g1 = grid;
  g1.axes[0].n = 1;
  EXPECT_THROW(rt::assemble_transfer<Ball>(g1, par.data(), options(0.05)), std::invalid_argument);
  EXPECT_EQ(rt::parse_scheme("hat"), rt::TransferScheme::hat);
  // Ulam's `cell` was withdrawn: the name gets the reason.
  EXPECT_THROW((void)rt::parse_scheme("cell"), std::invalid_argument);
  EXPECT_THROW(rt::parse_scheme("interpolate"), std::invalid_argument);
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
  const auto op = rt::assemble_transfer<BrokenBall>(grid, par.data(), options(0.05));
  ASSERT_FALSE(op.ok());
  // The first failing column is the first node (C order: x slowest) whose dual cell has a
  // sample with p > 1.5, i.e. at x = 0; its sample starts there.
  EXPECT_GT(op.failure.status.state[1], 1.5);
  EXPECT_EQ(op.failure.status.error, rt::TraceError::non_finite_flow);
  EXPECT_NE(op.failure_message.find("forward trajectory from"), std::string::npos)
      << op.failure_message;
  EXPECT_NE(op.failure_message.find("flight"), std::string::npos) << op.failure_message;
}

}  // namespace
