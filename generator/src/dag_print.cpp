// The text printers of the expression DAG (dag.hpp): GiNaC input syntax and LaTeX, over the
// sign placement they share with the C lowering (dag_print.hpp).

#include "dag_print.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "dag_store.hpp"
#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/errors.hpp"

namespace hybgen::gen {
namespace detail {

namespace {

/// Whether a term of a sum has a negative numeric coefficient (prints with a minus sign).
bool term_negative(const DagStore& s, NodeId t) {
  const Node& x = s.at(t);
  if (x.kind == NodeKind::Product && s.is_number(x.ops[0]))
    return num_is_negative(s.at(x.ops[0]).num);
  if (s.is_number(t)) return num_is_negative(x.num);
  return false;
}

/// How many fewer minus signs a product with a negative sign prints if the sign is absorbed
/// into factor `f` (printed negated): <= 0 if that does not help or f cannot take it.
/// Negating a sum of n terms, k of them negative, turns 1 + k minus signs into n - k; only a
/// sum to an odd integer power can take the sign.
int absorb_gain(const DagStore& s, const Factor& f) {
  const Node& b = s.at(f.base);
  if (b.kind != NodeKind::Sum || !f.exp.is_int() || (f.exp.p.back() - '0') % 2 == 0) return 0;
  int k = 0;
  for (NodeId t : b.ops) k += term_negative(s, t) ? 1 : 0;
  return 1 + 2 * k - static_cast<int>(b.ops.size());
}

}  // namespace

MulView mul_view(const DagStore& s, NodeId n, bool absorb) {
  MulView v;
  v.coeff_rat.p = "1";
  const RatText one = s.at(s.one).rat;
  int best_gain = 0;
  Factor* best = nullptr;
  std::vector<std::pair<bool, std::size_t>> order;  // (in den, index), canonical order
  auto add_factor = [&](NodeId f) {
    const Node& fx = s.at(f);
    if (fx.kind == NodeKind::Power && s.is_rational(fx.ops[1])) {
      const RatText& e = s.at(fx.ops[1]).rat;
      if (e.neg) {
        v.den.push_back({fx.ops[0], e.flipped()});
        order.emplace_back(true, v.den.size() - 1);
        return;
      }
      v.num.push_back({fx.ops[0], e});
    } else {
      v.num.push_back({f, one});
    }
    order.emplace_back(false, v.num.size() - 1);
  };
  const Node& x = s.at(n);
  if (x.kind == NodeKind::Product) {
    std::size_t i = 0;
    if (s.is_number(x.ops[0])) {
      const Node& c = s.at(x.ops[0]);
      if (c.kind == NodeKind::Float) {
        v.coeff_float = true;
        v.neg = c.num.f < 0.0;
        v.coeff_f = std::fabs(c.num.f);
      } else {
        v.neg = c.rat.neg;
        v.coeff_rat = c.rat;
        v.coeff_rat.neg = false;
      }
      i = 1;
    }
    for (; i < x.ops.size(); ++i) add_factor(x.ops[i]);
  } else {
    add_factor(n);
  }
  if (!absorb || !v.neg) return v;
  for (const auto& [in_den, idx] : order) {
    Factor& f = in_den ? v.den[idx] : v.num[idx];
    if (const int g = absorb_gain(s, f); g > best_gain) {
      best_gain = g;
      best = &f;
    }
  }
  if (best) {
    best->flip = true;
    v.neg = false;
  }
  return v;
}

std::vector<std::pair<bool, NodeId>> sum_terms(const DagStore& s, NodeId n, bool flip) {
  std::vector<std::pair<bool, NodeId>> terms;
  for (NodeId t : s.at(n).ops) terms.emplace_back(term_negative(s, t) != flip, t);
  if (!terms.empty() && terms.front().first)
    std::stable_partition(terms.begin(), terms.end(), [](const auto& t) { return !t.first; });
  return terms;
}

namespace {

/// What the text printers share: the walk over the dag, signs of sums and products, the parts
/// of a product. `Derived` formats: rat_abs, float_abs, leaf (symbols, constants), function,
/// symbolic_power, power_text (base^e from the base's text), product_text and sum_text.
template <class Derived>
class TextPrinter {
 public:
  explicit TextPrinter(const DagStore& s) : s_(s) {}

  Txt print(NodeId n) const {
    const Node& x = s_.at(n);
    switch (x.kind) {
      case NodeKind::Rational:
        return with_sign(x.rat.neg, Derived::rat_abs(x.rat));
      case NodeKind::Float:
        return with_sign(x.num.f < 0.0, Derived::float_abs(std::fabs(x.num.f)));
      case NodeKind::Constant:
      case NodeKind::Symbol:
        return self().leaf(x);
      case NodeKind::Function:
        return self().function(x);
      case NodeKind::Power:
        if (!s_.is_rational(x.ops[1])) return self().symbolic_power(x.ops[0], x.ops[1]);
        [[fallthrough]];
      case NodeKind::Product:
      case NodeKind::Sum:
        return print_algebraic(*this, s_, n);
    }
    throw InternalError("ExprDag: bad node kind");
  }

 protected:
  template <class Printer>
  friend auto detail::print_algebraic(Printer& p, const DagStore& s, NodeId n);

  [[nodiscard]] const Derived& self() const { return static_cast<const Derived&>(*this); }

  static Txt with_sign(bool neg, Txt t) {
    if (neg) return {"-" + t.s, kSum};
    return t;
  }

  /// base^e (e > 0), the base (a Sum) printed negated if `flip`.
  Txt power(NodeId base, const RatText& e, bool flip) const {
    return self().power_text(base, flip ? sum(base, true) : print(base), e);
  }

  Txt view(const MulView& v) const {
    std::vector<Txt> num, den;
    if (v.coeff_float) {
      num.push_back(Derived::float_abs(v.coeff_f));
    } else {
      if (v.coeff_rat.p != "1") num.push_back({v.coeff_rat.p, kAtom});
      if (v.coeff_rat.q != "1") den.push_back({v.coeff_rat.q, kAtom});
    }
    for (const Factor& f : v.num) num.push_back(power(f.base, f.exp, f.flip));
    for (const Factor& d : v.den) den.push_back(power(d.base, d.exp, d.flip));
    return Derived::product_text(num, den, v.neg);
  }

  /// |term| of a sum (its sign comes from sum_terms).
  Txt magnitude(NodeId t) const {
    const Node& x = s_.at(t);
    if (x.kind == NodeKind::Rational) return Derived::rat_abs(x.rat);
    if (x.kind == NodeKind::Float) return Derived::float_abs(std::fabs(x.num.f));
    if (x.kind == NodeKind::Product && s_.is_number(x.ops[0])) {
      MulView v = mul_view(s_, t, false);
      v.neg = false;
      return view(v);
    }
    return print(t);
  }

  Txt sum(NodeId n, bool flip) const {
    std::vector<std::pair<bool, Txt>> terms;
    for (const auto& [neg, t] : sum_terms(s_, n, flip)) terms.emplace_back(neg, magnitude(t));
    return Derived::sum_text(terms);
  }

  const DagStore& s_;
};

// ---------------------------------------------------------------------------
// GiNaC input syntax

std::string ginac_float(double v) {
  std::string s = shortest_text(v);
  if (!has_float_marker(s)) s += ".0";
  return s;
}

class GinacPrinter : public TextPrinter<GinacPrinter> {
 public:
  explicit GinacPrinter(const DagStore& s) : TextPrinter(s) {}

  static Txt rat_abs(const RatText& r) {
    if (r.is_int()) return {r.p, kAtom};
    return {r.p + "/" + r.q, kMul};
  }

  static Txt float_abs(double v) {
    std::string s = ginac_float(v);
    return {s, s.find('e') == std::string::npos ? kAtom : kMul};
  }

  [[nodiscard]] static Txt leaf(const Node& x) { return {x.payload, kAtom}; }

  [[nodiscard]] Txt function(const Node& x) const {
    return {x.payload + "(" + print(x.ops[0]).s + ")", kAtom};
  }

  [[nodiscard]] Txt symbolic_power(NodeId b, NodeId e) const {
    return {paren(print(b), kAtom) + "^" + paren(print(e), kAtom), kPow};
  }

  static Txt power_text(NodeId /*base*/, const Txt& b, const RatText& e) {
    if (e.is("1", "1")) return b;
    if (e.is("1", "2")) return {"sqrt(" + b.s + ")", kAtom};
    const std::string et = e.is_int() ? e.p : "(" + e.p + "/" + e.q + ")";
    return {paren(b, kAtom) + "^" + et, kPow};
  }

  static Txt product_text(const std::vector<Txt>& num, const std::vector<Txt>& den, bool neg) {
    Txt out = join(num);
    if (!den.empty()) out = {paren(out, kMul) + "/" + paren(join(den), kPow), kMul};
    if (neg) out = {"-" + paren(out, kMul), kSum};
    return out;
  }

  static Txt sum_text(const std::vector<std::pair<bool, Txt>>& terms) {
    std::string s;
    for (std::size_t i = 0; i < terms.size(); ++i) {
      if (terms[i].first)
        s += "-";
      else if (i)
        s += "+";
      s += paren(terms[i].second, kMul);
    }
    return {s, kSum};
  }

 private:
  static Txt join(const std::vector<Txt>& parts) {
    if (parts.empty()) return {"1", kAtom};
    if (parts.size() == 1) return parts[0];
    std::string s;
    for (std::size_t i = 0; i < parts.size(); ++i) {
      if (i) s += "*";
      s += paren(parts[i], kPow);
    }
    return {s, kMul};
  }
};

// ---------------------------------------------------------------------------
// LaTeX

std::string latex_float(double v) {
  const std::string s = shortest_text(v);
  const auto epos = s.find('e');
  if (epos == std::string::npos) return s;
  std::string mant = s.substr(0, epos);
  std::string ex = s.substr(epos + 1);
  bool eneg = false;
  if (!ex.empty() && (ex[0] == '+' || ex[0] == '-')) {
    eneg = ex[0] == '-';
    ex.erase(0, 1);
  }
  while (ex.size() > 1 && ex[0] == '0') ex.erase(0, 1);
  return mant + " \\cdot 10^{" + (eneg ? "-" : "") + ex + "}";
}

std::string tex_symbol(const std::string& name, const std::map<std::string, std::string>& tex) {
  if (auto it = tex.find(name); it != tex.end()) return it->second;
  const auto us = name.find('_');
  if (us != std::string::npos && us > 0 && us + 1 < name.size())
    return tex_symbol(name.substr(0, us), tex) + "_{" + tex_symbol(name.substr(us + 1), tex) + "}";
  if (name.size() == 1) return name;
  return "\\mathrm{" + name + "}";
}

std::string tex_function(const std::string& name) {
  if (name == "asin") return "\\arcsin";
  if (name == "acos") return "\\arccos";
  if (name == "atan") return "\\arctan";
  return "\\" + name;
}

std::string lparen(const std::string& s) {
  return "\\left(" + s + "\\right)";
}

/// A factor or term: parenthesised if it is a sum.
std::string lparen_sum(const Txt& t) {
  return t.prec <= kSum ? lparen(t.s) : t.s;
}

class LatexPrinter : public TextPrinter<LatexPrinter> {
 public:
  LatexPrinter(const DagStore& s, const std::map<std::string, std::string>& tex)
      : TextPrinter(s), tex_(tex) {}

  static Txt rat_abs(const RatText& r) {
    if (r.is_int()) return {r.p, kAtom};
    return {"\\frac{" + r.p + "}{" + r.q + "}", kMul};
  }

  static Txt float_abs(double v) {
    std::string s = latex_float(v);
    return {s, s.find('\\') == std::string::npos ? kAtom : kMul};
  }

  [[nodiscard]] Txt leaf(const Node& x) const {
    if (x.kind == NodeKind::Constant) return {"\\pi", kAtom};
    return {tex_symbol(x.payload, tex_), kAtom};
  }

  [[nodiscard]] Txt function(const Node& x) const {
    if (x.payload == "abs") return {"\\left|" + print(x.ops[0]).s + "\\right|", kAtom};
    // kPow: a function is parenthesised as the base of a power.
    return {tex_function(x.payload) + lparen(print(x.ops[0]).s), kPow};
  }

  [[nodiscard]] Txt symbolic_power(NodeId b, NodeId e) const {
    return {base(print(b)) + "^{" + print(e).s + "}", kPow};
  }

  [[nodiscard]] Txt power_text(NodeId b, const Txt& bt, const RatText& e) const {
    if (e.is("1", "1")) return bt;
    if (e.p == "1" && e.q == "2") return {"\\sqrt{" + bt.s + "}", kAtom};
    if (e.p == "1" && !e.is_int() && e.q.size() == 1)
      return {"\\sqrt[" + e.q + "]{" + bt.s + "}", kAtom};
    const std::string et = e.is_int() ? e.p : "\\frac{" + e.p + "}{" + e.q + "}";
    const Node& bx = s_.at(b);
    if (bx.kind == NodeKind::Function && bx.payload != "abs" && e.is_int())
      return {tex_function(bx.payload) + "^{" + et + "}" + lparen(print(bx.ops[0]).s), kPow};
    return {base(bt) + "^{" + et + "}", kPow};
  }

  static Txt product_text(const std::vector<Txt>& num, const std::vector<Txt>& den, bool neg) {
    Txt out;
    if (den.empty())
      out = num.size() == 1 ? num[0] : Txt{join(num), kMul};
    else
      out = {"\\frac{" + join(num) + "}{" + join(den) + "}", kMul};
    if (neg) out = {"-" + lparen_sum(out), kSum};
    return out;
  }

  static Txt sum_text(const std::vector<std::pair<bool, Txt>>& terms) {
    std::string s;
    for (std::size_t i = 0; i < terms.size(); ++i) {
      if (i)
        s += terms[i].first ? " - " : " + ";
      else if (terms[i].first)
        s += "-";
      s += lparen_sum(terms[i].second);
    }
    return {s, kSum};
  }

 private:
  static std::string base(const Txt& t) { return t.prec < kAtom ? lparen(t.s) : t.s; }

  static std::string join(const std::vector<Txt>& parts) {
    if (parts.empty()) return "1";
    if (parts.size() == 1) return parts[0].s;
    std::string s;
    for (std::size_t i = 0; i < parts.size(); ++i) {
      const std::string p = lparen_sum(parts[i]);
      if (i) {
        const bool digit = !p.empty() && (std::isdigit(static_cast<unsigned char>(p[0])) != 0);
        s += digit ? " \\cdot " : " ";
      }
      s += p;
    }
    return s;
  }

  const std::map<std::string, std::string>& tex_;
};

}  // namespace
}  // namespace detail

// ---------------------------------------------------------------------------
// ExprDag

std::string ExprDag::to_ginac(NodeId n) const {
  return detail::GinacPrinter(*store_).print(n).s;
}

std::string ExprDag::to_latex(NodeId n, const std::map<std::string, std::string>& tex_names) const {
  return detail::LatexPrinter(*store_, tex_names).print(n).s;
}

}  // namespace hybgen::gen
