#pragma once
/// \file check.hpp
/// Stage 2 (check): AST -> Model. Resolves every name, turns expressions into
/// exact GiNaC expressions, evaluates defaults, and rejects anything wrong with
/// a located ModelError. Also applies `--set KEY=VALUE` overrides.

#include <string>
#include <vector>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/model.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

/// Stage 2: check the AST of `src` and build the Model. Throws ModelError.
Model check(const ModelAst& ast, const SourceText& src);

/// Apply `KEY=VALUE` overrides: a parameter name, or one of grid, t_end, dt,
/// method, tol, max_events, and `domain.X=[a,b]`. Throws UsageError.
void apply_overrides(Model& model, const std::vector<std::string>& sets);

/// The simulation settings `--set` accepts (for help texts and errors).
const std::vector<std::string>& setting_names();

/// A setting's value as written: a number, or a word (e.g. a method name).
using SettingValue = rt::SettingValue;

/// Whether `key` is a row of the settings table (runtime/include/hybgen/rt/settings.hpp);
/// grid and domain.X are handled separately.
bool is_simulation_setting(const std::string& key);

/// Set one setting of `model` (the same rules for the model file's simulation block and for
/// --set: the table's). Returns "" on success, else why the value is invalid (the caller
/// adds where).
std::string set_simulation_setting(Model& model, const std::string& key, const SettingValue& v);

/// Parse a grid literal such as "75x75" (UsageError if malformed).
std::vector<long> parse_grid(const std::string& text);

/// Most grid nodes a run may have (2^28: one float64 frame is then 2 GiB).
inline constexpr long kMaxGridNodes = 1L << 28;

/// Why a grid with these node counts cannot be run, or "": too many nodes, or with
/// `marginals` (density=marginals: only the pairs of axes are held) too many pair nodes.
std::string grid_size_problem(const std::vector<long>& counts, bool marginals = false);

/// Whether the run keeps marginals only (the setting density=marginals).
bool marginals_only(const Simulation& sim);

/// Exact rational of a decimal literal ("0.25" -> 1/4, "1e-3" -> 1/1000).
GiNaC::numeric exact_number(const std::string& literal);

}  // namespace hybgen::gen
