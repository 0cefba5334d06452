#pragma once
/// \file dag_print.hpp
/// What the printers of the expression DAG share (dag_print.cpp: GiNaC input syntax and
/// LaTeX; dag_lower.cpp: C): where signs go in sums and products, and the parts of a
/// product as printed. Internal to the generator library: not a public header.
///
/// Readable signs (printers only; nodes are unchanged). A product printed on its
/// own (not as a term of a sum, where its sign is the sum's + or -) whose
/// coefficient is negative gives its sign to one sum factor with an odd integer
/// exponent, printed negated and positive terms first, when that prints fewer
/// minus signs: -i*(f-1) prints as i*(1-f), -1/(f-1) as 1/(1-f); -(f-1)^2 and
/// -i*(a+b) stay. Of several such factors the one saving the most minus signs
/// wins, the first in canonical order on ties (`mul_view`). All three printers
/// share this decision, so their outputs keep the same shape.

#include <string>
#include <utility>
#include <vector>

#include "dag_store.hpp"

namespace hybgen::gen::detail {

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

/// Decompose a Product, or a Power with a negative rational exponent, or any node (a single
/// numerator factor). With `absorb`, a negative sign goes into the sum factor (to an odd
/// power) whose negation saves the most minus signs, the first in canonical order on ties:
/// -i*(f-1) prints as i*(1-f). Terms of sums are viewed without `absorb` (their sign is the
/// sum's + or -).
MulView mul_view(const DagStore& s, NodeId n, bool absorb);

/// The terms of sum `n` (negated if `flip`) in print order, each as (negative?, node): canonical
/// order, except that if the first term would be negative the positive terms come first (each
/// group in canonical order): -f+1 prints as 1-f.
std::vector<std::pair<bool, NodeId>> sum_terms(const DagStore& s, NodeId n, bool flip);

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

/// Precedence of printed text: a text is parenthesised where a higher one is needed.
enum Prec : int { kSum = 1, kMul = 2, kPow = 3, kAtom = 4 };

/// Printed text and its precedence.
struct Txt {
  std::string s;     ///< The text.
  int prec = kAtom;  ///< Its precedence.
};

/// `t`, parenthesised if its precedence is below `min_prec`.
inline std::string paren(const Txt& t, int min_prec) {
  return t.prec < min_prec ? "(" + t.s + ")" : t.s;
}

}  // namespace hybgen::gen::detail
