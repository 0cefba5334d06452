// Stage 4 (emit): IR -> kernel header + report, and the derive renderings.
//
// Size: the header, report.md and derive's text, LaTeX and JSON forms print through one
// Printer (one DAG, so one naming of subexpressions); the emitter owns the layout.
//
// Builder in the style of CasADi's code generator: separate buffers for the
// provenance header, the static tables and each kernel, assembled at the end.

#include "hybgen/gen/emit.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <set>
#include <sstream>

#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/tex.hpp"

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

const char* direction_word(Direction d) {
  return d == Direction::Decreasing ? "decreasing" : "increasing";
}

/// Prints GiNaC expressions deterministically through one DAG.
class Printer {
 public:
  explicit Printer(const Model& m) : tex_(m.tex) {}
  std::string ginac(const ex& e) { return dag_.to_ginac(dag_.import(e)); }
  std::string latex(const ex& e) { return dag_.to_latex(dag_.import(e), tex_); }
  NodeId node(const ex& e) { return dag_.import(e); }
  ExprDag& dag() { return dag_; }
  /// "+ latex" / "- latex(-e)" for a term of a sum.
  std::string signed_term(const ex& e) {
    std::string s = latex(e);
    if (!GiNaC::is_a<GiNaC::add>(e) && !s.empty() && s[0] == '-') return " - " + latex(-e);
    if (GiNaC::is_a<GiNaC::add>(e)) return " + \\left(" + s + "\\right)";
    return " + " + s;
  }

 private:
  ExprDag dag_;
  std::map<std::string, std::string> tex_;
};

/// Names in generated kernels that a state variable or parameter must not take: C++
/// keywords, the kernels' arguments and locals, the generated struct's members, and the
/// object-like macros of <cmath> (glibc's), <cerrno> and <cstdio>. Temporaries (t0, ct0, c0,
/// w0, …) are matched by is_temporary_name. Every name here becomes a free one by appending
/// '_' (none ends in '_'), so the renaming loop ends.
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
      // The kernels' arguments and locals (mode, state and parameter are words of the model
      // language, so no model name can clash with them), and the namespaces they name.
      "mode", "state", "parameter", "out", "result", "slot", "std", "hybgen", "hybgen_model",
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

/// Whether `n` is a name emit_c_block gives a temporary: a lower-case prefix and a number.
/// (Appending '_' makes any name not one, so HeaderBuilder's renaming ends.)
bool is_temporary_name(const std::string& n) {
  std::size_t i = 0;
  while (i < n.size() && std::islower(static_cast<unsigned char>(n[i]))) ++i;
  if (i == 0 || i == n.size()) return false;
  for (std::size_t j = i; j < n.size(); ++j)
    if (!std::isdigit(static_cast<unsigned char>(n[j]))) return false;
  return true;
}

/// The kernel-header builder: one buffer per kernel. A kernel names the state variables
/// and parameters it reads (`const double p = state[1];`) and leaves unread arguments unnamed,
/// so that it compiles without warnings and reads like the model.
class HeaderBuilder {
 public:
  HeaderBuilder(const HybridSystem& sys, Printer& pr) : sys_(sys), m_(*sys.model), pr_(pr) {
    // C names: the model's own, with '_' appended while one clashes (c_reserved_names) or
    // repeats an earlier one.
    std::set<std::string> taken;
    auto c_name = [&](std::string n) {
      while (c_reserved_names().count(n) || is_temporary_name(n) || taken.count(n)) n += '_';
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

  /// A kernel `static void NAME(int mode, const double* state, const double* parameter, double*
  /// out)` switching on k; `outputs(k)` gives the expressions for case k.
  void vector_kernel(const std::string& doc, const std::string& name, std::size_t cases,
                     std::size_t n_out,
                     const std::function<std::vector<ex>(std::size_t)>& outputs) {
    begin_kernel();
    std::ostringstream body;
    body << "    switch (mode) {\n";
    for (std::size_t c = 0; c < cases; ++c) {
      std::vector<CAssignment> as;
      const auto es = outputs(c);
      for (std::size_t i = 0; i < es.size(); ++i)
        as.push_back({"out[" + std::to_string(i) + "]", pr_.node(es[i])});
      begin_case();
      body << "      case " << c << ": {\n"
           << name_values(es, "        ") << emit_c_block(pr_.dag(), as, bind_, "        ")
           << "        break;\n      }\n";
    }
    // An invalid index yields NaN in every output, never stale memory.
    body << "      default:\n        for (int slot = 0; slot < " << n_out
         << "; ++slot) out[slot] = std::nan(\"\");\n        break;\n    }\n  }\n\n";
    kernels_ += "  /// " + doc + "\n  static void " + name + "(int mode, " + arguments() +
                ", double* out) {\n" + body.str();
  }

  /// A kernel `static double NAME(int mode, const double* state, const double* parameter)`.
  void scalar_kernel(const std::string& doc, const std::string& name, std::size_t cases,
                     const std::function<ex(std::size_t)>& value) {
    begin_kernel();
    std::ostringstream body;
    body << "    double result = 0.0;\n    switch (mode) {\n";
    for (std::size_t c = 0; c < cases; ++c) {
      const ex v = value(c);
      std::vector<CAssignment> as{{"result", pr_.node(v)}};
      begin_case();
      body << "      case " << c << ": {\n"
           << name_values({v}, "        ") << emit_c_block(pr_.dag(), as, bind_, "        ")
           << "        break;\n      }\n";
    }
    body << "      default:\n        break;\n    }\n    return result;\n  }\n\n";
    kernels_ += "  /// " + doc + "\n  static double " + name + "(int mode, " + arguments() +
                ") {\n" + body.str();
  }

  /// Emit `conds` as a boolean test into `os`, after naming the values they read (returns
  /// the C condition).
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
    os << emit_c_block(pr_.dag(), as, bind_, indent, var + "t");
    std::string test;
    for (std::size_t i = 0; i < conds.size(); ++i)
      test += (i ? " && " : "") + var + std::to_string(i) + " " + conds[i].op + " 0.0";
    return test;
  }

  void density_kernels() {
    const auto& sim = m_.sim;
    {
      begin_kernel();
      std::ostringstream body;
      const std::string test = conditions(body, sim.support, "    ", "c");
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
        body << "      case " << c << ": {\n";
        const std::string region = conditions(body, closed, "        ", "w");
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
      body << "      case " << c << ": {\n";
      const std::string region = conditions(body, sys_.modes[c].where, "        ", "w");
      const ex u0 = c < sim.initial.size() ? sim.initial[c] : ex(0);
      if (region != "true") body << "        if (!(" << region << ")) return 0.0;\n";
      body << name_values({u0}, "        ")
           << emit_c_block(pr_.dag(), {{"result", pr_.node(u0)}}, bind_, "        ")
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
    os << "  /// Guards: source mode, target mode, direction (-1 decreasing, +1 increasing), "
          "closed-form inverse.\n";
    os << "  static constexpr std::array<hybgen::rt::GuardInfo, " << gnames.size() << "> guards{{";
    for (std::size_t g = 0; g < sys_.guards.size(); ++g) {
      const auto& gd = sys_.guards[g];
      os << (g ? ", " : "") << "{" << gd.from << ", " << gd.to << ", "
         << (gd.direction == Direction::Decreasing ? -1 : 1) << ", "
         << (gd.has_inverse ? "true" : "false") << "}";
    }
    os << "}};\n\n";
    os << kernels_;
    os << "};\n\n";
    os << "static_assert(hybgen::rt::HybridModel<" << sname << ">);\n\n";
    os << "}  // namespace hybgen_model\n";
    return os.str();
  }

 private:
  const HybridSystem& sys_;
  const Model& m_;
  Printer& pr_;
  std::map<std::string, std::string> bind_;    ///< Symbol -> its C name in kernels.
  std::map<std::string, std::string> source_;  ///< Symbol -> "state[i]" or "parameter[j]".
  std::string kernels_;
  bool uses_x_ = false, uses_par_ = false;  ///< Whether the kernel reads state, parameter.
  std::set<std::string> declared_;          ///< Symbols named in the current scope.

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

/// |J| in LaTeX: a number is printed as its absolute value.
std::string abs_latex(Printer& pr, const ex& e) {
  if (GiNaC::is_a<GiNaC::numeric>(e)) return pr.latex(GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(e)));
  return "\\left|" + pr.latex(e) + "\\right|";
}

std::string tuple_latex(Printer& pr, const std::vector<ex>& v) {
  std::string s = "\\left(";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + pr.latex(v[i]);
  return s + "\\right)";
}

std::string tuple_text(Printer& pr, const std::vector<ex>& v) {
  std::string s = "(";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + pr.ginac(v[i]);
  return s + ")";
}

/// J∘Δ⁻¹: the factor of the jump condition written at the post-reset point.
ex jacobian_at_preimage(const HybridSystem& sys, const IrGuard& g) {
  if (!g.has_inverse) return g.hybrid_jacobian_on_surface;
  GiNaC::exmap at;
  for (std::size_t i = 0; i < g.reset_inverse.size(); ++i)
    at[sys.model->state_symbols[i]] = g.reset_inverse[i];
  return simplify(g.hybrid_jacobian_on_surface.subs(at, GiNaC::subs_options::no_pattern));
}

std::string pde_latex(const HybridSystem& sys, Printer& pr, const IrMode& md,
                      const std::string& u) {
  const Model& m = *sys.model;
  std::string s = "\\frac{\\partial " + u + "}{\\partial t}";
  for (std::size_t i = 0; i < m.state.size(); ++i) {
    if (md.flow[i].is_zero()) continue;
    // A coefficient ±1 is a sign only (not "+ 1 ∂u/∂x").
    const std::string coefficient = md.flow[i].is_equal(1)    ? " + "
                                    : md.flow[i].is_equal(-1) ? " - "
                                                              : pr.signed_term(md.flow[i]) + "\\,";
    s += coefficient + "\\frac{\\partial " + u + "}{\\partial " + m.tex.at(m.state[i]) + "}";
  }
  if (md.divergence.is_zero()) return s + " = 0";
  // −div·u, with the sign folded into a single term when div is not a sum.
  const std::string rhs = GiNaC::is_a<GiNaC::add>(md.divergence)
                              ? "-\\left(" + pr.latex(md.divergence) + "\\right)"
                              : pr.latex(-md.divergence);
  return s + " = " + rhs + "\\, " + u;
}

std::string state_args_latex(const Model& m) {
  std::string s;
  for (const auto& x : m.state) s += ", " + m.tex.at(x);
  return s;
}

/// "(e1, e2, ...)" of names.
std::string name_tuple(const std::vector<std::string>& v) {
  std::string s = "(";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s + ")";
}

/// " - c" of q = φ − c: nothing for c = 0, " + 2" for c = −2, " - (a + b)" for sums.
std::string minus_level(const ex& c, const std::function<std::string(const ex&)>& print,
                        const std::string& open, const std::string& close) {
  if (c.is_zero()) return "";
  if (GiNaC::is_a<GiNaC::numeric>(c))
    return GiNaC::ex_to<GiNaC::numeric>(c).is_negative() ? " + " + print(-c) : " - " + print(c);
  if (GiNaC::is_a<GiNaC::add>(c)) return " - " + open + print(c) + close;
  return " - " + print(c);
}

/// The reduction objects of a Lie-group model in text (derive --format text).
void reduction_text(std::ostream& os, const Model& m, Printer& pr) {
  const Reduction& r = *m.reduction;
  const unsigned n = r.algebra_dim;
  os << "\nLie-group reduction (paper §3.2, Impact Lie-Poisson Reduction theorem)\n";
  if (r.coordinates.empty())
    os << "  group        " << r.group << ", given by structure constants on the basis "
       << name_tuple(r.basis) << "\n";
  else
    os << "  group        " << r.group << ", coordinates " << name_tuple(r.coordinates)
       << ", basis E_i = dg/dc_i at the identity " << name_tuple(r.basis) << "\n";
  os << "  brackets     ";
  bool any = false;
  for (unsigned i = 0; i < n; ++i)
    for (unsigned j = i + 1; j < n; ++j)
      if (r.bracket[i][j] != "0") {
        os << (any ? ", " : "") << "[" << r.basis[i] << ", " << r.basis[j]
           << "] = " << r.bracket[i][j];
        any = true;
      }
  os << (any ? "   (others zero)\n" : "all zero (abelian)\n");
  if (r.constrained) {
    os << "  constraints  body velocity xi(w) = " << tuple_text(pr, r.dh)
       << "   (Euler-Poincare-Suslov, multipliers eliminated)\n";
    os << "  energy       = " << pr.ginac(r.hamiltonian)
       << "   (1/2 xi^T I xi on the constraints)\n";
    os << "  ad*_{xi}     (mu' = ad*_{xi} mu + constraint forces, mu = I xi)\n";
  } else {
    os << "  h(zeta)      = " << pr.ginac(r.hamiltonian)
       << "   (H(g, p) = h((l_g)^* p): left-invariant)\n";
    os << "  zeta^#       = dh/dzeta = " << tuple_text(pr, r.dh) << "\n";
    os << "  ad*_{dh}     (zeta' = ad*_{dh} zeta for the column vector zeta)\n";
  }
  for (unsigned i = 0; i < n; ++i) {
    os << "    [";
    for (unsigned j = 0; j < n; ++j) os << (j ? ", " : "") << pr.ginac(r.coadjoint(i, j));
    os << "]\n";
  }
  os << "  q            = phi(g)"
     << minus_level(
            r.level, [&](const ex& e) { return pr.ginac(e); }, "(", ")")
     << (r.coordinates.empty() ? std::string() : ",  phi = " + pr.ginac(r.phi)) << "  ("
     << (r.multiplicative ? "a homomorphism to R*" : "a homomorphism to R or S^1")
     << (r.coordinates.empty() ? ", given by dphi_e" : "") << ")\n";
  os << "  K            = ker phi,  k = ker dphi_e,  dphi_e = " << tuple_text(pr, r.dphi_e) << "\n";
  os << "  q'           = " << pr.ginac(r.q_dot) << "   (depends on (zeta, q) only)\n";
  for (std::size_t k = 0; k < r.momentum_jumps.size() && k < m.guards.size(); ++k)
    os << (r.constrained ? "  Delta w      = " : "  Delta zeta   = ")
       << tuple_text(pr, r.momentum_jumps[k]) << "   (guard " << m.guards[k].name
       << (r.constrained ? "; I B Delta w in Ann(k) + constraint forms)\n" : "; in Ann(k))\n");
  os << "  hypotheses   normal: " << (r.normal ? "yes" : "no")
     << ", codim1: " << (r.codim1 ? "yes" : "no")
     << ", left_invariant: " << (r.left_invariant ? "yes" : "no")
     << ", transversal: " << (r.transversal ? "yes" : "no") << "\n";
}

/// The reduction objects in LaTeX (derive --format latex and report.md).
void reduction_latex(std::ostream& os, const Model& m, Printer& pr) {
  const Reduction& r = *m.reduction;
  const unsigned n = r.algebra_dim;
  const std::string q = m.tex.at(r.q);
  os << "% Lie-group reduction (Impact Lie--Poisson Reduction theorem), group " << r.group << "\n";
  os << "\\[\n  h(\\zeta) = " << pr.latex(r.hamiltonian)
     << ", \\qquad \\zeta^\\sharp = \\frac{\\partial h}{\\partial\\zeta} = "
     << tuple_latex(pr, r.dh) << "\n\\]\n";
  os << "\\[\n  \\mathrm{ad}^*_{\\partial h/\\partial\\zeta} = \\begin{pmatrix}\n";
  for (unsigned i = 0; i < n; ++i) {
    os << "    ";
    for (unsigned j = 0; j < n; ++j) os << (j ? " & " : "") << pr.latex(r.coadjoint(i, j));
    os << (i + 1 < n ? " \\\\\n" : "\n");
  }
  os << "  \\end{pmatrix}, \\qquad \\dot\\zeta = "
        "\\mathrm{ad}^*_{\\partial h/\\partial\\zeta}\\,\\zeta, \\qquad "
     << tex_dot(q) << " = " << pr.latex(r.q_dot) << "\n\\]\n";
  os << "\\[\n  " << q << " = " << pr.latex(r.phi)
     << minus_level(
            r.level, [&](const ex& e) { return pr.latex(e); }, "\\left(", "\\right)")
     << ", \\qquad \\mathfrak k = \\ker d\\phi_e,\\ d\\phi_e = " << tuple_latex(pr, r.dphi_e);
  for (std::size_t k = 0; k < r.momentum_jumps.size() && k < m.guards.size(); ++k)
    os << ", \\qquad \\Delta\\zeta_{" << tex_label(m.guards[k].name)
       << "} = " << tuple_latex(pr, r.momentum_jumps[k]);
  os << "\n\\]\n";
}

/// The `reduction` block of derive --format json (docs/design.md).
nlohmann::ordered_json reduction_json(const Model& m, Printer& pr) {
  const Reduction& r = *m.reduction;
  const unsigned n = r.algebra_dim;
  auto strings = [&](const std::vector<ex>& v) {
    std::vector<std::string> out;
    for (const auto& e : v) out.push_back(pr.ginac(e));
    return out;
  };
  nlohmann::ordered_json j;
  j["algebra_dim"] = n;
  j["momenta"] = r.momenta;
  j["q"] = r.q;
  j["group"] = r.group;
  j["coordinates"] = r.coordinates;
  j["basis"] = r.basis;
  j["bracket"] = r.bracket;
  nlohmann::ordered_json c = nlohmann::ordered_json::array();
  for (unsigned i = 0; i < n; ++i) {
    nlohmann::ordered_json ci = nlohmann::ordered_json::array();
    for (unsigned k = 0; k < n; ++k) {
      std::vector<std::string> row;
      for (unsigned l = 0; l < n; ++l)
        row.push_back(pr.ginac(r.structure_constants[(i * n + k) * n + l]));
      ci.push_back(row);
    }
    c.push_back(ci);
  }
  j["structure_constants"] = c;
  nlohmann::ordered_json ad = nlohmann::ordered_json::array();
  for (unsigned i = 0; i < n; ++i) {
    std::vector<std::string> row;
    for (unsigned k = 0; k < n; ++k) row.push_back(pr.ginac(r.coadjoint(i, k)));
    ad.push_back(row);
  }
  j["coadjoint"] = ad;
  j["hamiltonian"] = pr.ginac(r.hamiltonian);
  j["dh"] = strings(r.dh);
  j["phi"] = pr.ginac(r.phi);
  j["level"] = pr.ginac(r.level);
  j["homomorphism"] = r.multiplicative ? "multiplicative" : "additive";
  j["dphi_e"] = strings(r.dphi_e);
  j["q_equation"] = pr.ginac(r.q_dot);
  nlohmann::ordered_json jumps = nlohmann::ordered_json::array();
  for (std::size_t k = 0; k < r.momentum_jumps.size() && k < m.guards.size(); ++k)
    jumps.push_back({{"guard", m.guards[k].name}, {"delta_zeta", strings(r.momentum_jumps[k])}});
  j["momentum_jumps"] = jumps;
  j["constrained"] = r.constrained;
  j["hypotheses"] = {{"normal", r.normal},
                     {"codim1", r.codim1},
                     {"left_invariant", r.left_invariant},
                     {"transversal", r.transversal}};
  return j;
}

std::string report_markdown(const HybridSystem& sys, Printer& pr) {
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
  if (!sys.warnings.empty()) {
    os << "## Warnings\n\n";
    for (const auto& w : sys.warnings) os << "- " << w << "\n";
  }
  return os.str();
}

}  // namespace

GeneratedFiles emit(const HybridSystem& sys) {
  const Model& m = *sys.model;
  Printer pr(m);
  HeaderBuilder hb(sys, pr);
  const std::size_t nm = sys.modes.size(), ng = sys.guards.size();
  const std::size_t n = m.state.size();
  hb.vector_kernel("Vector field X of mode k.", "flow", nm, n,
                   [&](std::size_t k) { return sys.modes[k].flow; });
  hb.scalar_kernel("Divergence of X in mode k (Lebesgue measure in the state coordinates).",
                   "divergence", nm, [&](std::size_t k) { return sys.modes[k].divergence; });
  hb.scalar_kernel("Guard function s_k; the guard surface is s_k = 0.", "guard_surface", ng,
                   [&](std::size_t k) { return sys.guards[k].surface; });
  hb.vector_kernel("Gradient of s_k.", "guard_gradient", ng, n,
                   [&](std::size_t k) { return sys.guards[k].gradient; });
  hb.vector_kernel("Reset map of guard k.", "reset", ng, n,
                   [&](std::size_t k) { return sys.guards[k].reset; });
  hb.vector_kernel("Inverse reset of guard k (closed form where guards[k].has_inverse).",
                   "reset_inverse", ng, n, [&](std::size_t k) {
                     return sys.guards[k].has_inverse ? sys.guards[k].reset_inverse
                                                      : m.state_symbols;
                   });
  hb.vector_kernel("Jacobian matrix of the reset of guard k, row-major.", "reset_jacobian", ng,
                   n * n, [&](std::size_t k) { return sys.guards[k].reset_jacobian; });
  hb.scalar_kernel("Hybrid Jacobian of guard k at a point of its surface.", "hybrid_jacobian", ng,
                   [&](std::size_t k) { return sys.guards[k].hybrid_jacobian_on_surface; });
  hb.density_kernels();
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

std::string derive_text(const HybridSystem& sys) {
  const Model& m = *sys.model;
  Printer pr(m);
  std::ostringstream os;
  os << "model " << m.name << " ("
     << (m.reduction ? "Lie-group impact system reduced to g* x K\\G: " : "general hybrid system: ")
     << m.state.size() << " states, " << sys.modes.size() << " mode"
     << (sys.modes.size() == 1 ? "" : "s") << ", " << sys.guards.size() << " guard"
     << (sys.guards.size() == 1 ? "" : "s") << ")\n";
  os << "state       (";
  for (std::size_t i = 0; i < m.state.size(); ++i) os << (i ? ", " : "") << m.state[i];
  os << ")   measure: Lebesgue in these coordinates\n";
  os << "parameters  ";
  for (std::size_t j = 0; j < m.params.size(); ++j)
    os << (j ? ", " : "") << m.params[j].name << " = " << pr.ginac(m.params[j].value);
  os << "\n";
  if (m.reduction) reduction_text(os, m, pr);
  for (const auto& md : sys.modes) {
    os << "\nmode " << md.name << "\n";
    if (md.hamiltonian)
      os << "  H = " << pr.ginac(*md.hamiltonian) << "   (Hamilton's equations)\n";
    for (std::size_t i = 0; i < m.state.size(); ++i)
      os << "  " << m.state[i] << "' = " << pr.ginac(md.flow[i]) << "\n";
    os << "  div X = " << pr.ginac(md.divergence) << "\n";
  }
  for (const auto& g : sys.guards) {
    os << "\nguard " << g.name << ": " << sys.modes[static_cast<std::size_t>(g.from)].name << " -> "
       << sys.modes[static_cast<std::size_t>(g.to)].name << " when s = " << pr.ginac(g.surface)
       << " crosses 0, " << direction_word(g.direction) << "\n";
    os << "  reset            Delta" << tuple_text(pr, m.state_symbols) << " = "
       << tuple_text(pr, g.reset) << "\n";
    if (g.has_inverse)
      os << "  inverse reset    Delta^-1" << tuple_text(pr, m.state_symbols) << " = "
         << tuple_text(pr, g.reset_inverse) << "\n";
    else if (g.inverse_on_guard_only)
      os << "  inverse reset    none: locally injective on the guard only (methods transfer, "
            "invariant, particles)\n";
    else
      os << "  inverse reset    numeric (Newton at run time)\n";
    os << "  hybrid Jacobian  J = " << pr.ginac(g.hybrid_jacobian_on_surface) << "   (on s = 0)\n";
    if (!g.surface_note.empty() &&
        !is_identically_zero(g.hybrid_jacobian - g.hybrid_jacobian_on_surface, {}))
      os << "                   general form: J = " << pr.ginac(g.hybrid_jacobian) << "\n";
  }
  os << "\nhybrid Frobenius-Perron PDE (paper Thm 3.11)\n";
  for (const auto& md : sys.modes) {
    std::string u = sys.modes.size() > 1 ? "u_" + md.name : "u";
    os << "  d" << u << "/dt";
    for (std::size_t i = 0; i < m.state.size(); ++i)
      if (!md.flow[i].is_zero())
        os << " + (" << pr.ginac(md.flow[i]) << ") d" << u << "/d" << m.state[i];
    os << " = " << (md.divergence.is_zero() ? "0" : "-(" + pr.ginac(md.divergence) + ") " + u)
       << "\n";
  }
  for (const auto& g : sys.guards) {
    std::string uf =
        sys.modes.size() > 1 ? "u_" + sys.modes[static_cast<std::size_t>(g.from)].name : "u";
    std::string ut =
        sys.modes.size() > 1 ? "u_" + sys.modes[static_cast<std::size_t>(g.to)].name : "u";
    os << "  jump at " << g.name << ": " << ut << "(t+, y) = " << uf
       << "(t-, Delta^-1(y)) / |J(Delta^-1(y))|";
    if (g.has_inverse) {
      std::string pre = tuple_text(pr, g.reset_inverse);
      os << "\n      = " << uf << "(t-, " << pre.substr(1, pre.size() - 2) << ") / |"
         << pr.ginac(jacobian_at_preimage(sys, g)) << "|";
    }
    os << "   for y in Delta(S)\n";
  }
  if (!sys.warnings.empty()) {
    os << "\nwarnings\n";
    for (const auto& w : sys.warnings) os << "  " << w << "\n";
  }
  return os.str();
}

std::string derive_latex(const HybridSystem& sys) {
  const Model& m = *sys.model;
  Printer pr(m);
  std::ostringstream os;
  const bool multi = sys.modes.size() > 1;
  os << "% hybgen " << generator_version() << ": hybrid Frobenius--Perron PDE of '" << m.name
     << "' (needs amsmath)\n";
  if (m.reduction) reduction_latex(os, m, pr);
  // Each mode's field, one line per state (its own derivative), and its divergence.
  for (const auto& md : sys.modes) {
    os << "\\[\n  \\text{mode } " << tex_label(md.name) << ":\\qquad\n  \\begin{aligned}\n";
    for (std::size_t i = 0; i < m.state.size(); ++i)
      os << "    " << tex_dot(m.tex.at(m.state[i])) << " &= " << pr.latex(md.flow[i]) << ", \\\\\n";
    os << "    \\operatorname{div}_\\mu X &= " << pr.latex(md.divergence)
       << "\n  \\end{aligned}\n\\]\n";
  }
  // Each guard: its surface, its reset (and inverse) and the hybrid Jacobian.
  for (const auto& g : sys.guards) {
    os << "\\[\n  \\text{guard } " << tex_label(g.name) << "\\ ("
       << tex_label(sys.modes[static_cast<std::size_t>(g.from)].name) << " \\to "
       << tex_label(sys.modes[static_cast<std::size_t>(g.to)].name)
       << "):\\qquad\n  \\begin{aligned}\n    \\mathcal S_{" << tex_label(g.name) << "} &= \\{"
       << pr.latex(g.surface) << " = 0\\}, \\\\\n    \\Delta" << tuple_latex(pr, m.state_symbols)
       << " &= " << tuple_latex(pr, g.reset) << ", \\\\\n";
    if (g.has_inverse)
      os << "    \\Delta^{-1}" << tuple_latex(pr, m.state_symbols)
         << " &= " << tuple_latex(pr, g.reset_inverse) << ", \\\\\n";
    os << "    \\mathcal J^X_\\mu(\\Delta) &= " << pr.latex(g.hybrid_jacobian_on_surface)
       << "\n  \\end{aligned}\n\\]\n";
  }
  os << "\\[\n\\begin{cases}\n";
  for (const auto& md : sys.modes) {
    std::string u = multi ? "u_{" + tex_label(md.name) + "}" : "u";
    os << "  " << pde_latex(sys, pr, md, u) << ", & x \\notin \\Delta(\\mathcal S); \\\\[1ex]\n";
  }
  for (std::size_t k = 0; k < sys.guards.size(); ++k) {
    const auto& g = sys.guards[k];
    std::string uf =
        multi ? "u_{" + tex_label(sys.modes[static_cast<std::size_t>(g.from)].name) + "}" : "u";
    std::string ut =
        multi ? "u_{" + tex_label(sys.modes[static_cast<std::size_t>(g.to)].name) + "}" : "u";
    std::string args = state_args_latex(m);
    os << "  " << ut << "(t^+" << args << ") = ";
    if (g.has_inverse) {
      std::string pre;
      for (const auto& e : g.reset_inverse) pre += ", " + pr.latex(e);
      const ex Jpre = jacobian_at_preimage(sys, g);
      if (GiNaC::is_a<GiNaC::numeric>(Jpre) && GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(Jpre)) == 1)
        os << uf << "(t^-" << pre << ")";
      else
        os << "\\dfrac{" << uf << "(t^-" << pre << ")}{" << abs_latex(pr, Jpre) << "}";
    } else {
      os << "\\dfrac{" << uf
         << "(t^-, \\Delta^{-1}(x))}{\\left|\\mathcal J(\\Delta^{-1}(x))\\right|}";
    }
    os << ", & x \\in \\Delta(\\mathcal S_{" << tex_label(g.name) << "})"
       << (k + 1 < sys.guards.size() ? ";\\\\[1ex]" : ".") << "\n";
  }
  os << "\\end{cases}\n\\]\n";
  return os.str();
}

std::string derive_latex_document(const HybridSystem& sys) {
  const Model& m = *sys.model;
  Printer pr(m);
  std::string name;
  for (char c : m.name) name += c == '_' ? std::string("\\_") : std::string(1, c);
  std::ostringstream os;
  os << "% hybgen " << generator_version() << ": pdflatex this file\n"
     << "\\documentclass[11pt]{article}\n\\usepackage[margin=2cm]{geometry}\n"
     << "\\usepackage{amsmath,amssymb}\n\\allowdisplaybreaks\n\\begin{document}\n"
     << "\\section*{The hybrid Frobenius--Perron equation of \\texttt{" << name << "}}\n"
     << "State $" << tuple_latex(pr, m.state_symbols) << "$";
  if (!m.params.empty()) {
    os << ", parameters ";
    for (std::size_t j = 0; j < m.params.size(); ++j)
      os << (j ? ", " : "") << "$" << m.tex.at(m.params[j].name) << " = "
         << pr.latex(m.params[j].value) << "$";
  }
  os << ". The density $u$ is with respect to the Lebesgue measure $\\mu$ in these "
        "coordinates.\n\n"
     << derive_latex(sys) << "\\end{document}\n";
  return os.str();
}

nlohmann::ordered_json derive_json(const HybridSystem& sys) {
  const Model& m = *sys.model;
  Printer pr(m);
  nlohmann::ordered_json j;
  j["model"] = m.name;
  j["kind"] = m.reduction ? "lie" : "hybrid";
  j["state"] = m.state;
  nlohmann::ordered_json params = nlohmann::ordered_json::object();
  for (const auto& p : m.params) {
    if (GiNaC::is_a<GiNaC::numeric>(p.value) &&
        GiNaC::ex_to<GiNaC::numeric>(p.value).is_integer() && std::fabs(p.value_d) < 9.0e15)
      params[p.name] = static_cast<long long>(p.value_d);
    else
      params[p.name] = p.value_d;
  }
  j["parameters"] = params;
  nlohmann::ordered_json modes = nlohmann::ordered_json::array();
  for (const auto& md : sys.modes) {
    nlohmann::ordered_json mj;
    mj["name"] = md.name;
    std::vector<std::string> flow;
    for (const auto& f : md.flow) flow.push_back(pr.ginac(f));
    mj["flow"] = flow;
    mj["divergence"] = pr.ginac(md.divergence);
    if (md.hamiltonian) mj["hamiltonian"] = pr.ginac(*md.hamiltonian);
    modes.push_back(mj);
  }
  j["modes"] = modes;
  nlohmann::ordered_json guards = nlohmann::ordered_json::array();
  for (const auto& g : sys.guards) {
    nlohmann::ordered_json gj;
    gj["name"] = g.name;
    gj["from"] = sys.modes[static_cast<std::size_t>(g.from)].name;
    gj["to"] = sys.modes[static_cast<std::size_t>(g.to)].name;
    gj["surface"] = pr.ginac(g.surface);
    gj["direction"] = direction_word(g.direction);
    std::vector<std::string> reset, inverse;
    for (const auto& e : g.reset) reset.push_back(pr.ginac(e));
    gj["reset"] = reset;
    if (g.has_inverse) {
      for (const auto& e : g.reset_inverse) inverse.push_back(pr.ginac(e));
      gj["reset_inverse"] = inverse;
    } else {
      gj["reset_inverse"] = nullptr;
    }
    gj["reset_inverse_kind"] =
        g.has_inverse ? "symbolic" : (g.inverse_on_guard_only ? "none" : "numeric");
    gj["hybrid_jacobian"] = pr.ginac(g.hybrid_jacobian_on_surface);
    gj["hybrid_jacobian_general"] = pr.ginac(g.hybrid_jacobian);
    guards.push_back(gj);
  }
  j["guards"] = guards;
  if (m.reduction)
    j["reduction"] = reduction_json(m, pr);
  else
    j["reduction"] = nullptr;
  j["warnings"] = sys.warnings;
  return j;
}

}  // namespace hybgen::gen
