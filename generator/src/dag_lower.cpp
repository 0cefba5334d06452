// The C lowering of the expression DAG (dag.hpp): a hash-consed graph of C operations built
// with the printers' sign placement (dag_print.hpp), printed as one expression (ExprDag::to_c)
// or as a straight-line block with common-subexpression elimination (emit_c_block).

#include <cctype>
#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "dag_print.hpp"
#include "dag_store.hpp"
#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/errors.hpp"

namespace hybgen::gen {
namespace detail {

namespace {

using LId = std::uint32_t;

enum class LKind : std::uint8_t { Leaf, Neg, Sum, Prod, Quot, Call };

struct LNode {
  LKind kind = LKind::Leaf;
  std::string text;         // Leaf: C text; Call: function name
  std::vector<LId> ops;     // operands
  std::vector<bool> minus;  // Sum: sign of each operand
};

/// C literal of a non-negative double.
std::string c_double(double v) {
  if (!std::isfinite(v))
    throw InternalError("ExprDag: number " + fmt_g(v, 17) + " is not a finite double");
  std::string s = fmt_g(v, 17);
  if (!has_float_marker(s)) s += ".0";
  return s;
}

/// C literal of a non-negative exact rational: n.0, (p.0/q.0), or %.17g of the nearest double.
std::string c_rational(const RatText& r) {
  if (r.is_int()) return fits53(r.p) ? r.p + ".0" : c_double(r.value);
  if (fits53(r.p) && fits53(r.q)) return "(" + r.p + ".0/" + r.q + ".0)";
  return c_double(r.value);
}

/// Whether a bound C text can be used as an operand without parentheses.
bool c_atomic(const std::string& s) {
  if (s.empty()) return false;
  if (!(std::isalpha(static_cast<unsigned char>(s[0])) != 0 || s[0] == '_')) return false;
  int depth = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    if (c == '[') {
      ++depth;
    } else if (c == ']') {
      if (--depth < 0) return false;
    } else if (depth == 0 && c == '-') {
      if (i + 1 >= s.size() || s[i + 1] != '>') return false;
      ++i;
    } else if (depth == 0 && !(std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_' ||
                               c == '.' || c == ':')) {
      return false;
    }
  }
  return depth == 0;
}

constexpr int kSmallPow = 8;

class CLowering {
 public:
  CLowering(const DagStore& s, const std::map<std::string, std::string>& bind, bool cse)
      : s_(s), bind_(bind), cse_(cse) {}

  LId lower(NodeId n) {
    if (auto it = memo_.find(n); it != memo_.end()) return it->second;
    const LId id = lower_uncached(n);
    memo_.emplace(n, id);
    return id;
  }

  [[nodiscard]] const std::vector<LNode>& nodes() const { return nodes_; }

  /// Whether a node is never worth a temporary.
  [[nodiscard]] bool trivial(LId id) const {
    const LNode& x = nodes_[id];
    return x.kind == LKind::Leaf || (x.kind == LKind::Neg && nodes_[x.ops[0]].kind == LKind::Leaf);
  }

  /// Text of a reference to `id` (the temporary's name if it has one).
  [[nodiscard]] Txt ref(LId id, const std::vector<std::string>* temps) const {
    if (temps && !(*temps)[id].empty()) return {(*temps)[id], kAtom};
    return def(id, temps);
  }

  /// Text of the definition of `id` (children by reference).
  [[nodiscard]] Txt def(LId id, const std::vector<std::string>* temps) const {
    const LNode& x = nodes_[id];
    switch (x.kind) {
      case LKind::Leaf:
        return {x.text, kAtom};
      case LKind::Call: {
        std::string s = x.text + "(";
        for (std::size_t i = 0; i < x.ops.size(); ++i) {
          if (i) s += ", ";
          s += ref(x.ops[i], temps).s;
        }
        return {s + ")", kAtom};
      }
      case LKind::Neg: {
        const Txt t = ref(x.ops[0], temps);
        const bool p = t.prec <= kSum || is_neg(x.ops[0], temps);
        return {"-" + (p ? "(" + t.s + ")" : t.s), kSum};
      }
      case LKind::Sum: {
        std::string s;
        for (std::size_t i = 0; i < x.ops.size(); ++i) {
          const Txt t = ref(x.ops[i], temps);
          if (i)
            s += x.minus[i] ? " - " : " + ";
          else if (x.minus[i])
            s += "-";
          const bool p = t.prec <= kSum || is_neg(x.ops[i], temps);
          s += p ? "(" + t.s + ")" : t.s;
        }
        return {s, kSum};
      }
      case LKind::Prod: {
        std::string s;
        for (std::size_t i = 0; i < x.ops.size(); ++i) {
          const Txt t = ref(x.ops[i], temps);
          const bool p = t.prec < kMul || (i > 0 && t.prec == kMul) || is_neg(x.ops[i], temps);
          if (i) s += "*";
          s += p ? "(" + t.s + ")" : t.s;
        }
        return {s, kMul};
      }
      case LKind::Quot: {
        const Txt a = ref(x.ops[0], temps);
        const Txt b = ref(x.ops[1], temps);
        const bool pa = a.prec < kMul || is_neg(x.ops[0], temps);
        const bool pb = b.prec <= kMul || is_neg(x.ops[1], temps);
        return {(pa ? "(" + a.s + ")" : a.s) + "/" + (pb ? "(" + b.s + ")" : b.s), kMul};
      }
    }
    throw InternalError("ExprDag: bad lowered node");
  }

 private:
  template <class Printer>
  friend auto detail::print_algebraic(Printer& p, const DagStore& s, NodeId n);

  [[nodiscard]] bool is_neg(LId id, const std::vector<std::string>* temps) const {
    if (temps && !(*temps)[id].empty()) return false;
    return nodes_[id].kind == LKind::Neg;
  }

  LId make(LNode n) {
    std::string key;
    key += static_cast<char>('0' + static_cast<int>(n.kind));
    key += n.text;
    key += '\x1f';
    for (std::size_t i = 0; i < n.ops.size(); ++i) {
      key += std::to_string(n.ops[i]);
      key += (i < n.minus.size() && n.minus[i]) ? '-' : ',';
    }
    if (auto it = table_.find(key); it != table_.end()) return it->second;
    const auto id = static_cast<LId>(nodes_.size());
    nodes_.push_back(std::move(n));
    table_.emplace(std::move(key), id);
    return id;
  }

  LId leaf(const std::string& text) { return make({LKind::Leaf, text, {}, {}}); }
  LId neg(LId a) { return make({LKind::Neg, {}, {a}, {}}); }
  LId call(const std::string& f, std::vector<LId> args) {
    return make({LKind::Call, f, std::move(args), {}});
  }
  LId prod(std::vector<LId> ops) {
    if (ops.size() == 1) return ops[0];
    return make({LKind::Prod, {}, std::move(ops), {}});
  }
  LId quot(LId a, LId b) { return make({LKind::Quot, {}, {a, b}, {}}); }
  LId one() { return leaf("1.0"); }

  LId lower_uncached(NodeId n) {
    const Node& x = s_.at(n);
    switch (x.kind) {
      case NodeKind::Rational: {
        RatText a = x.rat;
        a.neg = false;
        const LId l = leaf(c_rational(a));
        return x.rat.neg ? neg(l) : l;
      }
      case NodeKind::Float: {
        const LId l = leaf(c_double(std::fabs(x.num.f)));
        return x.num.f < 0.0 ? neg(l) : l;
      }
      case NodeKind::Constant:
        return leaf(c_double(3.14159265358979323846));
      case NodeKind::Symbol: {
        auto it = bind_.find(x.payload);
        if (it == bind_.end() || it->second.empty())
          throw InternalError("emit_c: symbol '" + x.payload + "' has no C binding");
        return leaf(c_atomic(it->second) ? it->second : "(" + it->second + ")");
      }
      case NodeKind::Function: {
        const std::string f = x.payload == "abs" ? "std::fabs" : "std::" + x.payload;
        return call(f, {lower(x.ops[0])});
      }
      case NodeKind::Power:
        if (!s_.is_rational(x.ops[1])) return call("std::pow", {lower(x.ops[0]), lower(x.ops[1])});
        [[fallthrough]];
      case NodeKind::Product:
      case NodeKind::Sum:
        return print_algebraic(*this, s_, n);
    }
    throw InternalError("ExprDag: bad node kind");
  }

  /// b^k for 1 <= k <= kSmallPow by squaring.
  LId intpow(LId b, int k) {
    if (k == 1) return b;
    if (k % 2 == 0) {
      const LId h = intpow(b, k / 2);
      return prod({h, h});
    }
    return prod({intpow(b, k - 1), b});
  }

  /// base^e for a positive rational e, the base (a Sum) negated if `flip`.
  LId power(NodeId base, const RatText& e, bool flip) {
    const LId b = flip ? sum(base, true) : lower(base);
    if (e.is("1", "1")) return b;
    const bool expand = cse_ || nodes_[b].kind == LKind::Leaf;
    RatText a = e;
    a.neg = false;
    if (e.is_int()) {
      const int k = e.small_int();
      if (k >= 2 && k <= kSmallPow && expand) return intpow(b, k);
      return call("std::pow", {b, leaf(c_rational(a))});
    }
    if (e.q == "2" && e.p.size() <= 2) {
      const int k = std::stoi(e.p);
      const LId r = call("std::sqrt", {b});
      if (k == 1) return r;
      if (k <= 2 * kSmallPow + 1 && expand) return prod({intpow(b, (k - 1) / 2), r});
    }
    return call("std::pow", {b, leaf(c_rational(a))});
  }

  LId view(const MulView& v) {
    std::vector<LId> num, den;
    if (v.coeff_float)
      num.push_back(leaf(c_double(v.coeff_f)));
    else if (!v.coeff_rat.is("1", "1"))
      num.push_back(leaf(c_rational(v.coeff_rat)));
    for (const Factor& f : v.num) num.push_back(power(f.base, f.exp, f.flip));
    for (const Factor& d : v.den) den.push_back(power(d.base, d.exp, d.flip));
    LId out = num.empty() ? one() : prod(num);
    if (!den.empty()) out = quot(out, prod(den));
    return v.neg ? neg(out) : out;
  }

  /// |term| of a sum (its sign comes from sum_terms).
  LId magnitude(NodeId t) {
    const Node& x = s_.at(t);
    if (x.kind == NodeKind::Product && s_.is_number(x.ops[0])) {
      MulView v = mul_view(s_, t, false);
      v.neg = false;
      return view(v);
    }
    const LId l = lower(t);
    return nodes_[l].kind == LKind::Neg ? nodes_[l].ops[0] : l;
  }

  LId sum(NodeId n, bool flip) {
    auto& memo = flip ? flipped_memo_ : memo_;
    if (auto it = memo.find(n); it != memo.end()) return it->second;
    LNode node{LKind::Sum, {}, {}, {}};
    for (const auto& [minus, t] : sum_terms(s_, n, flip)) {
      node.ops.push_back(magnitude(t));
      node.minus.push_back(minus);
    }
    const LId id = make(std::move(node));
    memo.emplace(n, id);
    return id;
  }

  const DagStore& s_;
  const std::map<std::string, std::string>& bind_;
  bool cse_;
  std::vector<LNode> nodes_;
  std::map<std::string, LId> table_;
  std::unordered_map<NodeId, LId> memo_;          ///< Lowered nodes.
  std::unordered_map<NodeId, LId> flipped_memo_;  ///< Lowered negated sums.
};

}  // namespace
}  // namespace detail

// ---------------------------------------------------------------------------
// ExprDag

std::string ExprDag::to_c(NodeId n, const std::map<std::string, std::string>& bind) const {
  detail::CLowering low(*store_, bind, false);
  const detail::LId root = low.lower(n);
  return low.def(root, nullptr).s;
}

std::string emit_c_block(const ExprDag& dag, const std::vector<CAssignment>& out,
                         const std::map<std::string, std::string>& bind, const std::string& indent,
                         const std::string& prefix) {
  using detail::LId;
  detail::CLowering low(*dag.store_, bind, true);
  std::vector<LId> roots;
  roots.reserve(out.size());
  for (const CAssignment& a : out) roots.push_back(low.lower(a.value));
  const auto& nodes = low.nodes();

  // Count uses: one per assignment plus one per (distinct parent, operand slot).
  std::vector<int> uses(nodes.size(), 0);
  std::vector<char> seen(nodes.size(), 0);
  std::vector<LId> stack;
  for (LId r : roots) {
    ++uses[r];
    stack.push_back(r);
  }
  while (!stack.empty()) {
    const LId id = stack.back();
    stack.pop_back();
    if (seen[id]) continue;
    seen[id] = 1;
    for (LId op : nodes[id].ops) {
      ++uses[op];
      stack.push_back(op);
    }
  }

  // Number temporaries in post-order over the assignments in order.
  std::vector<std::string> temps(nodes.size());
  std::vector<char> done(nodes.size(), 0);
  std::string body;
  std::size_t count = 0;
  // Iterative post-order: (node, next operand index).
  std::vector<std::pair<LId, std::size_t>> dfs;
  for (LId r : roots) {
    if (done[r]) continue;
    dfs.emplace_back(r, 0);
    while (!dfs.empty()) {
      auto& [id, next] = dfs.back();
      if (next < nodes[id].ops.size()) {
        const LId child = nodes[id].ops[next++];
        if (!done[child]) dfs.emplace_back(child, 0);
        continue;
      }
      const LId fin = id;
      dfs.pop_back();
      if (done[fin]) continue;
      done[fin] = 1;
      if (uses[fin] >= 2 && !low.trivial(fin)) {
        const std::string name = prefix + std::to_string(count++);
        body += indent + "const double " + name + " = " + low.def(fin, &temps).s + ";\n";
        temps[fin] = name;
      }
    }
  }
  for (std::size_t i = 0; i < out.size(); ++i)
    body += indent + out[i].lhs + " = " + low.ref(roots[i], &temps).s + ";\n";
  return body;
}

}  // namespace hybgen::gen
