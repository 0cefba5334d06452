#pragma once
/// \file check_lie.hpp
/// Stage 2 for Lie-group models (check_lie.cpp): AST -> LieModel, the input of
/// the reduce stage (reduce.hpp, which states the theorem and its hypotheses).
/// The parts a Lie-group model shares with general models are checked by
/// `check` (check.hpp) with the same rules and messages.

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/reduce.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

/// Whether the AST is a Lie-group model (it has a `group`, `momenta`,
/// `hamiltonian`, `inertia` or `reduced` statement).
bool is_lie_model(const ModelAst& ast);

/// Stage 2 for Lie-group models: resolve names, build the group (hypothesis
/// lie_algebra), convert h and q. Throws ModelError.
LieModel check_lie(const ModelAst& ast, const SourceText& src);

}  // namespace hybgen::gen
