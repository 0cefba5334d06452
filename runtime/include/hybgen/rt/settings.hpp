#pragma once
/// \file settings.hpp
/// The run's settings, defined once. `kSettings` is the table (name, type, default, range
/// or words, the methods that read it, help); everything else is derived from it:
///  - the model file's `simulation` block and `--set KEY=VALUE` (generator/src/check.cpp,
///    `Settings::set`), with one error text per setting;
///  - the run configuration the generator writes and the runner reads (`Settings::to_json`,
///    `Settings::from_json`, which validates every value again with the same rules);
///  - `hybgen run --help` and the settings table of docs/settings.md (`settings_help`,
///    `settings_markdown`; a test checks that the page is the table).
/// The solvers read a setting by name through a compile-time lookup (`Settings::real<"tol">`),
/// so a misspelt or mistyped name does not compile.
///
/// Adding a setting: one row here, then read it where it is used (docs/design.md,
/// "Adding a setting").

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "hybgen/rt/method_table.hpp"

namespace hybgen::rt {

/// What a setting holds.
enum class SettingType {
  real,     ///< A finite double in its range.
  integer,  ///< A whole number in its range (stored as a double: exact up to 2^53).
  word,     ///< One of its words.
  words,    ///< Some of its words, joined by '+' (`netcdf+png`), each at most once.
  /// Names of the model's own (state variables), joined by '+', each at most once; empty for
  /// the default. The runner checks the syntax, the checker that each is a state.
  names,
};

/// One row of the settings table.
struct SettingSpec {
  std::string_view name;  ///< Key in the simulation block, `--set` and the run configuration.
  SettingType type;       ///< What it holds.
  double number;          ///< Default (numbers).
  std::string_view word;  ///< Default (words).
  double lo;              ///< Smallest value (numbers).
  double hi;              ///< Largest value (numbers).
  bool lo_open;           ///< Whether lo itself is excluded.
  /// The allowed words, '|'-separated (words).
  std::string_view words;
  /// Who reads it: "all", "derive" (the generator's symbolic stage, not the runner), or the
  /// methods (names of method_table.hpp's rows), space-separated.
  std::string_view methods;
  std::string_view help;  ///< One line of help; the meaning of 0 where 0 means "automatic".
};

/// Largest exactly representable integer setting (the seed's range).
inline constexpr double kMaxExactInteger = 9007199254740992.0;  // 2^53

/// Why `scheme=cell` is refused (the settings check, generator/src/check.cpp, and transfer.hpp's
/// parse_scheme say it).
inline constexpr const char* kWithdrawnCell =
    "'cell' (Ulam) was withdrawn: it put each of a cell's K samples on one node, so every "
    "share was a multiple of 1/K and the error did not fall with the grid (13-15 % on the "
    "sawtooth's invariant density at 101 to 1601 nodes); use 'hat' (the default: forward "
    "samples deposited on hat functions) or 'fv' (the finite-volume generator, order 5)";

/// The settings table.
inline constexpr std::array kSettings = {
    SettingSpec{"t_end", SettingType::real, 1.0, "", 0.0, 1e300, true, "", "all", "final time"},
    SettingSpec{"dt", SettingType::real, 0.0, "", 0.0, 1e300, true, "", "all",
                "output interval (default: t_end/10)"},
    SettingSpec{"method", SettingType::word, 0.0, method_spec(Method::characteristics).name, 0, 0,
                false, kMethodWords, "all", "the solver"},
    SettingSpec{"tol", SettingType::real, 1e-10, "", 1e-14, 0.1, false, "", "all",
                "relative tolerance of the ODE integrator (absolute: tol/100; below 1e-14 "
                "double precision cannot meet it)"},
    SettingSpec{"max_events", SettingType::integer, 100000, "", 1, 1e9, false, "", "all",
                "cap on resets per characteristic or trajectory (a Zeno cap)"},
    SettingSpec{"budget", SettingType::word, 0.0, "fast", 0, 0, false, "full|fast|off",
                "characteristics",
                "mass budget: fast (capped, about the solve's cost), full (to budget_tol), off"},
    SettingSpec{"budget_tol", SettingType::real, 3e-4, "", 1e-12, 0.1, false, "", "characteristics",
                "relative tolerance of the full mass budget's cubatures"},
    SettingSpec{"values", SettingType::word, 0.0, "auto", 0, 0, false, "auto|nodes|cells",
                "characteristics",
                "what the grid holds: nodes (the exact density at each node), cells (its mean "
                "over each node's dual cell, by adaptive cubature, with an L1 error estimate), "
                "or auto (cells when the nodes under-resolve the density, by the mass budget)"},
    SettingSpec{"step", SettingType::real, 0.0, "", 0.0, 1e300, false, "",
                "transfer invariant escape almost_invariant",
                "time step of the transfer operator (0: dt); scheme=fv of transfer: a cap of its "
                "time step (0: the stability bound alone)"},
    SettingSpec{"scheme", SettingType::word, 0.0, "auto", 0, 0, false, "auto|hat|fv|galerkin",
                "transfer invariant escape almost_invariant coherent",
                "auto (fv for method=invariant where it applies, else hat), hat (forward "
                "samples on hat functions), fv (a cut-cell finite-volume "
                "generator, order 5; guards that are coordinate planes; one process): its null "
                "vector for invariant, stepped in time for transfer, or galerkin (transfer: the "
                "density's hat expansion moved exactly and projected back, second order, no "
                "growth of the error with the number of steps; one process)"},
    SettingSpec{"fv_order", SettingType::integer, 5, "", 1, 5, false, "", "transfer invariant",
                "scheme=fv: order of the upwind reconstruction (5, the default, or 3; 1 and 2 for "
                "tests of the order; 4 is refused)"},
    SettingSpec{"samples", SettingType::integer, 0, "", 0, 64, false, "",
                "transfer invariant escape almost_invariant coherent",
                "sample points per axis and cell (0: 4 up to 2-D, 3 in 3-D, 2 above; twice as "
                "many up to 3-D with scheme=galerkin)"},
    SettingSpec{"eigenvalues", SettingType::integer, 6, "", 1, 64, false, "", "invariant escape",
                "eigenvalues of the transfer operator to report"},
    SettingSpec{"sets", SettingType::integer, 2, "", 2, 16, false, "", "almost_invariant coherent",
                "number of almost-invariant sets (from as many leading eigenvectors of the "
                "reversibilised transfer operator, by SEBA), or of coherent pairs (from as many "
                "leading singular vectors of the normalised transport over [0, t_end])"},
    SettingSpec{"particles", SettingType::integer, 1000000, "", 1, 1e10, false, "", "particles",
                "number of samples"},
    SettingSpec{"seed", SettingType::integer, 1, "", 0, kMaxExactInteger, false, "", "particles",
                "random seed (counter-based streams: results do not depend on "
                "the number of threads)"},
    SettingSpec{"density", SettingType::word, 0.0, "grid", 0, 0, false, "grid|marginals",
                "particles",
                "grid: the density on every node; marginals: the 2-D marginal of every pair of "
                "axes and the moments, for grids too large to hold (docs/methods.md)"},
    SettingSpec{"outputs", SettingType::words, 0.0, "netcdf+png+pdf+gif+html", 0, 0, false,
                "netcdf|png|pdf|svg|gif|html|npy|vti", "all",
                "files of a run, joined by '+': run.nc (netcdf), pictures (png: one per frame; "
                "pdf: one page per frame; svg), animation.gif, report.html, .npy arrays, .vti "
                "images with a .pvd collection (summary.json always)"},
    SettingSpec{"figure_scale", SettingType::word, 0.0, "auto", 0, 0, false, "auto|linear|log",
                "all",
                "colour scale of the pictures, fixed for the whole run: linear from 0, log over "
                "four decades, or auto (log when the maximum is over 100 times the 99th "
                "percentile)"},
    SettingSpec{"figure_axes", SettingType::names, 0.0, "", 0, 0, false, "", "all",
                "the state axes whose pairs the pictures show in 3-D and more, joined by '+' "
                "(default: every axis)"},
    SettingSpec{"threads", SettingType::integer, 0, "", 0, 4096, false, "", "all",
                "worker threads of the runner (0: $OMP_NUM_THREADS, else one per core, shared "
                "by the ranks on a machine)"},
    SettingSpec{"backend", SettingType::word, 0.0, "openmp", 0, 0, false, "openmp|mpi", "all",
                "openmp: one process (the default); mpi: ranks under mpiexec with PETSc and "
                "SLEPc (docs/distributed.md)"},
    SettingSpec{"ranks", SettingType::integer, 1, "", 1, 1e6, false, "", "all",
                "backend=mpi: the processes `hybgen run` starts (mpiexec -n; `--ranks N` sets "
                "both)"},
    SettingSpec{"max_expr_nodes", SettingType::integer, 200000, "", 100, 1e12, false, "", "derive",
                "largest derived expression, in tree nodes"},
    SettingSpec{"max_expand_terms", SettingType::real, 1e5, "", 1, 1e300, false, "", "derive",
                "largest estimated expansion that simplify attempts"},
    SettingSpec{"derive_seconds", SettingType::real, 120, "", 0.001, 1e9, false, "", "derive",
                "wall-clock budget of the symbolic derivation, in seconds"},
};

/// Index of setting `name` in kSettings, or kSettings.size() when there is none.
constexpr std::size_t setting_index(std::string_view name) {
  for (std::size_t i = 0; i < kSettings.size(); ++i)
    if (kSettings[i].name == name) return i;
  return kSettings.size();
}

/// The setting `name`'s row, or null.
constexpr const SettingSpec* find_setting(std::string_view name) {
  const std::size_t i = setting_index(name);
  return i < kSettings.size() ? &kSettings[i] : nullptr;
}

/// Whether `readers` (a settings row's `methods` column) names the method `name`: `all`
/// names every method, `derive` none.
constexpr bool setting_read_by(std::string_view readers, std::string_view name) {
  if (readers == "all") return true;
  std::size_t i = 0;
  while (i < readers.size()) {
    std::size_t j = readers.find(' ', i);
    if (j == std::string_view::npos) j = readers.size();
    if (readers.substr(i, j - i) == name) return true;
    i = j + 1;
  }
  return false;
}

/// Whether method `m` reads setting `s` (the settings table's `methods` column).
constexpr bool method_reads(const MethodSpec& m, const SettingSpec& s) {
  return setting_read_by(s.methods, m.name);
}

static_assert(
    [] {
      for (const SettingSpec& s : kSettings) {
        if (s.methods == "all" || s.methods == "derive") continue;
        std::size_t i = 0;
        while (i < s.methods.size()) {
          std::size_t j = s.methods.find(' ', i);
          if (j == std::string_view::npos) j = s.methods.size();
          if (method_index(s.methods.substr(i, j - i)) == kMethods.size()) return false;
          i = j + 1;
        }
      }
      return true;
    }(),
    "kSettings: every reader named in the `methods` column is a row of kMethods");

/// The default number of setting `name`, at compile time (a misspelt name does not compile).
consteval double setting_number(std::string_view name) {
  const std::size_t i = setting_index(name);
  if (i == kSettings.size()) throw "no such setting";
  return kSettings[i].number;
}

/// A setting's name as a template argument (`Settings::real<"tol">()`).
template <std::size_t L>
struct SettingName {
  char text[L]{};  ///< The name, NUL-terminated.
  /// From a string literal.
  constexpr SettingName(const char (&s)[L]) { std::copy_n(s, L, text); }  // NOLINT: implicit
  /// As a string view.
  constexpr std::string_view view() const { return {text, L - 1}; }
};

namespace detail {

/// A number for messages and help: whole numbers in full unless they end in four or more
/// zeros (1e9, 2e5), others as %g, exponents without '+' and leading zeros (3e-4, 1e300).
inline std::string fmt_g(double v) {
  char b[48];
  if (v == std::floor(v) && std::fabs(v) < 1e16) {
    std::snprintf(b, sizeof b, "%.0f", v);
    std::string t = b;
    std::size_t zeros = 0;
    while (zeros + 1 < t.size() && t[t.size() - 1 - zeros] == '0') ++zeros;
    if (zeros < 4) return t;
    return t.substr(0, t.size() - zeros) + "e" + std::to_string(zeros);
  }
  std::snprintf(b, sizeof b, "%g", v);
  std::string t = b;
  const std::size_t e = t.find('e');
  if (e == std::string::npos) return t;
  std::string exp = t.substr(e + 1);
  const bool neg = exp[0] == '-';
  exp = exp.substr(1);
  while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
  return t.substr(0, e) + "e" + (neg ? "-" : "") + exp;
}

/// Who reads a setting, for help: "every method", or the methods joined by ", ".
inline std::string readers(std::string_view methods) {
  if (methods == "all") return "every method";
  std::string out;
  for (char ch : methods) out += ch == ' ' ? std::string(", ") : std::string(1, ch);
  return out;
}

/// The words of a word setting as a list "a, b, c".
inline std::string word_list(std::string_view words) {
  std::string out;
  for (char ch : words) out += ch == '|' ? std::string(", ") : std::string(1, ch);
  return out;
}

/// Whether `w` is one of `words` ('|'-separated).
inline bool has_word(std::string_view words, std::string_view w) {
  std::size_t i = 0;
  while (i <= words.size()) {
    std::size_t j = words.find('|', i);
    if (j == std::string_view::npos) j = words.size();
    if (words.substr(i, j - i) == w) return true;
    i = j + 1;
  }
  return false;
}

/// The parts of a '+'-joined word list ("netcdf+png" -> netcdf, png; "" -> one empty part).
inline std::vector<std::string_view> split_plus(std::string_view list) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (true) {
    const std::size_t j = list.find('+', i);
    out.push_back(list.substr(i, j == std::string_view::npos ? std::string_view::npos : j - i));
    if (j == std::string_view::npos) return out;
    i = j + 1;
  }
}

}  // namespace detail

/// What a setting accepts, in words: "positive", "an integer in [1, 1e9]", "one of: a, b".
inline std::string setting_range(const SettingSpec& s) {
  if (s.type == SettingType::word) return "one of: " + detail::word_list(s.words);
  if (s.type == SettingType::words)
    return "some of: " + detail::word_list(s.words) + ", joined by '+'";
  if (s.type == SettingType::names) return "state variables joined by '+'";
  const bool integer = s.type == SettingType::integer;
  if (s.lo == 0 && s.lo_open && s.hi >= 1e300) return integer ? "a positive integer" : "positive";
  if (s.hi >= 1e300)
    return (integer ? "an integer " : "") + std::string("at least ") + detail::fmt_g(s.lo);
  return std::string(integer ? "an integer in " : "in ") + (s.lo_open ? "(" : "[") +
         detail::fmt_g(s.lo) + ", " + detail::fmt_g(s.hi) + "]";
}

/// The default of a setting as text.
inline std::string setting_default(const SettingSpec& s) {
  if (s.type == SettingType::names && s.word.empty()) return "every axis";
  if (s.type == SettingType::word || s.type == SettingType::words) return std::string(s.word);
  if (s.number == 0 && s.lo_open) return "automatic";  // outside the range: the help says how
  return detail::fmt_g(s.number);
}

/// A setting's value as given (a model file or `--set`): a word or a number.
struct SettingValue {
  std::string word;         ///< Set when the value is an identifier.
  double number = 0;        ///< Set when the value is numeric.
  bool has_number = false;  ///< Whether `number` is meaningful.
};

/// Why `v` is not a valid value of `s` ("" when it is). The one place the rules are applied.
inline std::string setting_problem(const SettingSpec& s, const SettingValue& v) {
  if (s.type == SettingType::word) {
    if (v.has_number || v.word.empty()) return "needs one of: " + detail::word_list(s.words);
    if (!detail::has_word(s.words, v.word))
      return "unknown value '" + v.word + "' (available: " + detail::word_list(s.words) + ")";
    return "";
  }
  if (s.type == SettingType::words) {
    if (v.has_number || v.word.empty()) return "needs " + setting_range(s);
    std::vector<std::string_view> seen;
    for (const std::string_view w : detail::split_plus(v.word)) {
      if (!detail::has_word(s.words, w))
        return "unknown value '" + std::string(w) + "' (available: " + detail::word_list(s.words) +
               ", joined by '+')";
      if (std::find(seen.begin(), seen.end(), w) != seen.end())
        return "'" + std::string(w) + "' is given twice";
      seen.push_back(w);
    }
    return "";
  }
  if (s.type == SettingType::names) {
    if (v.has_number) return "needs " + setting_range(s);
    if (v.word.empty()) return "";  // the default: every axis
    std::vector<std::string_view> seen;
    for (const std::string_view w : detail::split_plus(v.word)) {
      const bool identifier = !w.empty() &&
                              (std::isalpha(static_cast<unsigned char>(w[0])) || w[0] == '_') &&
                              std::all_of(w.begin(), w.end(), [](char c) {
                                return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
                              });
      if (!identifier) return "'" + std::string(w) + "' is not a name (" + setting_range(s) + ")";
      if (std::find(seen.begin(), seen.end(), w) != seen.end())
        return "'" + std::string(w) + "' is given twice";
      seen.push_back(w);
    }
    return "";
  }
  if (!v.has_number) return "needs a number (" + setting_range(s) + ")";
  const double x = v.number;
  const bool in = std::isfinite(x) && (s.lo_open ? x > s.lo : x >= s.lo) && x <= s.hi;
  if (!in || (s.type == SettingType::integer && x != std::floor(x)))
    return "must be " + setting_range(s);
  return "";
}

/// The values of every setting (defaults until set). Numbers and words by table index.
class Settings {
 public:
  /// Every setting at its default.
  Settings() {
    for (std::size_t i = 0; i < kSettings.size(); ++i) {
      number_[i] = kSettings[i].number;
      word_[i] = std::string(kSettings[i].word);
    }
  }

  /// Set `name` to `v`; returns why not ("" on success, "unknown setting" for no such name).
  std::string set(std::string_view name, const SettingValue& v) {
    const std::size_t i = setting_index(name);
    if (i == kSettings.size()) return "unknown setting";
    if (std::string why = setting_problem(kSettings[i], v); !why.empty()) return why;
    if (kSettings[i].type == SettingType::word || kSettings[i].type == SettingType::words ||
        kSettings[i].type == SettingType::names)
      word_[i] = v.word;
    else
      number_[i] = v.number;
    given_[i] = true;
    return "";
  }

  /// Set `name` to `v`, or throw std::invalid_argument "setting 'NAME': why".
  void assign(std::string_view name, const SettingValue& v) {
    if (std::string why = set(name, v); !why.empty())
      throw std::invalid_argument("setting '" + std::string(name) + "': " + why);
  }

  /// Whether `name` was set (not left at its default).
  bool given(std::string_view name) const {
    const std::size_t i = setting_index(name);
    return i < kSettings.size() && given_[i];
  }

  /// A real setting.
  template <SettingName N>
  double real() const {
    constexpr std::size_t i = checked<N>(SettingType::real);
    return number_[i];
  }
  /// An integer setting.
  template <SettingName N>
  long long integer() const {
    constexpr std::size_t i = checked<N>(SettingType::integer);
    return static_cast<long long>(number_[i]);
  }
  /// A word setting.
  template <SettingName N>
  const std::string& word() const {
    constexpr std::size_t i = checked<N>(SettingType::word);
    return word_[i];
  }
  /// Whether the word-list setting N includes `w` (`includes<"outputs">("npy")`).
  template <SettingName N>
  bool includes(std::string_view w) const {
    constexpr std::size_t i = checked<N>(SettingType::words);
    for (const std::string_view part : detail::split_plus(word_[i]))
      if (part == w) return true;
    return false;
  }
  /// The names of a names setting, in order (empty: the default).
  template <SettingName N>
  std::vector<std::string> names() const {
    constexpr std::size_t i = checked<N>(SettingType::names);
    std::vector<std::string> out;
    if (!word_[i].empty())
      for (const std::string_view part : detail::split_plus(word_[i])) out.emplace_back(part);
    return out;
  }
  /// Set a number directly (a derived default such as dt = t_end/10); unchecked.
  template <SettingName N>
  void put(double x) {
    constexpr std::size_t i = setting_index(N.view());
    static_assert(i < kSettings.size(), "no such setting");
    static_assert(kSettings[i].type != SettingType::word, "a word setting");
    number_[i] = x;
  }

  /// Every setting read by the runner (not `derive`), as JSON members of the run configuration.
  nlohmann::json to_json() const {
    nlohmann::json j = nlohmann::json::object();
    for (std::size_t i = 0; i < kSettings.size(); ++i) {
      const SettingSpec& s = kSettings[i];
      if (s.methods == "derive") continue;
      if (s.type == SettingType::word || s.type == SettingType::words ||
          s.type == SettingType::names)
        j[std::string(s.name)] = word_[i];
      else if (s.type == SettingType::integer)
        j[std::string(s.name)] = static_cast<long long>(number_[i]);
      else
        j[std::string(s.name)] = number_[i];
    }
    return j;
  }

  /// The settings of a run configuration, each validated by the table's rule; a missing
  /// member keeps its default. Throws std::invalid_argument naming the setting (`assign`).
  static Settings from_json(const nlohmann::json& j) {
    Settings out;
    for (const SettingSpec& s : kSettings) {
      if (s.methods == "derive") continue;
      const std::string key(s.name);
      if (!j.contains(key)) continue;
      const nlohmann::json& x = j.at(key);
      SettingValue v;
      if (x.is_string())
        v.word = x.get<std::string>();
      else if (x.is_number())
        v.number = x.get<double>(), v.has_number = true;
      out.assign(s.name, v);
    }
    return out;
  }

 private:
  template <SettingName N>
  static constexpr std::size_t checked(SettingType t) {
    constexpr std::size_t i = setting_index(N.view());
    static_assert(i < kSettings.size(), "no such setting (runtime/include/hybgen/rt/settings.hpp)");
    if (kSettings[i].type != t) throw std::logic_error("setting read with the wrong type");
    return i;
  }

  std::array<double, kSettings.size()> number_{};
  std::array<std::string, kSettings.size()> word_{};
  std::array<bool, kSettings.size()> given_{};
};

/// The settings as help text, one per line: name, range, default, methods, help; under
/// `method`, each method with its line of help (method_table.hpp, MethodSpec::help).
inline std::string settings_help() {
  std::string out;
  for (const SettingSpec& s : kSettings) {
    std::string line = "  " + std::string(s.name);
    line.resize(std::max<std::size_t>(line.size() + 1, 20), ' ');
    out += line + std::string(s.help) + "\n" + std::string(20, ' ') + setting_range(s) +
           "; default " + setting_default(s) + "; " + detail::readers(s.methods) + "\n";
    if (s.name == "method")
      for (const MethodSpec& m : kMethods)
        out += std::string(22, ' ') + std::string(m.name) + ": " + std::string(m.help) + "\n";
  }
  return out;
}

/// The settings as a Markdown table (docs/settings.md), then the methods with their lines of
/// help (method_table.hpp, MethodSpec::help).
inline std::string settings_markdown() {
  std::string out = "| setting | what | accepts | default | read by |\n|---|---|---|---|---|\n";
  for (const SettingSpec& s : kSettings)
    out += "| `" + std::string(s.name) + "` | " + std::string(s.help) + " | " + setting_range(s) +
           " | " + setting_default(s) + " | " + detail::readers(s.methods) + " |\n";
  out += "\nThe words of `method`:\n\n";
  for (const MethodSpec& m : kMethods)
    out += "- `" + std::string(m.name) + "`: " + std::string(m.help) + "\n";
  return out;
}

}  // namespace hybgen::rt
