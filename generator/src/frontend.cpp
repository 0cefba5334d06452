// The front end as one function of the source (frontend.hpp): the order of the stages, the
// overrides between check and derive, and the watchdogs around the symbolic stages.

#include "hybgen/gen/frontend.hpp"

#include <chrono>
#include <optional>
#include <ostream>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/check_lie.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/limits.hpp"
#include "hybgen/gen/parse.hpp"

namespace hybgen::gen {

Frontend::Frontend(SourceText source, const FrontendOptions& options)
    : src(std::move(source)), sets(options.sets) {
  const auto t0 = std::chrono::steady_clock::now();
  src.validate();
  const ModelAst ast = parse(src);  // stage 1: text -> AST
  lie = is_lie_model(ast);
  if (lie) {
    if (options.before_lie && !options.before_lie(ast)) return;
    std::optional<Watchdog> w;  // armed around each symbolic stage when options.watchdog
    if (options.watchdog) w.emplace(src.path(), DeriveLimits{}.derive_seconds);
    const LieModel lm = check_lie(ast, src);  // stage 2: AST -> LieModel
    w.reset();
    if (options.watchdog) w.emplace(src.path(), lm.base.limits.derive_seconds);
    model = reduce(lm, src, options.target);  // LieModel -> Model (general kind)
  } else {
    if (options.target == ReduceTarget::Unreduced)
      throw UsageError("--unreduced applies to Lie-group models only ('" + src.path() +
                       "' is a general model)");
    model = check(ast, src);  // stage 2: AST -> Model
  }
  for (const auto& p : model.params) file_params.push_back(p.value_d);
  apply_overrides(model, options.sets);  // --set KEY=VALUE
  stage = FrontendStage::Checked;
  if (options.before_derive && !options.before_derive(model)) return;
  {
    // A single GiNaC operation cannot be interrupted: past the derivation's own budget
    // (checked between operations) the watchdog ends the process with a located error
    // naming the object being derived.
    std::optional<Watchdog> w;
    if (options.watchdog) w.emplace(src.path(), model.limits.derive_seconds);
    sys = derive(model, src);  // stage 3: Model -> IR
  }
  sys.model = &model;
  stage = FrontendStage::Derived;
  seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void Frontend::print_warnings(std::ostream& os) const {
  for (const auto& w : sys.warnings) os << src.warning(w.loc, w.text) << "\n";
}

}  // namespace hybgen::gen
