// Reference check of the shipped models/so3_rigid_body.model, which hybgen REJECTS (`hybgen
// check` exits 1 naming the hypothesis 'codim1': tests/e2e/test_lie_models.cpp), so that it has
// no kernel in generated/. What is checked here, from the model file's group data and without
// hybgen, is that the rejection is right, and the sign convention of the reduced equations that
// hybgen uses for the models it accepts (test_shipped_heisenberg.cpp derives them the same way).
//
// The model: R(ψ, θ, φ) = Rz(ψ) Ry(θ) Rx(φ) (yaw, pitch, roll), the identity at 0; inertia
// diag(I1, I2, I3) = diag(1, 2, 3); walls at ψ = 1 (q = ψ).
//  * Lie algebra. E_c = ∂R/∂c at 0 (central differences of the model's R, step 1e-5: exact to
//    ~1e-10 for these entire functions): E_ψ = L_z, E_θ = L_y, E_φ = L_x with L_a the
//    infinitesimal rotations about the axes, [L_x, L_y] = L_z cyclically. The three brackets
//    [E_ψ, E_θ], [E_θ, E_φ], [E_φ, E_ψ] are linearly independent (their coordinates have a
//    determinant ±1): [g, g] = g, so(3) is perfect. An ideal of codimension 1 would contain
//    [g, g] (g/ideal is 1-D, hence abelian), so there is none, and SO(3) (connected) has no
//    closed normal subgroup of codimension 1: no impact surface is a coset of one. This is the
//    hypothesis 'codim1' of the Impact Lie–Poisson Reduction theorem.
//  * The yaw is no homomorphism: ψ(R1 R2) ≠ ψ(R1) + ψ(R2), and K = {ψ = 0} is not closed under
//    products, so the wall {ψ = 1} is not a coset of a subgroup either.
//  * Sign of the reduced equations. For a left-invariant kinetic energy the body momentum
//    obeys ζ' = ad*_ξ ζ, (ad*_ξ ζ)_k = Σ_j ξ_j ⟨ζ, [E_j, E_k]⟩, ξ = I⁻¹ζ (the formula behind
//    test_shipped_heisenberg.cpp). On so(3) with the brackets computed from the matrices, in
//    the basis (L_x, L_y, L_z) = (E_φ, E_θ, E_ψ), it must give Euler's Π' = Π × Ω, Ω = I⁻¹Π;
//    checked at random Π to 1e-9 (the finite-difference brackets), and the opposite sign (the
//    right-invariant, spatial form) is refused. Euler's equations are also checked to keep
//    |Π|² and the energy ½ Π·Ω.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

namespace {

/// A 3 × 3 matrix.
using Mat3 = std::array<std::array<double, 3>, 3>;
/// A vector of ℝ³.
using Vec3 = std::array<double, 3>;

/// R(ψ, θ, φ) exactly as the model file writes it.
Mat3 rotation(double psi, double theta, double phi) {
  const double cp = std::cos(psi), sp = std::sin(psi), ct = std::cos(theta), st = std::sin(theta),
               cf = std::cos(phi), sf = std::sin(phi);
  return {{{cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf},
           {sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf},
           {-st, ct * sf, ct * cf}}};
}

/// The matrix product.
Mat3 product(const Mat3& a, const Mat3& b) {
  Mat3 c{};
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j)
      for (std::size_t k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

/// [a, b] = ab − ba.
Mat3 commutator(const Mat3& a, const Mat3& b) {
  const Mat3 ab = product(a, b), ba = product(b, a);
  Mat3 c{};
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j) c[i][j] = ab[i][j] - ba[i][j];
  return c;
}

/// The yaw of a rotation matrix (R = Rz(ψ) Ry(θ) Rx(φ), |θ| < π/2).
double yaw(const Mat3& r) {
  return std::atan2(r[1][0], r[0][0]);
}

/// E_c = ∂R/∂c at 0 for c = ψ, θ, φ (index 0, 1, 2), by central differences.
std::array<Mat3, 3> generators() {
  const double h = 1e-5;
  std::array<Mat3, 3> e{};
  for (std::size_t c = 0; c < 3; ++c) {
    std::array<double, 3> p{}, m{};
    p[c] = h;
    m[c] = -h;
    const Mat3 rp = rotation(p[0], p[1], p[2]), rm = rotation(m[0], m[1], m[2]);
    for (std::size_t i = 0; i < 3; ++i)
      for (std::size_t j = 0; j < 3; ++j) e[c][i][j] = (rp[i][j] - rm[i][j]) / (2.0 * h);
  }
  return e;
}

/// Coordinates of an antisymmetric matrix in the basis (L_x, L_y, L_z): A = Σ a_k L_k with
/// (L_k)_{ij} = −ε_{kij}, i.e. A v = a × v.
Vec3 axial(const Mat3& a) {
  return {a[2][1], a[0][2], a[1][0]};
}

/// The cross product.
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

/// det(a, b, c) = a · (b × c).
double det(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 bc = cross(b, c);
  return a[0] * bc[0] + a[1] * bc[1] + a[2] * bc[2];
}

TEST(ShippedSo3RigidBody,
     TheAlgebraIsPerfectSoNoImpactSurfaceIsACosetOfACodimensionOneNormalSubgroup) {
  const auto e = generators();
  // E_ψ = L_z, E_θ = L_y, E_φ = L_x.
  const std::array<Vec3, 3> want{Vec3{0, 0, 1}, Vec3{0, 1, 0}, Vec3{1, 0, 0}};
  for (std::size_t c = 0; c < 3; ++c) {
    const Vec3 a = axial(e[c]);
    for (std::size_t k = 0; k < 3; ++k) EXPECT_NEAR(a[k], want[c][k], 1e-9) << c << k;
    for (std::size_t i = 0; i < 3; ++i)  // antisymmetric: so(3)
      for (std::size_t j = 0; j < 3; ++j) EXPECT_NEAR(e[c][i][j], -e[c][j][i], 1e-9);
  }
  const Vec3 b01 = axial(commutator(e[0], e[1])), b12 = axial(commutator(e[1], e[2])),
             b20 = axial(commutator(e[2], e[0]));
  // [g, g] is spanned by the three brackets: it is all of g.
  EXPECT_NEAR(std::fabs(det(b01, b12, b20)), 1.0, 1e-8);
  // [L_x, L_y] = L_z: [E_φ, E_θ] = E_ψ.
  const Vec3 b21 = axial(commutator(e[2], e[1]));
  for (std::size_t k = 0; k < 3; ++k) EXPECT_NEAR(b21[k], want[0][k], 1e-9);
}

TEST(ShippedSo3RigidBody, TheYawIsNoHomomorphism) {
  const Mat3 r1 = rotation(0.3, 0.4, 0.5), r2 = rotation(0.2, -0.3, 0.6);
  EXPECT_NEAR(yaw(r1), 0.3, 1e-14);
  EXPECT_GT(std::fabs(yaw(product(r1, r2)) - (yaw(r1) + yaw(r2))), 0.05);
  // K = {ψ = 0} is not a subgroup: a product of two of its elements has ψ ≠ 0.
  const Mat3 k1 = rotation(0.0, 0.4, 0.5), k2 = rotation(0.0, -0.3, 0.6);
  EXPECT_GT(std::fabs(yaw(product(k1, k2))), 0.05);
}

TEST(ShippedSo3RigidBody, LiePoissonSignGivesEulersEquations) {
  const auto e = generators();
  // Basis (L_x, L_y, L_z) = (E_φ, E_θ, E_ψ); C[j][k] = coordinates of [L_j, L_k].
  const std::array<Mat3, 3> basis{e[2], e[1], e[0]};
  std::array<std::array<Vec3, 3>, 3> c{};
  for (std::size_t j = 0; j < 3; ++j)
    for (std::size_t k = 0; k < 3; ++k) c[j][k] = axial(commutator(basis[j], basis[k]));
  const Vec3 inertia{1.0, 2.0, 3.0};
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  for (int n = 0; n < 100; ++n) {
    const Vec3 pi{u(rng), u(rng), u(rng)};
    const Vec3 omega{pi[0] / inertia[0], pi[1] / inertia[1], pi[2] / inertia[2]};
    Vec3 body{};  // (ad*_Ω Π)_k = Σ_j Ω_j ⟨Π, [L_j, L_k]⟩
    for (std::size_t k = 0; k < 3; ++k)
      for (std::size_t j = 0; j < 3; ++j)
        for (std::size_t i = 0; i < 3; ++i) body[k] += omega[j] * pi[i] * c[j][k][i];
    const Vec3 euler = cross(pi, omega);
    double scale = 0.0;
    for (std::size_t k = 0; k < 3; ++k) scale = std::max(scale, std::fabs(euler[k]));
    for (std::size_t k = 0; k < 3; ++k) {
      EXPECT_NEAR(body[k], euler[k], 1e-9 * (1.0 + scale)) << n << k;
    }
    // The spatial (right-invariant) sign would be −Π × Ω: refused wherever Π × Ω ≠ 0.
    if (scale > 1e-3) {
      double diff = 0.0;
      for (std::size_t k = 0; k < 3; ++k) diff = std::max(diff, std::fabs(body[k] + euler[k]));
      EXPECT_GT(diff, 1e-3);
    }
    // Euler's equations keep |Π|² and the energy: Π·Π' = 0, Ω·Π' = 0.
    double dpi = 0.0, denergy = 0.0;
    for (std::size_t k = 0; k < 3; ++k) dpi += pi[k] * body[k], denergy += omega[k] * body[k];
    EXPECT_NEAR(dpi, 0.0, 1e-8);
    EXPECT_NEAR(denergy, 0.0, 1e-8);
  }
}

}  // namespace
