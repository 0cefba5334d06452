#pragma once
/// \file method_table.hpp
/// The methods of `hybgen run`, defined once. `kMethods` is the table (name, what the
/// method needs, what it writes, where its fields go in summary.json); everything else
/// reads it:
///  - the words of the setting `method` (settings.hpp, `kMethodWords`, built from the names);
///  - the dispatcher (methods/methods.hpp, `solve_method`: one solve function per entry, in
///    the table's order);
///  - the rules that relate the method to other settings (setting_rules.hpp: a method that
///    inverts the resets, one that deposits marginals);
///  - the run's chain (runner.hpp), the writers (runtime/src/io/) and `hybgen sweep`'s table
///    (generator/src/sweep.cpp), which read the method's block of summary.json by
///    `summary_key`.
/// The settings a method reads are the rows of the settings table that name it
/// (settings.hpp, `SettingSpec::methods`); `method_reads` answers from there.
///
/// Adding a method: an entry here, its solve function in methods/ and its entry in
/// `solvers` (methods/methods.hpp) — docs/design.md, "Adding a method".

#include <array>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace hybgen::rt {

/// summary.json's members, named once: the runner writes them (runner.hpp), the writers
/// (runtime/src/io/), `hybgen sweep` (generator/src/sweep.cpp) and the tests read them.
namespace summary_key {
inline constexpr const char* model = "model";                ///< The model's name.
inline constexpr const char* method = "method";              ///< The method's name.
inline constexpr const char* settings = "settings";          ///< Every setting of the run.
inline constexpr const char* seconds = "seconds";            ///< Time per stage.
inline constexpr const char* times = "times";                ///< Frame times.
inline constexpr const char* initial_mass = "initial_mass";  ///< Mass on the grid at t = 0.
inline constexpr const char* mass = "mass";                  ///< Mass on the grid per time.
inline constexpr const char* mass_error = "mass_error";      ///< Its error (particles: 2 sigma).
inline constexpr const char* outflow = "outflow";            ///< Mass out of the box per time.
inline constexpr const char* atom = "atom";                  ///< Mass at a Zeno point per time.
inline constexpr const char* atom_error = "atom_error";      ///< Its estimated error.
/// Per absorbing guard (`reset absorb`), by its name: the mass it took by each frame
/// (`values`, part of `outflow`) and its estimated error (`errors`).
inline constexpr const char* absorbed = "absorbed";
/// Per guard, by its name: the impacts by each frame (`values`, mass-weighted firings,
/// methods/impacts.hpp) and their `errors`, the mean rate over the interval that ends at each
/// frame (`rate`, `rate_errors`), and `infinite_from` (the time from which they are infinite:
/// a Zeno accumulation, null values there; null if never).
inline constexpr const char* impacts = "impacts";
inline constexpr const char* warnings = "warnings";                ///< The method's warnings.
inline constexpr const char* output_warnings = "output_warnings";  ///< The outputs' warnings.
/// Per observable (`observe`): its expectation per frame (`values`) and error (`errors`).
inline constexpr const char* observables = "observables";
/// The blocks of the methods' own fields (MethodSpec::summary_key).
inline constexpr const char* budget = "budget";  ///< characteristics: the mass budget.
/// characteristics: what the grid's values are (nodes or cell averages) and their error.
inline constexpr const char* values = "values";
inline constexpr const char* transfer = "transfer";    ///< transfer: the operator and march.
inline constexpr const char* invariant = "invariant";  ///< invariant: density and spectrum.
inline constexpr const char* particles = "particles";  ///< particles: the samples.
inline constexpr const char* escape = "escape";        ///< escape: the escape rate and its density.
/// almost_invariant: the sets, their masses and invariance ratios.
inline constexpr const char* almost_invariant = "almost_invariant";
/// coherent: the coherent pairs, their masses at both times and their forward and backward
/// ratios.
inline constexpr const char* coherent = "coherent";
}  // namespace summary_key

/// A method, in the table's order.
enum class Method {
  characteristics,
  transfer,
  invariant,
  particles,
  escape,
  almost_invariant,
  coherent
};

/// One row of the methods table.
struct MethodSpec {
  Method id;              ///< Its enumerator (the row's index).
  std::string_view name;  ///< The word of the setting `method`, and summary.json's `method`.
  /// Whether it traces backward through the resets, so that every reset needs an inverse:
  /// in the whole space, or on its guard for a reset with one constant component
  /// (GuardInfo::image_axis; the generator refuses the method otherwise: setting_rules.hpp).
  bool inverts_resets;
  /// Whether it writes one frame (`frame`, the stationary answer) instead of a time series.
  bool one_frame;
  std::string_view frame;  ///< The one frame's name (its file stem), when `one_frame`.
  /// What the one frame is, when `one_frame`: the pictures' titles and run.nc's long_name.
  std::string_view frame_what;
  /// Whether it writes the two frames t = 0 and t_end only, whatever dt (a transport over the
  /// whole interval).
  bool ends_only;
  /// Whether it needs the whole transfer operator in one process (the sets' eigenvectors).
  bool whole_operator;
  /// Whether it can keep the 2-D marginals instead of the grid (the setting density).
  bool deposits_marginals;
  /// The member of summary.json that holds its own fields (summary_key).
  const char* summary_key;
  std::string_view help;  ///< One line for `--help` and docs/settings.md.
};

/// The methods table, in the order `--help` lists them.
inline constexpr std::array kMethods = {
    MethodSpec{Method::characteristics, "characteristics", true, false, "", "", false, false, false,
               summary_key::budget,
               "exact backward characteristics per node; the mass budget by adaptive cubature"},
    MethodSpec{Method::transfer, "transfer", false, false, "", "", false, false, false,
               summary_key::transfer,
               "a one-step transfer operator on node masses, marched by mat-vecs"},
    MethodSpec{Method::invariant, "invariant", false, true, "invariant",
               "invariant density of the transfer operator", false, false, false,
               summary_key::invariant,
               "the leading eigenvector of the transfer operator, and its next eigenvalues"},
    MethodSpec{Method::particles, "particles", false, false, "", "", false, false, true,
               summary_key::particles,
               "Monte-Carlo samples of the initial density pushed forward and deposited"},
    MethodSpec{Method::escape, "escape", false, true, "escape",
               "conditionally invariant density of the open system", false, false, false,
               summary_key::escape,
               "the escape rate of an open system (-ln lambda1 / step) and its conditionally "
               "invariant density"},
    MethodSpec{Method::almost_invariant, "almost_invariant", false, true, "almost_invariant",
               "invariant density (its almost-invariant sets: sets.png, run.nc set_label)", false,
               true, false, summary_key::almost_invariant,
               "K regions of state x mode whose invariant mass stays in them over a step with the "
               "highest probability, with their invariance ratios (setting sets)"},
    MethodSpec{Method::coherent, "coherent", false, false, "", "", true, true, false,
               summary_key::coherent,
               "K pairs of regions, at t = 0 and at t_end, such that the initial density's mass "
               "in the first is carried into the second, with the highest probability both ways "
               "(setting sets)"},
};

static_assert(
    [] {
      for (std::size_t i = 0; i < kMethods.size(); ++i)
        if (static_cast<std::size_t>(kMethods[i].id) != i) return false;
      return true;
    }(),
    "kMethods: each row's id is its index");

/// The row of method `m`.
constexpr const MethodSpec& method_spec(Method m) {
  return kMethods[static_cast<std::size_t>(m)];
}

/// The index of the row named `name`, or kMethods.size() when there is none. (An index, not
/// a pointer, so that compile-time checks hold under -fsanitize=undefined too: GCC 12 does not
/// take a pointer's comparison with null as a constant expression there.)
constexpr std::size_t method_index(std::string_view name) {
  for (std::size_t i = 0; i < kMethods.size(); ++i)
    if (kMethods[i].name == name) return i;
  return kMethods.size();
}

/// The row named `name`, or null.
constexpr const MethodSpec* find_method(std::string_view name) {
  const std::size_t i = method_index(name);
  return i < kMethods.size() ? &kMethods[i] : nullptr;
}

/// The row named `name`; throws std::invalid_argument "unknown method 'NAME'".
inline const MethodSpec& method_named(std::string_view name) {
  if (const MethodSpec* m = find_method(name)) return *m;
  throw std::invalid_argument("unknown method '" + std::string(name) + "'");
}

/// "a, b or c".
inline std::string or_list(const std::vector<std::string_view>& words) {
  std::string out;
  for (std::size_t i = 0; i < words.size(); ++i)
    out += (i == 0 ? "" : i + 1 == words.size() ? " or " : ", ") + std::string(words[i]);
  return out;
}

/// The methods that never invert a reset (they push mass forward), "a, b or c": what the
/// messages about a reset without an inverse name.
inline std::string forward_methods() {
  std::vector<std::string_view> names;
  for (const MethodSpec& m : kMethods)
    if (!m.inverts_resets) names.push_back(m.name);
  return or_list(names);
}

namespace detail {

/// The length of the method names joined by '|'.
consteval std::size_t method_words_length() {
  std::size_t n = 0;
  for (const MethodSpec& m : kMethods) n += m.name.size() + 1;
  return n - 1;
}

/// The method names joined by '|' (the words of the setting `method`).
inline constexpr auto kMethodWordsText = [] {
  std::array<char, method_words_length()> out{};
  std::size_t at = 0;
  for (const MethodSpec& m : kMethods) {
    if (at > 0) out[at++] = '|';
    for (const char ch : m.name) out[at++] = ch;
  }
  return out;
}();

}  // namespace detail

/// The methods' names, '|'-separated, in the table's order (the setting `method`'s words).
inline constexpr std::string_view kMethodWords{detail::kMethodWordsText.data(),
                                               detail::kMethodWordsText.size()};

}  // namespace hybgen::rt
