// Stage 4 (emit): IR -> kernel header + report.md. `hybgen derive`'s renderings of the
// same system are in render.cpp (report.md embeds its LaTeX).
//
// Builder in the style of CasADi's code generator: separate buffers for the
// provenance header, the static tables and each kernel, assembled at the end.

#include "hybgen/gen/emit.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>
#include <set>
#include <sstream>

#include "expr_printer.hpp"
#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/render.hpp"

#ifndef HYBGEN_VERSION
#define HYBGEN_VERSION "0.0.0"
#endif

namespace hybgen::gen {

using GiNaC::ex;

const char* generator_version() {
  return HYBGEN_VERSION;
}

std::string model_struct_name(const std::string& model_name) {
  std::string s;
  for (char c : model_name) s += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  if (s.empty() || std::isdigit(static_cast<unsigned char>(s[0]))) s = "m_" + s;
  return s;
}

namespace {

std::string fmt_double(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  std::string s = buf;
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

/// Names in generated kernels that a state variable or parameter must not take: C++
/// keywords, the kernels' arguments and locals, the generated struct's members, and the
/// object-like macros of <cmath> (glibc's), <cerrno> and <cstdio>. The locals the emitter
/// numbers (_t0, _c0, …) are matched by is_generated_local. Every name here becomes a free
/// one by appending '_' (none ends in '_'), so the renaming loop ends.
const std::set<std::string>& c_reserved_names() {
  static const std::set<std::string> r = {
      // C++20 keywords and alternative tokens.
      "alignas", "alignof", "and", "and_eq", "asm", "auto", "bitand", "bitor", "bool", "break",
      "case", "catch", "char", "char8_t", "char16_t", "char32_t", "class", "compl", "concept",
      "const", "consteval", "constexpr", "constinit", "const_cast", "continue", "co_await",
      "co_return", "co_yield", "decltype", "default", "delete", "do", "double", "dynamic_cast",
      "else", "enum", "explicit", "export", "extern", "false", "float", "for", "friend", "goto",
      "if", "inline", "int", "long", "mutable", "namespace", "new", "noexcept", "not", "not_eq",
      "nullptr", "operator", "or", "or_eq", "private", "protected", "public", "register",
      "reinterpret_cast", "requires", "return", "short", "signed", "sizeof", "static",
      "static_assert", "static_cast", "struct", "switch", "template", "this", "thread_local",
      "throw", "true", "try", "typedef", "typeid", "typename", "union", "unsigned", "using",
      "virtual", "void", "volatile", "wchar_t", "while", "xor", "xor_eq",
      // The kernels' arguments and locals (mode, guard, state and parameter are words of the
      // model language, so no model name can clash with them), and the namespaces they name.
      "mode", "guard", "state", "parameter", "out", "result", "slot", "std", "hybgen",
      "hybgen_model",
      // The generated struct's members.
      "name", "n_state", "n_param", "n_mode", "n_guard", "state_names", "param_names",
      "param_defaults", "mode_names", "guard_names", "guards", "flow", "divergence",
      "guard_surface", "guard_gradient", "reset", "reset_inverse", "reset_jacobian",
      "hybrid_jacobian", "in_support", "in_region", "initial_density",
      // Object-like macros of <cmath>, <cerrno> and <cstdio>.
      "NAN", "INFINITY", "HUGE_VAL", "HUGE_VALF", "HUGE_VALL", "NULL", "EOF", "EDOM", "ERANGE",
      "EILSEQ", "errno", "MATH_ERRNO", "MATH_ERREXCEPT", "math_errhandling", "FP_NAN",
      "FP_INFINITE", "FP_ZERO", "FP_SUBNORMAL", "FP_NORMAL", "FP_ILOGB0", "FP_ILOGBNAN",
      "FP_FAST_FMA", "FP_FAST_FMAF", "FP_FAST_FMAL", "M_E", "M_LOG2E", "M_LOG10E", "M_LN2",
      "M_LN10", "M_PI", "M_PI_2", "M_PI_4", "M_1_PI", "M_2_PI", "M_2_SQRTPI", "M_SQRT2",
      "M_SQRT1_2", "M_El", "M_LOG2El", "M_LOG10El", "M_LN2l", "M_LN10l", "M_PIl", "M_PI_2l",
      "M_PI_4l", "M_1_PIl", "M_2_PIl", "M_2_SQRTPIl", "M_SQRT2l", "M_SQRT1_2l"};
  return r;
}

// Names of the locals the emitter numbers. A kernel declares three kinds of names: the
// model's state variables and parameters, as the model writes them (`zeta1`, `theta0`);
// its fixed arguments and locals (`mode`, `guard`, `state`, `out`, `result`, `slot`:
// c_reserved_names); and numbered locals — emit_c_block's common subexpressions and the
// values of `support` and `where` relations. The numbered ones are an underscore, a
// lower-case prefix and a number, `_[a-z]+[0-9]+`:
//   _t0, _t1, …    common subexpressions of a kernel or `case` (kTempPrefix);
//   _c0, _c1, …    the support relations of in_support, their subexpressions _ct0, …;
//   _w0, _w1, …    a mode's `where` relations, their subexpressions _wt0, ….
// They live in function scope, where C++ reserves only names with a double underscore or an
// underscore and an upper-case letter ([lex.name]); `_t0` is neither. The model language
// accepts every identifier [A-Za-z_][A-Za-z0-9_]* (generator/src/lexer.hpp,
// is_ident_start), so no spelling is out of its reach: a model name of the numbered form
// (`_t0`; no shipped model has a leading underscore) is renamed to `_t0_`, which is not of
// the form, and every other name — lower-case letters and digits included — stays as
// written.

/// Prefix of emit_c_block's temporaries in generated kernels (see above).
constexpr const char* kTempPrefix = "_t";

/// Whether `n` has the form of a numbered local of a generated kernel, `_[a-z]+[0-9]+` (see
/// above). Appending '_' makes any name not one, so HeaderBuilder's renaming ends.
bool is_generated_local(const std::string& n) {
  if (n.empty() || n[0] != '_') return false;
  std::size_t i = 1;
  while (i < n.size() && std::islower(static_cast<unsigned char>(n[i]))) ++i;
  if (i == 1 || i == n.size()) return false;
  for (std::size_t j = i; j < n.size(); ++j)
    if (!std::isdigit(static_cast<unsigned char>(n[j]))) return false;
  return true;
}

/// The cases of a kernel's switch: the index it switches on (`mode` or `guard`) and, per
/// case, the comment naming it (`mode heat`, `guard off: heat -> cool`).
struct KernelCases {
  std::string index;                ///< Name of the index argument.
  std::vector<std::string> labels;  ///< One per case, in index order.
};

/// The kernel-header builder: one buffer per kernel. A kernel names the state variables
/// and parameters it reads (`const double p = state[1];`) and leaves unread arguments unnamed,
/// so that it compiles without warnings and reads like the model.
class HeaderBuilder {
 public:
  HeaderBuilder(const HybridSystem& sys, ExprPrinter& pr) : sys_(sys), m_(*sys.model), pr_(pr) {
    // C names: the model's own, with '_' appended while one clashes (c_reserved_names) or
    // repeats an earlier one.
    std::set<std::string> taken;
    auto c_name = [&](std::string n) {
      while (c_reserved_names().count(n) || is_generated_local(n) || taken.count(n)) n += '_';
      taken.insert(n);
      return n;
    };
    for (std::size_t i = 0; i < m_.state.size(); ++i) {
      bind_[m_.state[i]] = c_name(m_.state[i]);
      source_[m_.state[i]] = "state[" + std::to_string(i) + "]";
    }
    for (std::size_t j = 0; j < m_.params.size(); ++j) {
      bind_[m_.params[j].name] = c_name(m_.params[j].name);
      source_[m_.params[j].name] = "parameter[" + std::to_string(j) + "]";
    }
  }

  /// The modes as the cases of a kernel: `int mode`, `case k: {  // mode NAME`.
  [[nodiscard]] KernelCases mode_cases() const {
    KernelCases cases{"mode", {}};
    for (const auto& md : sys_.modes) cases.labels.push_back("mode " + md.name);
    return cases;
  }

  /// The guards as the cases of a kernel: `int guard`, `case k: {  // guard NAME: FROM -> TO`.
  [[nodiscard]] KernelCases guard_cases() const {
    KernelCases cases{"guard", {}};
    for (const auto& g : sys_.guards)
      cases.labels.push_back(
          "guard " + g.name + ": " + sys_.modes[static_cast<std::size_t>(g.from)].name + " -> " +
          (g.absorbing ? "(absorbed)" : sys_.modes[static_cast<std::size_t>(g.to)].name));
    return cases;
  }

  /// A kernel `static void NAME(int INDEX, const double* state, const double* parameter,
  /// double* out)` switching on INDEX (`mode` or `guard`); `outputs(k)` gives the expressions
  /// for case k, or none for a case that has no value (an absorbing guard's reset): it then
  /// takes the default, NaN.
  void vector_kernel(const std::string& doc, const std::string& name, const KernelCases& cases,
                     std::size_t n_out,
                     const std::function<std::vector<ex>(std::size_t)>& outputs) {
    begin_kernel();
    std::ostringstream body;
    body << "    switch (" << cases.index << ") {\n";
    for (std::size_t c = 0; c < cases.labels.size(); ++c) {
      std::vector<CAssignment> as;
      const auto es = outputs(c);
      if (es.empty()) continue;
      for (std::size_t i = 0; i < es.size(); ++i)
        as.push_back({"out[" + std::to_string(i) + "]", pr_.node(es[i])});
      begin_case();
      body << case_line(cases, c) << name_values(es, "        ")
           << emit_c_block(pr_.dag(), as, bind_, "        ", kTempPrefix)
           << "        break;\n      }\n";
    }
    // An invalid index yields NaN in every output, never stale memory.
    body << "      default:\n        for (int slot = 0; slot < " << n_out
         << "; ++slot) out[slot] = std::nan(\"\");\n        break;\n    }\n  }\n\n";
    kernels_ += "  /// " + doc + "\n  static void " + name + "(int " + cases.index + ", " +
                arguments() + ", double* out) {\n" + body.str();
  }

  /// A kernel `static double NAME(int INDEX, const double* state, const double* parameter)`;
  /// `value(k)` is case k's expression, or nullopt where it has none (an absorbing guard's
  /// hybrid Jacobian): NaN there.
  void scalar_kernel(const std::string& doc, const std::string& name, const KernelCases& cases,
                     const std::function<std::optional<ex>(std::size_t)>& value) {
    begin_kernel();
    std::ostringstream body;
    body << "    double result = 0.0;\n    switch (" << cases.index << ") {\n";
    for (std::size_t c = 0; c < cases.labels.size(); ++c) {
      const std::optional<ex> vc = value(c);
      if (!vc) {
        body << case_line(cases, c) << "        return std::nan(\"\");\n      }\n";
        continue;
      }
      const ex v = *vc;
      std::vector<CAssignment> as{{"result", pr_.node(v)}};
      begin_case();
      body << case_line(cases, c) << name_values({v}, "        ")
           << emit_c_block(pr_.dag(), as, bind_, "        ", kTempPrefix)
           << "        break;\n      }\n";
    }
    body << "      default:\n        break;\n    }\n    return result;\n  }\n\n";
    kernels_ += "  /// " + doc + "\n  static double " + name + "(int " + cases.index + ", " +
                arguments() + ") {\n" + body.str();
  }

  /// Emit `conds` as a boolean test into `os`, after naming the values they read (returns
  /// the C condition). The values are named `var` and a number (`_c0`, `_w0`).
  std::string conditions(std::ostringstream& os, const std::vector<Condition>& conds,
                         const std::string& indent, const std::string& var) {
    if (conds.empty()) return "true";
    std::vector<ex> es;
    for (const auto& c : conds) es.push_back(c.expr);
    os << name_values(es, indent);
    std::vector<CAssignment> as;
    for (std::size_t i = 0; i < conds.size(); ++i) {
      os << indent << "double " << var << i << " = 0.0;\n";
      as.push_back({var + std::to_string(i), pr_.node(conds[i].expr)});
    }
    os << emit_c_block(pr_.dag(), as, bind_, indent, var + "t");  // _ct0, …; _wt0, …
    std::string test;
    for (std::size_t i = 0; i < conds.size(); ++i)
      test += (i ? " && " : "") + var + std::to_string(i) + " " + conds[i].op + " 0.0";
    return test;
  }

  void density_kernels() {
    const auto& sim = m_.sim;
    const KernelCases modes = mode_cases();
    {
      begin_kernel();
      std::ostringstream body;
      const std::string test = conditions(body, sim.support, "    ", "_c");
      kernels_ +=
          "  /// Whether x lies in the state space (the model's `support` relations).\n"
          "  static bool in_support(" +
          arguments() + ") {\n" + body.str() + "    return " + test + ";\n  }\n\n";
    }
    // The modes' regions (`where`), for the forward methods to keep each mode's mass inside
    // its own region (runtime/include/hybgen/rt/methods/transfer.hpp); only for models that have
    // any.
    bool any_region = false;
    for (const auto& md : sys_.modes) any_region = any_region || !md.where.empty();
    if (any_region) {
      begin_kernel();
      std::ostringstream body;
      body << "    switch (mode) {\n";
      for (std::size_t c = 0; c < sys_.modes.size(); ++c) {
        std::vector<Condition> closed = sys_.modes[c].where;
        for (auto& cond : closed) {
          if (cond.op == "<") cond.op = "<=";
          if (cond.op == ">") cond.op = ">=";
        }
        begin_case();
        body << case_line(modes, c);
        const std::string region = conditions(body, closed, "        ", "_w");
        body << "        return " << region << ";\n      }\n";
      }
      body << "      default:\n        return false;\n    }\n  }\n\n";
      kernels_ +=
          "  /// Whether x lies in the closure of mode k's region (its `where` relations, < read "
          "as <=\n  /// and > as >=).\n  static bool in_region(int mode, " +
          arguments() + ") {\n" + body.str();
    }
    begin_kernel();
    uses_x_ = uses_par_ = true;  // in_support(state, parameter)
    std::ostringstream body;
    body << "    if (!in_support(state, parameter)) return 0.0;\n";
    body << "    double result = 0.0;\n    switch (mode) {\n";
    for (std::size_t c = 0; c < sys_.modes.size(); ++c) {
      begin_case();
      body << case_line(modes, c);
      const std::string region = conditions(body, sys_.modes[c].where, "        ", "_w");
      const ex u0 = c < sim.initial.size() ? sim.initial[c] : ex(0);
      if (region != "true") body << "        if (!(" << region << ")) return 0.0;\n";
      body << name_values({u0}, "        ")
           << emit_c_block(pr_.dag(), {{"result", pr_.node(u0)}}, bind_, "        ", kTempPrefix)
           << "        break;\n      }\n";
    }
    body << "      default:\n        break;\n    }\n    return result;\n  }\n\n";
    kernels_ +=
        "  /// Initial density of mode k at x (0 outside the support and the mode's region).\n"
        "  static double initial_density(int mode, " +
        arguments() + ") {\n" + body.str();
  }

  std::string assemble() {
    const std::string sname = model_struct_name(m_.name);
    const std::size_t n = m_.state.size();
    std::ostringstream os;
    os << "// Generated by hybgen " << generator_version() << " -- DO NOT EDIT.\n";
    os << "// model: " << m_.name << "\n";
    os << "// source sha256: " << m_.source_hash << "\n";
    os << "// Regenerate with `hybgen generate` from the model file; a golden test diffs this "
          "file.\n";
    os << "#pragma once\n\n#include <array>\n#include <cmath>\n\n#include "
          "<hybgen/rt/model.hpp>\n\n";
    os << "namespace hybgen_model {\n\n";
    os << "/// Kernels of the hybrid system '" << m_.name
       << "' (see report.md for the derivation).\n";
    os << "struct " << sname << " {\n";
    os << "  /// Model name.\n  static constexpr const char* name = " << quoted(m_.name) << ";\n";
    os << "  /// Number of state variables.\n  static constexpr int n_state = " << n << ";\n";
    os << "  /// Number of parameters.\n  static constexpr int n_param = " << m_.params.size()
       << ";\n";
    os << "  /// Number of modes.\n  static constexpr int n_mode = " << sys_.modes.size() << ";\n";
    os << "  /// Number of guards.\n  static constexpr int n_guard = " << sys_.guards.size()
       << ";\n";
    auto names = [&](const std::vector<std::string>& v) {
      std::string s;
      for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + quoted(v[i]);
      return s;
    };
    std::vector<std::string> pnames, mnames, gnames;
    std::string pdefaults;
    for (std::size_t j = 0; j < m_.params.size(); ++j) {
      pnames.push_back(m_.params[j].name);
      pdefaults += (j ? ", " : "") + fmt_double(m_.params[j].value_d);
    }
    for (const auto& md : sys_.modes) mnames.push_back(md.name);
    for (const auto& g : sys_.guards) gnames.push_back(g.name);
    os << "  /// State variable names, in order.\n  static constexpr std::array<const char*, " << n
       << "> state_names{" << names(m_.state) << "};\n";
    os << "  /// Parameter names.\n  static constexpr std::array<const char*, " << pnames.size()
       << "> param_names{" << names(pnames) << "};\n";
    os << "  /// Parameter defaults.\n  static constexpr std::array<double, " << pnames.size()
       << "> param_defaults{" << pdefaults << "};\n";
    os << "  /// Mode names.\n  static constexpr std::array<const char*, " << mnames.size()
       << "> mode_names{" << names(mnames) << "};\n";
    os << "  /// Guard names.\n  static constexpr std::array<const char*, " << gnames.size()
       << "> guard_names{" << names(gnames) << "};\n";
    os << "  /// Guards: source mode, target mode (-1: absorbing), direction (-1 decreasing, +1 "
          "increasing), closed-form inverse, axis of a constant reset component (-1: none).\n";
    os << "  static constexpr std::array<hybgen::rt::GuardInfo, " << gnames.size() << "> guards{{";
    for (std::size_t g = 0; g < sys_.guards.size(); ++g) {
      const auto& gd = sys_.guards[g];
      os << (g ? ", " : "") << "{" << gd.from << ", " << gd.to << ", "
         << (gd.direction == Direction::Decreasing ? -1 : 1) << ", "
         << (gd.has_inverse ? "true" : "false") << ", " << gd.image_axis << "}";
    }
    os << "}};\n";
    if (const auto& obs = m_.sim.observables; !obs.empty()) {
      std::vector<std::string> onames;
      for (const Observable& o : obs) onames.push_back(o.name);
      os << "  /// Number of observables (`observe` lines).\n  static constexpr int n_observable = "
         << obs.size() << ";\n";
      os << "  /// Observable names.\n  static constexpr std::array<const char*, " << obs.size()
         << "> observable_names{" << names(onames) << "};\n";
    }
    os << "\n" << kernels_;
    os << "};\n\n";
    os << "static_assert(hybgen::rt::HybridModel<" << sname << ">);\n\n";
    os << "}  // namespace hybgen_model\n";
    return os.str();
  }

 private:
  const HybridSystem& sys_;
  const Model& m_;
  ExprPrinter& pr_;
  std::map<std::string, std::string> bind_;    ///< Symbol -> its C name in kernels.
  std::map<std::string, std::string> source_;  ///< Symbol -> "state[i]" or "parameter[j]".
  std::string kernels_;
  bool uses_x_ = false, uses_par_ = false;  ///< Whether the kernel reads state, parameter.
  std::set<std::string> declared_;          ///< Symbols named in the current scope.

  /// `      case k: {  // LABEL`: the line opening case k of a switch over `cases`.
  static std::string case_line(const KernelCases& cases, std::size_t k) {
    return "      case " + std::to_string(k) + ": {  // " + cases.labels[k] + "\n";
  }

  /// Start a kernel: nothing read yet.
  void begin_kernel() {
    uses_x_ = uses_par_ = false;
    declared_.clear();
  }

  /// Start a `case` block: a new scope.
  void begin_case() { declared_.clear(); }

  /// The state and parameter arguments, named only where the kernel reads them.
  [[nodiscard]] std::string arguments() const {
    return std::string("const double*") + (uses_x_ ? " state" : "") + ", const double*" +
           (uses_par_ ? " parameter" : "");
  }

  /// `const double NAME = state[i];` (or `= parameter[j];`) for every state variable and parameter
  /// that `exprs` read, in model order; records that the kernel reads x or par.
  std::string name_values(const std::vector<ex>& exprs, const std::string& indent) {
    std::string out;
    auto declare = [&](const std::string& name, const ex& sym, bool& flag) {
      const bool used =
          std::any_of(exprs.begin(), exprs.end(), [&](const ex& e) { return e.has(sym); });
      if (!used || !declared_.insert(name).second) return;
      out += indent + "const double " + bind_.at(name) + " = " + source_.at(name) + ";\n";
      flag = true;
    };
    for (std::size_t i = 0; i < m_.state.size(); ++i)
      declare(m_.state[i], m_.state_symbols[i], uses_x_);
    for (const auto& p : m_.params) declare(p.name, p.symbol, uses_par_);
    return out;
  }
};

/// report.md: the state, the parameters' defaults, derive_latex (render.hpp) and the warnings.
std::string report_markdown(const HybridSystem& sys, ExprPrinter& pr) {
  const Model& m = *sys.model;
  std::ostringstream os;
  os << "<!-- Generated by hybgen " << generator_version()
     << " -- DO NOT EDIT. model sha256: " << m.source_hash << " -->\n";
  os << "# Derivation report: `" << m.name << "`\n\n";
  // One math span per formula (a `$` inside a `$…$` span breaks every Markdown renderer),
  // and the reference measure written out, not called μ (a model may have a parameter μ).
  os << "State $x = (";
  for (std::size_t i = 0; i < m.state.size(); ++i) os << (i ? ", " : "") << m.tex.at(m.state[i]);
  os << ")$; densities are with respect to the Lebesgue measure $";
  for (std::size_t i = 0; i < m.state.size(); ++i)
    os << (i ? " \\wedge " : "") << "d" << m.tex.at(m.state[i]);
  os << "$ in these coordinates.\n\nParameters (defaults): ";
  for (std::size_t j = 0; j < m.params.size(); ++j)
    os << (j ? ", " : "") << "$" << m.tex.at(m.params[j].name) << " = "
       << pr.latex(m.params[j].value) << "$";
  os << ".\n\n";
  os << derive_latex(sys) << "\n";
  if (!m.sim.observables.empty()) {
    // What the runs report the mean of (runtime/include/hybgen/rt/methods/observables.hpp).
    os << "## Observables\n\n";
    for (const Observable& o : m.sim.observables) {
      const auto k = static_cast<std::size_t>(std::max(o.mode, 0));
      os << "- `" << o.name << "` $= " << pr.latex(o.per_mode.at(k)) << "$";
      if (o.mode >= 0) os << " in mode `" << m.modes[k].name << "`, 0 in the others";
      os << "\n";
    }
    os << "\n";
  }
  if (!sys.warnings.empty()) {
    os << "## Warnings\n\n";
    for (const auto& w : sys.warnings) os << "- " << w.text << "\n";
  }
  return os.str();
}

}  // namespace

GeneratedFiles emit(const HybridSystem& sys) {
  const Model& m = *sys.model;
  ExprPrinter pr(m);
  HeaderBuilder hb(sys, pr);
  const KernelCases modes = hb.mode_cases(), guards = hb.guard_cases();
  const std::size_t ng = sys.guards.size();
  const std::size_t n = m.state.size();
  hb.vector_kernel("Vector field X of mode k.", "flow", modes, n,
                   [&](std::size_t k) { return sys.modes[k].flow; });
  hb.scalar_kernel("Divergence of X in mode k (Lebesgue measure in the state coordinates).",
                   "divergence", modes, [&](std::size_t k) { return sys.modes[k].divergence; });
  hb.scalar_kernel("Guard function s_k; the guard surface is s_k = 0.", "guard_surface", guards,
                   [&](std::size_t k) { return sys.guards[k].surface; });
  hb.vector_kernel("Gradient of s_k.", "guard_gradient", guards, n,
                   [&](std::size_t k) { return sys.guards[k].gradient; });
  hb.vector_kernel("Reset map of guard k.", "reset", guards, n,
                   [&](std::size_t k) { return sys.guards[k].reset; });
  hb.vector_kernel("Inverse reset of guard k (closed form where guards[k].has_inverse).",
                   "reset_inverse", guards, n, [&](std::size_t k) {
                     return sys.guards[k].has_inverse ? sys.guards[k].reset_inverse
                                                      : m.state_symbols;
                   });
  hb.vector_kernel("Jacobian matrix of the reset of guard k, row-major.", "reset_jacobian", guards,
                   n * n, [&](std::size_t k) { return sys.guards[k].reset_jacobian; });
  hb.scalar_kernel("Hybrid Jacobian of guard k at a point of its surface.", "hybrid_jacobian",
                   guards, [&](std::size_t k) -> std::optional<ex> {
                     if (sys.guards[k].absorbing) return std::nullopt;
                     return sys.guards[k].hybrid_jacobian_on_surface;
                   });
  hb.density_kernels();
  if (!m.sim.observables.empty()) {
    // One case per observable and mode, at index i·n_mode + k (runtime/include/hybgen/rt/
    // model.hpp, `observable_value`).
    KernelCases cases{"index", {}};
    std::vector<ex> values;
    for (const Observable& o : m.sim.observables)
      for (std::size_t k = 0; k < sys.modes.size(); ++k) {
        cases.labels.push_back("observable " + o.name + " in mode " + sys.modes[k].name);
        values.push_back(o.per_mode[k]);
      }
    hb.scalar_kernel("Observable i in mode k at x, at index i * n_mode + k (`observe` lines).",
                     "observable", cases, [&](std::size_t c) { return values[c]; });
  }
  GeneratedFiles files;
  files.header_name = m.name + ".hpp";
  files.header = hb.assemble();
  files.report_name = "report.md";
  files.report = report_markdown(sys, pr);
  files.n_state = static_cast<int>(n);
  files.n_guard = static_cast<int>(ng);
  return files;
}

void write_generated(const GeneratedFiles& files, const std::string& dir) {
  std::filesystem::create_directories(dir);
  write_file_atomic(dir + "/" + files.header_name, files.header);
  write_file_atomic(dir + "/" + files.report_name, files.report);
}

}  // namespace hybgen::gen
