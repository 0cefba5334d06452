// The symbolic core of hybrid Lie–Poisson reduction (lie.hpp).
//
// Every derived object is checked by an independent route: matrix
// commutators and Frobenius traces instead of structure-constant index
// bookkeeping, Noether's conserved spatial momentum of the unreduced system
// instead of the Lie–Poisson formula, Jacobi's formula for d det instead of the
// left-trivialisation solve, closed-form solutions, conservation laws.
//
// Paper errata found and asserted here (each test comment names its own):
//  E1 §2.3: the reduced bracket {f,k}(μ) = ⟨μ,[df,dk]⟩ is the PLUS bracket; with
//     ḟ = {f,h} it gives μ̇ = −ad*_{dh} μ, contradicting the paper's own
//     μ̇ = ad*_{dh} μ. For left-invariant H (body momenta, J_R) the bracket is
//     the minus bracket {f,k}₋(μ) = −⟨μ,[df,dk]⟩. The equation μ̇ = ad*_{dh} μ
//     (Π̇ = Π × Ω for so(3)) is right. Also "for all ξ ∈ 𝔤*" should be ξ ∈ 𝔤.
//  E2 §4.3: the paper states [A,B] = BA − AB; its ad* matrix and eq.
//     (cont_eom_matrix_groups) are in fact consistent with [A,B] = AB − BA
//     (docs/design.md). Its 4×4 "ad*_{dh}" is the matrix acting on ROW vectors from
//     the right (ζ̇ = ζ M); the column-vector matrix is Mᵀ. In coordinates
//     ad*_ξ ζ = [ξᵀ, ζ] = ξᵀζ − ζξᵀ, so ζ̇ = ζᵀζ − ζζᵀ for h = ½ tr(ζζᵀ).
//  E3 §4.3: "ζ̇_i = C_ij^k (ζᵀ)^i ζ_k" has the free index wrong: ζ̇_j =
//     Σ_{i,k} C_ij^k (∂h/∂ζ)^i ζ_k. "dh = Σ ζ_Id ζ_i" is garbled (dh = ζ^♯ = ζ).
//     "adj(A) the coadjoint of A" means the adjugate.
//  E4 §4.3: q(t) = q₀e^{Ct} − 1 is wrong: q + 1 = (q₀ + 1)e^{Ct}.
//  E5 §4.3: the closed-form gl_2 solution (secular terms D²t, CDt) is wrong
//     (energy would grow without bound); with u = ζ1−ζ4, w = ζ2+ζ3 the correct
//     one is u = u₀cos 2Dt − w₀ sin 2Dt, w = w₀ cos 2Dt + u₀ sin 2Dt, C, D
//     constant. The paper also defines D = ζ2 − ζ3 and later D = ζ3⁰ − ζ2⁰.
//  E6 §4.3: the hybrid Jacobian of the reduced GL₂ system is J = +1, not −1
//     (and u(t⁺) = −u(t⁻) would make a density negative). div = tr ζ is right.
//  E7 §4.3: q̇ = (q + 1) tr(ζ) holds for h = ½ tr(ζζᵀ) only; in general
//     q̇ = (q + 1) tr(ζ^♯) with ζ^♯ = ∂h/∂ζ.
//  E8 Corollary (Δζ): the numerator's ds_{g0}((ℓ_{g0⁻¹})_* ζ^♯) translates the
//     wrong way; it must be ds_{g0}((ℓ_{g0})_* ζ^♯) = ((ℓ_{g0})^*ds_{g0})(ζ^♯)
//     (both agree at g0 = I_n, so §4.3's Δζ = −(2/n) tr(ζ) I_n is right).
//     Proof of the Proposition: ġ = (ℓ_{g⁻¹})_* ζ^♯ should be (ℓ_g)_* ζ^♯.
//  E9 Aff(1) remark: the displayed Δζ = (β, −b₀aβ/a₀) mixes Δp and Δζ = aΔp and
//     inverts the ratio: the corner condition gives a₀Δζ_a + b₀Δζ_b = 0, a
//     direction fixed by g₀ alone, and energy fixes the size from ζ — so the
//     elastic reset does NOT depend on the point of Σ = Kg₀. What non-normality
//     breaks is the theorem's Δζ ∈ Ann(𝔨): here Δζ ∈ Ann(Ad_{g₀⁻¹}𝔨) ≠ Ann(𝔨)
//     for b₀ ≠ 0, which depends on the coset representative. hybgen still
//     requires normality (docs/design.md), so Aff(1) with K = {b = 0} is rejected.
//  E10 §4.2: the paper's Lie algebra element A has the rotation block
//     transposed ([[0, θ̇], [−θ̇, 0]]) and untranslated ẋ, ẏ; for
//     g = [[cos θ, −sin θ, x], [sin θ, cos θ, y], [0, 0, 1]] the body velocity is
//     g⁻¹ġ = [[0, −θ̇, u], [θ̇, 0, v], [0, 0, 0]], u = ẋ cos θ + ẏ sin θ,
//     v = −ẋ sin θ + ẏ cos θ (the paper's ζ, which is right).

#include <gtest/gtest.h>

#include <chrono>
#include <iostream>
#include <random>

#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/lie.hpp"

namespace hybgen::gen {
namespace {

using GiNaC::ex;
using GiNaC::matrix;
using GiNaC::numeric;
using GiNaC::realsymbol;

bool same(const ex& a, const ex& b) {
  return is_identically_zero((a - b).expand(), {});
}

matrix hat(const ex& x1, const ex& x2, const ex& x3) {
  return matrix{{0, -x3, x2}, {x3, 0, -x1}, {-x2, x1, 0}};
}

/// ζ as an n×n matrix from row-major components.
matrix as_matrix(const std::vector<ex>& z, unsigned n) {
  matrix m(n, n);
  for (unsigned a = 0; a < n; ++a)
    for (unsigned b = 0; b < n; ++b) m(a, b) = z[a * n + b];
  return m;
}

ex mtrace(const matrix& m) {
  ex s = 0;
  for (unsigned i = 0; i < m.rows(); ++i) s += m(i, i);
  return s;
}

/// Frobenius pairing ⟨A, B⟩ = tr(AᵀB).
ex frob(const matrix& a, const matrix& b) {
  return mtrace(a.transpose().mul(b));
}

Components random_rationals(unsigned n, std::mt19937& rng) {
  std::uniform_int_distribution<int> num(-40, 40), den(1, 13);
  Components v;
  for (unsigned i = 0; i < n; ++i) v.push_back(numeric(num(rng), den(rng)));
  return v;
}

ex subs_all(const ex& e, const std::vector<ex>& syms, const Components& vals) {
  GiNaC::exmap m;
  for (std::size_t i = 0; i < syms.size(); ++i) m[syms[i]] = vals[i];
  return e.subs(m);
}

// ------------------------------------------------------ structure constants

TEST(LieStructure, So3IsEpsilon) {
  // so(3) with E_i = hat(e_i): [hat u, hat v] = hat(u × v), so C_ij^k = ε_ijk.
  const LieAlgebra g = LieAlgebra::so3();
  ASSERT_EQ(g.dim(), 3u);
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j)
      for (unsigned k = 0; k < 3; ++k) {
        const int eps =
            static_cast<int>((i == j || j == k || k == i) ? 0 : (((j + 3 - i) % 3 == 1) ? 1 : -1));
        EXPECT_EQ(g.c(i, j, k), ex(eps)) << i << j << k;
      }
  // Independent: the matrix commutator of hats of random vectors is the hat of
  // the cross product, and bracket() reproduces it.
  std::mt19937 rng(1);
  const Components u = random_rationals(3, rng), v = random_rationals(3, rng);
  const matrix hu = hat(u[0], u[1], u[2]), hv = hat(v[0], v[1], v[2]);
  const matrix comm = hu.mul(hv).sub(hv.mul(hu));
  const Components w = g.bracket(u, v);
  const matrix hw = hat(w[0], w[1], w[2]);
  for (unsigned r = 0; r < 3; ++r)
    for (unsigned c = 0; c < 3; ++c) EXPECT_TRUE(same(comm(r, c), hw(r, c)));
  // The same constants given directly pass antisymmetry and Jacobi.
  std::vector<std::vector<std::vector<ex>>> c(3, std::vector<std::vector<ex>>(3, Components(3)));
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j)
      for (unsigned k = 0; k < 3; ++k) c[i][j][k] = g.c(i, j, k);
  EXPECT_NO_THROW(LieAlgebra::from_structure_constants(c));
}

TEST(LieStructure, StructureConstantsAreChecked) {
  // Not antisymmetric.
  std::vector<std::vector<std::vector<ex>>> c(3, std::vector<std::vector<ex>>(3, Components(3, 0)));
  c[0][1][2] = 1;
  EXPECT_THROW(LieAlgebra::from_structure_constants(c), LieError);
  // Antisymmetric but not Jacobi: [E1,E2] = E1, [E2,E3] = E1, [E1,E3] = E2 give
  // [[E1,E2],E3] + [[E2,E3],E1] + [[E3,E1],E2] = E2 + 0 + 0 ≠ 0.
  c = std::vector<std::vector<std::vector<ex>>>(3,
                                                std::vector<std::vector<ex>>(3, Components(3, 0)));
  c[0][1][0] = 1, c[1][0][0] = -1;
  c[1][2][0] = 1, c[2][1][0] = -1;
  c[0][2][1] = 1, c[2][0][1] = -1;
  try {
    LieAlgebra::from_structure_constants(c);
    FAIL() << "Jacobi violation not detected";
  } catch (const LieError& e) {
    EXPECT_EQ(e.hypothesis(), "lie_algebra");
    EXPECT_NE(std::string(e.what()).find("Jacobi"), std::string::npos) << e.what();
  }
  // A "parametrisation" whose tangent space is not closed under the bracket:
  // g(x, y) = [[1, x], [y, 1]] has E_x = E12, E_y = E21, [E12, E21] = E11 − E22.
  realsymbol x("x"), y("y");
  try {
    MatrixGroup bad(matrix{{1, x}, {y, 1}}, {x, y}, {0, 0});
    FAIL() << "non-closed bracket not detected";
  } catch (const LieError& e) {
    EXPECT_EQ(e.hypothesis(), "lie_algebra");
    EXPECT_NE(std::string(e.what()).find("not in the span"), std::string::npos) << e.what();
  }
  // Brackets close at the identity (E_x = E11, E_y = E12) but the set is not a
  // group: g(x, y) = [[1 + x, y], [0, 1 + x²]]; g·E_x = [[1 + x, 0], [0, 0]] is not
  // tangent to it (∂g/∂x has the entry 2x at (2, 2)).
  try {
    MatrixGroup bad(matrix{{1 + x, y}, {0, 1 + x * x}}, {x, y}, {0, 0});
    FAIL() << "non-group parametrisation not detected";
  } catch (const LieError& e) {
    EXPECT_NE(std::string(e.what()).find("not tangent"), std::string::npos) << e.what();
  }
  // Rank deficiency: g(x, y) = [[1, x + y], [0, 1]].
  EXPECT_THROW(MatrixGroup(matrix{{1, x + y}, {0, 1}}, {x, y}, {0, 0}), LieError);
}

TEST(LieStructure, Se2FromParametrisation) {
  realsymbol x("x"), y("y"), th("theta");
  const matrix g{{cos(th), -sin(th), x}, {sin(th), cos(th), y}, {0, 0, 1}};
  const MatrixGroup se2(g, {x, y, th}, {0, 0, 0});
  const LieAlgebra& a = se2.algebra();
  // By hand: E_x = e13, E_y = e23, E_θ = [[0,−1,0],[1,0,0],[0,0,0]];
  // [E_x, E_y] = 0, [E_θ, E_x] = E_y, [E_θ, E_y] = −E_x.
  const unsigned X = 0, Y = 1, T = 2;
  for (unsigned k = 0; k < 3; ++k) EXPECT_EQ(a.c(X, Y, k), ex(0));
  EXPECT_EQ(a.c(T, X, Y), ex(1));
  EXPECT_EQ(a.c(T, X, X), ex(0));
  EXPECT_EQ(a.c(T, Y, X), ex(-1));
  EXPECT_EQ(a.c(T, Y, Y), ex(0));
  EXPECT_EQ(a.c(X, T, Y), ex(-1));
  // Left trivialisation c' = L ξ (erratum E10): ẋ = cos θ ξx − sin θ ξy,
  // ẏ = sin θ ξx + cos θ ξy, θ' = ξθ — the inverse of the paper's ζ = g⁻¹ġ.
  const matrix& L = se2.left_trivialization();
  const matrix expect{{cos(th), -sin(th), 0}, {sin(th), cos(th), 0}, {0, 0, 1}};
  for (unsigned r = 0; r < 3; ++r)
    for (unsigned c = 0; c < 3; ++c) EXPECT_TRUE(same(L(r, c), expect(r, c))) << r << c << L;
}

TEST(LieStructure, Gl2AndGl3) {
  // [E_ab, E_cd] = δ_bc E_ad − δ_da E_cb, row-major index a n + b.
  for (unsigned n : {2u, 3u}) {
    const LieAlgebra g = LieAlgebra::gl(n);
    const MatrixGroup G = MatrixGroup::gl(n);
    ASSERT_EQ(g.dim(), n * n);
    for (unsigned a = 0; a < n; ++a)
      for (unsigned b = 0; b < n; ++b)
        for (unsigned c = 0; c < n; ++c)
          for (unsigned d = 0; d < n; ++d) {
            const unsigned i = a * n + b, j = c * n + d;
            for (unsigned k = 0; k < n * n; ++k) {
              int expect = 0;
              if (b == c && k == a * n + d) expect += 1;
              if (d == a && k == c * n + b) expect -= 1;
              EXPECT_EQ(g.c(i, j, k), ex(expect));
              EXPECT_EQ(G.algebra().c(i, j, k), ex(expect));
            }
          }
  }
}

TEST(LieStructure, Aff1) {
  // Aff(1) = {[[a, b], [0, 1]]}, identity (a, b) = (1, 0): E_a = E11, E_b = E12,
  // [E_a, E_b] = E11E12 − E12E11 = E12 = E_b.
  realsymbol a("a"), b("b");
  const MatrixGroup aff(matrix{{a, b}, {0, 1}}, {a, b}, {1, 0}, {"Ea", "Eb"});
  EXPECT_EQ(aff.algebra().c(0, 1, 0), ex(0));
  EXPECT_EQ(aff.algebra().c(0, 1, 1), ex(1));
  EXPECT_EQ(aff.algebra().c(1, 0, 1), ex(-1));
}

// --------------------------------------------------------------------- ad*

TEST(LieCoadjoint, ConventionByMatrixCommutators) {
  // (ad*_ξ ζ)(η) = ζ([ξ, η]) with ζ(η) = tr(ζᵀη) and [ξ, η] = ξη − ηξ, checked
  // by matrix products for random rational ξ, ζ, η in gl_2 and gl_3.
  std::mt19937 rng(7);
  for (unsigned n : {2u, 3u}) {
    const LieAlgebra g = LieAlgebra::gl(n);
    for (int trial = 0; trial < 5; ++trial) {
      const Components xi = random_rationals(n * n, rng), zeta = random_rationals(n * n, rng),
                       eta = random_rationals(n * n, rng);
      const Components adz = g.coadjoint_action(xi, zeta);
      ex lhs = 0;
      for (unsigned j = 0; j < n * n; ++j) lhs += adz[j] * eta[j];
      const matrix X = as_matrix(xi, n), Z = as_matrix(zeta, n), H = as_matrix(eta, n);
      const ex rhs = frob(Z, X.mul(H).sub(H.mul(X)));
      EXPECT_EQ(lhs.expand(), rhs.expand());
      // Closed form ad*_ξ ζ = [ξᵀ, ζ] (erratum E2).
      const matrix closed = X.transpose().mul(Z).sub(Z.mul(X.transpose()));
      for (unsigned k = 0; k < n * n; ++k) EXPECT_EQ(adz[k], closed(k / n, k % n));
    }
  }
}

TEST(LieCoadjoint, Gl2AgainstPaperMatrix) {
  // §4.3 prints, for dh = (α1 α2 α3 α4),
  //   M = [[0, −α3, α2, 0], [−α2, α1−α4, 0, α2], [α3, 0, α4−α1, −α3], [0, α3, −α2, 0]],
  // used as ζ̇ = ζ M with ζ a row vector. Erratum E2: our column-vector matrix
  // coadjoint(α) (ζ̇ = coadjoint(α) ζ) equals Mᵀ; M itself is right only in the
  // row-vector reading, and only with [A,B] = AB − BA (not the paper's BA − AB,
  // which would flip every sign).
  const std::vector<ex> al = make_symbols(4, "alpha");
  const ex &a1 = al[0], &a2 = al[1], &a3 = al[2], &a4 = al[3];
  const matrix M{{0, -a3, a2, 0}, {-a2, a1 - a4, 0, a2}, {a3, 0, a4 - a1, -a3}, {0, a3, -a2, 0}};
  const matrix ad = LieAlgebra::gl(2).coadjoint(Components(al.begin(), al.end()));
  const matrix Mt = M.transpose();
  for (unsigned r = 0; r < 4; ++r)
    for (unsigned c = 0; c < 4; ++c) EXPECT_TRUE(same(ad(r, c), Mt(r, c))) << r << c;
  EXPECT_FALSE(same(ad(0, 1), M(0, 1)));  // so the matrix is not symmetric: orientation matters
}

// ------------------------------------------------------------ Lie–Poisson

TEST(LiePoissonTest, So3EulerEquations) {
  const LieAlgebra g = LieAlgebra::so3();
  const std::vector<ex> P = make_symbols(3, "Pi");
  realsymbol I1("I1"), I2("I2"), I3("I3");
  const ex h = inertia_hamiltonian(matrix{{I1, 0, 0}, {0, I2, 0}, {0, 0, I3}}, P);
  EXPECT_TRUE(same(h, (P[0] * P[0] / I1 + P[1] * P[1] / I2 + P[2] * P[2] / I3) / 2));
  const LiePoisson lp = lie_poisson(g, P, h);
  const ex W[3] = {P[0] / I1, P[1] / I2, P[2] / I3};  // Ω = I⁻¹Π
  // Π' = Π × Ω (docs/design.md; paper §2.3 example, right).
  EXPECT_TRUE(same(lp.zeta_dot[0], P[1] * W[2] - P[2] * W[1]));
  EXPECT_TRUE(same(lp.zeta_dot[1], P[2] * W[0] - P[0] * W[2]));
  EXPECT_TRUE(same(lp.zeta_dot[2], P[0] * W[1] - P[1] * W[0]));
  // Euler's form: I1 Ω1' = (I2 − I3) Ω2 Ω3.
  EXPECT_TRUE(same(lp.zeta_dot[0], (I2 - I3) * W[1] * W[2]));

  // Independent route deciding the sign (‖Π‖² and h are conserved for either
  // sign): the unreduced body Ṙ = R hat(Ω) conserves the spatial angular
  // momentum π = RΠ (Noether, left invariance). d/dt(RΠ) = R(Ω × Π + Π') must
  // vanish identically for a generic symbolic R.
  matrix R(3, 3);
  std::vector<ex> rs = make_symbols(9, "r");
  for (unsigned i = 0; i < 9; ++i) R(i / 3, i % 3) = rs[i];
  const matrix Rdot = R.mul(hat(W[0], W[1], W[2]));
  const matrix Pi{{P[0]}, {P[1]}, {P[2]}};
  const matrix Pidot{{lp.zeta_dot[0]}, {lp.zeta_dot[1]}, {lp.zeta_dot[2]}};
  const matrix dpi = Rdot.mul(Pi).add(R.mul(Pidot));
  for (unsigned i = 0; i < 3; ++i) EXPECT_TRUE(same(dpi(i, 0), 0)) << dpi(i, 0);

  // Conservation: the Casimir ‖Π‖² and the energy.
  const ex C = P[0] * P[0] + P[1] * P[1] + P[2] * P[2];
  EXPECT_TRUE(is_casimir(g, P, C));
  EXPECT_TRUE(same(lie_derivative(C, P, lp.zeta_dot), 0));
  EXPECT_TRUE(same(lie_derivative(h, P, lp.zeta_dot), 0));
  EXPECT_FALSE(is_casimir(g, P, h));

  // Erratum E1: ζ_j' = {ζ_j, h}₋ with the MINUS bracket; the paper's
  // {f,k} = ⟨μ,[df,dk]⟩ gives the opposite sign.
  for (unsigned j = 0; j < 3; ++j) {
    EXPECT_TRUE(same(poisson_bracket(g, P, P[j], h), lp.zeta_dot[j]));
    EXPECT_TRUE(same(-poisson_bracket(g, P, P[j], h), -lp.zeta_dot[j]));
  }
}

TEST(LiePoissonTest, Gl2AgainstPaper) {
  const LieAlgebra g = LieAlgebra::gl(2);
  const std::vector<ex> z = make_symbols(4, "zeta");
  ex h = 0;
  for (const auto& zi : z) h += zi * zi / 2;  // ½ tr(ζζᵀ)
  const LiePoisson lp = lie_poisson(g, z, h);
  // Paper eq. (cont_eom_matrix_groups), right (given erratum E2's reading):
  //   ζ̇ = (−ζ2² + ζ3², (ζ1−ζ4)(ζ2−ζ3), (ζ1−ζ4)(ζ2−ζ3), ζ2² − ζ3²).
  EXPECT_TRUE(same(lp.zeta_dot[0], -z[1] * z[1] + z[2] * z[2]));
  EXPECT_TRUE(same(lp.zeta_dot[1], (z[0] - z[3]) * (z[1] - z[2])));
  EXPECT_TRUE(same(lp.zeta_dot[2], (z[0] - z[3]) * (z[1] - z[2])));
  EXPECT_TRUE(same(lp.zeta_dot[3], z[1] * z[1] - z[2] * z[2]));
  // Independent closed form ζ̇ = ζᵀζ − ζζᵀ.
  const matrix Z = as_matrix(z, 2);
  const matrix closed = Z.transpose().mul(Z).sub(Z.mul(Z.transpose()));
  for (unsigned k = 0; k < 4; ++k) EXPECT_TRUE(same(lp.zeta_dot[k], closed(k / 2, k % 2)));

  // The paper's claims: C = tr ζ and D = ζ2 − ζ3 are constant (right). tr ζ and
  // tr(ζ²) are Casimirs; D is conserved for this h but is not a Casimir.
  const ex C = z[0] + z[3], D = z[1] - z[2];
  EXPECT_TRUE(same(lie_derivative(C, z, lp.zeta_dot), 0));
  EXPECT_TRUE(same(lie_derivative(D, z, lp.zeta_dot), 0));
  EXPECT_TRUE(same(lie_derivative(h, z, lp.zeta_dot), 0));
  EXPECT_TRUE(is_casimir(g, z, C));
  EXPECT_TRUE(is_casimir(g, z, mtrace(Z.mul(Z))));
  EXPECT_FALSE(is_casimir(g, z, D));
  EXPECT_FALSE(is_casimir(g, z, h));

  // Erratum E5: the correct closed-form solution satisfies the ODE; the
  // paper's ζ1(t) = D²t + ζ1⁰ cos 2Dt + ζ3⁰ sin 2Dt does not (wrong slope at 0).
  realsymbol t("t");
  const std::vector<ex> z0 = make_symbols(4, "z0_");
  const ex C0 = z0[0] + z0[3], D0 = z0[1] - z0[2], u0 = z0[0] - z0[3], w0 = z0[1] + z0[2];
  const ex u = u0 * cos(2 * D0 * t) - w0 * sin(2 * D0 * t);
  const ex w = w0 * cos(2 * D0 * t) + u0 * sin(2 * D0 * t);
  const std::vector<ex> sol = {(C0 + u) / 2, (w + D0) / 2, (w - D0) / 2, (C0 - u) / 2};
  for (unsigned k = 0; k < 4; ++k) {
    EXPECT_TRUE(same(sol[k].subs(t == 0), z0[k]));
    EXPECT_TRUE(same(sol[k].diff(t), subs_all(lp.zeta_dot[k], z, sol))) << k;
  }
  const ex paper1 = D0 * D0 * t + z0[0] * cos(2 * D0 * t) + z0[2] * sin(2 * D0 * t);
  EXPECT_FALSE(same(paper1.diff(t).subs(t == 0),
                    subs_all(lp.zeta_dot[0], z, Components(z0.begin(), z0.end()))));
}

TEST(LiePoissonTest, Gl3DerivesFast) {
  // Everything the gl3 model needs: group + algebra + left trivialisation,
  // ad*, ζ̇, q̇ and Δζ. Must be well under 5 s.
  const auto t0 = std::chrono::steady_clock::now();
  const MatrixGroup G = MatrixGroup::gl(3);
  const std::vector<ex> z = make_symbols(9, "zeta");
  ex h = 0;
  for (const auto& zi : z) h += zi * zi / 2;
  const LiePoisson lp = lie_poisson(G.algebra(), z, h);
  realsymbol q("q");
  const QEquation qe = q_equation(G, GiNaC::determinant(G.g()), 1, lp.dh, q);
  const Components dz =
      momentum_jump(G.differential_at_identity(GiNaC::determinant(G.g()) - 1), z, h);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cout << "[ gl3 derive ] " << secs << " s\n";
  EXPECT_LT(secs, 5.0);
  const matrix Z = as_matrix(z, 3);
  const matrix closed = Z.transpose().mul(Z).sub(Z.mul(Z.transpose()));
  for (unsigned k = 0; k < 9; ++k) EXPECT_TRUE(same(lp.zeta_dot[k], closed(k / 3, k % 3)));
  EXPECT_TRUE(same(qe.q_dot, (q + 1) * mtrace(Z)));
  for (unsigned k = 0; k < 9; ++k)
    EXPECT_TRUE(same(dz[k], k % 4 == 0 ? -ex(2) / 3 * mtrace(Z) : ex(0)));
  EXPECT_TRUE(is_casimir(G.algebra(), z, mtrace(Z)));
  EXPECT_TRUE(is_casimir(G.algebra(), z, mtrace(Z.mul(Z))));
  EXPECT_TRUE(is_casimir(G.algebra(), z, mtrace(Z.mul(Z).mul(Z))));
}

// ------------------------------------------------------ normality / ideals

TEST(LieNormality, SlnIsAnIdealOfGln) {
  for (unsigned n : {2u, 3u}) {
    const MatrixGroup G = MatrixGroup::gl(n);
    // dφ_e for φ = det is the trace form: ∂det/∂a_ab (I) = δ_ab.
    const Components form = G.differential_at_identity(GiNaC::determinant(G.g()));
    for (unsigned k = 0; k < n * n; ++k) EXPECT_EQ(form[k], ex(k % (n + 1) == 0 ? 1 : 0));
    const IdealCheck c = check_ideal(G.algebra(), kernel_of_form(form));
    EXPECT_TRUE(c.subalgebra);
    EXPECT_TRUE(c.ideal) << c.reason;
    EXPECT_NO_THROW(require_normal_kernel(G.algebra(), form));
    // sl_n is the only codimension-1 ideal: Ann([gl_n, gl_n]) = span(tr).
    const auto forms = codim1_ideal_forms(G.algebra());
    ASSERT_EQ(forms.size(), 1u);
    for (unsigned k = 0; k < n * n; ++k)
      EXPECT_TRUE(same(forms[0][k] * form[0], form[k] * forms[0][0]));
  }
}

TEST(LieNormality, Aff1WithBZeroIsNotNormal) {
  // The paper's remark: K = {b = 0} in Aff(1), 𝔨 = ker db_e = span(E_a).
  // [E_b, E_a] = −E_b ∉ 𝔨: not an ideal (right).
  realsymbol a("a"), b("b");
  const MatrixGroup aff(matrix{{a, b}, {0, 1}}, {a, b}, {1, 0}, {"Ea", "Eb"});
  const Components form = aff.differential_at_identity(b);
  const IdealCheck c = check_ideal(aff.algebra(), kernel_of_form(form));
  EXPECT_TRUE(c.subalgebra);
  EXPECT_FALSE(c.ideal);
  EXPECT_NE(c.reason.find("[Eb, Ea] = -Eb"), std::string::npos) << c.reason;
  try {
    require_normal_kernel(aff.algebra(), form);
    FAIL();
  } catch (const LieError& e) {
    EXPECT_EQ(e.hypothesis(), "normal");
  }
  // The translations ker da_e = span(E_b) (φ = a = det) are normal, and the
  // only codimension-1 ideal: [aff, aff] = span(E_b).
  EXPECT_TRUE(check_ideal(aff.algebra(), kernel_of_form(aff.differential_at_identity(a))).ideal);
  const auto forms = codim1_ideal_forms(aff.algebra());
  ASSERT_EQ(forms.size(), 1u);
  EXPECT_EQ(forms[0][1], ex(0));
  // q for a coordinate that is not a homomorphism: q' = dφ(g ξ) = a ξ_b
  // depends on a, so the check refuses it and names the coordinate.
  const std::vector<ex> z = make_symbols(2, "zeta");
  try {
    q_equation(aff, b, 0, Components(z.begin(), z.end()), realsymbol("q"));
    FAIL();
  } catch (const LieError& e) {
    EXPECT_EQ(e.hypothesis(), "coset");
    EXPECT_NE(std::string(e.what()).find("coordinate a"), std::string::npos) << e.what();
  }
}

TEST(LieNormality, Aff1ResetIsPointIndependentPaperRemarkIsWrong) {
  // Erratum E9. Σ = K g0 = {[[α a0, α b0], [0, 1]]} is the zero set of
  // s = b − (b0/a0) a. The Proposition's (ℓ_g)^* ds_g = a·(−b0/a0, 1): its
  // direction (the direction of Δζ) does not depend on the point g of Σ.
  realsymbol a("a"), b("b"), a0("a0"), b0("b0");
  const MatrixGroup aff(matrix{{a, b}, {0, 1}}, {a, b}, {1, 0}, {"Ea", "Eb"});
  const ex s = b - b0 / a0 * a;
  const Components sg = aff.left_trivialized_differential(s);
  EXPECT_TRUE(same(sg[0], -a * b0 / a0));
  EXPECT_TRUE(same(sg[1], a));
  // It annihilates Ad_{g0⁻¹}𝔨 = span(E_a + (b0/a0) E_b) = (ℓ_{g⁻¹})_* T_gΣ, not
  // 𝔨 = span(E_a) (unless b0 = 0): Δζ ∉ Ann(𝔨), which is what normality buys.
  EXPECT_TRUE(same(sg[0] + b0 / a0 * sg[1], 0));
  EXPECT_FALSE(same(sg[0], 0));
  // Hence Δζ (elastic, h = ½|ζ|²) is the same at every g ∈ Σ.
  const std::vector<ex> z = make_symbols(2, "zeta");
  const ex h = (z[0] * z[0] + z[1] * z[1]) / 2;
  const Components dz_g = momentum_jump(sg, z, h);
  const Components dz_0 = momentum_jump({-b0 / a0, 1}, z, h);
  for (unsigned k = 0; k < 2; ++k) EXPECT_TRUE(same(dz_g[k], dz_0[k]));
}

TEST(LieNormality, So3HasNoCodim1Ideal) {
  // so(3) is simple: [so3, so3] = so3, so Ann([g, g]) = 0 and no hyperplane is
  // an ideal (no codimension-1 normal subgroup exists: the rigid body model
  // must be rejected).
  const LieAlgebra g = LieAlgebra::so3();
  EXPECT_TRUE(codim1_ideal_forms(g).empty());
  // Independently, every candidate kernel fails the bracket test, the three
  // coordinate planes, diagonal ones and random ones.
  std::vector<Components> forms = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}, {2, -3, 5}};
  std::mt19937 rng(3);
  for (int i = 0; i < 10; ++i) forms.push_back(random_rationals(3, rng));
  for (const auto& f : forms) {
    if (f[0].is_zero() && f[1].is_zero() && f[2].is_zero()) continue;
    const IdealCheck c = check_ideal(g, kernel_of_form(f));
    EXPECT_FALSE(c.ideal) << f[0] << "," << f[1] << "," << f[2];
    EXPECT_FALSE(c.subalgebra);  // in so(3) no plane is even a subalgebra
  }
  // Symbolically: for λ = (l1, l2, l3) ≠ 0, ker λ is an ideal iff λ([x, y]) = 0
  // for all x and y ∈ ker λ. Take x = E_i and the kernel vectors λ × E_j:
  // λ(E_i × (λ × E_j)) = |λ|² δ_ij − l_i l_j; its trace over i = j is 2|λ|² ≠ 0.
  realsymbol l1("l1"), l2("l2"), l3("l3");
  const Components lam = {l1, l2, l3};
  ex tr = 0;
  for (unsigned i = 0; i < 3; ++i) {
    Components ei(3, ex(0)), ej(3, ex(0));
    ei[i] = 1;
    ej[i] = 1;
    const Components y = g.bracket(lam, ej);  // λ × E_i ∈ ker λ
    const Components br = g.bracket(ei, y);
    for (unsigned k = 0; k < 3; ++k) tr += lam[k] * br[k];
  }
  EXPECT_TRUE(same(tr, 2 * (l1 * l1 + l2 * l2 + l3 * l3)));
  EXPECT_THROW(kernel_of_form({0, 0, 0}), LieError);
}

TEST(LieNormality, Se2TranslationsAreNormal) {
  // Chaplygin (§4.2): Σ = {θ = ±θ0} are cosets of ℝ² = ker dθ, an ideal (right).
  realsymbol x("x"), y("y"), th("theta");
  const MatrixGroup se2(matrix{{cos(th), -sin(th), x}, {sin(th), cos(th), y}, {0, 0, 1}},
                        {x, y, th}, {0, 0, 0});
  EXPECT_NO_THROW(require_normal_kernel(se2.algebra(), se2.differential_at_identity(th)));
  EXPECT_THROW(require_normal_kernel(se2.algebra(), se2.differential_at_identity(x)), LieError);
  // q = θ is additive: q' = ξ_θ = ω.
  const std::vector<ex> z = make_symbols(3, "zeta");
  const QEquation qe = q_equation(se2, th, 0, Components(z.begin(), z.end()), realsymbol("q"));
  EXPECT_EQ(qe.kind, HomomorphismKind::Additive);
  EXPECT_TRUE(same(qe.q_dot, z[2]));
}

// ------------------------------------------------------------- q equation

TEST(LieQEquation, Gl2Determinant) {
  const MatrixGroup G = MatrixGroup::gl(2);
  const std::vector<ex> z = make_symbols(4, "zeta");
  realsymbol q("q");
  const ex det = GiNaC::determinant(G.g());
  // h = ½ tr(ζζᵀ): ζ^♯ = ζ and q' = (q + 1) tr ζ (paper §4.3, right for this h).
  ex h = 0;
  for (const auto& zi : z) h += zi * zi / 2;
  const QEquation qe = q_equation(G, det, 1, lie_poisson(G.algebra(), z, h).dh, q);
  EXPECT_EQ(qe.kind, HomomorphismKind::Multiplicative);
  EXPECT_TRUE(same(qe.q_dot, (q + 1) * (z[0] + z[3])));
  // Only (ζ, q) remain.
  for (const auto& c : G.coords()) EXPECT_FALSE(qe.q_dot.has(c));
  // Independent (Jacobi's formula, no left trivialisation): along Ȧ = Aξ,
  // d det(A)/dt = Σ ∂det/∂a_rc (Aξ)_rc = det(A) tr ξ.
  const matrix Axi = G.g().mul(as_matrix(z, 2));
  ex ddet = 0;
  for (unsigned k = 0; k < 4; ++k)
    ddet += det.diff(GiNaC::ex_to<GiNaC::symbol>(G.coords()[k])) * Axi(k / 2, k % 2);
  EXPECT_TRUE(same(ddet, det * (z[0] + z[3])));
  // Erratum E7: with a non-Frobenius metric h = ½ Σ ζ_k²/I_k, q' = (q+1) tr ζ^♯.
  const std::vector<ex> I = make_symbols(4, "I");
  const ex hI = inertia_hamiltonian(
      matrix{{I[0], 0, 0, 0}, {0, I[1], 0, 0}, {0, 0, I[2], 0}, {0, 0, 0, I[3]}}, z);
  const QEquation qI = q_equation(G, det, 1, lie_poisson(G.algebra(), z, hI).dh, q);
  EXPECT_TRUE(same(qI.q_dot, (q + 1) * (z[0] / I[0] + z[3] / I[3])));
  // Erratum E4: q(t) = (q0 + 1) e^{Ct} − 1 solves q' = (q + 1) C; the paper's
  // q0 e^{Ct} − 1 does not (unless q0 = −1… or C = 0).
  realsymbol t("t"), q0("q0"), C("C");
  const ex good = (q0 + 1) * exp(C * t) - 1, paper = q0 * exp(C * t) - 1;
  EXPECT_TRUE(same(good.diff(t), (good + 1) * C));
  EXPECT_TRUE(same(good.subs(t == 0), q0));
  EXPECT_FALSE(same(paper.subs(t == 0), q0));
}

// -------------------------------------------------------------------- Δζ

TEST(LieReset, GlnDeltaZeta) {
  std::mt19937 rng(11);
  for (unsigned n : {2u, 3u}) {
    const MatrixGroup G = MatrixGroup::gl(n);
    const std::vector<ex> z = make_symbols(n * n, "zeta");
    ex h = 0;
    for (const auto& zi : z) h += zi * zi / 2;
    const ex det = GiNaC::determinant(G.g());
    // σ = (ℓ_I)^* ds_I = I_n (s = det − 1; ds_A = adj(A)ᵀ).
    const Components sigma = G.differential_at_identity(det - 1);
    const Components dz = momentum_jump(sigma, z, h);
    const matrix Z = as_matrix(z, n);
    // Paper §4.3: Δζ = −(2/n) tr(ζ) I_n (right).
    for (unsigned k = 0; k < n * n; ++k)
      EXPECT_TRUE(same(dz[k], k % (n + 1) == 0 ? -ex(2) / n * mtrace(Z) : ex(0))) << n << k;
    Components zp;
    for (unsigned k = 0; k < n * n; ++k) zp.push_back(z[k] + dz[k]);
    // tr ζ⁺ = −tr ζ⁻; h(ζ + Δζ) = h(ζ); Δζ ∈ Ann(sl_n).
    EXPECT_TRUE(same(mtrace(as_matrix(zp, n)), -mtrace(Z)));
    EXPECT_TRUE(same(subs_all(h, z, zp), h));
    const auto sl = kernel_of_form(G.differential_at_identity(det));
    for (const auto& k : sl) {
      ex pair = 0;
      for (unsigned i = 0; i < n * n; ++i) pair += dz[i] * k[i];
      EXPECT_TRUE(same(pair, 0));
    }
    // The same at random numeric ζ.
    for (int trial = 0; trial < 3; ++trial) {
      const Components zr = random_rationals(n * n, rng);
      Components zr_p;
      for (unsigned k = 0; k < n * n; ++k) zr_p.push_back(zr[k] + subs_all(dz[k], z, zr));
      EXPECT_EQ(subs_all(h, z, zr_p).expand(), subs_all(h, z, zr).expand());
      EXPECT_EQ(mtrace(as_matrix(zr_p, n)).expand(), (-mtrace(as_matrix(zr, n))).expand());
    }
    // Paper §4.3 for n = 2: ζ⁺ = (−ζ4, ζ2, ζ3, −ζ1) (right, with ζ1⁻).
    if (n == 2) {
      EXPECT_TRUE(same(zp[0], -z[3]));
      EXPECT_TRUE(same(zp[1], z[1]));
      EXPECT_TRUE(same(zp[2], z[2]));
      EXPECT_TRUE(same(zp[3], -z[0]));
    }
    // The Proposition at a generic g: (ℓ_g)^* ds_g = gᵀ adj(g)ᵀ = det(g) I_n,
    // computed here from GiNaC's inverse (adj = det · inverse): on SL_n it is
    // I_n at every point, so the reset does not depend on g (K = SL_n normal).
    const Components sg = G.left_trivialized_differential(det - 1);
    const matrix adjT = G.g().inverse().mul_scalar(det).transpose();
    const matrix expect = G.g().transpose().mul(adjT);
    for (unsigned k = 0; k < n * n; ++k) {
      EXPECT_TRUE(same(sg[k], expect(k / n, k % n)));
      EXPECT_TRUE(same(sg[k], k % (n + 1) == 0 ? det : ex(0)));
    }
    // Restitution e: Δζ = −((1 + e)/n) tr ζ I_n, tr ζ⁺ = −e tr ζ⁻.
    realsymbol e("e");
    const Components dze = momentum_jump(sigma, z, h, e);
    ex trp = 0;
    for (unsigned k = 0; k < n * n; k += n + 1) trp += z[k] + dze[k];
    EXPECT_TRUE(same(trp, -e * mtrace(Z)));
  }
}

TEST(LieReset, RequiresQuadraticHamiltonian) {
  const std::vector<ex> z = make_symbols(2, "zeta");
  EXPECT_THROW(momentum_jump({1, 0}, z, z[0] * z[0] * z[0] + z[1] * z[1]), LieError);
  EXPECT_THROW(momentum_jump({1, 0}, z, z[0] * z[0] / 2 + z[1]), LieError);
  // σ null for the metric: h = ½ ζ2² and σ = (1, 0).
  EXPECT_THROW(momentum_jump({1, 0}, z, z[1] * z[1] / 2), LieError);
}

// ------------------------------- the reduced GL₂ system: div and J (paper)

TEST(LieReducedGl2, DivergenceAndHybridJacobian) {
  const MatrixGroup G = MatrixGroup::gl(2);
  const std::vector<ex> z = make_symbols(4, "zeta");
  realsymbol q("q");
  ex h = 0;
  for (const auto& zi : z) h += zi * zi / 2;
  const LiePoisson lp = lie_poisson(G.algebra(), z, h);
  const ex det = GiNaC::determinant(G.g());
  const QEquation qe = q_equation(G, det, 1, lp.dh, q);
  const Components dz = momentum_jump(G.differential_at_identity(det - 1), z, h);
  std::vector<ex> x(z.begin(), z.end());
  x.push_back(q);
  Components X(lp.zeta_dot);
  X.push_back(qe.q_dot);
  // div_μ X for μ = dζ1∧…∧dζ4∧dq: tr ζ = C (paper, right).
  ex div = 0;
  for (unsigned i = 0; i < 5; ++i) div += X[i].diff(GiNaC::ex_to<GiNaC::symbol>(x[i]));
  EXPECT_TRUE(same(div, z[0] + z[3]));
  // Erratum E6: docs/design.md's basis formula on the guard q = 0 with tangent
  // basis e_ζ1..e_ζ4: J = det[DΔ·e_1…DΔ·e_4 | X(Δx)] / det[e_1…e_4 | X(x)].
  Components reset;
  for (unsigned k = 0; k < 4; ++k) reset.push_back(z[k] + dz[k]);
  reset.push_back(q);
  matrix num(5, 5), den(5, 5);
  for (unsigned c = 0; c < 4; ++c)
    for (unsigned r = 0; r < 5; ++r) {
      num(r, c) = reset[r].diff(GiNaC::ex_to<GiNaC::symbol>(x[c]));
      den(r, c) = r == c ? 1 : 0;
    }
  for (unsigned r = 0; r < 5; ++r) {
    num(r, 4) = subs_all(X[r], x, reset);
    den(r, 4) = X[r];
  }
  const ex J = GiNaC::normal((num.determinant() / den.determinant()).subs(q == 0));
  EXPECT_EQ(J, ex(1));  // the paper prints J = −1
}

TEST(LieMetricTest, Se2LeftInvariantInertia) {
  realsymbol x("x"), y("y"), th("theta"), m("m"), a("a"), I("I");
  const matrix g{{cos(th), -sin(th), x}, {sin(th), cos(th), y}, {0, 0, 1}};
  const MatrixGroup se2(g, {x, y, th}, {0, 0, 0});
  // The sleigh's metric in (x, y, θ) (paper §4.2): ½ m |ṗ|² + ½ I θ̇² for the
  // centre of mass p = (x, y) + a (cos θ, sin θ), ṗ = (ẋ − a θ̇ sin θ, ẏ + a θ̇ cos θ).
  // Independently, in the body velocity (ẋ, ẏ) = R(θ)(v, w), θ̇ = ω (so
  // −ẋ sin θ + ẏ cos θ = w) it is ½ (m v² + m (w + a ω)² + I ω²), i.e.
  // I = [[m, 0, 0], [0, m, m a], [0, m a, I + m a²]].
  const matrix M{{m, 0, -m * a * sin(th)},
                 {0, m, m * a * cos(th)},
                 {-m * a * sin(th), m * a * cos(th), I + m * a * a}};
  const matrix body = left_invariant_inertia(se2, M);
  const matrix expect{{m, 0, 0}, {0, m, m * a}, {0, m * a, I + m * a * a}};
  for (unsigned r = 0; r < 3; ++r)
    for (unsigned c = 0; c < 3; ++c) EXPECT_TRUE(same(body(r, c), expect(r, c))) << r << c;
  // Not left-invariant: the body inertia used as a metric in (x, y, θ) (the
  // offset frozen along the fixed y axis): I_13 = (cos θ, sin θ, 0)·(0, m a, ·)
  // = m a sin θ depends on θ.
  const matrix bad{{m, 0, 0}, {0, m, m * a}, {0, m * a, I + m * a * a}};
  try {
    (void)left_invariant_inertia(se2, bad);
    ADD_FAILURE() << "accepted a metric that is not left-invariant";
  } catch (const LieError& e) {
    EXPECT_EQ(e.hypothesis(), "left_invariant");
    EXPECT_NE(std::string(e.what()).find("coordinate theta"), std::string::npos) << e.what();
  }
}

TEST(LieMetricTest, LieGroupWithoutCoordinates) {
  // H3 by structure constants: [E1, E2] = E3.
  std::vector<std::vector<std::vector<ex>>> c(
      3, std::vector<std::vector<ex>>(3, std::vector<ex>(3, ex(0))));
  c[0][1][2] = 1;
  c[1][0][2] = -1;
  const LieGroup h3(LieAlgebra::from_structure_constants(c));
  EXPECT_FALSE(h3.has_coordinates());
  EXPECT_EQ(h3.algebra().dim(), 3u);
  EXPECT_TRUE(h3.coords().empty());
  EXPECT_THROW((void)h3.left_trivialization(), InternalError);
  EXPECT_THROW((void)h3.matrix_group(), InternalError);
  const LieGroup gl2(MatrixGroup::gl(2));
  EXPECT_TRUE(gl2.has_coordinates());
  EXPECT_EQ(gl2.coords().size(), 4u);
  EXPECT_EQ(&gl2.algebra(), &gl2.matrix_group().algebra());
  // q' = λ(ξ) or (q + 1) λ(ξ).
  realsymbol q("q"), a("a"), b("b"), d("d");
  const QEquation add = q_equation_of_form(HomomorphismKind::Additive, {1, 0, 2}, {a, b, d}, q);
  EXPECT_TRUE(same(add.q_dot, a + 2 * d));
  const QEquation mul =
      q_equation_of_form(HomomorphismKind::Multiplicative, {1, 0, 2}, {a, b, d}, q);
  EXPECT_TRUE(same(mul.q_dot, (q + 1) * (a + 2 * d)));
  EXPECT_EQ(mul.kind, HomomorphismKind::Multiplicative);
}

}  // namespace
}  // namespace hybgen::gen
