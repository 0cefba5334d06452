// Validation of the shipped models/heisenberg_algebra.model: the particle between two walls of
// models/heisenberg.model with the Heisenberg group given by the structure constants of its
// Lie algebra, [E_x, E_y] = E_z (the others 0), and the reduced coordinate by the differential
// dφ_e = (1, 0, 0) of the homomorphism φ: H3 → ℝ it is a value of. References written here,
// as in test_shipped_heisenberg.cpp (which derives the same reduced system from the matrices
// and checks it in more depth); on the reference side only the Gauss–Legendre nodes come from
// hybgen.
//
// Hand derivation, from the model file's data alone. ξ = ∂h/∂ζ = ζ for h = ½|ζ|², and
//   ζ' = ad*_ξ ζ,  (ad*_ξ ζ)_k = Σ_j ξ_j ⟨ζ, [E_j, E_k]⟩   (the sign checked on so(3) by
// test_shipped_so3_rigid_body.cpp): ζx' = −ζy ζz, ζy' = ζx ζz, ζz' = 0; q' = ⟨dφ_e, ξ⟩ = ζx
// (q = φ(g) and φ is a homomorphism, so q' = dφ_e(g⁻¹ġ)). div X = 0. The walls q = ±1 are
// cosets of K = ker φ (normal: k = ker dφ_e = span(E_y, E_z) ⊇ [h3, h3] = span(E_z)); the
// impulse lies in Ann(k) = span(dφ_e) and the restitution law ⟨dφ_e, ξ⁺⟩ = −e⟨dφ_e, ξ⟩ gives
// Δ(ζ, q) = (−eζx, ζy, ζz, q); J = e² (the flux argument of test_shipped_heisenberg.cpp).
// u0 = exp(−2(ζx − ½)² − 2ζy² − 2(ζz − ½)² − 4q²) on |q| ≤ 1.
//
// Compared:
//  * the generated kernel against the hand formulas (200 random states, J at 200 points of
//    each wall, e = 1 and 0.7, relative 1e-12), and against the kernel of heisenberg.model;
//  * weak form, e = 1, t = 1, 2, over the cylinder Z = {ζx² + ζy² ≤ 3², |q| ≤ 1} with the
//    fibred rule of test_shipped_heisenberg.cpp (3 × 3 Gauss nodes in the invariants ρ, ζz;
//    96 angles × 48 nodes in q): measured 3.2e-4 relative to mass·rms φ, asserted < 1e-3;
//  * pointwise, e = 0.7 (J = 0.49), t = 1, 2: u at 2000 random states against an independent
//    backward tracer (RK4, step 1e-3); measured 2.2e-10, asserted 1e-6.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "heisenberg/heisenberg.hpp"
#include "heisenberg_algebra/heisenberg_algebra.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "support/validation_harness.hpp"

namespace {

namespace rt = hybgen::rt;
// From support/validation_harness.hpp.
using hybgen::testing::validation::close;
using hybgen::testing::validation::HandGuard;
/// The generated kernels under test (generated/).
using M = hybgen_model::heisenberg_algebra;
/// The state dimension.
constexpr std::size_t N = 4;
/// A state.
using State = std::array<double, N>;  // (ζx, ζy, ζz, q)

/// h3 as the model file gives it: C[i][j] = coordinates of [E_i, E_j] in (E_x, E_y, E_z);
/// [E_x, E_y] = E_z, antisymmetry, the others 0.
struct Algebra {
  std::array<std::array<std::array<double, 3>, 3>, 3> C{};  ///< structure constants
  Algebra() {
    C[0][1] = {0.0, 0.0, 1.0};
    C[1][0] = {0.0, 0.0, -1.0};
  }
};

#include "shipped_heisenberg_hand.inc"

TEST(ShippedHeisenbergAlgebra, SameKernelAsTheMatrixGroupModel) {
  using H = hybgen_model::heisenberg;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  const double par[1] = {0.7};
  for (int n = 0; n < 100; ++n) {
    const State x{u(rng), u(rng), u(rng), u(rng)};
    State a{}, b{};
    M::flow(0, x.data(), par, a.data());
    H::flow(0, x.data(), par, b.data());
    for (std::size_t k = 0; k < N; ++k) EXPECT_EQ(a[k], b[k]);
    for (int g = 0; g < 2; ++g) {
      M::reset(g, x.data(), par, a.data());
      H::reset(g, x.data(), par, b.data());
      for (std::size_t k = 0; k < N; ++k) EXPECT_EQ(a[k], b[k]);
      EXPECT_EQ(M::hybrid_jacobian(g, x.data(), par), H::hybrid_jacobian(g, x.data(), par));
    }
  }
}

TEST(ShippedHeisenbergAlgebra, KernelMatchesTheHandDerivation) {
  Hand hand;
  EXPECT_EQ(M::param_defaults[0], hand.e);
  expect_kernel_matches(hand);
  hand.e = 0.7;  // the restitution of the second weak-form check
  expect_kernel_matches(hand);
}

TEST(ShippedHeisenbergAlgebra, ElasticWallsInWeakForm) {
  double share = 0.0;
  EXPECT_LT(weak_form_difference(1.0, {1.0, 2.0}, {2.5, 1, 3, 96, -0.5, 1.5, 3, 12}, share), 1e-3);
  EXPECT_GT(share, 0.4);
}

TEST(ShippedHeisenbergAlgebra, InelasticWallsPointwise) {
  expect_inelastic_walls_pointwise();
}

}  // namespace
