#pragma once
/// \file overrides_pipeline.hpp
/// `hybgen run --set KEY=VALUE` as the fuzzer (fuzz/fuzz_overrides.cpp) and
/// the regression tests (tests/gen/test_fuzz_regressions.cpp) drive it: the
/// first line of the input is a grid literal for parse_grid; every non-empty
/// line is one --set argument for apply_overrides on a fixed checked model
/// (two parameters and every simulation setting).
///
/// Expected: success, or a hybgen::gen::Error that is not an InternalError
/// (normally a UsageError, exit 2). Anything else is a finding — and so is an
/// accepted override that leaves the model in a state the runner cannot use
/// (a non-finite parameter, t_end/dt/tol out of range, an empty domain, a grid
/// axis < 2 nodes): that would be a silent wrong answer later.

#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/rt/method_table.hpp"

namespace hybgen::fuzz {

inline constexpr std::size_t kMaxOverrideBytes = 4096;

/// The checked model the overrides apply to.
inline const gen::Model& overrides_base_model() {
  static const gen::Model m = [] {
    const char* const text = R"(model overrides
parameter m = 1, e = 0.5
state x, p
mode flight { hamiltonian p^2/(2*m) + x }
guard ground { when x = 0 decreasing  reset restitution e }
simulation {
  domain x in [0, 2]
  domain p in [-2, 2]
  grid 9x9
  initial exp(-(x-1)^2 - p^2)
  t_end 1
  dt 0.1
  tol 1e-8
  max_events 100
  method characteristics
}
)";
    gen::SourceText src("overrides.model", text);
    return gen::check(gen::parse(src), src);
  }();
  return m;
}

/// What is wrong with a model after accepted overrides ("" if nothing).
inline std::string override_invariant_violation(const gen::Model& m) {
  const auto& s = m.sim;
  const auto& k = s.settings;
  for (const auto& p : m.params)
    if (!std::isfinite(p.value_d)) return "non-finite parameter " + p.name + " accepted";
  // Written out by hand, not from the settings table (runtime/include/hybgen/rt/settings.hpp),
  // so that a wrong row in the table is caught too.
  const double t_end = k.real<"t_end">(), dt = k.real<"dt">(), tol = k.real<"tol">();
  const double step = k.real<"step">();
  if (!(t_end > 0) || !std::isfinite(t_end)) return "bad t_end accepted";
  if (!(dt > 0) || !std::isfinite(dt)) return "bad dt accepted";
  if (!(tol > 0 && tol < 1)) return "bad tol accepted";
  if (k.integer<"max_events">() < 1) return "bad max_events accepted";
  if (s.grid.size() != m.state.size()) return "grid rank changed";
  double nodes = 1;
  for (long n : s.grid) nodes *= static_cast<double>(n);
  if (nodes > static_cast<double>(gen::kMaxGridNodes)) return "grid above the node limit accepted";
  if (k.integer<"particles">() < 1 || k.integer<"seed">() < 0 || step < 0 || !std::isfinite(step))
    return "bad particles/seed/step accepted";
  if (k.integer<"eigenvalues">() < 1 || k.integer<"eigenvalues">() > 64)
    return "bad eigenvalues accepted";
  if (!rt::find_method(k.word<"method">())) return "unknown method accepted";
  const std::string& scheme = k.word<"scheme">();
  if (scheme != "auto" && scheme != "hat" && scheme != "cell" && scheme != "fv")
    return "unknown scheme accepted";
  if (k.integer<"samples">() < 0 || k.integer<"samples">() > 64) return "bad samples accepted";
  if (!(m.limits.derive_seconds > 0) || m.limits.max_expr_nodes < 1 ||
      !(m.limits.max_expand_terms >= 1))
    return "bad derivation limit accepted";
  for (long n : s.grid)
    if (n < 2) return "grid axis < 2 accepted";
  for (std::size_t i = 0; i < s.lo.size(); ++i)
    if (!(s.lo[i] < s.hi[i]) || !std::isfinite(s.lo[i]) || !std::isfinite(s.hi[i]))
      return "bad domain of " + m.state[i] + " accepted";
  return "";
}

/// The first line of `text`.
inline std::string first_line(std::string_view text) {
  return std::string(text.substr(0, text.find('\n')));
}

/// The non-empty lines of `text` (an empty --set never reaches
/// apply_overrides: the CLI's KEY=VALUE option needs a value).
inline std::vector<std::string> override_lines(std::string_view text) {
  std::vector<std::string> sets;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t nl = text.find('\n', start);
    if (nl == std::string_view::npos) nl = text.size();
    if (nl > start) sets.emplace_back(text.substr(start, nl - start));
    start = nl + 1;
  }
  return sets;
}

/// parse_grid on the first line; "" or what is wrong with an accepted grid.
/// Throws what parse_grid throws.
inline std::string run_parse_grid(std::string_view text) {
  const std::vector<long> g = gen::parse_grid(first_line(text));
  if (g.empty()) return "parse_grid accepted an empty grid";
  for (long n : g)
    if (n < 2) return "parse_grid accepted an axis < 2";
  return "";
}

/// apply_overrides with every line; "" or what is wrong with the accepted
/// model. Throws what apply_overrides throws.
inline std::string run_overrides(std::string_view text) {
  gen::Model m = overrides_base_model();
  gen::apply_overrides(m, override_lines(text));
  return override_invariant_violation(m);
}

}  // namespace hybgen::fuzz
