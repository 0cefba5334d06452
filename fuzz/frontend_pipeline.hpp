#pragma once
/// \file frontend_pipeline.hpp
/// The front end as the fuzzer (fuzz/fuzz_frontend.cpp) and the regression
/// tests (tests/gen/test_fuzz_regressions.cpp) drive it, with the fuzzing
/// resource caps:
///   general models:   SourceText (validate) -> parse -> check -> derive;
///   Lie-group models: SourceText (validate) -> parse -> check_lie -> reduce
///                     -> derive (ReduceTarget::Reduced), then the unreduced
///                     twin: reduce (ReduceTarget::Unreduced) -> derive.
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
///    expanded_terms(): (x+y+z+w)^4096 is 9 nodes, but 10^10 terms expanded;
///  - Lie-group models: check_lie and reduce are skipped (Stage::Parsed) when
///    the group has more than kMaxLieDim (9, gl(3)) dimensions or a matrix
///    larger than kMaxGroupMatrix (4×4), or when an expression of the Lie
///    statements (group matrix, identity point, brackets, Hamiltonian,
///    inertia, metric, reduced coordinate, constraints) has more than
///    kMaxExprNodes AST nodes. check_lie and reduce invert and normalise
///    symbolic n×n matrices (the left trivialisation, the inertia, the
///    Hessian of h) with no limits of their own (hybgen/gen/limits.hpp
///    covers derive only), so these caps are what bounds their time here.
///    The unreduced twin (2n states) is derived under the same caps as any
///    model: for n ≤ 3 only.
/// derive's own limits (hybgen/gen/limits.hpp) end such derivations with a
/// located model error; these caps only keep the fuzzer fast.
/// Parse and check always run (they must be cheap on any input of ≤ 4 KiB).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/frontend.hpp"
#include "hybgen/gen/limits.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/gen/reduce.hpp"

namespace hybgen::fuzz {

inline constexpr std::size_t kMaxInputBytes = 4096;
inline constexpr std::size_t kMaxStates = 6;
inline constexpr std::size_t kMaxExprNodes = 200;
inline constexpr double kMaxExpandedTerms = 1e4;
/// Largest group dimension (gl(3)) for which check_lie and reduce run.
inline constexpr std::size_t kMaxLieDim = 9;
/// Largest matrix g(c) (N×N) of a parametrised group for which they run.
inline constexpr std::size_t kMaxGroupMatrix = 4;

/// Which caps to apply. Both are the size caps today; `All` would also hold
/// guards for open findings (inputs whose fix is not in yet), so that the
/// fuzzer skips them while the regression tests (SizeOnly) run them unguarded.
enum class Guards { All, SizeOnly };

/// How far the pipeline got: Skipped (too long), Parsed (a Lie-group model
/// beyond the Lie caps), Checked (checked, and for Lie-group models reduced,
/// but beyond the derive caps), Derived.
enum class Stage { Skipped, Parsed, Checked, Derived };

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

/// Number of nodes of an AST expression (0 for null).
inline std::size_t ast_size(const gen::ExprPtr& e) {
  if (!e) return 0;
  std::size_t n = 1;
  for (const auto& a : e->args) n += ast_size(a);
  return n;
}

namespace detail {

// The Lie statements grow (structure constants, `metric`): the members that
// not every version of ast.hpp has are reached through requires-expressions,
// so that this header compiles with and without them.

/// Basis size of `group G = algebra(E1, ..., En) { ... }` (0 otherwise).
template <class G>
std::size_t algebra_basis_size(const G& g) {
  if constexpr (requires { g.basis.size(); })
    return g.basis.size();
  else
    return 0;
}

/// Call f on every bracket value of an `algebra` group.
template <class G, class F>
void for_each_bracket(const G& g, F&& f) {
  if constexpr (requires { g.brackets; })
    for (const auto& b : g.brackets) f(b.value);
}

/// Call f on every entry of the `metric` matrix, if the model has one.
template <class L, class F>
void for_each_metric_entry(const L& lie, F&& f) {
  if constexpr (requires { lie.metric; })
    if (lie.metric)
      for (const auto& row : lie.metric->rows)
        for (const auto& e : row) f(e);
}

}  // namespace detail

/// Whether the Lie statements are within the caps for check_lie and reduce.
inline bool within_lie_caps(const gen::LieDecl& lie) {
  const gen::GroupDecl& g = lie.group;
  const auto n = static_cast<std::size_t>(std::clamp(g.shortcut_n, 0L, 64L));
  const std::size_t dim =
      g.shortcut == "gl" ? n * n : std::max(g.coordinates.size(), detail::algebra_basis_size(g));
  if (dim > kMaxLieDim || g.matrix.rows.size() > kMaxGroupMatrix) return false;
  if (lie.momenta.size() > kMaxLieDim || lie.velocities.size() > kMaxLieDim) return false;
  bool ok = true;
  auto small = [&ok](const gen::ExprPtr& e) { ok = ok && ast_size(e) <= kMaxExprNodes; };
  for (const auto& row : g.matrix.rows) {
    ok = ok && row.size() <= kMaxGroupMatrix;
    for (const auto& e : row) small(e);
  }
  for (const auto& e : g.identity) small(e);
  detail::for_each_bracket(g, small);
  small(lie.hamiltonian);
  if (lie.inertia) {
    ok = ok && lie.inertia->rows.size() <= kMaxLieDim;
    for (const auto& row : lie.inertia->rows) {
      ok = ok && row.size() <= kMaxLieDim;
      for (const auto& e : row) small(e);
    }
  }
  detail::for_each_metric_entry(lie, small);
  small(lie.reduced_expr);
  for (const auto& c : lie.constraints) small(c.rhs);
  return ok;
}

/// The front end's options with the caps: check_lie and reduce only within the Lie caps,
/// derive only within the derive caps and with derive_seconds below the fuzzer's
/// -timeout=10 (a hang is a finding).
inline gen::FrontendOptions capped_options(gen::ReduceTarget target) {
  gen::FrontendOptions o;
  o.target = target;
  o.sets = {"derive_seconds=5"};
  o.before_lie = [](const gen::ModelAst& ast) { return within_lie_caps(*ast.lie); };
  o.before_derive = [](const gen::Model& m) { return within_derive_caps(m); };
  return o;
}

/// How far `fe` went, as a Stage.
inline Stage stage_of(const gen::Frontend& fe) {
  switch (fe.stage) {
    case gen::FrontendStage::Parsed:
      return Stage::Parsed;
    case gen::FrontendStage::Checked:
      return Stage::Checked;
    case gen::FrontendStage::Derived:
      return Stage::Derived;
  }
  return Stage::Parsed;
}

/// Run the front end (hybgen/gen/frontend.hpp) on `text` (as file "fuzz.model"), and for a
/// Lie-group model within the caps its unreduced twin too. Returns the stage of the
/// (reduced) model. Throws what the stages throw: hybgen::gen::Error (other than
/// InternalError) is the expected outcome for bad input; anything else is a bug.
inline Stage run_frontend(std::string_view text, [[maybe_unused]] Guards guards = Guards::All) {
  if (text.size() > kMaxInputBytes) return Stage::Skipped;
  const gen::SourceText src("fuzz.model", std::string(text));
  const gen::Frontend fe(src, capped_options(gen::ReduceTarget::Reduced));
  if (fe.lie && fe.stage != gen::FrontendStage::Parsed)
    const gen::Frontend twin(src, capped_options(gen::ReduceTarget::Unreduced));
  return stage_of(fe);
}

}  // namespace hybgen::fuzz
