// Tests of hybgen/rt/methods/coherent.hpp on transports whose coherent pairs and ratios are
// known exactly: two weakly coupled blocks over several steps (the pairs are the blocks, the
// bound attained), the same with unequal initial masses (forward and backward ratios differ),
// a ring with two bottlenecks that is also turned by 7 nodes (the pairs move: B is A turned),
// and two blocks that never exchange mass (σ = 1 repeated). Every expected value is summed
// here from the transport's entries, independently of the code under test.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "hybgen/rt/methods/coherent.hpp"

namespace {

namespace rt = hybgen::rt;
using Csr = rt::CsrMatrix;
using Dense = Eigen::MatrixXd;

/// The CSR matrix of a dense one (rows: destinations).
Csr sparse(const Dense& D) {
  Csr F = D.sparseView();
  F.makeCompressed();
  return F;
}

/// Two blocks of three nodes; from each node 1 − eps of its mass spreads evenly over its own
/// block and eps over the other (one step).
Dense two_blocks(double eps) {
  Dense P(6, 6);
  for (int j = 0; j < 6; ++j)
    for (int c = 0; c < 6; ++c) P(j, c) = ((j < 3) == (c < 3) ? 1.0 - eps : eps) / 3.0;
  return P;
}

/// Σ_{i∈A} Σ_{j∈B} F_ji p_i for the labels given (the carried mass, summed here).
double carried(const Dense& F, const std::vector<double>& p, const std::vector<std::int32_t>& a,
               std::int32_t la, const std::vector<std::int32_t>& b, std::int32_t lb) {
  double t = 0.0;
  for (int j = 0; j < F.rows(); ++j)
    for (int i = 0; i < F.cols(); ++i)
      if (a[static_cast<std::size_t>(i)] == la && b[static_cast<std::size_t>(j)] == lb)
        t += F(j, i) * p[static_cast<std::size_t>(i)];
  return t;
}

TEST(Coherent, TwoWeaklyCoupledBlocksOverThreeStepsAreThePairsAndAttainTheBound) {
  // Three steps of the blocks: a block keeps (1 + (1 − 2 eps)³)/2 of its mass (the difference
  // of the two block masses decays by 1 − 2 eps a step). F is doubly stochastic and symmetric
  // with p uniform, so L = F, σ₂ = (1 − 2 eps)³, and the block indicators are its singular
  // vectors: the sum √(fwd·bwd) over the pairs equals the bound 1 + σ₂.
  const double eps = 0.05, keep = (1.0 + std::pow(1.0 - 2.0 * eps, 3)) / 2.0;
  const Dense F = two_blocks(eps) * two_blocks(eps) * two_blocks(eps);
  const std::vector<double> p(6, 1.0 / 6.0);
  const rt::CoherentSets c = rt::coherent_sets(sparse(F), p, 2, 1);
  ASSERT_EQ(c.sets.size(), 2u);
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(c.initial_label[i], c.initial_label[i < 3 ? 0 : 3]) << i;
    EXPECT_EQ(c.final_label[i], c.initial_label[i]) << i;
  }
  EXPECT_NE(c.initial_label[0], c.initial_label[3]);
  for (const rt::CoherentPair& a : c.sets) {
    EXPECT_NEAR(a.initial_mass, 0.5, 1e-12);
    EXPECT_NEAR(a.final_mass, 0.5, 1e-12);
    EXPECT_NEAR(a.forward, keep, 1e-12);
    EXPECT_NEAR(a.backward, keep, 1e-12);
  }
  ASSERT_EQ(c.singular_values.size(), 2u);
  EXPECT_NEAR(c.singular_values[0], 1.0, 1e-10);
  EXPECT_NEAR(c.singular_values[1], std::pow(1.0 - 2.0 * eps, 3), 1e-10);
  EXPECT_NEAR(c.coherence_sum, c.bound, 1e-10);
}

TEST(Coherent, UnequalInitialMassesMakeTheForwardAndBackwardRatiosDiffer) {
  // One step of the blocks from masses 0.7 and 0.3: block 1 keeps 1 − eps of its mass
  // (forward), and of block 1's final mass 0.7(1 − eps) + 0.3 eps the share 0.7(1 − eps) came
  // from it (backward).
  const double eps = 0.05;
  const Dense F = two_blocks(eps);
  std::vector<double> p(6);
  for (int i = 0; i < 6; ++i) p[static_cast<std::size_t>(i)] = (i < 3 ? 0.7 : 0.3) / 3.0;
  const rt::CoherentSets c = rt::coherent_sets(sparse(F), p, 2, 1);
  ASSERT_EQ(c.sets.size(), 2u);
  // Ranked by initial mass: pair 1 is block 1.
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(c.initial_label[i], i < 3 ? 1 : 2) << i;
    EXPECT_EQ(c.final_label[i], i < 3 ? 1 : 2) << i;
  }
  const rt::CoherentPair& a = c.sets[0];
  EXPECT_NEAR(a.initial_mass, 0.7, 1e-12);
  EXPECT_NEAR(a.final_mass, 0.7 * (1.0 - eps) + 0.3 * eps, 1e-12);
  EXPECT_NEAR(a.forward, 1.0 - eps, 1e-12);
  EXPECT_NEAR(a.backward, 0.7 * (1.0 - eps) / (0.7 * (1.0 - eps) + 0.3 * eps), 1e-12);
  const rt::CoherentPair& b = c.sets[1];
  EXPECT_NEAR(b.forward, 1.0 - eps, 1e-12);
  EXPECT_NEAR(b.backward, 0.3 * (1.0 - eps) / (0.3 * (1.0 - eps) + 0.7 * eps), 1e-12);
  EXPECT_LE(c.coherence_sum, c.bound + 1e-12);
}

TEST(Coherent, ATurnedRingWithTwoBottlenecksCarriesEachArcIntoTheTurnedArc) {
  // 60 nodes on a ring; a node sends d of its mass to each neighbour, but only b across the
  // bottlenecks between nodes 29 | 30 and 59 | 0; then the ring turns by 7 nodes. The pairs
  // are the arcs 0…29 and 30…59 at the initial time and the same arcs turned by 7 at the final
  // one; the turn carries an arc onto the turned arc exactly, so each ratio is what stays on
  // its side of the bottlenecks, summed here from F.
  const int n = 60, turn = 7;
  const double d = 0.2, b = 0.002;
  Dense D = Dense::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    const int right = (i + 1) % n, left = (i + n - 1) % n;
    const double to_right = (i == 29 || i == 59) ? b : d;
    const double to_left = (i == 30 || i == 0) ? b : d;
    D(right, i) += to_right, D(left, i) += to_left, D(i, i) += 1.0 - to_right - to_left;
  }
  Dense S = Dense::Zero(n, n);
  for (int i = 0; i < n; ++i) S((i + turn) % n, i) = 1.0;
  const Dense F = S * D;
  const std::vector<double> p(static_cast<std::size_t>(n), 1.0 / n);
  const rt::CoherentSets c = rt::coherent_sets(sparse(F), p, 2, 1);
  ASSERT_EQ(c.sets.size(), 2u);
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(c.initial_label[static_cast<std::size_t>(i)], c.initial_label[i < 30 ? 0 : 30]) << i;
    EXPECT_EQ(c.final_label[static_cast<std::size_t>((i + turn) % n)],
              c.initial_label[static_cast<std::size_t>(i)])
        << i;
  }
  EXPECT_NE(c.initial_label[0], c.initial_label[30]);
  for (std::int32_t k = 1; k <= 2; ++k) {
    const rt::CoherentPair& a = c.sets[static_cast<std::size_t>(k - 1)];
    const double t = carried(F, p, c.initial_label, k, c.final_label, k);
    EXPECT_NEAR(a.carried, t, 1e-14);
    // Each end node of the arc sends b across: 2b/n of the arc's 30/n leaves.
    EXPECT_NEAR(a.forward, 1.0 - 2.0 * b / 30.0, 1e-12);
    EXPECT_NEAR(a.backward, 1.0 - 2.0 * b / 30.0, 1e-12);
  }
  EXPECT_LE(c.coherence_sum, c.bound + 1e-12);
}

TEST(Coherent, BlocksThatNeverExchangeMassAreExactlyCoherentPairs) {
  // eps = 0: two pieces, σ = 1 twice; each solved on its own.
  const Dense F = two_blocks(0.0) * two_blocks(0.0);
  std::vector<double> p(6);
  for (int i = 0; i < 6; ++i) p[static_cast<std::size_t>(i)] = (i < 3 ? 0.6 : 0.4) / 3.0;
  const rt::CoherentSets c = rt::coherent_sets(sparse(F), p, 2, 1);
  EXPECT_EQ(c.components, 2u);
  ASSERT_EQ(c.sets.size(), 2u);
  for (const rt::CoherentPair& a : c.sets) {
    EXPECT_NEAR(a.forward, 1.0, 1e-13);
    EXPECT_NEAR(a.backward, 1.0, 1e-13);
  }
  EXPECT_NEAR(c.sets[0].initial_mass, 0.6, 1e-13);
  EXPECT_NEAR(c.bound, 2.0, 1e-10);
}

TEST(Coherent, TooFewSetsOrTooSmallASupportIsRefused) {
  const Dense F = two_blocks(0.1);
  const std::vector<double> p(6, 1.0 / 6.0);
  EXPECT_THROW((void)rt::coherent_sets(sparse(F), p, 1, 1), std::invalid_argument);
  EXPECT_THROW((void)rt::coherent_sets(sparse(F), std::vector<double>(5, 0.2), 2, 1),
               std::invalid_argument);
  // Mass on two nodes only: too few for two sets (each needs a node, and one more).
  std::vector<double> point(6, 0.0);
  point[0] = 0.5, point[1] = 0.5;
  EXPECT_THROW((void)rt::coherent_sets(sparse(Dense::Identity(6, 6)), point, 2, 1),
               std::invalid_argument);
}

}  // namespace
