#pragma once
/// \file frontend.hpp
/// The front half of the pipeline, once for every caller (the CLI, the tests, the fuzzer):
///
///   SourceText --parse--> ModelAst --check--------------------> Model --(--set)--> derive --> IR
///                                  \-check_lie--> LieModel --reduce-/
///
/// A Frontend owns the source, the checked model and the IR together, so that the IR's
/// pointer to its model (HybridSystem::model) and the model's locations into the source
/// stay valid for as long as any of them is used. docs/design.md, "Pipeline", lists the
/// stages and their files.

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/model.hpp"
#include "hybgen/gen/reduce.hpp"
#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

/// How far the front end went: a caller's cap (FrontendOptions) may stop it early.
enum class FrontendStage {
  Parsed,   ///< A Lie-group model that before_lie refused: only the AST exists.
  Checked,  ///< Checked (a Lie-group model: reduced) and overridden, not derived.
  Derived,  ///< The IR exists.
};

/// What the front end is asked to do besides parse, check and derive.
struct FrontendOptions {
  /// Lie-group models: the reduced system or its 2n-dimensional twin (`--unreduced`).
  ReduceTarget target = ReduceTarget::Reduced;
  /// `--set KEY=VALUE` overrides, applied to the checked model before derive.
  std::vector<std::string> sets;
  /// Arm the derivation watchdog (limits.hpp), which ends the process with a located
  /// error when one GiNaC operation overruns: the CLI's choice; tests and the fuzzer leave
  /// it off (the fuzzer has its own timeout).
  bool watchdog = false;
  /// Called on a Lie-group model's AST before check_lie; false stops at Parsed.
  std::function<bool(const ModelAst&)> before_lie;
  /// Called on the checked, overridden model before derive; false stops at Checked.
  std::function<bool(const Model&)> before_derive;
};

/// A model's source, its checked model and its IR. Not copyable: sys.model points at model.
class Frontend {
 public:
  /// Run the stages on `src`; throws what they throw (ModelError, UsageError for an
  /// `--unreduced` general model or a bad `--set`).
  explicit Frontend(SourceText src, const FrontendOptions& options = {});
  Frontend(const Frontend&) = delete;             ///< sys.model would dangle.
  Frontend& operator=(const Frontend&) = delete;  ///< sys.model would dangle.

  SourceText src;                   ///< The model text.
  Model model;                      ///< Checked (reduced for `lie`), with the overrides.
  HybridSystem sys;                 ///< The IR (stage Derived only); sys.model == &model.
  std::vector<double> file_params;  ///< The parameters' values as in the file, before --set.
  std::vector<std::string> sets;    ///< The `--set KEY=VALUE` overrides applied, in order.
  FrontendStage stage = FrontendStage::Parsed;  ///< How far the stages went.
  bool lie = false;                             ///< Whether the model is a Lie-group model.
  double seconds = 0;                           ///< Wall time of the stages.

  /// The derivation's warnings: `PATH:LINE:COL: warning: …` with the source line and a
  /// caret (`PATH: warning: …` for one about the model as a whole).
  void print_warnings(std::ostream& os) const;
};

}  // namespace hybgen::gen
