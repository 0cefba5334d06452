// Stage 2 (check): AST -> Model.
//
// Size: the Checker, one method per statement kind, the expression converter with its
// bounds (fuzzing findings), and the --set overrides, which apply the same rules.
//
// Invariants of the result: every symbol in every expression is a state
// variable or a parameter of the model (parameter defaults use earlier
// parameters only); every number is an exact rational; every default is a
// finite real; every mode defines the whole vector field; every guard names
// existing modes and a reset of the right arity.

#include "hybgen/gen/check.hpp"

#include "check_internal.hpp"
#include "lexer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "hybgen/gen/hash.hpp"
#include "hybgen/gen/limits.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/gen/tex.hpp"
#include "hybgen/rt/setting_rules.hpp"

namespace hybgen::gen {

namespace {

using GiNaC::ex;

const std::set<std::string>& function_names() {
  static const std::set<std::string> f = {"sin",  "cos",  "tan", "asin", "acos", "atan", "sinh",
                                          "cosh", "tanh", "exp", "log",  "sqrt", "abs"};
  return f;
}

const std::set<std::string>& reserved_names() {
  static const std::set<std::string> r = {"model", "parameter",  "state", "mode",
                                          "guard", "simulation", "pi"};
  return r;
}

/// Levenshtein distance, for "did you mean" hints.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
      cur[j] =
          std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] != b[j - 1] ? 1u : 0u)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string suggestion(const std::string& name, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_d = 3;
  for (const auto& c : candidates) {
    std::size_t d = edit_distance(name, c);
    if (d < best_d) best_d = d, best = c;
  }
  return best.empty() ? std::string() : " (did you mean '" + best + "'?)";
}

/// Converts AST expressions to GiNaC with a scope of visible names.
class Converter {
 public:
  Converter(const SourceText& src, std::map<std::string, ex> scope, std::string what)
      : src_(src), scope_(std::move(scope)), what_(std::move(what)) {}

  ex convert(const ExprPtr& e) const {
    try {
      return convert_node(*e, 0);
    } catch (const ModelError&) {
      throw;
    } catch (const std::exception& err) {
      throw src_.error(e->loc, std::string("cannot evaluate expression: ") + err.what());
    }
  }

 private:
  /// r, the result of e, unless GiNaC's automatic evaluation folded exponents
  /// past kMaxExponent: (x^a)^b becomes x^(a·b) and x^a·x^b becomes x^(a+b),
  /// so each written exponent can be in bounds while the folded one is not
  /// (fuzzer finding F1b: ((x^4096)^4096)^4096 is x^(2^36)). Only r's own
  /// power and the factors of its product are new; deeper terms were checked.
  /// A symbolic exponent is bounded too, by its constant part: expand turns
  /// a^(n + x) into a^n·a^x (finding F8: (2/5)^(10^17 + x) hung in expand).
  /// A power of zero with a symbolic exponent is refused: 0^e is 0 for e > 0 and
  /// a pole for e < 0, and GiNaC differentiates it as 0^e·(e'·log 0 + e·0'·0^(-1)),
  /// which throws, and leaks, even where 0^e = 0 (finding F11: 0^(-f) in a reset).
  ex bounded(const ex& r, const Expr& e) const {
    auto check_power = [&](const ex& f) {
      if (!GiNaC::is_a<GiNaC::power>(f)) return;
      if (!GiNaC::is_a<GiNaC::numeric>(f.op(1))) {
        if (f.op(0).is_zero())
          throw src_.error(e.loc,
                           "0 to a symbolic power: 0^e is 0 for e > 0 and a pole for e < "
                           "0, and hybgen cannot differentiate it; write the value it has");
        const double c = expanded_constant_bound(f.op(1));
        if (c > kMaxExponent) {
          char about[32];
          std::snprintf(about, sizeof about, "%.3g", c);
          throw src_.error(e.loc, std::string("exponent too large: its constant part is up to ") +
                                      about + " (at most " + std::to_string(kMaxExponent) +
                                      " in x^(a + y), which expands to x^a*x^y)");
        }
        return;
      }
      const auto& n = GiNaC::ex_to<GiNaC::numeric>(f.op(1));
      if (!n.is_rational() || GiNaC::abs(n.numer()) > kMaxExponent || n.denom() > kMaxExponent)
        throw src_.error(e.loc, "exponent too large once powers are combined (at most " +
                                    std::to_string(kMaxExponent) +
                                    " in x^a, after (x^a)^b = x^(a*b))");
    };
    check_power(r);
    if (GiNaC::is_a<GiNaC::mul>(r))
      for (std::size_t i = 0; i < r.nops(); ++i) check_power(r.op(i));
    return r;
  }

  ex convert_node(const Expr& e, int depth) const {
    if (depth > 512) throw src_.error(e.loc, "expression is nested too deeply");
    switch (e.kind) {
      case Expr::Kind::Number: {
        try {
          return ex(exact_number(e.text));
        } catch (const std::exception& err) {
          throw src_.error(e.loc, err.what());
        }
      }
      case Expr::Kind::Symbol: {
        if (e.text == "pi") return GiNaC::Pi;
        auto it = scope_.find(e.text);
        if (it != scope_.end()) return it->second;
        std::vector<std::string> names;
        for (const auto& [k, v] : scope_) names.push_back(k);
        throw src_.error(e.loc,
                         "unknown name '" + e.text + "' in " + what_ + suggestion(e.text, names));
      }
      case Expr::Kind::Unary: {
        ex a = convert_node(*e.args.at(0), depth + 1);
        return e.text == "-" ? -a : a;
      }
      case Expr::Kind::Binary: {
        ex a = convert_node(*e.args.at(0), depth + 1);
        ex b = convert_node(*e.args.at(1), depth + 1);
        if (e.text == "+") return a + b;
        if (e.text == "-") return a - b;
        if (e.text == "*") return bounded(a * b, e);
        if (e.text == "/") {
          if (b.is_zero()) throw src_.error(e.args.at(1)->loc, "division by zero");
          return bounded(a / b, e);
        }
        if (e.text == "^" || e.text == "**") {
          if (a.is_zero() && GiNaC::is_a<GiNaC::numeric>(b) &&
              !GiNaC::ex_to<GiNaC::numeric>(b).is_positive())
            throw src_.error(e.loc, "0 raised to a non-positive power");
          // Bound exact arithmetic: a huge exponent (even on a symbol) makes
          // every later exact evaluation hang, and a numeric power is computed
          // exactly here, so its size is bounded too.
          if (GiNaC::is_a<GiNaC::numeric>(b)) {
            const auto& nb = GiNaC::ex_to<GiNaC::numeric>(b);
            if (!nb.is_rational() || GiNaC::abs(nb.numer()) > kMaxExponent ||
                nb.denom() > kMaxExponent)
              throw src_.error(e.args.at(1)->loc,
                               "exponent too large (at most " + std::to_string(kMaxExponent) + ")");
            // Not only a number: a product or power with a numeric part
            // raises that part exactly too (finding F12).
            const double bits = exact_bits_per_power(a) * GiNaC::abs(nb).to_double();
            if (bits > kMaxExactBits)
              throw src_.error(
                  e.loc, "number too large: this power has about " +
                             std::to_string(static_cast<long long>(bits)) + " bits (at most " +
                             std::to_string(static_cast<long long>(kMaxExactBits)) + ")");
          }
          return bounded(GiNaC::pow(a, b), e);
        }
        throw InternalError("unknown binary operator '" + e.text + "'");
      }
      case Expr::Kind::Call: {
        if (!function_names().count(e.text)) {
          std::vector<std::string> names(function_names().begin(), function_names().end());
          throw src_.error(e.loc, "unknown function '" + e.text + "'" + suggestion(e.text, names));
        }
        if (e.args.size() != 1)
          throw src_.error(e.loc, "function '" + e.text + "' takes 1 argument, " +
                                      std::to_string(e.args.size()) + " given");
        ex a = convert_node(*e.args[0], depth + 1);
        const std::string& f = e.text;
        if (f == "sin") return GiNaC::sin(a);
        if (f == "cos") return GiNaC::cos(a);
        if (f == "tan") return GiNaC::tan(a);
        if (f == "asin") return GiNaC::asin(a);
        if (f == "acos") return GiNaC::acos(a);
        if (f == "atan") return GiNaC::atan(a);
        if (f == "sinh") return GiNaC::sinh(a);
        if (f == "cosh") return GiNaC::cosh(a);
        if (f == "tanh") return GiNaC::tanh(a);
        if (f == "exp") return GiNaC::exp(a);
        if (f == "log") {
          if (a.is_zero()) throw src_.error(e.loc, "log(0) is not finite");
          return GiNaC::log(a);
        }
        if (f == "sqrt") return GiNaC::sqrt(a);
        if (f == "abs") return GiNaC::abs(a);
        throw InternalError("function table out of sync: " + f);
      }
    }
    throw InternalError("unknown expression kind");
  }

  const SourceText& src_;
  std::map<std::string, ex> scope_;
  std::string what_;
};

/// Evaluate a constant expression to a finite double, or return nullopt.
std::optional<double> to_finite_double(const ex& e) {
  try {
    ex v = GiNaC::evalf(e);
    if (!GiNaC::is_a<GiNaC::numeric>(v)) return std::nullopt;
    const auto& n = GiNaC::ex_to<GiNaC::numeric>(v);
    if (!n.is_real()) return std::nullopt;
    double d = n.to_double();
    if (!std::isfinite(d)) return std::nullopt;
    return d;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

bool depends_on_any(const ex& e, const std::vector<ex>& syms) {
  for (const auto& s : syms)
    if (e.has(s)) return true;
  return false;
}

/// The names of the states and parameters of `m` as its symbols: what an observable may use.
std::map<std::string, ex> model_scope(const Model& m) {
  std::map<std::string, ex> scope;
  for (std::size_t i = 0; i < m.state.size(); ++i) scope[m.state[i]] = m.state_symbols[i];
  for (const Parameter& p : m.params) scope[p.name] = p.symbol;
  return scope;
}

/// `observe NAME = [MODE:] EXPR` of `src` as an Observable of `m` (its modes and symbols):
/// f = EXPR in MODE, or in every mode without one, and 0 in the others. Throws ModelError,
/// located: an unknown mode, an expression that does not convert.
Observable checked_observable(const Model& m, const ObserveDecl& d, const SourceText& src) {
  Observable o;
  o.name = d.name.name;
  o.loc = d.name.loc;
  const Converter conv(src, model_scope(m), "the observable '" + o.name + "'");
  const ex f = conv.convert(d.value);
  std::vector<std::string> names;
  for (const ModeSpec& md : m.modes) names.push_back(md.name);
  if (d.mode) {
    const auto it = std::find(names.begin(), names.end(), d.mode->name);
    if (it == names.end()) {
      std::string hint = suggestion(d.mode->name, names);
      if (hint.empty()) {
        for (const std::string& n : names) hint += (hint.empty() ? " (the modes: " : ", ") + n;
        hint += ")";
      }
      throw src.error(d.mode->loc, "unknown mode '" + d.mode->name + "'" + hint);
    }
    o.mode = static_cast<int>(it - names.begin());
  }
  for (int k = 0; k < static_cast<int>(m.modes.size()); ++k)
    o.per_mode.push_back(o.mode >= 0 && k != o.mode ? ex(0) : f);
  return o;
}

}  // namespace

GiNaC::numeric exact_number(const std::string& literal) {
  // literal := digits [. digits] [(e|E) [+-] digits]  (or . digits ...)
  std::string mant, exps;
  std::size_t epos = literal.find_first_of("eE");
  mant = literal.substr(0, epos);
  if (epos != std::string::npos) exps = literal.substr(epos + 1);
  std::string digits;
  long frac = 0;
  bool seen_dot = false;
  for (char c : mant) {
    if (c == '.') {
      if (seen_dot) throw std::invalid_argument("malformed number '" + literal + "'");
      seen_dot = true;
    } else if (c >= '0' && c <= '9') {
      digits += c;
      if (seen_dot) ++frac;
    } else {
      throw std::invalid_argument("malformed number '" + literal + "'");
    }
  }
  if (digits.empty()) throw std::invalid_argument("malformed number '" + literal + "'");
  long e10 = 0;
  if (!exps.empty()) {
    std::size_t i = 0;
    bool neg = false;
    if (exps[0] == '+' || exps[0] == '-') neg = exps[0] == '-', i = 1;
    if (i >= exps.size()) throw std::invalid_argument("malformed exponent in '" + literal + "'");
    for (; i < exps.size(); ++i) {
      if (exps[i] < '0' || exps[i] > '9')
        throw std::invalid_argument("malformed exponent in '" + literal + "'");
      e10 = e10 * 10 + (exps[i] - '0');
      if (e10 > 400) throw std::invalid_argument("number '" + literal + "' is out of range");
    }
    if (neg) e10 = -e10;
  }
  std::size_t nz = digits.find_first_not_of('0');
  digits = nz == std::string::npos ? "0" : digits.substr(nz);
  if (digits.size() > 400)
    throw std::invalid_argument("number '" + literal + "' has too many digits");
  GiNaC::numeric value(digits.c_str());
  long shift = e10 - frac;
  GiNaC::numeric ten(10);
  if (shift > 0) value *= GiNaC::pow(ten, GiNaC::numeric(shift));
  if (shift < 0) value /= GiNaC::pow(ten, GiNaC::numeric(-shift));
  if (!value.is_zero()) {
    double d = value.to_double();
    if (!std::isfinite(d) || d == 0.0)
      throw std::invalid_argument("number '" + literal + "' is out of range (not a finite double)");
  }
  return value;
}

namespace {

/// Stage 2 for a general model, one method per statement kind in the order check() runs
/// them; each refuses what the paper's hypotheses or the language forbid with a located error.
/// A struct: its fields are the model being checked and the scopes the methods share.
struct Checker {
  /// A checker of `src`'s model.
  explicit Checker(const SourceText& source) : src(source) {
    m.path = source.path();
    m.source_hash = sha256_hex(source.text());
  }

  /// The model's name: `model NAME`, else the file stem.
  void name(const ModelAst& ast) {
    if (ast.name) {
      m.name = ast.name->name;
    } else {
      std::string stem = src.path();
      auto slash = stem.find_last_of('/');
      if (slash != std::string::npos) stem = stem.substr(slash + 1);
      auto dot = stem.find('.');
      if (dot != std::string::npos) stem = stem.substr(0, dot);
      std::string clean;
      for (char c : stem) clean += (std::isalnum(static_cast<unsigned char>(c)) ? c : '_');
      if (clean.empty() || std::isdigit(static_cast<unsigned char>(clean[0]))) clean = "m_" + clean;
      m.name = clean;
    }
  }

  /// States and parameters share a namespace; checked in source order so that an error
  /// points at the later of two declarations.
  void names(const ModelAst& ast) {
    {
      std::vector<std::pair<SourceLoc, std::pair<std::string, const char*>>> decls;
      for (const auto& st : ast.states) decls.push_back({st.loc, {st.name, "state variable"}});
      for (const auto& p : ast.params) decls.push_back({p.loc, {p.name, "parameter"}});
      std::stable_sort(decls.begin(), decls.end(), [](const auto& a, const auto& b) {
        return a.first.line != b.first.line ? a.first.line < b.first.line
                                            : a.first.col < b.first.col;
      });
      for (const auto& [loc, d] : decls) declare(d.first, loc, d.second);
    }
  }

  /// The state variables, as real symbols.
  void states(const ModelAst& ast) {
    if (ast.states.empty())
      throw src.error({1, 1}, "the model declares no state variables (write e.g. 'state x, p')");
    for (const auto& s : ast.states) {
      ex sym = GiNaC::realsymbol(s.name);
      m.state.push_back(s.name);
      m.state_symbols.push_back(sym);
      state_scope[s.name] = sym;
    }
  }

  /// The parameters: defaults may use earlier parameters only.
  void parameters(const ModelAst& ast) {
    for (const auto& p : ast.params) {
      Converter conv(src, param_values, "the default of parameter '" + p.name + "'");
      ex value = conv.convert(p.value);
      auto d = to_finite_double(value);
      if (!d)
        throw src.error(p.value->loc,
                        "the default of parameter '" + p.name + "' is not a finite real number");
      ex sym = GiNaC::realsymbol(p.name);
      m.params.push_back({p.name, sym, value, *d, p.loc});
      param_scope[p.name] = sym;
      param_values[p.name] = value;
    }
    full_scope = state_scope;
    full_scope.insert(param_scope.begin(), param_scope.end());
    state_syms = m.state_symbols;
  }

  /// The modes: a vector field, or a Hamiltonian with its coordinates and momenta, and the
  /// mode's region (`where`).
  void modes(const ModelAst& ast) {
    if (ast.modes.empty())
      throw src.error({1, 1}, "the model declares no mode (write 'mode NAME { x' = ... }')");
    for (const auto& md : ast.modes) {
      if (mode_index.count(md.name.name))
        throw src.error(md.name.loc, "mode '" + md.name.name + "' is already declared");
      mode_index[md.name.name] = static_cast<int>(m.modes.size());
      ModeSpec spec;
      spec.name = md.name.name;
      spec.loc = md.name.loc;
      const std::string where = "mode '" + md.name.name + "'";
      if (md.hamiltonian && !md.flows.empty())
        throw src.error(md.flows.front().var.loc,
                        where + " has both a Hamiltonian and flow equations; give one of them");
      if (!md.hamiltonian && (!md.coordinates.empty() || !md.momenta.empty()))
        throw src.error(md.name.loc, where + " names coordinates/momenta but has no Hamiltonian");
      if (md.hamiltonian) {
        Converter conv(src, full_scope, "the Hamiltonian of " + where);
        spec.hamiltonian = conv.convert(md.hamiltonian);
        const std::size_t n = m.state.size();
        auto resolve = [&](const std::vector<Name>& names, std::vector<int>& out,
                           const char* what) {
          for (const auto& nm : names) {
            auto it = std::find(m.state.begin(), m.state.end(), nm.name);
            if (it == m.state.end())
              throw src.error(nm.loc,
                              std::string(what) + " '" + nm.name + "' is not a state variable");
            out.push_back(static_cast<int>(it - m.state.begin()));
          }
        };
        resolve(md.coordinates, spec.coordinates, "coordinate");
        resolve(md.momenta, spec.momenta, "momentum");
        if (spec.coordinates.empty() && spec.momenta.empty()) {
          if (n % 2 != 0)
            throw src.error(md.hamiltonian_loc,
                            where +
                                ": a Hamiltonian needs as many momenta as coordinates, but the "
                                "state has " +
                                std::to_string(n) +
                                " variables (name them with 'coordinates' and 'momenta')");
          for (std::size_t i = 0; i < n / 2; ++i) spec.coordinates.push_back(static_cast<int>(i));
          for (std::size_t i = n / 2; i < n; ++i) spec.momenta.push_back(static_cast<int>(i));
        }
        std::set<int> all(spec.coordinates.begin(), spec.coordinates.end());
        all.insert(spec.momenta.begin(), spec.momenta.end());
        if (spec.coordinates.size() != spec.momenta.size() || all.size() != n ||
            spec.coordinates.size() + spec.momenta.size() != n)
          throw src.error(md.hamiltonian_loc,
                          where +
                              ": 'coordinates' and 'momenta' must split the state into two "
                              "lists of equal length covering every state variable once");
      } else {
        if (md.flows.empty())
          throw src.error(md.name.loc, where +
                                           " has no flow equations (write x' = ... for every "
                                           "state variable, or a hamiltonian)");
        std::vector<std::optional<ex>> flow(m.state.size());
        Converter conv(src, full_scope, "the flow of " + where);
        for (const auto& f : md.flows) {
          auto it = std::find(m.state.begin(), m.state.end(), f.var.name);
          if (it == m.state.end())
            throw src.error(f.var.loc, "'" + f.var.name + "' in " + where +
                                           " is not a state variable" +
                                           suggestion(f.var.name, m.state));
          auto i = static_cast<std::size_t>(it - m.state.begin());
          if (flow[i]) throw src.error(f.var.loc, where + " gives " + f.var.name + "' twice");
          flow[i] = conv.convert(f.rhs);
        }
        for (std::size_t i = 0; i < flow.size(); ++i) {
          if (!flow[i])
            throw src.error(md.name.loc, where + " has no equation for " + m.state[i] + "'");
          spec.flow.push_back(*flow[i]);
        }
      }
      Converter cconv(src, full_scope, "a 'where' condition of " + where);
      for (const auto& r : md.where)
        spec.where.push_back({cconv.convert(r.lhs) - cconv.convert(r.rhs), r.op, r.loc});
      m.modes.push_back(std::move(spec));
    }
  }

  /// The guards: surface, direction, source and target modes, and the reset.
  void guards(const ModelAst& ast) {
    std::set<std::string> guard_names;
    for (const auto& g : ast.guards) {
      if (!guard_names.insert(g.name.name).second)
        throw src.error(g.name.loc, "guard '" + g.name.name + "' is already declared");
      GuardSpec spec;
      spec.name = g.name.name;
      spec.loc = g.name.loc;
      const std::string where = "guard '" + g.name.name + "'";
      auto find_mode = [&](const Name& n) {
        auto it = mode_index.find(n.name);
        if (it == mode_index.end()) {
          std::vector<std::string> names;
          for (const auto& [k, v] : mode_index) names.push_back(k);
          throw src.error(n.loc,
                          "unknown mode '" + n.name + "' in " + where + suggestion(n.name, names));
        }
        return it->second;
      };
      if (g.from) {
        spec.from = find_mode(*g.from);
      } else if (m.modes.size() == 1) {
        spec.from = 0;
      } else {
        throw src.error(g.name.loc, where + " needs 'from MODE' (the model has " +
                                        std::to_string(m.modes.size()) + " modes)");
      }
      const bool absorb = g.has_reset && g.reset.kind == ResetDecl::Kind::Absorb;
      if (absorb && g.to)
        throw src.error(g.to->loc, where +
                                       " absorbs the mass that reaches it ('reset absorb'): it "
                                       "has no target mode; omit 'to " +
                                       g.to->name + "'");
      // An absorbing guard's mass leaves the system: no target mode (GuardSpec::to = −1).
      spec.to = absorb ? -1 : g.to ? find_mode(*g.to) : spec.from;
      if (!g.has_when)
        throw src.error(g.name.loc, where + " has no surface (write 'when s = 0 decreasing')");
      Converter conv(src, full_scope, "the surface of " + where);
      spec.surface = conv.convert(g.when.lhs) - conv.convert(g.when.rhs);
      spec.surface_loc = g.when.loc;
      spec.direction_loc = g.direction_loc;
      if (!depends_on_any(spec.surface, state_syms))
        throw src.error(g.when.loc, "the surface of " + where + " does not depend on the state");
      spec.direction = g.direction;
      if (!g.has_reset)
        throw src.error(g.name.loc, where +
                                        " has no reset (write 'reset identity', 'reset "
                                        "elastic', 'reset restitution e', 'reset absorb' or "
                                        "'reset (...)')");
      spec.reset_kind = g.reset.kind;
      spec.reset_loc = g.reset.loc;
      switch (g.reset.kind) {
        case ResetDecl::Kind::Identity:
        case ResetDecl::Kind::Absorb:
          break;
        case ResetDecl::Kind::Elastic:
          spec.restitution = 1;
          break;
        case ResetDecl::Kind::Restitution: {
          Converter rconv(src, full_scope, "the restitution coefficient of " + where);
          spec.restitution = rconv.convert(g.reset.coefficient);
          break;
        }
        case ResetDecl::Kind::Explicit: {
          if (g.reset.components.size() != m.state.size()) {
            std::string names;
            for (std::size_t i = 0; i < m.state.size(); ++i) names += (i ? ", " : "") + m.state[i];
            throw src.error(
                g.reset.components_loc,
                "the reset of " + where + " has " + std::to_string(g.reset.components.size()) +
                    " component" + (g.reset.components.size() == 1 ? "" : "s") + ", expected " +
                    std::to_string(m.state.size()) + " (one per state variable: " + names + ")");
          }
          Converter rconv(src, full_scope, "the reset of " + where);
          for (const auto& c : g.reset.components) spec.reset.push_back(rconv.convert(c));
          break;
        }
      }
      if ((spec.reset_kind == ResetDecl::Kind::Elastic ||
           spec.reset_kind == ResetDecl::Kind::Restitution)) {
        const auto& src_mode = m.modes[static_cast<std::size_t>(spec.from)];
        if (!src_mode.hamiltonian)
          throw src.error(g.reset.loc,
                          "an elastic/restitution reset needs a Hamiltonian in mode '" +
                              src_mode.name + "' (or write the reset explicitly)");
      }
      m.guards.push_back(std::move(spec));
    }
  }

  /// The simulation block: domain, grid, initial density, support and every setting.
  void simulation(const ModelAst& ast) {
    if (ast.simulation) {
      const auto& s = *ast.simulation;
      Simulation& sim = m.sim;
      sim.present = true;
      sim.loc = s.loc;
      const std::size_t n = m.state.size();
      sim.lo.assign(n, std::nan(""));
      sim.hi.assign(n, std::nan(""));
      Converter pconv(src, param_values, "a simulation setting");
      auto number = [&](const ExprPtr& e, const std::string& what) {
        ex v = pconv.convert(e);
        auto d = to_finite_double(v);
        if (!d) throw src.error(e->loc, what + " is not a finite real number");
        return *d;
      };
      for (const auto& d : s.domains) {
        auto it = std::find(m.state.begin(), m.state.end(), d.var.name);
        if (it == m.state.end())
          throw src.error(d.var.loc, "'" + d.var.name + "' is not a state variable" +
                                         suggestion(d.var.name, m.state));
        auto i = static_cast<std::size_t>(it - m.state.begin());
        if (!std::isnan(sim.lo[i]))
          throw src.error(d.var.loc, "the domain of '" + d.var.name + "' is given twice");
        sim.lo[i] = number(d.lo, "the lower end of the domain of " + d.var.name);
        sim.hi[i] = number(d.hi, "the upper end of the domain of " + d.var.name);
        if (!(sim.lo[i] < sim.hi[i]))
          throw src.error(d.lo->loc,
                          "the domain of '" + d.var.name + "' is empty (lower end >= upper end)");
      }
      for (std::size_t i = 0; i < n; ++i)
        if (std::isnan(sim.lo[i]))
          throw src.error(s.loc, "the simulation block has no domain for '" + m.state[i] +
                                     "' (write 'domain " + m.state[i] + " in [a, b]')");
      if (s.grid) {
        if (s.grid->counts.size() != n)
          throw src.error(s.grid->loc, "the grid has " + std::to_string(s.grid->counts.size()) +
                                           " axes, the state has " + std::to_string(n));
        for (long c : s.grid->counts)
          if (c < 2) throw src.error(s.grid->loc, "every grid axis needs at least 2 nodes");
        sim.grid = s.grid->counts;  // its size is checked with the settings (density)
      } else {
        sim.grid.assign(n, 65);
      }
      sim.initial.assign(m.modes.size(), ex(0));
      std::vector<bool> has_initial(m.modes.size(), false);
      Converter iconv(src, full_scope, "the initial density");
      for (const auto& ini : s.initial) {
        ex dens = iconv.convert(ini.density);
        if (ini.mode) {
          auto it = mode_index.find(ini.mode->name);
          if (it == mode_index.end())
            throw src.error(ini.mode->loc, "unknown mode '" + ini.mode->name + "'");
          auto k = static_cast<std::size_t>(it->second);
          if (has_initial[k])
            throw src.error(ini.loc, "mode '" + ini.mode->name + "' has two initial densities");
          sim.initial[k] = dens;
          has_initial[k] = true;
        } else {
          // Without a mode: modes with 'where' regions share it (each keeps its
          // region); otherwise it belongs to the first mode.
          bool any_region = false;
          for (std::size_t k = 0; k < m.modes.size(); ++k)
            if (!m.modes[k].where.empty()) any_region = true;
          for (std::size_t k = 0; k < m.modes.size(); ++k) {
            if (any_region ? !m.modes[k].where.empty() : k == 0) {
              if (has_initial[k])
                throw src.error(ini.loc,
                                "mode '" + m.modes[k].name + "' has two initial densities");
              sim.initial[k] = dens;
              has_initial[k] = true;
            }
          }
        }
      }
      if (s.initial.empty())
        throw src.error(s.loc,
                        "the simulation block has no initial density (write 'initial EXPR')");
      for (const ObserveDecl& d : s.observe) {
        for (const Observable& o : sim.observables)
          if (o.name == d.name.name)
            throw src.error(d.name.loc, "observable '" + o.name + "' is given twice (first at " +
                                            lexing::loc_str(o.loc) + ")");
        sim.observables.push_back(checked_observable(m, d, src));
      }
      Converter sconv(src, full_scope, "a 'support' condition");
      for (const auto& r : s.support)
        sim.support.push_back({sconv.convert(r.lhs) - sconv.convert(r.rhs), r.op, r.loc});
      std::set<std::string> seen;
      for (const auto& st : s.settings) {
        const std::string& k = st.key.name;
        if (!seen.insert(k).second)
          throw src.error(st.key.loc, "setting '" + k + "' is given twice");
        if (is_simulation_setting(k)) {
          SettingValue v;
          v.word = st.word;
          if (st.value && st.word.empty())
            v.number = number(st.value, "setting '" + k + "'"), v.has_number = true;
          if (const std::string why = set_simulation_setting(m, k, v); !why.empty())
            throw src.error(st.value_loc, "setting '" + k + "': " + why);
        } else {
          std::vector<std::string> keys = setting_names();
          throw src.error(st.key.loc,
                          "unknown simulation setting '" + k + "'" + suggestion(k, keys));
        }
      }
      if (!sim.settings.given("dt")) sim.settings.put<"dt">(sim.settings.real<"t_end">() / 10);
      if (const std::string why = grid_size_problem(sim.grid, marginals_only(sim)); !why.empty())
        throw src.error(s.grid ? s.grid->loc : s.loc, why);
    }
  }

  /// TeX names of the states and parameters (tex.hpp).
  void tex_names() {
    for (const auto& s : m.state) m.tex[s] = tex_identifier(s);
    for (const auto& p : m.params) m.tex[p.name] = tex_identifier(p.name);
  }

  /// Declare a state or parameter name (they share a namespace): refuse a function name, a
  /// reserved word or a second declaration.
  void declare(const std::string& name, SourceLoc loc, const char* what) {
    if (function_names().count(name))
      throw src.error(
          loc, std::string("a ") + what + " cannot be named '" + name + "': it is a function name");
    if (reserved_names().count(name))
      throw src.error(
          loc, std::string("a ") + what + " cannot be named '" + name + "': it is a reserved word");
    auto it = declared.find(name);
    if (it != declared.end())
      throw src.error(loc, "'" + name + "' is already declared at " +
                               std::to_string(it->second.line) + ":" +
                               std::to_string(it->second.col));
    declared[name] = loc;
  }

  const SourceText& src;                      ///< The model text.
  Model m;                                    ///< The model being checked.
  std::map<std::string, SourceLoc> declared;  ///< States and parameters.
  std::map<std::string, ex> state_scope;      ///< State names -> symbols.
  std::map<std::string, ex> param_scope;      ///< Parameter names -> symbols.
  std::map<std::string, ex> param_values;     ///< Parameter names -> defaults.
  std::map<std::string, ex> full_scope;       ///< States and parameters.
  std::vector<ex> state_syms;                 ///< The state symbols, in order.
  std::map<std::string, int> mode_index;      ///< Mode names -> indices.
};

}  // namespace

Model check(const ModelAst& ast, const SourceText& src) {
  Checker c(src);
  c.name(ast);
  c.names(ast);
  c.states(ast);
  c.parameters(ast);
  c.modes(ast);
  c.guards(ast);
  c.simulation(ast);
  c.tex_names();
  return std::move(c.m);
}

const std::vector<std::string>& setting_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v = {"grid"};
    for (const auto& spec : rt::kSettings) v.emplace_back(spec.name);
    v.emplace_back("domain.<state>");
    return v;
  }();
  return names;
}

bool marginals_only(const Simulation& sim) {
  return sim.settings.word<"density">() == "marginals";
}

std::string grid_size_problem(const std::vector<long>& counts, bool marginals) {
  double nodes = 1, pairs = 0;
  for (long c : counts) nodes *= static_cast<double>(c);
  for (std::size_t a = 0; a < counts.size(); ++a)
    for (std::size_t b = a + 1; b < counts.size(); ++b)
      pairs += static_cast<double>(counts[a]) * static_cast<double>(counts[b]);
  char b[240];
  if (marginals) {
    if (pairs <= static_cast<double>(kMaxGridNodes)) return "";
    std::snprintf(b, sizeof b,
                  "the grid's pairs of axes have %.3g nodes in all, more than the limit of %ld "
                  "(2^28)",
                  pairs, kMaxGridNodes);
    return b;
  }
  if (nodes <= static_cast<double>(kMaxGridNodes)) return "";
  std::snprintf(b, sizeof b,
                "the grid has %.3g nodes, more than the limit of %ld (2^28); particles can keep "
                "the marginals of every pair of axes instead (density marginals)",
                nodes, kMaxGridNodes);
  return b;
}

std::vector<long> parse_grid(const std::string& text) {
  std::vector<long> out;
  std::size_t i = 0;
  while (i <= text.size()) {
    std::size_t j = i;
    while (j < text.size() && std::isdigit(static_cast<unsigned char>(text[j]))) ++j;
    if (j == i || j - i > 9)
      throw UsageError("malformed grid '" + text + "' (expected e.g. 75x75)");
    out.push_back(std::stol(text.substr(i, j - i)));
    if (out.back() < 2)
      throw UsageError("every grid axis needs at least 2 nodes (got '" + text + "')");
    if (j == text.size()) break;
    if (text[j] != 'x' && text[j] != 'X')
      throw UsageError("malformed grid '" + text + "' (expected e.g. 75x75)");
    i = j + 1;
  }
  return out;
}

namespace {
GiNaC::numeric parse_override_exact(const std::string& key, const std::string& value) {
  if (value.empty()) throw UsageError("--set " + key + "= needs a value");
  // Accept decimal literals and fractions a/b, with an optional sign; exact.
  std::string v = value;
  bool neg = false;
  if (v[0] == '-' || v[0] == '+') neg = v[0] == '-', v = v.substr(1);
  try {
    GiNaC::numeric num;
    auto slash = v.find('/');
    if (slash != std::string::npos) {
      GiNaC::numeric den = exact_number(v.substr(slash + 1));
      if (den.is_zero()) throw UsageError("--set " + key + "=" + value + ": division by zero");
      num = exact_number(v.substr(0, slash)) / den;
    } else {
      num = exact_number(v);
    }
    if (!std::isfinite(num.to_double())) throw std::invalid_argument("not finite");
    return neg ? -num : num;
  } catch (const UsageError&) {
    throw;
  } catch (const std::exception&) {
    throw UsageError("--set " + key + "=" + value + ": '" + value + "' is not a finite number");
  }
}

double parse_override_number(const std::string& key, const std::string& value) {
  return parse_override_exact(key, value).to_double();
}

/// `--set domain.X=[a,b]`: exactly one '[', one ',' and one ']', in that order, two finite
/// numbers with a < b. Anything else is refused with the form it needs.
std::pair<double, double> parse_interval(const std::string& key, const std::string& value) {
  const std::string form = "--set " + key + "=" + value + ": expects an interval [a,b]";
  if (value.empty() || value.front() != '[')
    throw UsageError(form + " (it does not start with '[')");
  if (value.size() < 2 || value.back() != ']')
    throw UsageError(form + " (it does not end with ']')");
  const std::string inner = value.substr(1, value.size() - 2);
  const std::size_t comma = inner.find(',');
  if (comma == std::string::npos || inner.find(',', comma + 1) != std::string::npos ||
      inner.find_first_of("[]") != std::string::npos)
    throw UsageError(form + " (two numbers separated by one comma)");
  const auto trim = [](std::string t) {
    t.erase(0, t.find_first_not_of(' '));
    t.erase(t.find_last_not_of(' ') + 1);
    return t;
  };
  const double lo = parse_override_number(key, trim(inner.substr(0, comma)));
  const double hi = parse_override_number(key, trim(inner.substr(comma + 1)));
  if (!(lo < hi)) throw UsageError("--set " + key + "=" + value + ": empty interval (needs a < b)");
  return {lo, hi};
}
}  // namespace

bool is_simulation_setting(const std::string& key) {
  return rt::find_setting(key) != nullptr;
}

std::string set_simulation_setting(Model& model, const std::string& key, const SettingValue& v) {
  // The backward interpolating scheme created mass at resets with |J| != 1, and Ulam's cell
  // scheme did not converge: both were withdrawn, and their spellings get the reason
  // (runtime/include/hybgen/rt/methods/transfer.hpp).
  if (key == "scheme" && (v.word == "interpolate" || v.word == "conservative"))
    return "'" + v.word +
           "' was withdrawn: use 'hat' (the default: forward samples "
           "deposited on hat functions, conserving mass) or 'fv' (the finite-volume generator)";
  if (key == "scheme" && v.word == "cell") return rt::kWithdrawnCell;
  if (std::string why = model.sim.settings.set(key, v); !why.empty()) return why;
  // The pictures' axes are the model's states: two or more of them (the runner pairs them).
  // (The rule of runtime/include/hybgen/rt/setting_rules.hpp, checked here to locate it.)
  if (key == "figure_axes")
    if (std::string why = rt::figure_axes_rule(model.sim.settings, model.state); !why.empty())
      return why;
  // The derivation limits are the symbolic stage's (limits.hpp), read from the table.
  const rt::Settings& s = model.sim.settings;
  model.limits.max_expr_nodes = static_cast<std::size_t>(s.integer<"max_expr_nodes">());
  model.limits.max_expand_terms = s.real<"max_expand_terms">();
  model.limits.derive_seconds = s.real<"derive_seconds">();
  return "";
}

void apply_overrides(Model& model, const std::vector<std::string>& sets) {
  Simulation& sim = model.sim;
  for (const auto& kv : sets) {
    auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0)
      throw UsageError("--set expects KEY=VALUE, got '" + kv + "'");
    std::string key = kv.substr(0, eq), value = kv.substr(eq + 1);
    auto param = std::find_if(model.params.begin(), model.params.end(),
                              [&](const Parameter& p) { return p.name == key; });
    if (param != model.params.end()) {
      GiNaC::numeric v = parse_override_exact(key, value);
      param->value_d = v.to_double();
      param->value = v;
      continue;
    }
    if (key.rfind("observe.", 0) == 0) {
      // The argument itself, its '.' read as a space, is the source of one observe item, so
      // that an error's column is the argument's (parse.hpp, parse_observe). A name the model
      // observes already is replaced.
      std::string text = kv;
      text[std::string("observe").size()] = ' ';
      const SourceText arg("--set", text);
      Observable o = checked_observable(model, parse_observe(arg), arg);
      auto& list = sim.observables;
      const auto same = std::find_if(list.begin(), list.end(),
                                     [&](const Observable& x) { return x.name == o.name; });
      if (same != list.end())
        *same = std::move(o);
      else
        list.push_back(std::move(o));
      continue;
    }
    if (key == "grid") {
      auto g = parse_grid(value);
      if (g.size() != model.state.size())
        throw UsageError("--set grid=" + value + ": the grid needs " +
                         std::to_string(model.state.size()) + " axes");
      sim.grid = g;  // its size is checked after every --set (density)
    } else if (is_simulation_setting(key)) {
      SettingValue v;
      if (value.empty()) throw UsageError("--set " + key + "= needs a value");
      if (std::isalpha(static_cast<unsigned char>(value[0]))) {
        v.word = value;
      } else {
        v.number = parse_override_number(key, value);
        v.has_number = true;
      }
      if (const std::string why = set_simulation_setting(model, key, v); !why.empty())
        throw UsageError("--set " + key + "=" + value + ": " + why);
    } else if (key.rfind("domain.", 0) == 0) {
      std::string var = key.substr(7);
      auto it = std::find(model.state.begin(), model.state.end(), var);
      if (it == model.state.end())
        throw UsageError("--set " + key + ": '" + var + "' is not a state variable");
      const auto [lo, hi] = parse_interval(key, value);
      auto i = static_cast<std::size_t>(it - model.state.begin());
      sim.lo[i] = lo;
      sim.hi[i] = hi;
    } else {
      std::vector<std::string> keys;
      for (const auto& p : model.params) keys.push_back(p.name);
      for (const auto& s : setting_names()) keys.push_back(s);
      keys.emplace_back("grid");
      for (const auto& st : model.state) keys.push_back("domain." + st);
      keys.emplace_back("observe.NAME");
      std::string known;
      for (const auto& k : keys) known += (known.empty() ? "" : ", ") + k;
      throw UsageError("--set " + key + ": unknown key" + suggestion(key, keys) +
                       " (parameters and settings: " + known + ")");
    }
  }
  if (!sets.empty() && sim.present)
    if (const std::string why = grid_size_problem(sim.grid, marginals_only(sim)); !why.empty())
      throw UsageError("--set: " + why);
}

namespace detail {

GiNaC::ex convert_expression(const SourceText& src, const std::map<std::string, GiNaC::ex>& scope,
                             const std::string& what, const ExprPtr& e) {
  return Converter(src, scope, what).convert(e);
}

std::optional<double> finite_double(const GiNaC::ex& e) {
  return to_finite_double(e);
}

}  // namespace detail

}  // namespace hybgen::gen
