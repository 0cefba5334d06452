#pragma once
/// \file reduce.hpp
/// Lie-group models (docs/design.md "Two kinds of model", paper §3.2):
///
///   AST --check_lie--> LieModel --reduce--> Model (general kind) --derive--> IR
///
/// `check_lie` (check_lie.hpp) resolves the names of a `lie` model and builds
/// the matrix group; `reduce` applies the Impact Lie–Poisson Reduction theorem
/// and its corollary and returns an ordinary Model whose state is (ζ_1..ζ_n, q):
///
///   ζ' = ad*_{∂h/∂ζ} ζ,   q' = dφ_e(ζ^♯) (φ additive) or (q + c) dφ_e(ζ^♯) (φ = det-like),
///   guard q = c_k,        Δ(ζ, q) = (ζ + Δζ, q),
///   Δζ = −(1 + e) σ(ζ^♯)/σ(σ^♯) σ,  σ = dφ_e ∈ Ann(𝔨),  ♯ = Hessian of h,
///
/// plus a Reduction record. The hypotheses are checked there, each failure a
/// located ModelError naming it: codim1 (𝔤 has a codimension-1 ideal: not so(3)),
/// normal (𝔨 = ker dφ_e is an ideal), coset (q' depends on (ζ, q) alone),
/// quadratic (the corollary's reset needs h = ½ ζᵀHζ), reset (Δζ ∈ Ann(𝔨), q ↦ q),
/// transversal (q' does not vanish identically on a surface q = c).
/// derive then computes div, DΔ, Δ⁻¹ and J as for every general model.
///
/// The other target, ReduceTarget::Unreduced, gives the 2n-dimensional impact
/// system on T*G in the group coordinates: H(c, p) = h(ζ) at ζ_i = Σ_j p_j L_ji(c)
/// (ζ = (ℓ_g)^* p), the guards φ(c) − c = c_k and the corner-condition reset of
/// derive (elastic / restitution); for a constrained model, the system on TG in
/// (c, ċ) by Lagrange–d'Alembert in the coordinates with the impulsive
/// constrained impact law (unreduced.cpp). It is the reference the reduction is
/// tested against.

#include <optional>
#include <string>
#include <vector>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/lie.hpp"
#include "hybgen/gen/model.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

/// The reset of one impact, as written (the guards of a lie model).
struct LieImpact {
  ResetDecl::Kind kind = ResetDecl::Kind::Elastic;  ///< Form of the reset.
  GiNaC::ex restitution = 1;                        ///< e (Elastic: 1).
};

/// A checked Lie-group model (output of `check_lie`, check_lie.hpp).
///
/// Invariants: `base` is a checked general Model whose state is the momenta
/// followed by q (its one mode and its guards are placeholders that `reduce`
/// replaces; guard surfaces and explicit resets are already checked in the
/// reduced state); `h` is an expression in the momenta and parameters; `q_expr`
/// in the coordinates and parameters; impacts[k] belongs to base.guards[k].
struct LieModel {
  Model base;              ///< Name, parameters, reduced state, guards, simulation.
  std::string group_name;  ///< The group's name.
  /// The group: g(c), its algebra and left trivialisation (matrix groups), or
  /// only its algebra (groups given by structure constants; no coordinates).
  LieGroup group;
  std::vector<std::string> coordinate_names;  ///< Names of the coordinates c_i (may be empty).
  GiNaC::ex h;                                ///< h(ζ).
  GiNaC::ex q_expr;                ///< q = φ(g) − c in the coordinates (0 without coordinates).
  std::vector<LieImpact> impacts;  ///< One per guard.
  /// Constrained models (`velocities`, `constraint`): ξ_i(w), the body
  /// velocity in terms of the unconstrained velocities w (base's first states);
  /// empty for unconstrained models, whose state starts with the momenta ζ.
  std::vector<GiNaC::ex> xi_of_w;
  GiNaC::matrix inertia;      ///< The inertia I at the identity (constrained models).
  SourceLoc group_loc;        ///< Where the group was declared.
  SourceLoc hamiltonian_loc;  ///< Where h (or the inertia) was given.
  SourceLoc reduced_loc;      ///< Where q was defined.
  /// Groups without coordinates: dφ_e (components in the basis), with
  /// q = φ(g) (Additive) or φ(g) − 1 (Multiplicative); empty for matrix groups,
  /// whose φ is q_expr.
  Components dphi_e;
  HomomorphismKind phi_kind = HomomorphismKind::Additive;  ///< How that φ transforms.
};

/// Which system `reduce` produces.
enum class ReduceTarget {
  Reduced,    ///< The (n+1)-dimensional system on 𝔤* × K\G.
  Unreduced,  ///< The 2n-dimensional impact system on T*G (the twin).
};

/// The reduce stage: LieModel -> general Model (with `reduction` set for the
/// reduced target). Throws ModelError naming the failed hypothesis.
Model reduce(const LieModel& lie, const SourceText& src,
             ReduceTarget target = ReduceTarget::Reduced);

}  // namespace hybgen::gen
