#pragma once
/// \file random_model.hpp
/// Size: the model generator and its three evaluators (double, dual numbers, error bounds)
/// share one expression tree; splitting them would split that tree's definition.
/// Random well-formed general (non-Lie) hybrid models for the differential test of `derive`
/// (tests/gen/test_derive_random.cpp), and everything the test needs to evaluate them
/// WITHOUT hybgen: the model is kept as small expression trees (TreeNode) that this header
/// prints as `.model` text and evaluates in double precision, in forward-mode dual numbers
/// (exact first derivatives up to rounding) and in a running error bound (ErrorBound) that
/// bounds the rounding error of the double evaluation. No GiNaC, nothing from hybgen.
///
/// A model (random_model(seed), deterministic per seed: std::mt19937_64 and no
/// implementation-defined distribution) has 1–4 states x0…, 0–3 parameters p0…, 1–3 modes
/// with explicit flows (random trees of depth ≤ 3 over the states, parameters and decimal
/// constants: +, −, ×, integer powers 2 and 3 of small sums, sin and cos anywhere, exp only
/// of c·x_j with |c| ≤ 0.5 — no division, so nothing has a pole), 1–3 guards and, in most
/// models, a simulation block (domain, `initial 1`).
///
/// A guard's surface s = a·x_k + (affine in the other states) + (mildly nonlinear terms in
/// the other states: 0.3·x_j², 0.2·sin x_j, 0.25·x_j·x_l, …) [+ c₃·x_k³ with c₃a > 0] − c,
/// with c fitted so that s = 0 passes through a random point of the domain; ∂s/∂x_k never
/// vanishes, so s = 0 can be solved for the pivot x_k by a scalar root finder. Resets:
///  - `identity` (between two different modes: Filippov-type switching);
///  - all components unchanged, written out;
///  - affine y = A x + b with A well conditioned (some rows unchanged, some coefficients
///    parameters): closed-form inverse;
///  - affine in the changed variables plus nonlinear terms h(x_j) in unchanged x_j (a shear):
///    still a closed-form inverse by derive's rule (derive.hpp);
///  - nonlinear in the changed variables, triangular with strictly monotone diagonal maps
///    (d·x_i + c·x_i³, cd > 0, and h(x_j) of earlier variables), so a diffeomorphism, and
///    sometimes a non-monotone d·x_i + c·x_i² (a fold away from most points): numeric inverse;
///  - a constant component y_k = c at the surface's pivot k, the others not depending on x_k:
///    det DΔ ≡ 0 but DΔ is injective on T S (its kernel e_k is transversal, ∂s/∂x_k ≠ 0), so
///    derive must accept it with no inverse ("on the guard only").
/// About one model in 20 (with ≥ 2 states) instead carries a reset that COLLAPSES its guard:
/// a constant component y_j = c in a state the surface does not depend on, no other component
/// depending on x_j, so e_j ∈ ker DΔ ∩ T S; derive must refuse it (expect_refusal).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace hybgen::testing {

// ------------------------------------------------------------------ expression trees

/// The operation of a tree node.
enum class TreeOp { Constant, State, Parameter, Add, Sub, Mul, Neg, Pow, Sin, Cos, Exp };

struct TreeNode;
/// A shared, immutable expression tree.
using Tree = std::shared_ptr<const TreeNode>;

/// One node of an expression tree.
struct TreeNode {
  TreeOp op = TreeOp::Constant;  ///< What the node computes.
  double value = 0;              ///< Constant: the double nearest to `text`.
  std::string text;              ///< Constant: its exact decimal text (as hybgen reads it).
  int index = 0;                 ///< State / Parameter: its index; Pow: the exponent (2 or 3).
  Tree a;                        ///< First operand (unary and binary nodes).
  Tree b;                        ///< Second operand (binary nodes).
};

/// The decimal units·10^(−decimals) as a tree; its double is correctly rounded (units and
/// 10^decimals are exact doubles and IEEE division rounds once).
inline Tree constant(long long units, int decimals) {
  auto n = std::make_shared<TreeNode>();
  n->op = TreeOp::Constant;
  double scale = 1;
  for (int i = 0; i < decimals; ++i) scale *= 10;
  n->value = static_cast<double>(units) / scale;
  const unsigned long long mag = units < 0 ? 0ULL - static_cast<unsigned long long>(units)
                                           : static_cast<unsigned long long>(units);
  std::string digits = std::to_string(mag);
  if (decimals > 0) {
    if (digits.size() <= static_cast<std::size_t>(decimals))
      digits.insert(0, static_cast<std::size_t>(decimals) + 1 - digits.size(), '0');
    digits.insert(digits.size() - static_cast<std::size_t>(decimals), ".");
  }
  n->text = (units < 0 ? "-" : "") + digits;
  return n;
}

/// The state variable x_i.
inline Tree state(int i) {
  auto n = std::make_shared<TreeNode>();
  n->op = TreeOp::State;
  n->index = i;
  return n;
}

/// The parameter p_i.
inline Tree parameter(int i) {
  auto n = std::make_shared<TreeNode>();
  n->op = TreeOp::Parameter;
  n->index = i;
  return n;
}

/// A node `op` with operands a (and b).
inline Tree node(TreeOp op, Tree a, Tree b = nullptr, int index = 0) {
  auto n = std::make_shared<TreeNode>();
  n->op = op;
  n->a = std::move(a);
  n->b = std::move(b);
  n->index = index;
  return n;
}

/// a + b.
inline Tree add(Tree a, Tree b) {
  return node(TreeOp::Add, std::move(a), std::move(b));
}
/// a − b.
inline Tree sub(Tree a, Tree b) {
  return node(TreeOp::Sub, std::move(a), std::move(b));
}
/// a · b.
inline Tree mul(Tree a, Tree b) {
  return node(TreeOp::Mul, std::move(a), std::move(b));
}
/// −a.
inline Tree neg(Tree a) {
  return node(TreeOp::Neg, std::move(a));
}
/// a^k, k = 2 or 3.
inline Tree power(Tree a, int k) {
  return node(TreeOp::Pow, std::move(a), nullptr, k);
}
/// sin a.
inline Tree sin_of(Tree a) {
  return node(TreeOp::Sin, std::move(a));
}
/// cos a.
inline Tree cos_of(Tree a) {
  return node(TreeOp::Cos, std::move(a));
}
/// exp a.
inline Tree exp_of(Tree a) {
  return node(TreeOp::Exp, std::move(a));
}

/// The tree as `.model` expression text; every compound subexpression is parenthesised and
/// negative constants are written (-c), so the text means exactly the tree.
inline std::string to_text(const Tree& t, const std::vector<std::string>& states,
                           const std::vector<std::string>& params) {
  auto bin = [&](const char* op) {
    return "(" + to_text(t->a, states, params) + " " + op + " " + to_text(t->b, states, params) +
           ")";
  };
  switch (t->op) {
    case TreeOp::Constant:
      return t->value < 0 ? "(" + t->text + ")" : t->text;
    case TreeOp::State:
      return states.at(static_cast<std::size_t>(t->index));
    case TreeOp::Parameter:
      return params.at(static_cast<std::size_t>(t->index));
    case TreeOp::Add:
      return bin("+");
    case TreeOp::Sub:
      return bin("-");
    case TreeOp::Mul:
      return bin("*");
    case TreeOp::Neg:
      return "(-" + to_text(t->a, states, params) + ")";
    case TreeOp::Pow:
      return "(" + to_text(t->a, states, params) + ")^" + std::to_string(t->index);
    case TreeOp::Sin:
      return "sin(" + to_text(t->a, states, params) + ")";
    case TreeOp::Cos:
      return "cos(" + to_text(t->a, states, params) + ")";
    case TreeOp::Exp:
      return "exp(" + to_text(t->a, states, params) + ")";
  }
  return "?";
}

// ------------------------------------------------------------------ scalar types

/// The unit roundoff of IEEE double, 2⁻⁵³.
inline constexpr double kUnitRoundoff = 0x1p-53;

/// A first-order running error bound of a double evaluation (Wilkinson-style): `m` bounds
/// the magnitude of every intermediate value the evaluation combined (so also |value|) and
/// `e` the absolute error of the computed double against the exact value of the same
/// expression at the same (exact) inputs. Rules, with u = 2⁻⁵³ and fl(a ∘ b) = (a ∘ b)(1 + δ),
/// |δ| ≤ u: a ± b: e = e_a + e_b + u(m_a + m_b); a·b: e = e_a m_b + m_a e_b + e_a e_b +
/// u m_a m_b; sin, cos: e = e_a + 2u (|derivative| ≤ 1, libm within an ulp); exp:
/// e = e^{m_a}(e_a(1 + e_a) + 2u). Used to set tolerances that only rounding can meet.
struct ErrorBound {
  double m = 0;  ///< Bound on the magnitudes involved.
  double e = 0;  ///< Bound on the absolute rounding error.
};
/// a + b with its error bound.
inline ErrorBound operator+(ErrorBound a, ErrorBound b) {
  const double m = a.m + b.m;
  return {m, a.e + b.e + kUnitRoundoff * m};
}
/// a − b with its error bound (as a + b).
inline ErrorBound operator-(ErrorBound a, ErrorBound b) {
  return a + b;
}
/// −a (exact).
inline ErrorBound operator-(ErrorBound a) {
  return a;
}
/// a · b with its error bound.
inline ErrorBound operator*(ErrorBound a, ErrorBound b) {
  const double m = a.m * b.m;
  return {m, a.e * b.m + a.m * b.e + a.e * b.e + kUnitRoundoff * m};
}
/// sin a: |sin| ≤ min(1, |a|).
inline ErrorBound sin(ErrorBound a) {
  const double m = std::min(1.0, a.m);
  return {m, a.e + 2 * kUnitRoundoff * m};
}
/// cos a: |cos| ≤ 1.
inline ErrorBound cos(ErrorBound a) {
  return {1.0, a.e + 2 * kUnitRoundoff};
}
/// exp a: |exp a| ≤ e^{m_a}.
inline ErrorBound exp(ErrorBound a) {
  const double m = std::exp(a.m);
  return {m, m * (a.e * (1 + a.e) + 2 * kUnitRoundoff)};
}

/// A forward-mode dual number v + d·ε (ε² = 0): evaluating a tree on duals gives the exact
/// directional derivative up to rounding (no truncation error, unlike finite differences).
/// Dual<ErrorBound> runs the same operations on error bounds, so it bounds the rounding
/// error of the derivative that Dual<double> computed.
template <class T>
struct Dual {
  T v{};  ///< Value.
  T d{};  ///< Derivative along the seeded direction.
};
/// (a + b)' = a' + b'.
template <class T>
Dual<T> operator+(const Dual<T>& a, const Dual<T>& b) {
  return {a.v + b.v, a.d + b.d};
}
/// (a − b)' = a' − b'.
template <class T>
Dual<T> operator-(const Dual<T>& a, const Dual<T>& b) {
  return {a.v - b.v, a.d - b.d};
}
/// (−a)' = −a'.
template <class T>
Dual<T> operator-(const Dual<T>& a) {
  return {-a.v, -a.d};
}
/// (ab)' = a'b + ab'.
template <class T>
Dual<T> operator*(const Dual<T>& a, const Dual<T>& b) {
  return {a.v * b.v, a.d * b.v + a.v * b.d};
}
/// (sin a)' = cos(a) a'.
template <class T>
Dual<T> sin(const Dual<T>& a) {
  using std::cos;
  using std::sin;
  return {sin(a.v), cos(a.v) * a.d};
}
/// (cos a)' = −sin(a) a'.
template <class T>
Dual<T> cos(const Dual<T>& a) {
  using std::cos;
  using std::sin;
  return {cos(a.v), -(sin(a.v) * a.d)};
}
/// (exp a)' = exp(a) a'.
template <class T>
Dual<T> exp(const Dual<T>& a) {
  using std::exp;
  const T e = exp(a.v);
  return {e, e * a.d};
}

/// How a decimal constant of the model enters an evaluation in T.
template <class T>
struct Scalar;
/// double: the nearest double.
template <>
struct Scalar<double> {
  /// The constant c.
  static double constant(double c) { return c; }
};
/// ErrorBound: the double differs from the exact decimal (which hybgen uses) by ≤ u|c|.
template <>
struct Scalar<ErrorBound> {
  /// The constant c with its decimal rounding error.
  static ErrorBound constant(double c) { return {std::fabs(c), kUnitRoundoff * std::fabs(c)}; }
};
/// Dual: a constant has derivative 0.
template <class T>
struct Scalar<Dual<T>> {
  /// The constant c, derivative exactly 0.
  static Dual<T> constant(double c) { return {Scalar<T>::constant(c), Scalar<T>::constant(0)}; }
};

/// Evaluate a tree at states x and parameters p in the scalar type T (double, ErrorBound,
/// Dual<double>, Dual<ErrorBound>); integer powers are repeated products.
template <class T>
T evaluate(const Tree& t, const std::vector<T>& x, const std::vector<T>& p) {
  using std::cos;
  using std::exp;
  using std::sin;
  switch (t->op) {
    case TreeOp::Constant:
      return Scalar<T>::constant(t->value);
    case TreeOp::State:
      return x.at(static_cast<std::size_t>(t->index));
    case TreeOp::Parameter:
      return p.at(static_cast<std::size_t>(t->index));
    case TreeOp::Add:
      return evaluate(t->a, x, p) + evaluate(t->b, x, p);
    case TreeOp::Sub:
      return evaluate(t->a, x, p) - evaluate(t->b, x, p);
    case TreeOp::Mul:
      return evaluate(t->a, x, p) * evaluate(t->b, x, p);
    case TreeOp::Neg:
      return -evaluate(t->a, x, p);
    case TreeOp::Pow: {
      const T a = evaluate(t->a, x, p);
      T r = a;
      for (int i = 1; i < t->index; ++i) r = r * a;
      return r;
    }
    case TreeOp::Sin:
      return sin(evaluate(t->a, x, p));
    case TreeOp::Cos:
      return cos(evaluate(t->a, x, p));
    case TreeOp::Exp:
      return exp(evaluate(t->a, x, p));
  }
  return Scalar<T>::constant(std::nan(""));
}

// ------------------------------------------------------------------ random models

/// What derive must conclude about a reset's inverse (derive.hpp: closed form when Δ is
/// affine in the variables it changes, numeric otherwise; none when DΔ is singular
/// everywhere but injective on the guard; refused when it collapses the guard).
enum class InverseExpectation {
  ClosedForm,   ///< has_inverse, with symbolic Δ⁻¹.
  Numeric,      ///< Neither flag: Newton at run time.
  OnGuardOnly,  ///< inverse_on_guard_only (a constant component).
  Collapses,    ///< derive must refuse the model (ModelError).
};

/// A parameter of a random model.
struct RandomParameter {
  std::string name;  ///< Its name (p0…, or c0… for surface levels).
  std::string text;  ///< Its exact decimal value as written.
  double value = 0;  ///< The double nearest to `text` (what hybgen's value_d holds).
};

/// A mode: one flow component per state.
struct RandomMode {
  std::string name;        ///< Mode name.
  std::vector<Tree> flow;  ///< X^i in state order.
};

/// A guard with its surface, reset and what derive must say about the inverse.
struct RandomGuard {
  std::string name;               ///< Guard name.
  int from = 0;                   ///< Source mode.
  int to = 0;                     ///< Target mode.
  Tree surface;                   ///< s; the guard is s = 0.
  int pivot = 0;                  ///< k with ∂s/∂x_k ≠ 0 everywhere (s solvable for x_k).
  bool decreasing = true;         ///< Crossing direction.
  bool identity_keyword = false;  ///< Written `reset identity`.
  std::vector<Tree> reset;        ///< Δ^i (x_i itself for an unchanged component).
  InverseExpectation inverse = InverseExpectation::ClosedForm;  ///< Expected classification.
  std::string kind;  ///< Which family the reset was drawn from (for messages).
};

/// A random model: its own representation and the `.model` text printed from it.
struct RandomModel {
  std::uint64_t seed = 0;               ///< The seed it was generated from.
  std::vector<std::string> states;      ///< State names x0….
  std::vector<RandomParameter> params;  ///< Parameters in declaration order.
  std::vector<double> lo;               ///< Domain lower bounds per state.
  std::vector<double> hi;               ///< Domain upper bounds per state.
  std::vector<RandomMode> modes;        ///< Modes.
  std::vector<RandomGuard> guards;      ///< Guards.
  bool has_simulation = false;          ///< Whether the text has a simulation block.
  bool expect_refusal = false;          ///< A guard collapses: derive must refuse the model.
  std::string text;                     ///< The `.model` text.

  /// The parameter values, in declaration order.
  [[nodiscard]] std::vector<double> parameter_values() const {
    std::vector<double> v;
    for (const auto& p : params) v.push_back(p.value);
    return v;
  }
};

namespace detail {

/// The random draws of the model generators (random_model, random_run_model.hpp): no std
/// distributions, whose output is implementation-defined, so a seed gives the same model on
/// every platform.
class RandomDraws {
 public:
  /// Seed the engine.
  explicit RandomDraws(std::uint64_t seed) : rng_(seed) {}

 protected:
  /// Uniform in [0, 1).
  double uniform() { return static_cast<double>(rng_() >> 11) * 0x1p-53; }
  /// True with probability p.
  bool chance(double p) { return uniform() < p; }
  /// An integer in [lo, hi].
  int integer(int lo, int hi) {
    return lo + static_cast<int>(rng_() % static_cast<std::uint64_t>(hi - lo + 1));
  }
  /// A decimal ±[lo, hi]·10^(−decimals) in units, sign random.
  Tree signed_decimal(int lo_units, int hi_units, int decimals) {
    const long long u = integer(lo_units, hi_units);
    return constant(chance(0.5) ? -u : u, decimals);
  }

  std::mt19937_64 rng_;  ///< The engine.
};

/// The generator behind random_model (one object per model).
class ModelGenerator : RandomDraws {
 public:
  /// Seed the engine.
  explicit ModelGenerator(std::uint64_t seed) : RandomDraws(seed) { m_.seed = seed; }

  /// Draw the whole model and print its text.
  RandomModel run() {
    n_ = integer(1, 4);
    for (int i = 0; i < n_; ++i) m_.states.push_back("x" + std::to_string(i));
    const int np = integer(0, 3);
    for (int i = 0; i < np; ++i) {
      long long units = integer(2, 20) * (chance(0.3) ? -1 : 1);
      add_parameter("p" + std::to_string(i), units, 1);
    }
    base_params_ = np;
    for (int i = 0; i < n_; ++i) {
      const double lo = -0.5 * integer(0, 4) + 0.0;  // + 0.0: no "-0" in the text
      m_.lo.push_back(lo);
      m_.hi.push_back(lo + 0.5 * integer(2, 6));
    }
    const int nm = integer(1, 3);
    for (int k = 0; k < nm; ++k) {
      RandomMode md;
      md.name = "m" + std::to_string(k);
      for (int i = 0; i < n_; ++i) md.flow.push_back(tree(3));
      m_.modes.push_back(std::move(md));
    }
    const int ng = integer(1, 3);
    const int collapsing = n_ >= 2 && chance(0.05) ? integer(0, ng - 1) : -1;
    for (int gi = 0; gi < ng; ++gi) m_.guards.push_back(make_guard(gi, gi == collapsing));
    m_.expect_refusal = collapsing >= 0;
    m_.has_simulation = chance(0.75);
    m_.text = print();
    return std::move(m_);
  }

 private:
  void add_parameter(const std::string& name, long long units, int decimals) {
    const Tree c = constant(units, decimals);
    m_.params.push_back({name, c->text, c->value});
  }
  int random_param() { return integer(0, base_params_ - 1); }

  // ---- flows
  Tree leaf() {
    const double r = uniform();
    if (r < 0.55) return state(integer(0, n_ - 1));
    if (r < 0.8 || base_params_ == 0) return signed_decimal(1, 20, 1);
    return parameter(random_param());
  }
  /// A random tree of depth ≤ depth.
  Tree tree(int depth) {
    if (depth <= 0 || chance(0.2)) return leaf();
    const double r = uniform();
    if (r < 0.30) return add(tree(depth - 1), tree(depth - 1));
    if (r < 0.42) return sub(tree(depth - 1), tree(depth - 1));
    if (r < 0.70) return mul(tree(depth - 1), tree(depth - 1));
    if (r < 0.80) return power(chance(0.5) ? add(leaf(), leaf()) : leaf(), integer(2, 3));
    if (r < 0.84) return neg(tree(depth - 1));
    if (r < 0.91) return sin_of(tree(depth - 1));
    if (r < 0.97) return cos_of(tree(depth - 1));
    return exp_of(mul(signed_decimal(1, 5, 1), state(integer(0, n_ - 1))));
  }

  /// c·h(x_j), a mild nonlinearity in one state (second derivative not ≡ 0).
  Tree univariate(int j) {
    switch (integer(0, 3)) {
      case 0:
        return mul(signed_decimal(1, 5, 1), power(state(j), 2));
      case 1:
        return mul(signed_decimal(1, 3, 1), power(state(j), 3));
      case 2:
        return mul(signed_decimal(1, 5, 1), sin_of(state(j)));
      default:
        return mul(signed_decimal(1, 5, 1), cos_of(state(j)));
    }
  }

  static Tree sum(const std::vector<Tree>& terms) {
    Tree s = terms.at(0);
    for (std::size_t i = 1; i < terms.size(); ++i) s = add(s, terms[i]);
    return s;
  }

  // ---- guards
  /// s = a x_k + affine/mildly nonlinear in the states `allowed` (k excluded) − c.
  Tree surface(int k, const std::vector<bool>& allowed) {
    std::vector<Tree> terms;
    Tree a = chance(0.4) ? constant(chance(0.5) ? 1 : -1, 0) : signed_decimal(5, 20, 1);
    const double sign = a->value > 0 ? 1.0 : -1.0;
    terms.push_back(a->value == 1 ? state(k) : mul(a, state(k)));
    if (chance(0.1))  // monotone in x_k: a + 3c₃x_k² has the sign of a
      terms.push_back(
          mul(constant(static_cast<long long>(sign) * integer(1, 3), 1), power(state(k), 3)));
    std::vector<int> others;
    for (int j = 0; j < n_; ++j)
      if (j != k && allowed[static_cast<std::size_t>(j)]) others.push_back(j);
    for (int j : others)
      if (chance(0.5)) terms.push_back(mul(signed_decimal(1, 15, 1), state(j)));
    if (!others.empty() && chance(0.5)) {
      const int j =
          others[static_cast<std::size_t>(integer(0, static_cast<int>(others.size()) - 1))];
      if (others.size() >= 2 && chance(0.25)) {
        int l = j;
        while (l == j)
          l = others[static_cast<std::size_t>(integer(0, static_cast<int>(others.size()) - 1))];
        terms.push_back(mul(signed_decimal(1, 4, 1), mul(state(j), state(l))));
      } else {
        terms.push_back(univariate(j));
      }
    }
    // The level c: s(z0) = 0 for a random z0 in the domain, rounded to 2 decimals.
    std::vector<double> z0;
    for (int i = 0; i < n_; ++i)
      z0.push_back(m_.lo[static_cast<std::size_t>(i)] +
                   uniform() *
                       (m_.hi[static_cast<std::size_t>(i)] - m_.lo[static_cast<std::size_t>(i)]));
    const Tree body = sum(terms);
    const double level = evaluate(body, z0, m_.parameter_values());
    const auto units = static_cast<long long>(std::llround(level * 100));
    Tree c;
    if (chance(0.2)) {
      add_parameter("c" + std::to_string(m_.params.size()), units, 2);
      c = parameter(static_cast<int>(m_.params.size()) - 1);
    } else {
      c = constant(units, 2);
    }
    return sub(body, c);
  }

  /// A well-conditioned invertible |L|×|L| matrix of decimals as trees (entries may be
  /// parameters on the diagonal); lower triangular in the order of L when `triangular`.
  std::vector<std::vector<Tree>> invertible(std::size_t m, bool triangular) {
    for (int attempt = 0;; ++attempt) {
      std::vector<std::vector<Tree>> A(m, std::vector<Tree>(m));
      std::vector<std::vector<double>> v(m, std::vector<double>(m, 0.0));
      for (std::size_t i = 0; i < m; ++i)
        for (std::size_t j = 0; j < m; ++j) {
          if (i == j) {
            if (base_params_ > 0 && chance(0.15)) {
              const int p = random_param();
              if (std::fabs(m_.params[static_cast<std::size_t>(p)].value) >= 0.3) {
                A[i][j] = parameter(p);
                v[i][j] = m_.params[static_cast<std::size_t>(p)].value;
                continue;
              }
            }
            A[i][j] = signed_decimal(5, 20, 1);
          } else if ((!triangular || j < i) && attempt < 40 && chance(0.5)) {
            A[i][j] = signed_decimal(1, 8, 1);
          } else {
            continue;
          }
          v[i][j] = A[i][j]->value;
        }
      if (triangular || condition(v) < 50) return A;
    }
  }

  /// ‖A‖_∞‖A⁻¹‖_∞ by Gauss–Jordan with partial pivoting (∞ if singular).
  static double condition(std::vector<std::vector<double>> a) {
    const std::size_t m = a.size();
    double norm = 0;
    for (const auto& row : a) {
      double s = 0;
      for (double x : row) s += std::fabs(x);
      norm = std::max(norm, s);
    }
    std::vector<std::vector<double>> inv(m, std::vector<double>(m, 0.0));
    for (std::size_t i = 0; i < m; ++i) inv[i][i] = 1;
    for (std::size_t c = 0; c < m; ++c) {
      std::size_t piv = c;
      for (std::size_t r = c + 1; r < m; ++r)
        if (std::fabs(a[r][c]) > std::fabs(a[piv][c])) piv = r;
      if (std::fabs(a[piv][c]) < 1e-12) return INFINITY;
      std::swap(a[piv], a[c]);
      std::swap(inv[piv], inv[c]);
      const double d = a[c][c];
      for (std::size_t k = 0; k < m; ++k) a[c][k] /= d, inv[c][k] /= d;
      for (std::size_t r = 0; r < m; ++r) {
        if (r == c) continue;
        const double f = a[r][c];
        for (std::size_t k = 0; k < m; ++k) a[r][k] -= f * a[c][k], inv[r][k] -= f * inv[c][k];
      }
    }
    double ninv = 0;
    for (const auto& row : inv) {
      double s = 0;
      for (double x : row) s += std::fabs(x);
      ninv = std::max(ninv, s);
    }
    return norm * ninv;
  }

  /// The reset of guard `g` (pivot, from, to set); fills reset, inverse, kind.
  void make_reset(RandomGuard& g, bool collapsing, const std::vector<bool>& in_surface) {
    const int n = n_;
    const int k = g.pivot;
    auto identity_reset = [&] {
      g.reset.clear();
      for (int i = 0; i < n; ++i) g.reset.push_back(state(i));
      g.inverse = InverseExpectation::ClosedForm;
    };
    if (collapsing) {
      // y_j = c with s independent of x_j, all other components unchanged: e_j ∈ ker DΔ ∩ T S.
      int j = -1;
      for (int i = 0; i < n; ++i)
        if (!in_surface[static_cast<std::size_t>(i)]) j = i;
      identity_reset();
      g.reset[static_cast<std::size_t>(j)] =
          chance(0.5) ? signed_decimal(0, 20, 1) : constant(0, 0);
      g.inverse = InverseExpectation::Collapses;
      g.kind = "collapsing (constant x" + std::to_string(j) + ", s independent of it)";
      return;
    }
    const double r = uniform();
    if (g.from != g.to && r < 0.15) {
      identity_reset();
      g.identity_keyword = true;
      g.kind = "identity";
      return;
    }
    if (g.from != g.to && r < 0.18) {  // (into the same mode: beating, H.5)
      identity_reset();
      g.kind = "explicit, all components unchanged";
      return;
    }
    enum class Family { Affine, Shear, Nonlinear, ConstantComponent };
    Family family = r < 0.50   ? Family::Affine
                    : r < 0.62 ? Family::Shear
                    : r < 0.85 ? Family::Nonlinear
                               : Family::ConstantComponent;
    // Unchanged set U (never all of them), changed set C.
    std::vector<bool> unchanged(static_cast<std::size_t>(n), false);
    for (int i = 0; i < n; ++i) unchanged[static_cast<std::size_t>(i)] = chance(0.3);
    if (family == Family::ConstantComponent) unchanged[static_cast<std::size_t>(k)] = false;
    if (std::all_of(unchanged.begin(), unchanged.end(), [](bool b) { return b; }))
      unchanged[static_cast<std::size_t>(integer(0, n - 1))] = false;
    std::vector<int> U, L;  // L: changed components built as (triangular) affine + terms
    for (int i = 0; i < n; ++i) {
      if (unchanged[static_cast<std::size_t>(i)])
        U.push_back(i);
      else if (!(family == Family::ConstantComponent && i == k))
        L.push_back(i);
    }
    if (family == Family::Shear && U.empty()) family = Family::Affine;
    // Triangular order for the nonlinear family: a random permutation of L.
    if (family == Family::Nonlinear)
      for (std::size_t i = L.size(); i > 1; --i)
        std::swap(L[i - 1], L[static_cast<std::size_t>(integer(0, static_cast<int>(i) - 1))]);
    const auto A = invertible(L.size(), family == Family::Nonlinear);
    identity_reset();
    bool nonlinear_in_changed = false;
    for (std::size_t a = 0; a < L.size(); ++a) {
      const int i = L[a];
      std::vector<Tree> terms;
      for (std::size_t b = 0; b < L.size(); ++b)
        if (A[a][b]) terms.push_back(mul(A[a][b], state(L[b])));
      for (int j : U)
        if (chance(0.3)) terms.push_back(mul(signed_decimal(1, 10, 1), state(j)));
      if (family == Family::Shear) {
        if (chance(0.7))
          terms.push_back(
              univariate(U[static_cast<std::size_t>(integer(0, static_cast<int>(U.size()) - 1))]));
      } else if (family == Family::Nonlinear) {
        // h(x_j) of an earlier changed or an unchanged state: Δ stays triangular.
        std::vector<int> earlier(U);
        for (std::size_t b = 0; b < a; ++b) earlier.push_back(L[b]);
        if (!earlier.empty() && chance(0.5)) {
          const int j =
              earlier[static_cast<std::size_t>(integer(0, static_cast<int>(earlier.size()) - 1))];
          terms.push_back(univariate(j));
          if (!unchanged[static_cast<std::size_t>(j)]) nonlinear_in_changed = true;
        }
        const bool last = a + 1 == L.size();
        if (chance(0.5) || (last && !nonlinear_in_changed)) {
          // Self term: c x_i³ with c of the diagonal's sign (strictly monotone), or, now and
          // then, c x_i² (a fold where d + 2c x_i = 0).
          const double d = A[a][a]->op == TreeOp::Constant
                               ? A[a][a]->value
                               : m_.params[static_cast<std::size_t>(A[a][a]->index)].value;
          if (chance(0.2)) {
            terms.push_back(mul(signed_decimal(1, 3, 1), power(state(i), 2)));
          } else {
            const long long c = integer(1, 3) * (d > 0 ? 1 : -1);
            terms.push_back(mul(constant(c, 1), power(state(i), 3)));
          }
          nonlinear_in_changed = true;
        }
      }
      if (chance(0.6)) {
        if (base_params_ > 0 && chance(0.15))
          terms.push_back(parameter(random_param()));
        else
          terms.push_back(signed_decimal(1, 15, 1));
      }
      // 1.0·x_i alone would be an unchanged component to derive: change it.
      if (terms.size() == 1 && A[a][a]->op == TreeOp::Constant && A[a][a]->value == 1)
        terms.push_back(signed_decimal(1, 15, 1));
      g.reset[static_cast<std::size_t>(i)] = sum(terms);
    }
    switch (family) {
      case Family::Affine:
        g.inverse = InverseExpectation::ClosedForm;
        g.kind = "affine";
        break;
      case Family::Shear:
        g.inverse = InverseExpectation::ClosedForm;
        g.kind = "affine in the changed states, nonlinear in unchanged ones";
        break;
      case Family::Nonlinear:
        g.inverse = InverseExpectation::Numeric;
        g.kind = "nonlinear triangular";
        break;
      case Family::ConstantComponent:
        g.reset[static_cast<std::size_t>(k)] =
            base_params_ > 0 && chance(0.2) ? parameter(random_param()) : signed_decimal(0, 20, 1);
        g.inverse = InverseExpectation::OnGuardOnly;
        g.kind = "constant component x" + std::to_string(k);
        break;
    }
  }

  RandomGuard make_guard(int gi, bool collapsing) {
    RandomGuard g;
    g.name = "g" + std::to_string(gi);
    const int nm = static_cast<int>(m_.modes.size());
    g.from = integer(0, nm - 1);
    g.to = integer(0, nm - 1);
    g.decreasing = chance(0.5);
    g.pivot = integer(0, n_ - 1);
    std::vector<bool> allowed(static_cast<std::size_t>(n_), true);
    if (collapsing) {
      int j = g.pivot;
      while (j == g.pivot) j = integer(0, n_ - 1);
      allowed[static_cast<std::size_t>(j)] = false;
    }
    g.surface = surface(g.pivot, allowed);
    make_reset(g, collapsing, allowed);
    return g;
  }

  // ---- printing
  static std::string number(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v);  // domain bounds are multiples of 0.5: exact
    return b;
  }

  std::string print() const {
    std::vector<std::string> pnames;
    for (const auto& p : m_.params) pnames.push_back(p.name);
    auto text = [&](const Tree& t) { return to_text(t, m_.states, pnames); };
    std::string s = "# random model, seed " + std::to_string(m_.seed) +
                    " (tests/support/random_model.hpp)\nmodel random_" + std::to_string(m_.seed) +
                    "\n";
    for (const auto& p : m_.params) s += "parameter " + p.name + " = " + p.text + "\n";
    s += "state ";
    for (std::size_t i = 0; i < m_.states.size(); ++i) s += (i ? ", " : "") + m_.states[i];
    s += "\n";
    for (const auto& md : m_.modes) {
      s += "mode " + md.name + " {\n";
      for (std::size_t i = 0; i < md.flow.size(); ++i)
        s += "  " + m_.states[i] + "' = " + text(md.flow[i]) + "\n";
      s += "}\n";
    }
    bool constant_component = false;
    for (const auto& g : m_.guards) {
      s += "guard " + g.name + " {\n";
      if (m_.modes.size() > 1) {
        s += "  from " + m_.modes[static_cast<std::size_t>(g.from)].name;
        if (g.to != g.from) s += " to " + m_.modes[static_cast<std::size_t>(g.to)].name;
        s += "\n";
      }
      s += "  when " + text(g.surface) + " = 0 " + (g.decreasing ? "decreasing" : "increasing") +
           "\n";
      if (g.identity_keyword) {
        s += "  reset identity\n";
      } else {
        s += "  reset (";
        for (std::size_t i = 0; i < g.reset.size(); ++i) s += (i ? ", " : "") + text(g.reset[i]);
        s += ")\n";
      }
      s += "}\n";
      if (g.inverse == InverseExpectation::OnGuardOnly) constant_component = true;
    }
    if (m_.has_simulation) {
      s += "simulation {\n";
      for (std::size_t i = 0; i < m_.states.size(); ++i)
        s += "  domain " + m_.states[i] + " in [" + number(m_.lo[i]) + ", " + number(m_.hi[i]) +
             "]\n";
      s += "  initial 1\n";
      if (constant_component) s += "  method transfer\n";  // no inverse: a forward method
      s += "}\n";
    }
    return s;
  }

  RandomModel m_;
  int n_ = 1;
  int base_params_ = 0;
};

}  // namespace detail

/// The random model of `seed` (deterministic: the same seed gives the same model and text).
inline RandomModel random_model(std::uint64_t seed) {
  return detail::ModelGenerator(seed).run();
}

}  // namespace hybgen::testing
