#pragma once
/// \file dag.hpp
/// hybgen's own expression DAG: hash-consed, canonically ordered, printed
/// deterministically (GiNaC input syntax, LaTeX, C++) and emitted as C++ with
/// common-subexpression elimination.
///
/// GiNaC orders the operands of sums and products by hashes seeded from
/// addresses, so its printed output changes from run to run
/// (shared/GINAC_NOTES.md). An ExprDag re-sorts every sum and product by a
/// canonical total order on content, normalises signs, and hashes content only:
/// equal expressions get the same node and the same text whatever GiNaC's term
/// order was. NodeIds themselves depend on import order: print nodes, never
/// compare ids across dags or runs (use content_hash for that).
///
/// Canonical form of a node (see dag.cpp for the details):
/// - numbers are exact rationals or doubles (Float); Pi is a constant;
/// - a Sum has >= 2 terms, flattened, like terms collected, the constant term
///   last, and a leading term with a positive coefficient (otherwise the sum is
///   stored as Product(-1, negated sum));
/// - a Product is flattened, its numeric coefficient (if not 1) is the first
///   operand, equal bases are merged by adding rational exponents;
/// - odd functions (sin, tan, asin, atan, sinh, tanh) pull a negative
///   coefficient out of their argument, even ones (cos, cosh, abs) drop it.
///
/// Printing (all three printers alike, dag_print.hpp; nodes are not changed): a product with a
/// negative coefficient prints its sign inside one sum factor with an odd
/// integer exponent when that saves minus signs (`i*(1-f)`, `i/(1-f)`, not
/// `-i*(f-1)`); terms of sums keep their sign, and a sum whose first term would
/// be negative prints its positive terms first.
///
/// Not thread-safe (it uses GiNaC while importing).

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace GiNaC {
class ex;
}  // namespace GiNaC

namespace hybgen::gen {

/// Index of a node in an ExprDag; valid only for the dag that returned it.
using NodeId = std::uint32_t;

/// The kinds of DAG nodes, listed in canonical order (a node of an earlier kind
/// sorts before a node of a later kind).
enum class NodeKind : std::uint8_t {
  Rational,  ///< Exact rational number; payload "p" or "p/q" (sign included).
  Float,     ///< Inexact real number (a double); payload is its %a text.
  Constant,  ///< A named constant (only "Pi").
  Symbol,    ///< A symbol; payload is its name.
  Function,  ///< sin cos tan asin acos atan sinh cosh tanh exp log abs; one operand.
  Power,     ///< operands: base, exponent.
  Product,   ///< operands: [numeric coefficient if not 1,] factors (>= 1).
  Sum,       ///< operands: terms (>= 2), constant term (if not 0) last.
};

struct CAssignment;
namespace detail {
struct DagStore;
}  // namespace detail

/// A hash-consed expression DAG with content-based hashes: the same expression
/// always gets the same node, whatever GiNaC's internal term order was.
class ExprDag {
 public:
  /// An empty dag.
  ExprDag();
  /// Destructor.
  ~ExprDag();
  /// Deep copy (node ids stay valid in the copy).
  ExprDag(const ExprDag& other);
  /// Deep copy assignment.
  ExprDag& operator=(const ExprDag& other);
  /// Move construction.
  ExprDag(ExprDag&& other) noexcept;
  /// Move assignment.
  ExprDag& operator=(ExprDag&& other) noexcept;

  /// Import a real GiNaC expression. Supported: integers/rationals (exact), symbols (by name),
  /// add, mul, power (integer, rational and symbolic exponents), functions sin cos tan asin acos
  /// atan sinh cosh tanh exp log abs (sqrt is a power), constant Pi. Floats (non-rational
  /// numerics) are kept as doubles. Anything else (complex numbers, relations, unknown functions,
  /// other constants) -> InternalError naming it.
  NodeId import(const GiNaC::ex& e);

  /// Deterministic text in GiNaC input syntax (^ for powers, sqrt, exp, abs, Pi), parseable back
  /// by GiNaC::parser with the same symbol names; minimal parentheses; subtraction as a-b.
  [[nodiscard]] std::string to_ginac(NodeId n) const;

  /// Deterministic LaTeX (\frac, \sqrt, ^{...}, \sin, \exp, \left(\right)). `tex_names` maps
  /// symbol names to TeX (e.g. "theta" -> "\\theta"); an unmapped name is printed as is if it
  /// has one character, else in \mathrm{}; a name with an underscore ("x_dot") becomes a
  /// subscript (x_{\mathrm{dot}}), each part mapped by the same rules.
  [[nodiscard]] std::string to_latex(
      NodeId n, const std::map<std::string, std::string>& tex_names = {}) const;

  /// Single C++ expression without CSE (symbols mapped by `bind`; an unbound symbol ->
  /// InternalError). Small integer powers of non-leaf bases use std::pow here.
  [[nodiscard]] std::string to_c(NodeId n, const std::map<std::string, std::string>& bind) const;

  /// Number of nodes (including intermediate ones created while importing).
  [[nodiscard]] std::size_t size() const;
  /// Kind of a node.
  [[nodiscard]] NodeKind kind(NodeId n) const;
  /// Operands of a node, in canonical order (empty for numbers, constants and symbols).
  [[nodiscard]] const std::vector<NodeId>& operands(NodeId n) const;
  /// Name of a symbol, function or constant; exact text of a number ("-3/4", or %a for floats).
  [[nodiscard]] const std::string& payload(NodeId n) const;
  /// 64-bit content hash (FNV-1a over kind, payload and the operands' hashes): the same for
  /// equal expressions in every dag and every run.
  [[nodiscard]] std::uint64_t content_hash(NodeId n) const;
  /// The canonical total order on nodes: <0, 0 (same node) or >0.
  [[nodiscard]] int compare(NodeId a, NodeId b) const;

 private:
  friend std::string emit_c_block(const ExprDag& dag, const std::vector<CAssignment>& out,
                                  const std::map<std::string, std::string>& bind,
                                  const std::string& indent, const std::string& prefix);
  std::unique_ptr<detail::DagStore> store_;
};

/// One output of a kernel: a C lvalue and the node assigned to it.
struct CAssignment {
  std::string lhs;  ///< C lvalue, e.g. "dx[0]".
  NodeId value;     ///< Node whose value is assigned.
};

/// Emit a straight-line C++ block computing all assignments with common-subexpression
/// elimination across all of them: `const double t0 = ...;` temporaries (named prefix0,
/// prefix1, ... in post-order over the assignments in order) then `lhs = ...;`. `bind` maps each
/// symbol name to its C expression (e.g. "x" -> "x[0]", "m" -> "par[0]"); an unbound symbol ->
/// InternalError. Each line is prefixed by `indent` and ends with '\n'.
std::string emit_c_block(const ExprDag& dag, const std::vector<CAssignment>& out,
                         const std::map<std::string, std::string>& bind,
                         const std::string& indent = "  ", const std::string& prefix = "t");

}  // namespace hybgen::gen
