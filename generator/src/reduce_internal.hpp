#pragma once
// Internals shared by the reduce stage's two targets (reduce.cpp: the reduced
// system; unreduced.cpp: the twin on T*G). Not part of the public API.

#include <string>

#include "hybgen/gen/reduce.hpp"
#include "hybgen/gen/tex.hpp"

namespace hybgen::gen::reduce_detail {

/// GiNaC's printing of e (for messages).
std::string str(const GiNaC::ex& e);

/// The located ModelError of a failed hypothesis of the reduction.
ModelError hypothesis_error(const SourceText& src, SourceLoc loc, const LieError& e);

/// s(q) of a guard, checked to be a function of q (and parameters) only.
void require_level_set(const LieModel& lm, const GuardSpec& g, const SourceText& src);

/// The unreduced twin: the 2n-dimensional impact system on T*G.
/// For a constrained (nonholonomic) model it is the 2n-dimensional system on TG
/// in the state (c, ċ), derived in the coordinates without the Lie algebra
/// (Lagrange–d'Alembert): kinetic energy ½ ċᵀM(c)ċ with M = L⁻ᵀ I L⁻¹ (ξ = L⁻¹ċ),
/// constraint rows A(c) = C L⁻¹ (C ξ = 0 annihilates the allowed ξ = B w),
///     c' = ċ,  M c̈ = F + Aᵀλ,  F = ∂(½ċᵀMċ)/∂c − Ṁ ċ,
///     λ = −(A M⁻¹ Aᵀ)⁻¹ (A M⁻¹ F + Ȧ ċ)   (so d/dt (A ċ) = 0),
/// and at a guard s(c) = 0 the impulsive Lagrange–d'Alembert reset
///     ċ ↦ ċ + Δċ,  M Δċ = μ dsᵀ + Aᵀν,  A Δċ = 0,  ds·Δċ = −(1 + e) ds·ċ.
/// Explicit resets (written in the reduced state) are refused for it.
Model unreduced(const LieModel& lm, const SourceText& src);

}  // namespace hybgen::gen::reduce_detail
