// Reference check of the shipped models/aff1.model, the paper's counterexample, which hybgen
// REJECTS (`hybgen check` exits 1 naming the hypothesis 'normal' and the bracket
// [E_b, E_a] = −E_b: tests/e2e/test_lie_models.cpp), so that it has no kernel in generated/.
// What is checked here, from the model file's group data and without hybgen, is that the
// rejection is right.
//
// The model: Aff(1) = {g(a, b) = [[a, b], [0, 1]]}, identity at (1, 0), impact surface b = 0,
// i.e. the subgroup K = {[[a, 0], [0, 1]]} itself (q = b).
//  * Lie algebra. E_a = ∂g/∂a = e₁₁, E_b = ∂g/∂b = e₁₂ (central differences of the model's g);
//    [E_b, E_a] = e₁₂e₁₁ − e₁₁e₁₂ = −e₁₂ = −E_b. So k = span(E_a), the algebra of K, is not an
//    ideal ([E_b, E_a] ∉ k), and K is not normal.
//  * The group itself: K is a closed subgroup of codimension 1 (products and inverses of
//    [[a, 0], [0, 1]] keep b = 0), but g K g⁻¹ ≠ K: for g = g(1, 1), k = g(2, 0),
//    g k g⁻¹ = g(2, −1). And b is no homomorphism: b(g1 g2) = a1 b2 + b1 ≠ b1 + b2. The
//    Impact Lie–Poisson Reduction theorem needs the surface to be a coset of a NORMAL subgroup
//    (the hypothesis 'normal'); without it the reset would not descend to g* × K\G.

#include <gtest/gtest.h>

#include <array>
#include <cmath>

namespace {

/// A 2 × 2 matrix.
using Mat2 = std::array<std::array<double, 2>, 2>;

/// g(a, b) exactly as the model file writes it.
Mat2 group(double a, double b) {
  return {{{a, b}, {0.0, 1.0}}};
}

/// The matrix product.
Mat2 product(const Mat2& x, const Mat2& y) {
  Mat2 z{};
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < 2; ++j)
      for (std::size_t k = 0; k < 2; ++k) z[i][j] += x[i][k] * y[k][j];
  return z;
}

/// The inverse of g(a, b): g(1/a, −b/a).
Mat2 inverse(const Mat2& g) {
  return group(1.0 / g[0][0], -g[0][1] / g[0][0]);
}

TEST(ShippedAff1, TheSubgroupOfTheImpactSurfaceIsNotNormal) {
  // E_a, E_b by central differences at the identity (1, 0).
  const double h = 1e-6;
  Mat2 ea{}, eb{};
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < 2; ++j) {
      ea[i][j] = (group(1.0 + h, 0.0)[i][j] - group(1.0 - h, 0.0)[i][j]) / (2.0 * h);
      eb[i][j] = (group(1.0, h)[i][j] - group(1.0, -h)[i][j]) / (2.0 * h);
    }
  const Mat2 ba = product(eb, ea), ab = product(ea, eb);
  Mat2 bracket{};  // [E_b, E_a]
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t j = 0; j < 2; ++j) bracket[i][j] = ba[i][j] - ab[i][j];
  // [E_b, E_a] = −E_b: its E_b coordinate (entry (1, 2)) is −1, it has no E_a part, so it is
  // not in k = span(E_a).
  EXPECT_NEAR(bracket[0][1], -1.0, 1e-9);
  EXPECT_NEAR(bracket[0][0], 0.0, 1e-9);
  EXPECT_NEAR(bracket[1][0], 0.0, 1e-9);
  EXPECT_NEAR(bracket[1][1], 0.0, 1e-9);

  // K = {b = 0} is a subgroup (closed under products and inverses)...
  const Mat2 k1 = group(2.0, 0.0), k2 = group(0.5, 0.0);
  EXPECT_EQ(product(k1, k2)[0][1], 0.0);
  EXPECT_EQ(inverse(k1)[0][1], 0.0);
  // ...but not normal: g k g⁻¹ = g(2, −1) leaves it.
  const Mat2 g = group(1.0, 1.0), c = product(product(g, k1), inverse(g));
  EXPECT_DOUBLE_EQ(c[0][0], 2.0);
  EXPECT_DOUBLE_EQ(c[0][1], -1.0);
  // b is no homomorphism: b(g1 g2) = a1 b2 + b1.
  const Mat2 g1 = group(3.0, 0.5), g2 = group(1.5, 2.0);
  EXPECT_DOUBLE_EQ(product(g1, g2)[0][1], 3.0 * 2.0 + 0.5);
  EXPECT_NE(product(g1, g2)[0][1], 0.5 + 2.0);
}

}  // namespace
