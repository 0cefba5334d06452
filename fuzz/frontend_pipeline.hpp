#pragma once
/// \file frontend_pipeline.hpp
/// The front end as the fuzzer (fuzz/fuzz_frontend.cpp) and the regression
/// tests (tests/gen/test_fuzz_regressions.cpp) drive it: SourceText (validate)
/// -> parse -> check -> derive, with the fuzzing resource caps.
///
/// Size caps, so that the fuzzer cannot hang on input that is legitimately
/// expensive to differentiate, expand and simplify (real expression-size and
/// time limits inside derive are a later part of issue 5, "derivation
/// limits"; until then derive has none):
///  - inputs longer than kMaxInputBytes (4 KiB) are skipped;
///  - derive is skipped when the model has more than kMaxStates (6) state
///    variables, or when an expression of the checked model (parameter value,
///    flow component, Hamiltonian, region, guard surface, reset, restitution
///    coefficient, initial density, support) has more than kMaxExprNodes (200)
///    nodes (hybgen::gen::expr_size), or a subexpression whose expansion has
///    more than kMaxExpandedTerms (10^4) terms by the estimate of
///    expanded_terms(): (x+y+z+w)^4096 is 9 nodes, but derive's simplify()
///    expands it, and GiNaC asks for 183 GB at once.
/// Guard for an open finding (Guards::All only; the regression tests run
/// without it):
///  - F1b: derive is skipped when an expression has a numeric exponent other
///    than a/b with |a|, b ≤ kMaxExponent (4096). check bounds every exponent
///    as written, but GiNaC folds (x^a)^b into x^(a*b), so
///    ((x^4096)^4096)^4096 is x^(2^36) after check, and derive's
///    is_identically_zero raises random rationals to that power exactly.
/// Parse and check always run (they must be cheap on any input of ≤ 4 KiB).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/parse.hpp"

namespace hybgen::fuzz {

inline constexpr std::size_t kMaxInputBytes = 4096;
inline constexpr std::size_t kMaxStates = 6;
inline constexpr std::size_t kMaxExprNodes = 200;
inline constexpr double kMaxExpandedTerms = 1e4;
inline constexpr long kMaxExponent = 4096;

/// Which caps to apply: all (the fuzzer), or the size caps only (the
/// regression tests, so that they run the open findings' inputs unguarded).
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

/// Estimated number of terms of expand(e) (an upper estimate for
/// polynomials: sums add, products multiply, (k terms)^n has at most
/// C(n+k-1, k-1) monomials); saturates at 1e300.
inline double expanded_terms(const GiNaC::ex& e) {
  constexpr double kInf = 1e300;
  if (GiNaC::is_a<GiNaC::add>(e)) {
    double s = 0;
    for (std::size_t i = 0; i < e.nops(); ++i) s += expanded_terms(e.op(i));
    return std::min(s, kInf);
  }
  if (GiNaC::is_a<GiNaC::mul>(e)) {
    double p = 1;
    for (std::size_t i = 0; i < e.nops(); ++i) p = std::min(p * expanded_terms(e.op(i)), kInf);
    return p;
  }
  if (GiNaC::is_a<GiNaC::power>(e)) {
    const double k = expanded_terms(e.op(0));
    if (GiNaC::is_a<GiNaC::numeric>(e.op(1)) &&
        GiNaC::ex_to<GiNaC::numeric>(e.op(1)).is_pos_integer() && k > 1) {
      const double n = GiNaC::ex_to<GiNaC::numeric>(e.op(1)).to_double();
      const double log_c = std::lgamma(n + k) - std::lgamma(k) - std::lgamma(n + 1);
      return log_c > std::log(kInf) ? kInf : std::exp(log_c);
    }
    return k;
  }
  return 1;  // symbols, numbers, functions (their arguments are looked at on their own)
}

namespace detail {

/// Whether some subexpression of e expands to more than kMaxExpandedTerms terms.
inline bool expands_too_far(const GiNaC::ex& e) {
  if (expanded_terms(e) > kMaxExpandedTerms) return true;
  for (std::size_t i = 0; i < e.nops(); ++i)
    if (expands_too_far(e.op(i))) return true;
  return false;
}

/// Whether a power in e has a numeric exponent outside a/b, |a|, b ≤ kMaxExponent.
inline bool has_huge_exponent(const GiNaC::ex& e) {
  if (GiNaC::is_a<GiNaC::power>(e) && GiNaC::is_a<GiNaC::numeric>(e.op(1))) {
    const auto& n = GiNaC::ex_to<GiNaC::numeric>(e.op(1));
    if (!n.is_rational() || GiNaC::abs(n.numer()) > kMaxExponent || n.denom() > kMaxExponent)
      return true;
  }
  for (std::size_t i = 0; i < e.nops(); ++i)
    if (has_huge_exponent(e.op(i))) return true;
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

/// Whether an expression of the checked model has an exponent beyond
/// kMaxExponent (open finding F1b).
inline bool has_huge_exponent(const gen::Model& m) {
  bool huge = false;
  for_each_expression(m, [&](const GiNaC::ex& e) { huge = huge || detail::has_huge_exponent(e); });
  return huge;
}

/// Run the front end on `text` (as file "fuzz.model"). Throws what the stages
/// throw: hybgen::gen::Error (other than InternalError) is the expected
/// outcome for bad input; anything else is a bug.
inline Stage run_frontend(std::string_view text, Guards guards = Guards::All) {
  if (text.size() > kMaxInputBytes) return Stage::Skipped;
  gen::SourceText src("fuzz.model", std::string(text));
  src.validate();
  gen::ModelAst ast = gen::parse(src);
  gen::Model model = gen::check(ast, src);
  if (!within_derive_caps(model)) return Stage::Checked;
  if (guards == Guards::All && has_huge_exponent(model)) return Stage::Checked;
  gen::HybridSystem sys = gen::derive(model, src);
  sys.model = &model;
  return Stage::Derived;
}

}  // namespace hybgen::fuzz
