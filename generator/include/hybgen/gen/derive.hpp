#pragma once
/// \file derive.hpp
/// Stage 3 (derive): Model -> HybridSystem IR. The only stage (with emit) that
/// does symbolic mathematics.
///
/// Per mode: X (explicit, or Hamilton's equations q' = ∂H/∂p, p' = −∂H/∂q) and
/// div X = Σ ∂Xⁱ/∂xⁱ. Per guard: ∇s; Δ (identity, explicit, or the corner
/// condition reset p⁺ = p − (1+e) (M⁻¹(ds,p)/M⁻¹(ds,ds)) ds, q⁺ = q); DΔ; Δ⁻¹
/// (closed form when Δ is linear in the variables it changes, else numeric);
/// and the hybrid Jacobian of paper Def. 2.4,
///
///     J(x) = ∇s(x)ᵀ adj(DΔ(x)) X⁺(Δ(x)) / ∇s(x)ᵀ X⁻(x),   x ∈ S,
///
/// which equals docs/design.md's det[DΔ·t₁…DΔ·t_{N−1} | X⁺(Δx)] / det[t₁…t_{N−1} | X⁻(x)]
/// for every basis t of T_xS: both determinants are linear in their last column
/// and vanish on span(t) = ker ∇s, so det[T | v] = κ ∇sᵀv, and
/// det[A T | w] = det(A) det[T | A⁻¹w] = κ ∇sᵀ adj(A) w (a polynomial identity
/// in A, so it holds for singular A too). It needs no basis and no inverse and
/// holds when the vector field changes across the guard (Filippov switching).

#include <vector>

#include "hybgen/gen/model.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

/// Stage 3: derive the IR of a checked model. Throws ModelError when a check
/// fails (flow tangent to a guard everywhere, J ≡ 0, a non-invertible reset,
/// a reset that lands back on a guard it re-triggers (paper H.5), a restitution
/// reset without a natural Hamiltonian). Non-fatal findings go to `warnings`.
HybridSystem derive(const Model& model, const SourceText& src);

/// Simplify an expression: the smallest of e, expand(e) and normal(e).
GiNaC::ex simplify(const GiNaC::ex& e);

/// Whether e is identically zero: exact evaluation at random rational points
/// (rational functions), plus high-precision evaluation for transcendental ones
/// and for numeric powers too large to compute exactly (kMaxExactBits). False
/// when no point could be evaluated (a pole or an overflow at every one).
bool is_identically_zero(const GiNaC::ex& e, const std::vector<GiNaC::ex>& symbols);

/// Number of nodes of an expression tree (a size measure).
std::size_t expr_size(const GiNaC::ex& e);

}  // namespace hybgen::gen
