#pragma once
/// \file dag_store.hpp
/// The node store behind ExprDag (dag.hpp): exact numbers, nodes in canonical form and
/// their hash-consing (dag.cpp). Shared by the printers (dag_print.hpp, dag_print.cpp) and
/// the C lowering (dag_lower.cpp). Internal to the generator library: not a public header.

#include <ginac/ginac.h>

#include <cstdint>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/errors.hpp"

namespace hybgen::gen::detail {

// ---- numbers ----------------------------------------------------------------

/// %.{prec}g of a double.
std::string fmt_g(double v, int prec);

/// Shortest %g text that reads back as exactly `v` (finite v).
std::string shortest_text(double v);

/// Whether a number's text already reads as a floating-point literal ('.', an exponent,
/// inf or nan).
bool has_float_marker(const std::string& s);

/// Whether a decimal digit string (no sign) is <= 2^53.
bool fits53(const std::string& digits);

/// An exact rational or a double.
struct Num {
  bool is_float = false;  ///< Whether `f` (not `q`) holds the value.
  GiNaC::numeric q{0};    ///< Exact value.
  double f = 0.0;         ///< Inexact value.
};

/// Whether a number is < 0.
bool num_is_negative(const Num& a);

/// Sign and decimal digits of an exact rational, for printing without GiNaC.
struct RatText {
  bool neg = false;     ///< Negative?
  std::string p = "0";  ///< |numerator|.
  std::string q = "1";  ///< Denominator (> 0).
  double value = 0.0;   ///< Nearest double of |p/q|.

  /// Whether the number is an integer.
  [[nodiscard]] bool is_int() const { return q == "1"; }
  /// Whether |number| is pp/qq (digit strings).
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

// ---- the store --------------------------------------------------------------

/// One node of the dag.
struct Node {
  NodeKind kind = NodeKind::Rational;  ///< Kind.
  std::string payload;                 ///< Name, or exact number text.
  std::vector<NodeId> ops;             ///< Operands.
  std::uint64_t hash = 0;              ///< Content hash.
  Num num;                             ///< Value of a number.
  RatText rat;                         ///< Text of a rational.
};

/// The node store behind ExprDag: every node is built in canonical form (dag.hpp) by the
/// builders and hash-consed by `intern`.
struct DagStore {
  std::vector<Node> nodes;                                       ///< Nodes by id.
  std::unordered_map<std::uint64_t, std::vector<NodeId>> table;  ///< Content hash -> ids.
  NodeId zero = 0;                                               ///< The node 0.
  NodeId one = 0;                                                ///< The node 1.
  NodeId minus_one = 0;                                          ///< The node -1.
  NodeId none = ~NodeId{0};                                      ///< "No node" marker.

  /// A store holding 0, 1 and -1.
  DagStore();

  /// The node `n` (InternalError for an id this store did not give).
  [[nodiscard]] const Node& at(NodeId n) const {
    if (n >= nodes.size()) throw InternalError("ExprDag: invalid node id " + std::to_string(n));
    return nodes[n];
  }
  /// Whether `n` is a number (rational or float).
  [[nodiscard]] bool is_number(NodeId n) const {
    const NodeKind k = at(n).kind;
    return k == NodeKind::Rational || k == NodeKind::Float;
  }
  /// Whether `n` is an exact rational.
  [[nodiscard]] bool is_rational(NodeId n) const { return at(n).kind == NodeKind::Rational; }

  // ---- construction -------------------------------------------------------

  /// The id of `node` (hashed by content), added if new.
  NodeId intern(Node node);
  /// An exact rational.
  NodeId rational(const GiNaC::numeric& v);
  /// A float (finite; -0 is 0).
  NodeId real(double v);
  /// A number.
  NodeId number(const Num& v) { return v.is_float ? real(v.f) : rational(v.q); }
  /// A symbol, constant or function node by name.
  NodeId named(NodeKind kind, const std::string& name, std::vector<NodeId> ops = {});
  /// A node of `kind` with operands already in canonical form.
  NodeId raw(NodeKind kind, std::vector<NodeId> ops);

  // ---- canonical order ----------------------------------------------------

  /// The canonical total order (dag.cpp, "Canonical order"): <0, 0 (same node) or >0.
  [[nodiscard]] int cmp(NodeId a, NodeId b) const;
  /// (base, rational exponent) key of a term or factor; exponent node is `one` for non-powers.
  [[nodiscard]] std::pair<NodeId, NodeId> key(NodeId n) const;
  /// Order of the operands of sums and products: by base, then decreasing exponent.
  [[nodiscard]] int key_cmp(NodeId a, NodeId b) const;
  /// Sort operands by key_cmp.
  void sort_by_key(std::vector<NodeId>& v) const;

  // ---- canonical builders -------------------------------------------------

  /// Split a term into numeric coefficient and coefficient-free rest (none for a number).
  std::pair<Num, NodeId> split_coeff(NodeId t);
  /// c * rest for a coefficient-free canonical `rest` (or none: the number c).
  NodeId with_coeff(const Num& c, NodeId rest);
  /// The canonical sum of `terms`: flattened, like terms collected, constant last,
  /// leading coefficient positive.
  NodeId make_add(const std::vector<NodeId>& terms);
  /// The canonical product of `factors`: flattened, equal bases merged, coefficient first.
  NodeId make_mul(const std::vector<NodeId>& factors, int depth = 0);
  /// b^e, folded for numbers and integer powers of powers and products.
  NodeId make_pow(NodeId b, NodeId e);
  /// name(arg), a negative coefficient pulled out of odd functions and dropped by even ones.
  NodeId make_func(const std::string& name, NodeId arg);

  // ---- import -------------------------------------------------------------

  /// Memo of one import: keyed by GiNaC object address, which is safe only because the
  /// value keeps the expression alive (op() of add/mul builds temporaries whose addresses
  /// would otherwise be reused). It only saves work; it never changes a result.
  using ImportMemo = std::unordered_map<const GiNaC::basic*, std::pair<GiNaC::ex, NodeId>>;

  /// The node of a GiNaC expression (ExprDag::import).
  NodeId import(const GiNaC::ex& e, ImportMemo& memo);
  /// GiNaC's text of `e`, cut at 200 characters (for messages).
  static std::string describe(const GiNaC::ex& e);
  /// import without the memo lookup.
  NodeId import_uncached(const GiNaC::ex& e, ImportMemo& memo);

  // ---- views for printing -------------------------------------------------

  /// Whether n is Product(-1, Sum): printed as the sum with flipped signs.
  [[nodiscard]] bool is_negated_sum(NodeId n) const;
};

}  // namespace hybgen::gen::detail
