#pragma once
/// \file lie.hpp
/// The symbolic core of hybrid Lie–Poisson reduction (paper §2.3, §3.2, §4.3):
/// Lie algebras and matrix groups, ad*, the Lie–Poisson vector field, the
/// normality (ideal) check of a codimension-1 subalgebra, the q equation of the
/// Impact Lie–Poisson Reduction theorem and the momentum jump Δζ of its
/// corollary. Self-contained; the `lie` model kind wires it into the pipeline.
///
/// Conventions (docs/design.md, checked in tests/gen/test_lie.cpp):
///  - basis E_1..E_n of 𝔤; vectors ξ ∈ 𝔤 and covectors ζ ∈ 𝔤* are component
///    lists ξ = Σ ξ^i E_i, ζ(η) = Σ ζ_k η^k (for gl_n with the elementary
///    matrices, row-major, this is the Frobenius pairing tr(ζᵀη));
///  - matrix bracket [A, B] = AB − BA; structure constants
///        [E_i, E_j] = Σ_k C_ij^k E_k;
///  - (ad*_ξ ζ)(η) = ζ([ξ, η])  ⇒  (ad*_ξ ζ)_j = Σ_{i,k} C_ij^k ξ^i ζ_k, i.e. the
///    column-vector matrix of ζ ↦ ad*_ξ ζ is (ad_ξ)ᵀ;
///  - Lie–Poisson: ζ' = ad*_{∂h/∂ζ} ζ, equivalently f' = {f, h}₋ with the
///    minus bracket {f, k}₋(ζ) = −ζ([∂f/∂ζ, ∂k/∂ζ]) (left-invariant systems,
///    body momenta ζ = ℓ_g^* p). For so(3) this is Euler's Π' = Π × Ω.
///  - ζ^♯ = ∂h/∂ζ (= I⁻¹ζ for h = ½ ζᵀ I⁻¹ ζ), and g' = g ζ^♯.

#include <ginac/ginac.h>

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/gen/errors.hpp"

namespace hybgen::gen {

/// A failed hypothesis of the reduction (not a Lie algebra, K not normal, the
/// q equation depends on more than (ζ, q), ...): a model error (exit 1). The
/// message says which hypothesis failed and why; the caller adds the location.
class LieError : public Error {
 public:
  /// Construct from the name of the failed hypothesis and the reason.
  LieError(std::string hypothesis, const std::string& reason)
      : Error(reason, ExitCode::ModelError), hypothesis_(std::move(hypothesis)) {}
  /// The failed hypothesis: "lie_algebra", "normal", "codim1", "coset",
  /// "left_invariant", "quadratic", "reset", "transversal".
  [[nodiscard]] const std::string& hypothesis() const { return hypothesis_; }

 private:
  std::string hypothesis_;
};

/// Components of a vector in 𝔤 or a covector in 𝔤* (exact GiNaC expressions).
using Components = std::vector<GiNaC::ex>;

/// A finite-dimensional real Lie algebra with a chosen basis E_1..E_n, stored
/// by its structure constants C_ij^k ([E_i, E_j] = Σ_k C_ij^k E_k) and, when it
/// was built from matrices, by the matrices E_i themselves.
/// Invariants: n ≥ 1; C_ij^k = −C_ji^k; the Jacobi identity holds.
class LieAlgebra {
 public:
  /// From structure constants c[i][j][k] = C_ij^k (0-based). Checks the shape,
  /// antisymmetry and the Jacobi identity; throws LieError("lie_algebra").
  static LieAlgebra from_structure_constants(
      const std::vector<std::vector<std::vector<GiNaC::ex>>>& c,
      std::vector<std::string> names = {});

  /// From a basis of matrices (all N×N). Checks linear independence (rank n)
  /// and closure: each [E_i, E_j] = E_iE_j − E_jE_i must lie in the span, and
  /// its coordinates are the structure constants. Throws LieError("lie_algebra")
  /// naming the first bracket that leaves the span.
  static LieAlgebra from_matrix_basis(const std::vector<GiNaC::matrix>& basis,
                                      std::vector<std::string> names = {});

  /// gl_n with the elementary matrices E_ab (row-major: E_1 = E_11, E_2 = E_12,
  /// …, E_{n²} = E_nn), named "E11", "E12", ….
  static LieAlgebra gl(unsigned n);

  /// so(3) with E_i = hat(e_i) (hat(x)y = x × y), so [E_i, E_j] = ε_ijk E_k;
  /// names "E1", "E2", "E3".
  static LieAlgebra so3();

  /// Dimension n.
  [[nodiscard]] unsigned dim() const { return n_; }
  /// C_ij^k (0-based indices).
  [[nodiscard]] const GiNaC::ex& c(unsigned i, unsigned j, unsigned k) const {
    return c_[(i * n_ + j) * n_ + k];
  }
  /// Basis names (for messages and reports).
  [[nodiscard]] const std::vector<std::string>& names() const { return names_; }
  /// Whether the matrices E_i are known.
  [[nodiscard]] bool has_matrices() const { return !basis_.empty(); }
  /// The matrices E_i (empty when built from structure constants).
  [[nodiscard]] const std::vector<GiNaC::matrix>& matrices() const { return basis_; }

  /// Components of [x, y] = Σ C_ij^k x^i y^j E_k.
  [[nodiscard]] Components bracket(const Components& x, const Components& y) const;
  /// The n×n matrix of η ↦ [ξ, η]: ad(ξ)_kj = Σ_i C_ij^k ξ^i.
  [[nodiscard]] GiNaC::matrix ad(const Components& xi) const;
  /// The n×n matrix of ζ ↦ ad*_ξ ζ acting on column vectors ζ:
  /// coadjoint(ξ)_jk = Σ_i C_ij^k ξ^i = ad(ξ)ᵀ_jk.
  [[nodiscard]] GiNaC::matrix coadjoint(const Components& xi) const;
  /// ad*_ξ ζ, components (ad*_ξ ζ)_j = Σ_{i,k} C_ij^k ξ^i ζ_k.
  [[nodiscard]] Components coadjoint_action(const Components& xi, const Components& zeta) const;

  /// A human-readable component list, e.g. "-Eb" or "E1 + 2*E3" (for messages).
  [[nodiscard]] std::string format(const Components& x) const;

 private:
  LieAlgebra(unsigned n, std::vector<GiNaC::ex> c, std::vector<std::string> names,
             std::vector<GiNaC::matrix> basis);
  unsigned n_ = 0;
  std::vector<GiNaC::ex> c_;  ///< n³ entries, c_[(i n + j) n + k] = C_ij^k.
  std::vector<std::string> names_;
  std::vector<GiNaC::matrix> basis_;
};

/// A matrix Lie group given by a parametrisation g(c_1..c_n) with g(c0) = 1.
/// Its algebra has the basis E_i = ∂g/∂c_i (c0). Invariants: rank n; the
/// brackets close; the left-translated basis g E_i is tangent to the
/// parametrised set (g is a local chart of a group near c0 and at generic c).
class MatrixGroup {
 public:
  /// Checks g(c0) = identity, rank n of the E_i, closure of the brackets and
  /// tangency of g(c) E_i; throws LieError("lie_algebra") otherwise.
  /// `coords` are realsymbols; `names` default to "E_<coordinate>".
  MatrixGroup(GiNaC::matrix g, std::vector<GiNaC::ex> coords, std::vector<GiNaC::ex> identity_point,
              std::vector<std::string> names = {});

  /// GL_n parametrised by its entries a11..ann (row-major, realsymbols named
  /// `prefix` + row + column), identity at the identity matrix. Its algebra is
  /// gl_n with the elementary basis E_ab in row-major order.
  static MatrixGroup gl(unsigned n, const std::string& prefix = "a");

  /// The Lie algebra with basis E_i = ∂g/∂c_i (c0).
  [[nodiscard]] const LieAlgebra& algebra() const { return algebra_; }
  /// g(c).
  [[nodiscard]] const GiNaC::matrix& g() const { return g_; }
  /// The coordinate symbols c_i.
  [[nodiscard]] const std::vector<GiNaC::ex>& coords() const { return coords_; }
  /// The identity point c0.
  [[nodiscard]] const std::vector<GiNaC::ex>& identity_point() const { return c0_; }

  /// The n×n matrix L(c) of left translation in coordinates: g(c) E_i =
  /// Σ_j L_ji(c) ∂g/∂c_j, so g' = g ξ reads c' = L(c) ξ.
  [[nodiscard]] const GiNaC::matrix& left_trivialization() const { return left_; }

  /// (ℓ_g)^* df_g as a covector in 𝔤*: components df_g(g E_i) = Σ_j ∂f/∂c_j L_ji(c),
  /// functions of c (the Proposition's (ℓ_g)^* ds_g).
  [[nodiscard]] Components left_trivialized_differential(const GiNaC::ex& f) const;
  /// df at the identity: components ∂f/∂c_i (c0) (the form dφ_e whose kernel is
  /// the Lie algebra of K = ker φ for a homomorphism φ).
  [[nodiscard]] Components differential_at_identity(const GiNaC::ex& f) const;
  /// Substitute c = c0 into e.
  [[nodiscard]] GiNaC::ex at_identity(const GiNaC::ex& e) const;

 private:
  GiNaC::matrix g_;
  std::vector<GiNaC::ex> coords_;
  std::vector<GiNaC::ex> c0_;
  LieAlgebra algebra_;
  GiNaC::matrix left_;
};

/// A Lie group as a Lie-group model knows it: a MatrixGroup (coordinates c,
/// left trivialisation L(c)) or, when given by structure constants, only its
/// Lie algebra (no coordinates: functions on G such as φ are then given by
/// their differential at the identity). Invariant: algebra() is the matrix
/// group's algebra whenever there is a matrix group.
class LieGroup {
 public:
  /// A matrix group (the `group g(c) = [[...]] at (...)` and `gl(N)` forms).
  explicit LieGroup(MatrixGroup group);
  /// A group known by its Lie algebra only (the `algebra(...) { ... }` form).
  explicit LieGroup(LieAlgebra algebra);

  /// Whether the group has coordinates (it is a MatrixGroup).
  [[nodiscard]] bool has_coordinates() const { return matrix_.has_value(); }
  /// The Lie algebra.
  [[nodiscard]] const LieAlgebra& algebra() const;
  /// The matrix group; throws InternalError for a group without coordinates.
  [[nodiscard]] const MatrixGroup& matrix_group() const;
  /// The coordinate symbols c_i (empty without coordinates).
  [[nodiscard]] const std::vector<GiNaC::ex>& coords() const;
  /// L(c) of MatrixGroup::left_trivialization; throws InternalError without
  /// coordinates.
  [[nodiscard]] const GiNaC::matrix& left_trivialization() const;

 private:
  std::optional<MatrixGroup> matrix_;  ///< The matrix group, if given by one.
  std::optional<LieAlgebra> algebra_;  ///< Set iff matrix_ is not.
};

/// The body inertia of a kinetic energy ½ ċᵀ M(c) ċ given in the coordinates
/// of a matrix group: with ċ = L(c) ξ it is ½ ξᵀ I(c) ξ, I(c) = L(c)ᵀ M(c) L(c).
/// The metric is left-invariant iff I(c) is constant (⟨gE_i, gE_j⟩_g does not
/// depend on g); returns I = I(c0) then (entries simplified), and otherwise
/// throws LieError("left_invariant") naming an entry I_ij and a coordinate
/// c_k with ∂I_ij/∂c_k ≢ 0. `metric` must be n×n (n = dim).
GiNaC::matrix left_invariant_inertia(const MatrixGroup& group, const GiNaC::matrix& metric);

/// Realsymbols `prefix`1 … `prefix`n (the momenta ζ1..ζn).
std::vector<GiNaC::ex> make_symbols(unsigned n, const std::string& prefix);

/// h(ζ) = ½ ζᵀ I⁻¹ ζ for a symmetric invertible inertia I (n×n).
GiNaC::ex inertia_hamiltonian(const GiNaC::matrix& inertia, const std::vector<GiNaC::ex>& zeta);

/// The Lie–Poisson vector field of h on 𝔤*.
struct LiePoisson {
  Components dh;          ///< ξ = ∂h/∂ζ = ζ^♯ ∈ 𝔤.
  GiNaC::matrix ad_star;  ///< coadjoint(∂h/∂ζ): ζ' = ad_star · ζ (column vectors).
  Components zeta_dot;    ///< ζ' = ad*_{∂h/∂ζ} ζ, simplified.
};

/// ζ' = ad*_{∂h/∂ζ} ζ for h an expression in the symbols `zeta`.
LiePoisson lie_poisson(const LieAlgebra& g, const std::vector<GiNaC::ex>& zeta, const GiNaC::ex& h);

/// The minus Lie–Poisson bracket {f, k}₋(ζ) = −ζ([∂f/∂ζ, ∂k/∂ζ]), for which
/// f' = {f, h}₋ along ζ' = ad*_{∂h/∂ζ} ζ.
GiNaC::ex poisson_bracket(const LieAlgebra& g, const std::vector<GiNaC::ex>& zeta,
                          const GiNaC::ex& f, const GiNaC::ex& k);

/// Whether C(ζ) is a Casimir: ad*_{∂C/∂ζ} ζ ≡ 0 (then {C, f}₋ = 0 for all f).
bool is_casimir(const LieAlgebra& g, const std::vector<GiNaC::ex>& zeta, const GiNaC::ex& casimir);

/// d f/dt = Σ ∂f/∂x_j X_j along a vector field X (simplified).
GiNaC::ex lie_derivative(const GiNaC::ex& f, const std::vector<GiNaC::ex>& x,
                         const Components& field);

/// A basis of the kernel of a nonzero linear form λ on 𝔤 (components λ_i = λ(E_i)):
/// n − 1 vectors. Throws LieError("codim1") when λ = 0.
std::vector<Components> kernel_of_form(const Components& form);

/// Result of the ideal (normality) test of a subspace 𝔨 ⊂ 𝔤.
struct IdealCheck {
  bool subalgebra = false;  ///< [𝔨, 𝔨] ⊂ 𝔨.
  bool ideal = false;       ///< [𝔤, 𝔨] ⊂ 𝔨 (the Lie algebra of a normal subgroup).
  std::string reason;       ///< The first offending bracket, e.g. "[Eb, Ea] = -Eb ∉ 𝔨".
};

/// Test whether span(basis) is a subalgebra and an ideal of 𝔤 (exact rank test).
IdealCheck check_ideal(const LieAlgebra& g, const std::vector<Components>& basis);

/// Codimension-1 ideals of 𝔤 are exactly the hyperplanes ker λ with λ ≠ 0 and
/// λ([𝔤, 𝔤]) = 0 (if 𝔨 ⊃ [𝔤, 𝔤] then [𝔤, 𝔨] ⊂ 𝔨; conversely 𝔤/𝔨 is 1-dimensional,
/// hence abelian). Returns a basis of Ann([𝔤, 𝔤]); empty iff 𝔤 is perfect (e.g.
/// so(3), any simple algebra) and then no codimension-1 normal subgroup exists.
std::vector<Components> codim1_ideal_forms(const LieAlgebra& g);

/// Throws LieError("normal") with the offending bracket unless ker λ is an
/// ideal, and LieError("codim1") when λ = 0.
void require_normal_kernel(const LieAlgebra& g, const Components& form);

/// How φ: G → ℝ, ℝ*, S¹ transforms: φ(g g') = φ(g) + φ(g') (additive: angles,
/// ℝ-valued coordinates) or φ(g) φ(g') (multiplicative: det).
enum class HomomorphismKind { Additive, Multiplicative };

/// The q equation of the theorem for q = φ(g) − level.
struct QEquation {
  HomomorphismKind kind = HomomorphismKind::Additive;  ///< How φ turned out to transform.
  Components dphi_e;                                   ///< dφ at the identity; 𝔨 = ker dφ_e.
  GiNaC::ex q_dot;  ///< dφ_e(ζ^♯) (additive) or (q + level) dφ_e(ζ^♯) (multiplicative).
};

/// Derive q' along g' = g ζ^♯ with ζ^♯ = `xi` (from lie_poisson(...).dh) and
/// show that it depends on (ζ, q) alone: r = dφ_g(g ξ) must be independent of
/// the coordinates (additive) or r/φ must be (multiplicative). Otherwise throws
/// LieError("coset") naming a coordinate that q' still depends on.
QEquation q_equation(const MatrixGroup& group, const GiNaC::ex& phi, const GiNaC::ex& level,
                     const Components& xi, const GiNaC::ex& q);

/// The q equation of a group known by its algebra only, for φ given by its
/// differential λ = dφ_e (λ([𝔤, 𝔤]) = 0, checked by require_normal_kernel, so
/// λ is a Lie algebra homomorphism 𝔤 → ℝ and integrates to φ on the simply
/// connected group): along g' = g ξ, φ' = λ(ξ) (additive, q = φ) or
/// φ' = φ λ(ξ) (multiplicative, q = φ − 1), so q' = λ(ξ) or (q + 1) λ(ξ).
QEquation q_equation_of_form(HomomorphismKind kind, const Components& dphi_e, const Components& xi,
                             const GiNaC::ex& q);

/// The momentum jump of the corollary that follows the theorem, with
/// restitution e (e = 1 elastic): for σ = (ℓ_{g0})^* ds_{g0} ∈ Ann(𝔨),
///     Δζ = −(1 + e) σ(ζ^♯) / σ(σ^♯) · σ,   ♯ = Hessian of h (h quadratic),
/// so that σ(ζ⁺^♯) = −e σ(ζ^♯) and h(ζ + Δζ) = h(ζ) for e = 1. Throws
/// LieError("quadratic") unless h = ½ ζᵀ H ζ with a constant H, and
/// LieError("codim1") when σ(σ^♯) ≡ 0.
Components momentum_jump(const Components& sigma, const std::vector<GiNaC::ex>& zeta,
                         const GiNaC::ex& h, const GiNaC::ex& restitution = 1);

}  // namespace hybgen::gen
