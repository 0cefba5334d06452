#pragma once
/// \file parse.hpp
/// Stage 1 (parse): the text of a `.model` file -> ModelAst, by a hand-written
/// lexer and recursive-descent parser that implement docs/model-language.md.
///
/// The parser is purely syntactic: names, duplicates of list items, arities and
/// meanings are left to `check`. It rejects only what the grammar rejects, plus
/// what the AST cannot represent: a second `model` statement, a second
/// `simulation` block, and a second `hamiltonian`/`coordinates`/`momenta` in a
/// mode, `from`/`to`/`when`/`reset` in a guard or `grid` in the simulation.
///
/// Positions (SourceLoc, 1-based, columns in bytes) recorded in the AST:
/// - Number, Symbol, Call: the first character of the literal / name;
/// - Unary: the operator; Binary: where its left operand's text starts,
///   parentheses included, so that errors point at the start of the
///   expression: `(a+b)*c` is at the `(`, its inner `a+b` at the `a`
///   (parentheses around a node are not part of the node's own position);
/// - Relation and setting values: where the left side's / value's text starts
///   (parentheses included);
/// - names, keywords (`hamiltonian`, `reset`, `initial`, `simulation`), the
///   direction word, the `(` of explicit resets and grid literals: their first
///   character.
///
/// Other choices, within the grammar:
/// - `**` is stored as the operator "^"; a number may also be written `1.`;
/// - a setting whose whole value is one identifier (`method characteristics`)
///   gets both `Setting::word` and `Setting::value` (a Symbol), so that check
///   can take either a word or a number (a parameter name);
/// - expressions may nest at most 256 levels (parentheses, signs, powers) and
///   their trees may be at most 512 levels deep (e.g. a sum of 512 terms), so
///   that no input can exhaust the stack.

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

/// Stage 1 (parse): .model text -> AST. Throws ModelError at the first error.
ModelAst parse(const SourceText& src);

/// One `observe NAME = [MODE:] EXPR` item as the whole text (`--set observe.NAME=EXPR`, its
/// '.' read as a space, so that columns are the argument's). Throws ModelError.
ObserveDecl parse_observe(const SourceText& src);

}  // namespace hybgen::gen
