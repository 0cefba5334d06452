// Tests of hybgen/rt/methods/almost_invariant.hpp on Markov chains whose sets and invariance
// ratios are known exactly: two weakly coupled blocks, two blocks with no coupling (the
// eigenvalue 1 repeated), a rotation on a ring (P has no real second eigenvalue; its
// reversibilisation does), and a ring with two bottlenecks, large enough for the sparse
// eigen-solver. SEBA itself on a rotated basis of indicators.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "hybgen/rt/methods/almost_invariant.hpp"

namespace {

namespace rt = hybgen::rt;
using Csr = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

/// P (rows: destinations) from the column-stochastic entries P(j, c).
Csr matrix(std::size_t n, const std::vector<Eigen::Triplet<double>>& entries) {
  Csr P(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  P.setFromTriplets(entries.begin(), entries.end());
  P.makeCompressed();
  return P;
}

/// Two blocks of three states; from each state a fraction 1 − eps is spread evenly over its own
/// block, eps over the other. P is doubly stochastic, so μ is uniform, and the ratio of a block
/// is exactly 1 − eps; R = P here (Pᵀ = P), with λ₂ = 1 − 2 eps.
Csr two_blocks(double eps) {
  std::vector<Eigen::Triplet<double>> t;
  for (int c = 0; c < 6; ++c)
    for (int j = 0; j < 6; ++j) t.emplace_back(j, c, ((j < 3) == (c < 3) ? 1.0 - eps : eps) / 3.0);
  return matrix(6, t);
}

TEST(AlmostInvariant, TwoWeaklyCoupledBlocksAreTheSetsWithRatioOneMinusTheLeak) {
  const double eps = 0.05;
  const std::vector<double> mu(6, 1.0 / 6.0);
  const rt::AlmostInvariantSets a = rt::almost_invariant_sets(two_blocks(eps), mu, 2, 1);
  ASSERT_EQ(a.sets.size(), 2u);
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(a.label[i], 0) << i;
    EXPECT_EQ(a.label[i] == a.label[0], i < 3) << i;
  }
  for (const rt::AlmostInvariantSet& s : a.sets) {
    EXPECT_NEAR(s.mass, 0.5, 1e-14);
    EXPECT_NEAR(s.ratio, 1.0 - eps, 1e-14);
    EXPECT_EQ(s.nodes, 3u);
  }
  ASSERT_EQ(a.eigenvalues.size(), 2u);
  EXPECT_NEAR(a.eigenvalues[0], 1.0, 1e-12);
  EXPECT_NEAR(a.eigenvalues[1], 1.0 - 2.0 * eps, 1e-12);
  // Ky Fan: Σρ ≤ λ₁ + λ₂ = 2 − 2 eps, with equality for these sets.
  EXPECT_NEAR(a.sets[0].ratio + a.sets[1].ratio, a.bound, 1e-12);
  EXPECT_EQ(a.components, 1u);
  EXPECT_NEAR(a.unassigned, 0.0, 1e-15);
}

TEST(AlmostInvariant, DisjointInvariantBlocksAreFoundThoughTheEigenvalueOneRepeats) {
  // No coupling: λ = 1 twice. A Krylov solver from one start vector sees one vector of that
  // eigenspace; the components are solved apart, so both blocks come out, each with ratio 1.
  // Unequal masses (the left block 0.7) order the sets: set 1 is the heavier.
  const Csr P = two_blocks(0.0);
  const std::vector<double> mu{0.7 / 3, 0.7 / 3, 0.7 / 3, 0.1, 0.1, 0.1};
  const rt::AlmostInvariantSets a = rt::almost_invariant_sets(P, mu, 2, 1);
  EXPECT_EQ(a.components, 2u);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(a.label[i], i < 3 ? 1 : 2) << i;
  EXPECT_NEAR(a.sets[0].mass, 0.7, 1e-14);
  EXPECT_NEAR(a.sets[1].mass, 0.3, 1e-14);
  EXPECT_DOUBLE_EQ(a.sets[0].ratio, 1.0);
  EXPECT_DOUBLE_EQ(a.sets[1].ratio, 1.0);
  EXPECT_NEAR(a.bound, 2.0, 1e-12);
}

TEST(AlmostInvariant, ARotationOnARingSplitsIntoTwoArcsThatEachLoseOneNodePerStep) {
  // P moves node c to c + 1 (mod n): its eigenvalues are the n-th roots of unity, the second
  // real one is −1, and no eigenvector of P has sign structure. R = (shift + shiftᵀ)/2 is the
  // symmetric walk, whose second eigenfunctions are cos and sin: any half-ring arc. An arc of
  // L nodes keeps L − 1 of them one step later: ratio (L − 1)/L = 1 − 2/n for L = n/2.
  const std::size_t n = 40;
  std::vector<Eigen::Triplet<double>> t;
  for (std::size_t c = 0; c < n; ++c)
    t.emplace_back(static_cast<int>((c + 1) % n), static_cast<int>(c), 1.0);
  const std::vector<double> mu(n, 1.0 / static_cast<double>(n));
  const rt::AlmostInvariantSets a = rt::almost_invariant_sets(matrix(n, t), mu, 2, 1);
  // Each set an arc: its labels change exactly twice around the ring.
  int changes = 0;
  for (std::size_t i = 0; i < n; ++i) changes += a.label[i] != a.label[(i + 1) % n] ? 1 : 0;
  EXPECT_EQ(changes, 2);
  for (const rt::AlmostInvariantSet& s : a.sets) {
    const double L = static_cast<double>(s.nodes);
    EXPECT_NEAR(s.ratio, (L - 1.0) / L, 1e-14);
    EXPECT_NEAR(L, n / 2.0, 2.0);
  }
  EXPECT_NEAR(a.unassigned, 0.0, 1e-15);
  // R's λ₂ = cos(2π/n), and the ratios sum below the bound 1 + cos(2π/n).
  EXPECT_NEAR(a.eigenvalues[1], std::cos(2.0 * M_PI / n), 1e-10);
  EXPECT_LE(a.sets[0].ratio + a.sets[1].ratio, a.bound + 1e-12);
}

TEST(AlmostInvariant, ALargeRingWithTwoBottlenecksUsesTheSparseSolver) {
  // A lazy walk on a ring of 1000 nodes (stay 1/2, step either way 1/4), except across the
  // edges 499|500 and 999|0, where a step crosses with probability q = 0.001 instead of 1/4
  // (the rest stays). P is symmetric, μ uniform; the halves are the sets, and each sends q·μ
  // out through each of its two ends per step: ratio 1 − 2qμ/(1/2) = 1 − 4q/1000.
  const std::size_t n = 1000;
  const double q = 0.001;
  std::vector<Eigen::Triplet<double>> t;
  for (std::size_t c = 0; c < n; ++c) {
    const std::size_t right = (c + 1) % n, left = (c + n - 1) % n;
    const bool cut_right = c == 499 || c == 999, cut_left = c == 500 || c == 0;
    const double pr = cut_right ? q : 0.25, pl = cut_left ? q : 0.25;
    t.emplace_back(static_cast<int>(right), static_cast<int>(c), pr);
    t.emplace_back(static_cast<int>(left), static_cast<int>(c), pl);
    t.emplace_back(static_cast<int>(c), static_cast<int>(c), 1.0 - pr - pl);
  }
  const std::vector<double> mu(n, 1.0 / static_cast<double>(n));
  const rt::AlmostInvariantSets a = rt::almost_invariant_sets(matrix(n, t), mu, 2, 1);
  EXPECT_TRUE(a.converged);
  EXPECT_EQ(a.components, 1u);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_GT(a.label[i], 0) << i;
    EXPECT_EQ(a.label[i] == a.label[0], i < 500) << i;
  }
  for (const rt::AlmostInvariantSet& s : a.sets) {
    EXPECT_NEAR(s.mass, 0.5, 1e-12);
    EXPECT_NEAR(s.ratio, 1.0 - 4.0 * q / 1000.0, 1e-12);
  }
  EXPECT_LE(a.sets[0].ratio + a.sets[1].ratio, a.bound + 1e-12);
}

TEST(AlmostInvariant, SebaRecoversIndicatorsFromARotatedBasis) {
  // Three disjoint indicators (normalised), mixed by a rotation: SEBA returns them, each
  // scaled to maximum 1, up to order.
  const Eigen::Index p = 30;
  Eigen::MatrixXd ind = Eigen::MatrixXd::Zero(p, 3);
  for (Eigen::Index i = 0; i < p; ++i) ind(i, i < 8 ? 0 : i < 20 ? 1 : 2) = 1.0;
  for (Eigen::Index j = 0; j < 3; ++j) ind.col(j).normalize();
  const double a = 0.7, b = 0.4;
  Eigen::Matrix3d Ra, Rb;
  Ra << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  Rb << 1, 0, 0, 0, std::cos(b), -std::sin(b), 0, std::sin(b), std::cos(b);
  const Eigen::MatrixXd S = rt::detail::seba(ind * (Ra * Rb)).sparse;
  for (Eigen::Index j = 0; j < 3; ++j) {
    // Column j is one indicator: 1 on its block, 0 elsewhere (to rounding).
    Eigen::Index top = 0;
    S.col(j).maxCoeff(&top);
    const int block = top < 8 ? 0 : top < 20 ? 1 : 2;
    for (Eigen::Index i = 0; i < p; ++i) {
      const int bi = i < 8 ? 0 : i < 20 ? 1 : 2;
      EXPECT_NEAR(S(i, j), bi == block ? 1.0 : 0.0, 1e-9) << i << " " << j;
    }
  }
}

TEST(AlmostInvariant, TooFewNodesForTheSetsIsAClearError) {
  const std::vector<double> mu{1.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  EXPECT_THROW((void)rt::almost_invariant_sets(two_blocks(0.1), mu, 2, 1), std::invalid_argument);
  EXPECT_THROW(
      (void)rt::almost_invariant_sets(two_blocks(0.1), std::vector<double>(6, 1.0 / 6), 1, 1),
      std::invalid_argument);
}

}  // namespace
