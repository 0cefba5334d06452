// The expression DAG (dag.hpp): its numbers and its node store (dag_store.hpp), nodes
// hash-consed in canonical form, and ExprDag's accessors. The printers are in dag_print.cpp
// (GiNaC input syntax, LaTeX), the C lowering with CSE in dag_lower.cpp.

#include "hybgen/gen/dag.hpp"

#include <ginac/ginac.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <unordered_map>
#include <utility>

#include "dag_store.hpp"
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
// Where the printers place signs: dag_print.hpp.

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

}  // namespace

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

bool num_is_negative(const Num& a) {
  return a.is_float ? a.f < 0.0 : a.q.is_negative();
}

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

// ---------------------------------------------------------------------------
// DagStore

DagStore::DagStore() {
  zero = rational(GiNaC::numeric(0));
  one = rational(GiNaC::numeric(1));
  minus_one = rational(GiNaC::numeric(-1));
}

NodeId DagStore::intern(Node node) {
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

NodeId DagStore::rational(const GiNaC::numeric& v) {
  Node n;
  n.kind = NodeKind::Rational;
  n.num = num_exact(v);
  n.rat = rat_text(v);
  n.payload = (n.rat.neg ? "-" : "") + n.rat.p + (n.rat.is_int() ? "" : "/" + n.rat.q);
  return intern(std::move(n));
}

NodeId DagStore::real(double v) {
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

NodeId DagStore::named(NodeKind kind, const std::string& name, std::vector<NodeId> ops) {
  Node n;
  n.kind = kind;
  n.payload = name;
  n.ops = std::move(ops);
  return intern(std::move(n));
}

NodeId DagStore::raw(NodeKind kind, std::vector<NodeId> ops) {
  Node n;
  n.kind = kind;
  n.ops = std::move(ops);
  return intern(std::move(n));
}

int DagStore::cmp(NodeId a, NodeId b) const {
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

std::pair<NodeId, NodeId> DagStore::key(NodeId n) const {
  const Node& x = at(n);
  if (x.kind == NodeKind::Power && is_rational(x.ops[1])) return {x.ops[0], x.ops[1]};
  return {n, one};
}

int DagStore::key_cmp(NodeId a, NodeId b) const {
  if (a == b) return 0;
  const auto [ba, ea] = key(a);
  const auto [bb, eb] = key(b);
  if (int c = cmp(ba, bb); c != 0) return c;
  if (int c = at(eb).num.q.compare(at(ea).num.q); c != 0) return c;
  return cmp(a, b);
}

void DagStore::sort_by_key(std::vector<NodeId>& v) const {
  std::sort(v.begin(), v.end(), [this](NodeId a, NodeId b) { return key_cmp(a, b) < 0; });
}

std::pair<Num, NodeId> DagStore::split_coeff(NodeId t) {
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

NodeId DagStore::with_coeff(const Num& c, NodeId rest) {
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

NodeId DagStore::make_add(const std::vector<NodeId>& terms) {
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
  for (const auto& [rest, c] : collected) ops.push_back(with_coeff(negate ? num_neg(c) : c, rest));
  if (!num_is_zero(constant)) ops.push_back(number(negate ? num_neg(constant) : constant));
  const NodeId sum = raw(NodeKind::Sum, std::move(ops));
  return negate ? with_coeff(num_exact(GiNaC::numeric(-1)), sum) : sum;
}

NodeId DagStore::make_mul(const std::vector<NodeId>& factors, int depth) {
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

NodeId DagStore::make_pow(NodeId b, NodeId e) {
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

NodeId DagStore::make_func(const std::string& name, NodeId arg) {
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

NodeId DagStore::import(const GiNaC::ex& e, ImportMemo& memo) {
  const GiNaC::basic* key_ptr = &GiNaC::ex_to<GiNaC::basic>(e);
  if (auto it = memo.find(key_ptr); it != memo.end()) return it->second.second;
  const NodeId id = import_uncached(e, memo);
  memo.emplace(key_ptr, std::make_pair(e, id));
  return id;
}

std::string DagStore::describe(const GiNaC::ex& e) {
  std::ostringstream os;
  os << e;
  std::string s = os.str();
  if (s.size() > 200) s = s.substr(0, 200) + "...";
  return s;
}

NodeId DagStore::import_uncached(const GiNaC::ex& e, ImportMemo& memo) {
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
      throw InternalError("ExprDag::import: unsupported function '" + name + "' in " + describe(e));
    if (e.nops() != 1)
      throw InternalError("ExprDag::import: function '" + name + "' with " +
                          std::to_string(e.nops()) + " arguments");
    return make_func(name, import(e.op(0), memo));
  }
  throw InternalError(std::string("ExprDag::import: unsupported expression of class ") +
                      ex_to<basic>(e).class_name() + ": " + describe(e));
}

bool DagStore::is_negated_sum(NodeId n) const {
  const Node& x = at(n);
  return x.kind == NodeKind::Product && x.ops.size() == 2 && is_rational(x.ops[0]) &&
         num_is_minus_one(at(x.ops[0]).num) && at(x.ops[1]).kind == NodeKind::Sum;
}

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

}  // namespace hybgen::gen
