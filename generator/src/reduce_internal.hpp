#pragma once
// Internals shared by the reduce stage's two targets (reduce.cpp: the reduced
// system; unreduced.cpp: the twin on T*G). Not part of the public API.

#include <string>

#include "hybgen/gen/reduce.hpp"

namespace hybgen::gen::reduce_detail {

/// GiNaC's printing of e (for messages).
std::string str(const GiNaC::ex& e);

/// The located ModelError of a failed hypothesis of the reduction.
ModelError hypothesis_error(const SourceText& src, SourceLoc loc, const LieError& e);

/// s(q) of a guard, checked to be a function of q (and parameters) only.
void require_level_set(const LieModel& lm, const GuardSpec& g, const SourceText& src);

/// TeX name like check's: zeta1 -> \zeta_{1}, a11 -> a_{11}, p_a11 -> p_{a11}.
std::string tex_of(const std::string& nm);

/// The unreduced twin: the 2n-dimensional impact system on T*G.
Model unreduced(const LieModel& lm, const SourceText& src);

}  // namespace hybgen::gen::reduce_detail
