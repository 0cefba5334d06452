// The expression DAG (dag.hpp): hash-consed nodes in a canonical order, and its printers.
//
// Size: the store, the exact numbers, the three printers (GiNaC input, LaTeX, C with CSE) share
// the file-local types Node, DagStore and Num; splitting the file would make those part of
// the library's interface. Sections: numbers, store, shared printing, GiNaC, LaTeX, C.

#include "hybgen/gen/dag.hpp"

#include <ginac/ginac.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <unordered_map>
#include <utility>

#include "hybgen/gen/errors.hpp"

// Design notes.
//
// Node identity. Nodes live in a vector and are hash-consed through a table
// keyed by a 64-bit FNV-1a content hash (kind, payload text, operand hashes);
// a hit is confirmed by comparing kind, payload and operand ids, which is a
// full structural comparison because operands are themselves hash-consed.
// Nothing depends on addresses or on GiNaC's hashes.
//
// Canonical order. `cmp` is a structural total order: first the kind (in
// NodeKind order), then exact numeric value (rationals), value then %a text
// (floats), name (symbols, constants, functions), then the operands
// lexicographically by `cmp`, then their number. Two distinct nodes never
// compare equal (induction on size: equal kind, payload and operands mean the
// same node). The operands of sums and products are sorted by `key_cmp`, which
// compares the pair (base, exponent) of a term or factor — base^e with a
// rational e has key (base, e), anything else x has key (x, 1) — bases by
// `cmp`, exponents by decreasing value. Within a sum or product keys are
// distinct (equal bases are merged), so this is a strict total order on them,
// and it prints x^2 before x and before x^(-1).
//
// Sums keep the constant term last; a sum whose first term has a negative
// coefficient is stored as Product(-1, negated sum). Printers print such a
// product as the sum with flipped signs, positive terms first ("b-a"), so that
// GiNaC's `a-b` vs `-(b-a)` and `(b-a)/(c-d)` vs `(a-b)/(d-c)` print the same.
//
// Readable signs (printers only; nodes are unchanged). A product printed on its
// own (not as a term of a sum, where its sign is the sum's + or -) whose
// coefficient is negative gives its sign to one sum factor with an odd integer
// exponent, printed negated and positive terms first, when that prints fewer
// minus signs: -i*(f-1) prints as i*(1-f), -1/(f-1) as 1/(1-f); -(f-1)^2 and
// -i*(a+b) stay. Of several such factors the one saving the most minus signs
// wins, the first in canonical order on ties (`mul_view`). All three printers
// share this decision, so their outputs keep the same shape.

namespace hybgen::gen {
namespace detail {

namespace {

constexpr std::uint64_t kFnvOffset = 1469598103934665603ULL;
constexpr std::uint64_t kFnvPrime = 1099511628211ULL;

void fnv_byte(std::uint64_t& h, unsigned char b) {
  h ^= b;
  h *= kFnvPrime;
}

void fnv_u64(std::uint64_t& h, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) fnv_byte(h, static_cast<unsigned char>((v >> (8 * i)) & 0xffU));
}

void fnv_str(std::uint64_t& h, const std::string& s) {
  fnv_u64(h, s.size());
  for (char c : s) fnv_byte(h, static_cast<unsigned char>(c));
}

/// Decimal text of an integer numeric (sign included). Integers of at most 18 digits, by
/// far the most common, take std::to_string: printing through cln's ostream costs a
/// stream and a locale per call, and the dag prints every rational it interns.
std::string int_text(const GiNaC::numeric& i) {
  static const GiNaC::numeric kSmall("1000000000000000000");  // 10^18 < 2^63
  if (i.is_integer() && GiNaC::abs(i) < kSmall) return std::to_string(i.to_long());
  std::ostringstream os;
  os << i;
  return os.str();
}

/// %.{prec}g of a double.
std::string fmt_g(double v, int prec) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", prec, v);
  return buf;
}

/// Shortest %g text that reads back as exactly `v` (finite v).
std::string shortest_text(double v) {
  for (int prec = 1; prec < 17; ++prec) {
    std::string s = fmt_g(v, prec);
    if (std::strtod(s.c_str(), nullptr) == v) return s;
  }
  return fmt_g(v, 17);
}

bool has_float_marker(const std::string& s) {
  return s.find_first_of(".eEn") != std::string::npos;  // n: inf, nan
}

/// Whether a decimal digit string (no sign) is <= 2^53.
bool fits53(const std::string& digits) {
  static const std::string kTwo53 = "9007199254740992";
  if (digits.size() != kTwo53.size()) return digits.size() < kTwo53.size();
  return digits <= kTwo53;
}

}  // namespace

/// An exact rational or a double.
struct Num {
  bool is_float = false;  ///< Whether `f` (not `q`) holds the value.
  GiNaC::numeric q{0};    ///< Exact value.
  double f = 0.0;         ///< Inexact value.
};

namespace {

Num num_exact(const GiNaC::numeric& v) {
  return Num{false, v, 0.0};
}
Num num_float(double v) {
  return Num{true, GiNaC::numeric(0), v};
}
double num_double(const Num& a) {
  return a.is_float ? a.f : a.q.to_double();
}
bool num_is_zero(const Num& a) {
  return a.is_float ? a.f == 0.0 : a.q.is_zero();
}
bool num_is_one(const Num& a) {
  return !a.is_float && a.q.is_equal(GiNaC::numeric(1));
}
bool num_is_minus_one(const Num& a) {
  return !a.is_float && a.q.is_equal(GiNaC::numeric(-1));
}
bool num_is_negative(const Num& a) {
  return a.is_float ? a.f < 0.0 : a.q.is_negative();
}
Num num_neg(const Num& a) {
  return a.is_float ? num_float(-a.f) : num_exact(a.q.mul(-1));
}

Num num_add(const Num& a, const Num& b) {
  if (a.is_float || b.is_float) return num_float(num_double(a) + num_double(b));
  return num_exact(a.q.add(b.q));
}

Num num_mul(const Num& a, const Num& b) {
  if (a.is_float || b.is_float) return num_float(num_double(a) * num_double(b));
  return num_exact(a.q.mul(b.q));
}

/// A deterministic order on numbers, used to combine inexact ones reproducibly.
bool num_less(const Num& a, const Num& b) {
  const double x = num_double(a), y = num_double(b);
  if (x < y) return true;
  if (y < x) return false;
  if (a.is_float != b.is_float) return !a.is_float;
  if (!a.is_float) return a.q.compare(b.q) < 0;
  return std::signbit(a.f) && !std::signbit(b.f);
}

Num num_sum(std::vector<Num> v) {
  std::sort(v.begin(), v.end(), num_less);
  Num acc = num_exact(GiNaC::numeric(0));
  for (const Num& x : v) acc = num_add(acc, x);
  return acc;
}

Num num_product(std::vector<Num> v) {
  std::sort(v.begin(), v.end(), num_less);
  Num acc = num_exact(GiNaC::numeric(1));
  for (const Num& x : v) acc = num_mul(acc, x);
  return acc;
}

}  // namespace

/// Sign and decimal digits of an exact rational, for printing without GiNaC.
struct RatText {
  bool neg = false;     ///< Negative?
  std::string p = "0";  ///< |numerator|.
  std::string q = "1";  ///< Denominator (> 0).
  double value = 0.0;   ///< Nearest double of |p/q|.

  [[nodiscard]] bool is_int() const { return q == "1"; }
  [[nodiscard]] bool is(const char* pp, const char* qq) const { return p == pp && q == qq; }
  /// The same number with the sign flipped.
  [[nodiscard]] RatText flipped() const {
    RatText r = *this;
    r.neg = !r.neg;
    return r;
  }
  /// Small positive integer (1..9) or 0 if not one.
  [[nodiscard]] int small_int() const {
    if (neg || !is_int() || p.size() != 1) return 0;
    return p[0] - '0';
  }
};

namespace {

/// Nearest double of p/q (p >= 0, q > 0, decimal digit strings; inf if too large): strtod
/// (correctly rounding) of the quotient truncated to >= 40 significant digits, which avoids
/// cln's overflow/underflow traps for extreme values.
double rational_value(const GiNaC::numeric& a, const std::string& p, const std::string& q) {
  if (q == "1") return std::strtod(p.c_str(), nullptr);
  if (fits53(p) && fits53(q))
    return std::strtod(p.c_str(), nullptr) / std::strtod(q.c_str(), nullptr);
  const long k = 41 - (static_cast<long>(p.size()) - static_cast<long>(q.size()));
  const GiNaC::numeric ten(10);
  GiNaC::numeric num = a.numer(), den = a.denom();
  if (k >= 0)
    num = num.mul(ten.power(GiNaC::numeric(k)));
  else
    den = den.mul(ten.power(GiNaC::numeric(-k)));
  const std::string digits = int_text(GiNaC::iquo(num, den)) + "e" + std::to_string(-k);
  return std::strtod(digits.c_str(), nullptr);
}

RatText rat_text(const GiNaC::numeric& v) {
  RatText t;
  t.neg = v.is_negative();
  const GiNaC::numeric a = GiNaC::abs(v);
  t.p = int_text(a.numer());
  t.q = int_text(a.denom());
  t.value = rational_value(a, t.p, t.q);
  return t;
}

const char* const kOddFunctions[] = {"sin", "tan", "asin", "atan", "sinh", "tanh"};
const char* const kEvenFunctions[] = {"cos", "cosh", "abs"};
const char* const kOtherFunctions[] = {"acos", "exp", "log"};

bool in_list(const std::string& name, const char* const* begin, const char* const* end) {
  return std::find_if(begin, end, [&](const char* s) { return name == s; }) != end;
}

template <std::size_t N>
bool in_list(const std::string& name, const char* const (&list)[N]) {
  return in_list(name, list, list + N);
}

}  // namespace

/// One node of the dag.
struct Node {
  NodeKind kind = NodeKind::Rational;  ///< Kind.
  std::string payload;                 ///< Name, or exact number text.
  std::vector<NodeId> ops;             ///< Operands.
  std::uint64_t hash = 0;              ///< Content hash.
  Num num;                             ///< Value of a number.
  RatText rat;                         ///< Text of a rational.
};

/// The node store behind ExprDag.
struct DagStore {
  std::vector<Node> nodes;
  std::unordered_map<std::uint64_t, std::vector<NodeId>> table;
  NodeId zero = 0;
  NodeId one = 0;
  NodeId minus_one = 0;
  NodeId none = ~NodeId{0};  ///< "No node" marker.

  DagStore() {
    zero = rational(GiNaC::numeric(0));
    one = rational(GiNaC::numeric(1));
    minus_one = rational(GiNaC::numeric(-1));
  }

  [[nodiscard]] const Node& at(NodeId n) const {
    if (n >= nodes.size()) throw InternalError("ExprDag: invalid node id " + std::to_string(n));
    return nodes[n];
  }
  [[nodiscard]] bool is_number(NodeId n) const {
    const NodeKind k = at(n).kind;
    return k == NodeKind::Rational || k == NodeKind::Float;
  }
  [[nodiscard]] bool is_rational(NodeId n) const { return at(n).kind == NodeKind::Rational; }

  // ---- construction -------------------------------------------------------

  NodeId intern(Node node) {
    std::uint64_t h = kFnvOffset;
    fnv_byte(h, static_cast<unsigned char>(node.kind));
    fnv_str(h, node.payload);
    fnv_u64(h, node.ops.size());
    for (NodeId op : node.ops) fnv_u64(h, nodes[op].hash);
    node.hash = h;
    auto& bucket = table[h];
    for (NodeId id : bucket) {
      const Node& o = nodes[id];
      if (o.kind == node.kind && o.payload == node.payload && o.ops == node.ops) return id;
    }
    if (nodes.size() >= static_cast<std::size_t>(none))
      throw InternalError("ExprDag: too many nodes");
    const auto id = static_cast<NodeId>(nodes.size());
    nodes.push_back(std::move(node));
    bucket.push_back(id);
    return id;
  }

  NodeId rational(const GiNaC::numeric& v) {
    Node n;
    n.kind = NodeKind::Rational;
    n.num = num_exact(v);
    n.rat = rat_text(v);
    n.payload = (n.rat.neg ? "-" : "") + n.rat.p + (n.rat.is_int() ? "" : "/" + n.rat.q);
    return intern(std::move(n));
  }

  NodeId real(double v) {
    if (!std::isfinite(v)) throw InternalError("ExprDag: non-finite float " + fmt_g(v, 17));
    if (v == 0.0) v = 0.0;  // one zero
    Node n;
    n.kind = NodeKind::Float;
    n.num = num_float(v);
    char buf[64];
    std::snprintf(buf, sizeof buf, "%a", v);
    n.payload = buf;
    return intern(std::move(n));
  }

  NodeId number(const Num& v) { return v.is_float ? real(v.f) : rational(v.q); }

  NodeId named(NodeKind kind, const std::string& name, std::vector<NodeId> ops = {}) {
    Node n;
    n.kind = kind;
    n.payload = name;
    n.ops = std::move(ops);
    return intern(std::move(n));
  }

  NodeId raw(NodeKind kind, std::vector<NodeId> ops) {
    Node n;
    n.kind = kind;
    n.ops = std::move(ops);
    return intern(std::move(n));
  }

  // ---- canonical order ----------------------------------------------------

  [[nodiscard]] int cmp(NodeId a, NodeId b) const {
    if (a == b) return 0;
    const Node& x = at(a);
    const Node& y = at(b);
    if (x.kind != y.kind) return x.kind < y.kind ? -1 : 1;
    switch (x.kind) {
      case NodeKind::Rational:
        return x.num.q.compare(y.num.q);
      case NodeKind::Float:
        if (x.num.f < y.num.f) return -1;
        if (y.num.f < x.num.f) return 1;
        break;
      case NodeKind::Constant:
      case NodeKind::Symbol:
      case NodeKind::Function:
        if (x.payload != y.payload) return x.payload < y.payload ? -1 : 1;
        break;
      case NodeKind::Power:
      case NodeKind::Product:
      case NodeKind::Sum:
        break;
    }
    const std::size_t n = std::min(x.ops.size(), y.ops.size());
    for (std::size_t i = 0; i < n; ++i)
      if (int c = cmp(x.ops[i], y.ops[i]); c != 0) return c;
    if (x.ops.size() != y.ops.size()) return x.ops.size() < y.ops.size() ? -1 : 1;
    if (x.payload != y.payload) return x.payload < y.payload ? -1 : 1;
    throw InternalError("ExprDag: two distinct nodes compare equal");
  }

  /// (base, rational exponent) key of a term or factor; exponent node is `one` for non-powers.
  [[nodiscard]] std::pair<NodeId, NodeId> key(NodeId n) const {
    const Node& x = at(n);
    if (x.kind == NodeKind::Power && is_rational(x.ops[1])) return {x.ops[0], x.ops[1]};
    return {n, one};
  }

  /// Order of the operands of sums and products: by base, then decreasing exponent.
  [[nodiscard]] int key_cmp(NodeId a, NodeId b) const {
    if (a == b) return 0;
    const auto [ba, ea] = key(a);
    const auto [bb, eb] = key(b);
    if (int c = cmp(ba, bb); c != 0) return c;
    if (int c = at(eb).num.q.compare(at(ea).num.q); c != 0) return c;
    return cmp(a, b);
  }

  void sort_by_key(std::vector<NodeId>& v) const {
    std::sort(v.begin(), v.end(), [this](NodeId a, NodeId b) { return key_cmp(a, b) < 0; });
  }

  // ---- canonical builders -------------------------------------------------

  /// Split a term into numeric coefficient and coefficient-free rest (none for a number).
  std::pair<Num, NodeId> split_coeff(NodeId t) {
    const Node& x = at(t);
    if (x.kind == NodeKind::Rational || x.kind == NodeKind::Float) return {x.num, none};
    if (x.kind == NodeKind::Product && is_number(x.ops[0])) {
      std::vector<NodeId> rest(x.ops.begin() + 1, x.ops.end());
      const Num coeff = at(x.ops[0]).num;
      if (rest.size() == 1) return {coeff, rest[0]};
      return {coeff, raw(NodeKind::Product, std::move(rest))};
    }
    return {num_exact(GiNaC::numeric(1)), t};
  }

  /// c * rest for a coefficient-free canonical `rest` (or none: the number c).
  NodeId with_coeff(const Num& c, NodeId rest) {
    if (rest == none || num_is_zero(c)) return number(c);
    if (num_is_one(c)) return rest;
    std::vector<NodeId> ops{number(c)};
    const Node& r = at(rest);
    if (r.kind == NodeKind::Product)
      ops.insert(ops.end(), r.ops.begin(), r.ops.end());
    else
      ops.push_back(rest);
    return raw(NodeKind::Product, std::move(ops));
  }

  NodeId make_add(const std::vector<NodeId>& terms) {
    std::vector<std::pair<NodeId, Num>> contribs;
    std::vector<Num> consts;
    // Flatten with a work list of (term, multiplier).
    std::vector<std::pair<NodeId, Num>> work;
    for (auto it = terms.rbegin(); it != terms.rend(); ++it)
      work.emplace_back(*it, num_exact(GiNaC::numeric(1)));
    while (!work.empty()) {
      auto [t, m] = work.back();
      work.pop_back();
      if (is_number(t)) {
        consts.push_back(num_mul(at(t).num, m));
        continue;
      }
      if (at(t).kind == NodeKind::Sum) {
        const std::vector<NodeId> ops = at(t).ops;
        for (auto it = ops.rbegin(); it != ops.rend(); ++it) work.emplace_back(*it, m);
        continue;
      }
      auto [c, rest] = split_coeff(t);
      if (at(rest).kind == NodeKind::Sum) {
        work.emplace_back(rest, num_mul(c, m));
        continue;
      }
      contribs.emplace_back(rest, num_mul(c, m));
    }
    // Collect like terms (grouping by id is fine: the result is a set).
    std::sort(contribs.begin(), contribs.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<std::pair<NodeId, Num>> collected;
    for (std::size_t i = 0; i < contribs.size();) {
      std::size_t j = i;
      std::vector<Num> cs;
      for (; j < contribs.size() && contribs[j].first == contribs[i].first; ++j)
        cs.push_back(contribs[j].second);
      Num c = num_sum(std::move(cs));
      if (!num_is_zero(c)) collected.emplace_back(contribs[i].first, c);
      i = j;
    }
    const Num constant = num_sum(std::move(consts));
    std::sort(collected.begin(), collected.end(),
              [this](const auto& a, const auto& b) { return key_cmp(a.first, b.first) < 0; });
    if (collected.empty()) return number(constant);
    if (collected.size() == 1 && num_is_zero(constant))
      return with_coeff(collected[0].second, collected[0].first);
    const bool negate = num_is_negative(collected[0].second);
    std::vector<NodeId> ops;
    for (const auto& [rest, c] : collected)
      ops.push_back(with_coeff(negate ? num_neg(c) : c, rest));
    if (!num_is_zero(constant)) ops.push_back(number(negate ? num_neg(constant) : constant));
    const NodeId sum = raw(NodeKind::Sum, std::move(ops));
    return negate ? with_coeff(num_exact(GiNaC::numeric(-1)), sum) : sum;
  }

  NodeId make_mul(const std::vector<NodeId>& factors, int depth = 0) {
    if (depth > 64) throw InternalError("ExprDag: product normalisation does not terminate");
    std::vector<Num> coeffs;
    std::vector<std::pair<NodeId, GiNaC::numeric>> parts;  // base, rational exponent
    std::vector<NodeId> work(factors.rbegin(), factors.rend());
    while (!work.empty()) {
      const NodeId f = work.back();
      work.pop_back();
      const Node& x = at(f);
      if (x.kind == NodeKind::Rational || x.kind == NodeKind::Float) {
        coeffs.push_back(x.num);
      } else if (x.kind == NodeKind::Product) {
        for (auto it = x.ops.rbegin(); it != x.ops.rend(); ++it) work.push_back(*it);
      } else if (x.kind == NodeKind::Power && is_rational(x.ops[1])) {
        parts.emplace_back(x.ops[0], at(x.ops[1]).num.q);
      } else {
        parts.emplace_back(f, GiNaC::numeric(1));
      }
    }
    std::stable_sort(parts.begin(), parts.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<NodeId> out;
    bool again = false;
    for (std::size_t i = 0; i < parts.size();) {
      std::size_t j = i;
      GiNaC::numeric e(0);
      for (; j < parts.size() && parts[j].first == parts[i].first; ++j) e = e.add(parts[j].second);
      const NodeId base = parts[i].first;
      i = j;
      if (e.is_zero()) continue;
      const NodeId r = make_pow(base, rational(e));
      const NodeKind k = at(r).kind;
      if (k == NodeKind::Rational || k == NodeKind::Float || k == NodeKind::Product) again = true;
      out.push_back(r);
    }
    if (again) {
      for (const Num& c : coeffs) out.push_back(number(c));
      return make_mul(out, depth + 1);
    }
    const Num c = num_product(std::move(coeffs));
    if (num_is_zero(c) || out.empty()) return number(c);
    sort_by_key(out);
    if (out.size() == 1 && num_is_one(c)) return out[0];
    if (num_is_one(c)) return raw(NodeKind::Product, std::move(out));
    out.insert(out.begin(), number(c));
    return raw(NodeKind::Product, std::move(out));
  }

  NodeId make_pow(NodeId b, NodeId e) {
    const Node& ex = at(e);
    if (ex.kind == NodeKind::Rational) {
      const GiNaC::numeric ev = ex.num.q;
      if (ev.is_zero()) return one;
      if (ev.is_equal(GiNaC::numeric(1))) return b;
      const Node& bx = at(b);
      if (bx.kind == NodeKind::Rational) {
        const GiNaC::numeric bv = bx.num.q;
        if (bv.is_zero()) {
          if (ev.is_negative())
            throw InternalError("ExprDag: division by zero (0^" + ex.payload + ")");
          return zero;
        }
        if (bv.is_equal(GiNaC::numeric(1))) return one;
        if (ev.is_integer()) return rational(bv.power(ev));
      } else if (bx.kind == NodeKind::Float) {
        if (ev.is_integer()) return real(std::pow(bx.num.f, ev.to_double()));
      } else if (ev.is_integer()) {
        if (bx.kind == NodeKind::Power && is_rational(bx.ops[1])) {
          const NodeId inner = bx.ops[0];
          const GiNaC::numeric pe = at(bx.ops[1]).num.q.mul(ev);
          return make_pow(inner, rational(pe));
        }
        if (bx.kind == NodeKind::Product) {
          const std::vector<NodeId> ops = bx.ops;
          std::vector<NodeId> fs;
          for (NodeId op : ops) fs.push_back(make_pow(op, e));
          return make_mul(fs);
        }
      }
    }
    return raw(NodeKind::Power, {b, e});
  }

  NodeId make_func(const std::string& name, NodeId arg) {
    const bool odd = in_list(name, kOddFunctions);
    const bool even = in_list(name, kEvenFunctions);
    if (odd || even) {
      auto [c, rest] = split_coeff(arg);
      if (num_is_negative(c)) {
        const NodeId f = named(NodeKind::Function, name, {with_coeff(num_neg(c), rest)});
        return odd ? make_mul({minus_one, f}) : f;
      }
    }
    return named(NodeKind::Function, name, {arg});
  }

  // ---- import -------------------------------------------------------------

  /// Memo of one import: keyed by GiNaC object address, which is safe only because the
  /// value keeps the expression alive (op() of add/mul builds temporaries whose addresses
  /// would otherwise be reused). It only saves work; it never changes a result.
  using ImportMemo = std::unordered_map<const GiNaC::basic*, std::pair<GiNaC::ex, NodeId>>;

  NodeId import(const GiNaC::ex& e, ImportMemo& memo) {
    const GiNaC::basic* key_ptr = &GiNaC::ex_to<GiNaC::basic>(e);
    if (auto it = memo.find(key_ptr); it != memo.end()) return it->second.second;
    const NodeId id = import_uncached(e, memo);
    memo.emplace(key_ptr, std::make_pair(e, id));
    return id;
  }

  static std::string describe(const GiNaC::ex& e) {
    std::ostringstream os;
    os << e;
    std::string s = os.str();
    if (s.size() > 200) s = s.substr(0, 200) + "...";
    return s;
  }

  NodeId import_uncached(const GiNaC::ex& e, ImportMemo& memo) {
    using namespace GiNaC;
    if (is_a<numeric>(e)) {
      const numeric& v = ex_to<numeric>(e);
      if (v.is_rational()) return rational(v);
      if (v.is_real()) return real(v.to_double());
      throw InternalError("ExprDag::import: complex number " + describe(e) + " is not supported");
    }
    if (is_a<symbol>(e)) return named(NodeKind::Symbol, ex_to<symbol>(e).get_name());
    if (is_a<constant>(e)) {
      if (e.is_equal(Pi)) return named(NodeKind::Constant, "Pi");
      throw InternalError("ExprDag::import: unsupported constant " + describe(e));
    }
    if (is_a<add>(e) || is_a<mul>(e)) {
      std::vector<NodeId> ops;
      ops.reserve(e.nops());
      for (std::size_t i = 0; i < e.nops(); ++i) ops.push_back(import(e.op(i), memo));
      return is_a<add>(e) ? make_add(ops) : make_mul(ops);
    }
    if (is_a<power>(e)) {
      const NodeId b = import(e.op(0), memo);
      const NodeId x = import(e.op(1), memo);
      return make_pow(b, x);
    }
    if (is_a<function>(e)) {
      const std::string name = ex_to<function>(e).get_name();
      if (!in_list(name, kOddFunctions) && !in_list(name, kEvenFunctions) &&
          !in_list(name, kOtherFunctions))
        throw InternalError("ExprDag::import: unsupported function '" + name + "' in " +
                            describe(e));
      if (e.nops() != 1)
        throw InternalError("ExprDag::import: function '" + name + "' with " +
                            std::to_string(e.nops()) + " arguments");
      return make_func(name, import(e.op(0), memo));
    }
    throw InternalError(std::string("ExprDag::import: unsupported expression of class ") +
                        ex_to<basic>(e).class_name() + ": " + describe(e));
  }

  // ---- views for printing -------------------------------------------------

  /// Whether n is Product(-1, Sum): printed as the sum with flipped signs.
  [[nodiscard]] bool is_negated_sum(NodeId n) const {
    const Node& x = at(n);
    return x.kind == NodeKind::Product && x.ops.size() == 2 && is_rational(x.ops[0]) &&
           num_is_minus_one(at(x.ops[0]).num) && at(x.ops[1]).kind == NodeKind::Sum;
  }
};

/// A factor base^exp of a product as printed (exp > 0 and rational; exp is 1 for a factor that
/// is not a power with a rational exponent).
struct Factor {
  NodeId base;        ///< Base (or the whole factor if exp is 1).
  RatText exp;        ///< Positive exponent.
  bool flip = false;  ///< Print the base, a Sum, negated: it took the product's sign.
};

/// A product split for printing: sign, |coefficient|, numerator and denominator factors.
struct MulView {
  bool neg = false;          ///< Negative overall sign.
  bool coeff_float = false;  ///< Coefficient is a float.
  RatText coeff_rat;         ///< |coefficient| if rational.
  double coeff_f = 0.0;      ///< |coefficient| if float.
  std::vector<Factor> num;   ///< Numerator factors.
  std::vector<Factor> den;   ///< Denominator factors (exponents negated).
};

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

/// Decompose a Product, or a Power with a negative rational exponent, or any node (a single
/// numerator factor). With `absorb`, a negative sign goes into the sum factor (to an odd
/// power) whose negation saves the most minus signs, the first in canonical order on ties:
/// -i*(f-1) prints as i*(1-f). Terms of sums are viewed without `absorb` (their sign is the
/// sum's + or -).
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

/// The terms of sum `n` (negated if `flip`) in print order, each as (negative?, node): canonical
/// order, except that if the first term would be negative the positive terms come first (each
/// group in canonical order): -f+1 prints as 1-f.
std::vector<std::pair<bool, NodeId>> sum_terms(const DagStore& s, NodeId n, bool flip) {
  std::vector<std::pair<bool, NodeId>> terms;
  for (NodeId t : s.at(n).ops) terms.emplace_back(term_negative(s, t) != flip, t);
  if (!terms.empty() && terms.front().first)
    std::stable_partition(terms.begin(), terms.end(), [](const auto& t) { return !t.first; });
  return terms;
}

/// The part of every printer's walk that places signs: a Sum, a Product, or a Power with a
/// rational exponent, printed by `p`'s sum(sum, flip), power(base, exp, flip) or view(MulView).
template <class Printer>
auto print_algebraic(Printer& p, const DagStore& s, NodeId n) {
  const Node& x = s.at(n);
  if (x.kind == NodeKind::Sum) return p.sum(n, false);
  if (s.is_negated_sum(n)) return p.sum(x.ops[1], true);
  if (x.kind == NodeKind::Power && !s.at(x.ops[1]).rat.neg)
    return p.power(x.ops[0], s.at(x.ops[1]).rat, false);
  return p.view(mul_view(s, n, true));
}

enum Prec : int { kSum = 1, kMul = 2, kPow = 3, kAtom = 4 };

struct Txt {
  std::string s;
  int prec = kAtom;
};

std::string paren(const Txt& t, int min_prec) {
  return t.prec < min_prec ? "(" + t.s + ")" : t.s;
}

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
  friend auto print_algebraic(Printer& p, const DagStore& s, NodeId n);

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

// ---------------------------------------------------------------------------
// C: a lowered, hash-consed operation graph on which CSE runs.

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
  friend auto print_algebraic(Printer& p, const DagStore& s, NodeId n);

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

ExprDag::ExprDag() : store_(std::make_unique<detail::DagStore>()) {}
ExprDag::~ExprDag() = default;
ExprDag::ExprDag(const ExprDag& other)
    : store_(std::make_unique<detail::DagStore>(*other.store_)) {}
ExprDag& ExprDag::operator=(const ExprDag& other) {
  if (this != &other) store_ = std::make_unique<detail::DagStore>(*other.store_);
  return *this;
}
ExprDag::ExprDag(ExprDag&& other) noexcept = default;
ExprDag& ExprDag::operator=(ExprDag&& other) noexcept = default;

NodeId ExprDag::import(const GiNaC::ex& e) {
  detail::DagStore::ImportMemo memo;
  return store_->import(e, memo);
}

std::string ExprDag::to_ginac(NodeId n) const {
  return detail::GinacPrinter(*store_).print(n).s;
}

std::string ExprDag::to_latex(NodeId n, const std::map<std::string, std::string>& tex_names) const {
  return detail::LatexPrinter(*store_, tex_names).print(n).s;
}

std::string ExprDag::to_c(NodeId n, const std::map<std::string, std::string>& bind) const {
  detail::CLowering low(*store_, bind, false);
  const detail::LId root = low.lower(n);
  return low.def(root, nullptr).s;
}

std::size_t ExprDag::size() const {
  return store_->nodes.size();
}
NodeKind ExprDag::kind(NodeId n) const {
  return store_->at(n).kind;
}
const std::vector<NodeId>& ExprDag::operands(NodeId n) const {
  return store_->at(n).ops;
}
const std::string& ExprDag::payload(NodeId n) const {
  return store_->at(n).payload;
}
std::uint64_t ExprDag::content_hash(NodeId n) const {
  return store_->at(n).hash;
}
int ExprDag::compare(NodeId a, NodeId b) const {
  return store_->cmp(a, b);
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
