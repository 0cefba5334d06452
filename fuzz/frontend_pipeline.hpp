#pragma once
/// \file frontend_pipeline.hpp
/// The front end as the fuzzer (fuzz/fuzz_frontend.cpp) and the regression
/// tests (tests/gen/test_fuzz_regressions.cpp) drive it: SourceText (validate)
/// -> parse -> check -> derive, with the fuzzing resource caps.
///
/// Size caps, so that the fuzzer does not spend its time on input that is
/// legitimately expensive to differentiate, expand and simplify:
///  - inputs longer than kMaxInputBytes (4 KiB) are skipped;
///  - derive is skipped when the model has more than kMaxStates (6) state
///    variables, or when an expression of the checked model (parameter value,
///    flow component, Hamiltonian, region, guard surface, reset, restitution
///    coefficient, initial density, support) has more than kMaxExprNodes (200)
///    nodes (hybgen::gen::expr_size), or a subexpression whose expansion has
///    more than kMaxExpandedTerms (10^4) terms by the estimate of
///    expanded_terms(): (x+y+z+w)^4096 is 9 nodes, but 10^10 terms expanded.
/// derive's own limits (hybgen/gen/limits.hpp) end such derivations with a
/// located model error; these caps only keep the fuzzer fast.
/// Parse and check always run (they must be cheap on any input of ≤ 4 KiB).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/limits.hpp"
#include "hybgen/gen/parse.hpp"

namespace hybgen::fuzz {

inline constexpr std::size_t kMaxInputBytes = 4096;
inline constexpr std::size_t kMaxStates = 6;
inline constexpr std::size_t kMaxExprNodes = 200;
inline constexpr double kMaxExpandedTerms = 1e4;

/// Which caps to apply. Both are the size caps today; `All` would also hold
/// guards for open findings (inputs whose fix is not in yet), so that the
/// fuzzer skips them while the regression tests (SizeOnly) run them unguarded.
enum class Guards { All, SizeOnly };

/// How far the pipeline got.
enum class Stage { Skipped, Checked, Derived };

/// Call f on every expression of the checked model.
template <class F>
void for_each_expression(const gen::Model& m, F&& f) {
  for (const auto& p : m.params) f(p.value);
  for (const auto& md : m.modes) {
    for (const auto& e : md.flow) f(e);
    if (md.hamiltonian) f(*md.hamiltonian);
    for (const auto& c : md.where) f(c.expr);
  }
  for (const auto& g : m.guards) {
    f(g.surface);
    f(g.restitution);
    for (const auto& r : g.reset) f(r);
  }
  for (const auto& e : m.sim.initial) f(e);
  for (const auto& c : m.sim.support) f(c.expr);
}

/// Estimated number of terms of expand(e) (hybgen::gen::expanded_terms).
inline double expanded_terms(const GiNaC::ex& e) {
  return gen::expanded_terms(e);
}

namespace detail {

/// Whether some subexpression of e expands to more than kMaxExpandedTerms terms.
inline bool expands_too_far(const GiNaC::ex& e) {
  if (expanded_terms(e) > kMaxExpandedTerms) return true;
  for (std::size_t i = 0; i < e.nops(); ++i)
    if (expands_too_far(e.op(i))) return true;
  return false;
}

}  // namespace detail

/// Whether the checked model is within the size caps for derive.
inline bool within_derive_caps(const gen::Model& m) {
  if (m.state.size() > kMaxStates) return false;
  bool ok = true;
  for_each_expression(m, [&](const GiNaC::ex& e) {
    ok = ok && gen::expr_size(e) <= kMaxExprNodes && !detail::expands_too_far(e);
  });
  return ok;
}

/// Run the front end on `text` (as file "fuzz.model"). Throws what the stages
/// throw: hybgen::gen::Error (other than InternalError) is the expected
/// outcome for bad input; anything else is a bug.
inline Stage run_frontend(std::string_view text, [[maybe_unused]] Guards guards = Guards::All) {
  if (text.size() > kMaxInputBytes) return Stage::Skipped;
  gen::SourceText src("fuzz.model", std::string(text));
  src.validate();
  gen::ModelAst ast = gen::parse(src);
  gen::Model model = gen::check(ast, src);
  if (!within_derive_caps(model)) return Stage::Checked;
  model.limits.derive_seconds = 5;  // below the fuzzer's -timeout=10: a hang is a finding
  gen::HybridSystem sys = gen::derive(model, src);
  sys.model = &model;
  return Stage::Derived;
}

}  // namespace hybgen::fuzz
