#pragma once
/// \file check_internal.hpp
/// Helpers of stage 2 (check.cpp) shared with the Lie-group checker
/// (check_lie.cpp). Internal to the generator library: not a public header.

#include <ginac/ginac.h>

#include <map>
#include <optional>
#include <string>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen::detail {

/// Convert an AST expression to an exact GiNaC expression with the names of
/// `scope` visible (check's Converter: exact decimals, bounded exponents,
/// located errors); `what` names the expression in messages ("the Hamiltonian").
GiNaC::ex convert_expression(const SourceText& src, const std::map<std::string, GiNaC::ex>& scope,
                             const std::string& what, const ExprPtr& e);

/// A constant expression as a finite double, or nullopt.
std::optional<double> finite_double(const GiNaC::ex& e);

}  // namespace hybgen::gen::detail
