// Stage 3 (derive): Model -> HybridSystem IR. See derive.hpp for the maths.
//
// Size: derive_mode, derive_guard (reset, inverse, injectivity on the guard, J) and
// sample_guard (the numerical checks of the hypotheses) with the exact-zero test and the
// simplifier they share.

#include "hybgen/gen/derive.hpp"

#include <cmath>
#include <cstdio>
#include <functional>
#include <new>
#include <optional>
#include <random>
#include <string>
#include <utility>

#include "hybgen/gen/dag.hpp"
#include "hybgen/gen/limits.hpp"
#include "hybgen/rt/setting_rules.hpp"

namespace hybgen::gen {

using GiNaC::ex;
using GiNaC::matrix;

std::size_t expr_size(const ex& e) {
  std::size_t n = 1;
  for (std::size_t i = 0; i < e.nops(); ++i) n += expr_size(e.op(i));
  return n;
}

namespace {

/// A deterministic rank of an expression for `simplify`: the length and text of hybgen's
/// canonical printing (dag.hpp), which does not depend on GiNaC's term order; GiNaC's own
/// tree size does (normal() picks the sign of a numerator/denominator pair by its term
/// order, and the sizes of the two forms differ), which made the choice, and hence the
/// generated code, vary from run to run.
std::pair<std::size_t, std::string> canonical_rank(const ex& e) {
  try {
    ExprDag dag;
    std::string text = dag.to_ginac(dag.import(e));
    return {text.size(), std::move(text)};
  } catch (const InternalError&) {
    return {expr_size(e) * 1000, ""};  // not importable (e.g. complex): GiNaC's size
  }
}

}  // namespace

ex simplify(const ex& e) {
  LimitScope::check_time();
  ex best = e;
  auto best_rank = canonical_rank(e);
  auto consider = [&](const ex& c) {
    auto rank = canonical_rank(c);
    if (rank < best_rank) best = c, best_rank = std::move(rank);
  };
  // Candidates: e, expand(e), and numerator/denominator of normal(e) expanded, with both
  // signs (normal() fixes the sign by GiNaC's term order). Expanding is skipped when the
  // estimated expansion exceeds the limit: the unexpanded form is exact, only larger.
  if (LimitScope::may_expand(e)) {
    try {
      consider(e.expand());
      LimitScope::check_time();
      if (expr_size(best) < 4000) {
        const ex nd = GiNaC::numer_denom(e);
        const ex n = nd.op(0).expand(), d = nd.op(1).expand();
        consider(n / d);
        consider((-n).expand() / (-d).expand());
      }
    } catch (const std::bad_alloc&) {
      throw LimitExceeded("simplifying an expression ran out of memory");
    } catch (const LimitExceeded&) {
      throw;
    } catch (const std::exception&) {
      // simplification is best effort; the unsimplified expression is exact
    }
  }
  LimitScope::check_size(best);
  return best;
}

namespace {

/// All symbols occurring in e.
void collect_symbols(const ex& e, GiNaC::exset& out) {
  if (GiNaC::is_a<GiNaC::symbol>(e)) {
    out.insert(e);
    return;
  }
  for (std::size_t i = 0; i < e.nops(); ++i) collect_symbols(e.op(i), out);
}

/// e with every power a^x whose exponent x is symbolic replaced by a float
/// when, at the exact point `at`, a^x would be a number past kMaxExactBits:
/// e.subs(at) would compute (2/5)^(10^56·37/41) exactly and never end
/// (finding F8, a symbolic exponent scaled by a reset). Everything else is
/// left symbolic, for e.subs(at) to evaluate exactly; `approximated()` says
/// whether anything was replaced (the value at the point is then inexact).
class ApproximateHugePowers : public GiNaC::map_function {
 public:
  explicit ApproximateHugePowers(const GiNaC::exmap& at) : at_(at) {}
  ex operator()(const ex& e) override {
    if (e.nops() == 0) return e;
    if (!GiNaC::is_a<GiNaC::power>(e) || GiNaC::is_a<GiNaC::numeric>(e.op(1))) return e.map(*this);
    const ex b = (*this)(e.op(0)), x = (*this)(e.op(1));
    const ex bv = b.subs(at_), xv = x.subs(at_);  // may throw at a pole, like subs
    if (GiNaC::is_a<GiNaC::numeric>(bv) && GiNaC::is_a<GiNaC::numeric>(xv) &&
        exact_power_too_large(GiNaC::ex_to<GiNaC::numeric>(bv), GiNaC::ex_to<GiNaC::numeric>(xv))) {
      approximated_ = true;
      // numeric::power, not GiNaC::pow: when the float power overflows, pow
      // leaks the power object it had allocated (GiNaC 1.8.6 is not
      // exception-safe there); numeric arithmetic allocates nothing first.
      const ex fb = GiNaC::evalf(bv), fx = GiNaC::evalf(xv);
      return GiNaC::ex_to<GiNaC::numeric>(fb).power(GiNaC::ex_to<GiNaC::numeric>(fx));
    }
    return b.is_equal(e.op(0)) && x.is_equal(e.op(1)) ? e : GiNaC::pow(b, x);
  }
  /// Whether some power was replaced by a float.
  [[nodiscard]] bool approximated() const { return approximated_; }

 private:
  const GiNaC::exmap& at_;
  bool approximated_ = false;
};

/// Sets GiNaC::Digits for one scope and restores it, also when GiNaC throws.
class DigitsScope {
 public:
  explicit DigitsScope(long digits) : saved_(GiNaC::Digits) { GiNaC::Digits = digits; }
  ~DigitsScope() { GiNaC::Digits = saved_; }
  DigitsScope(const DigitsScope&) = delete;
  DigitsScope& operator=(const DigitsScope&) = delete;

 private:
  long saved_;
};

}  // namespace

/// Whether a matrix built from `entries` is singular at every sampled point. The entries are
/// evaluated at up to 4 random rational points (as in `is_identically_zero`) in 40-digit
/// floating point; `build` turns their values into an n×n matrix; a point counts as singular
/// when |det| ≤ 1e-24·Π_i ‖row_i‖₂ (Hadamard's bound times a relative tolerance far above
/// 40-digit rounding: a scale-free test, so exp(−12)·I is regular and a singular matrix with
/// entries of size exp(60) is singular). A point where an entry cannot be evaluated decides
/// nothing. Never forms a symbolic determinant (n! terms for a dense n×n matrix), and floating
/// values keep the determinant cheap whatever the size of exact values.
bool singular_at_sampled_points(
    const std::vector<ex>& entries, std::size_t n, const std::vector<ex>& symbols,
    const std::function<matrix(const std::vector<GiNaC::numeric>&)>& build) {
  GiNaC::exset syms(symbols.begin(), symbols.end());
  for (const auto& e : entries) collect_symbols(e, syms);
  std::mt19937_64 rng(0x5eed);
  std::uniform_int_distribution<int> num(-97, 97), den(1, 89);
  int evaluated = 0;
  for (int trial = 0; trial < 4; ++trial) {
    LimitScope::check_time();
    GiNaC::exmap at;
    for (const auto& sym : syms) {
      int k = num(rng);
      if (k == 0) k = 13;
      at[sym] = GiNaC::numeric(k, den(rng));
    }
    try {
      const DigitsScope digits(40);
      ApproximateHugePowers approximate(at);
      std::vector<GiNaC::numeric> values;
      for (const auto& e : entries) {
        const ex v = GiNaC::evalf(approximate(e).subs(at));
        if (!GiNaC::is_a<GiNaC::numeric>(v) || !v.info(GiNaC::info_flags::real)) return false;
        values.push_back(GiNaC::ex_to<GiNaC::numeric>(v));
      }
      const matrix A = build(values);
      GiNaC::numeric bound = 1;
      for (unsigned i = 0; i < n; ++i) {
        GiNaC::numeric row = 0;
        for (unsigned j = 0; j < n; ++j) {
          const GiNaC::numeric x = GiNaC::ex_to<GiNaC::numeric>(A(i, j));
          row += x * x;
        }
        bound *= GiNaC::sqrt(row);
      }
      const ex d = GiNaC::evalf(A.determinant());
      if (!GiNaC::is_a<GiNaC::numeric>(d)) return false;
      if (GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(d)) >
          GiNaC::numeric(1, 1000000000000) * GiNaC::numeric(1, 1000000000000) * bound)
        return false;
      ++evaluated;
    } catch (const std::exception&) {
      continue;  // a pole at this point: try another
    }
  }
  return evaluated > 0;
}

bool is_identically_zero(const ex& e, const std::vector<ex>& symbols) {
  if (e.is_zero()) return true;
  GiNaC::exset syms(symbols.begin(), symbols.end());
  collect_symbols(e, syms);
  std::mt19937_64 rng(0x5eed);
  std::uniform_int_distribution<int> num(-97, 97), den(1, 89);
  int evaluated = 0;
  for (int trial = 0; trial < 4; ++trial) {
    LimitScope::check_time();
    GiNaC::exmap at;
    for (const auto& s : syms) {
      int n = num(rng);
      if (n == 0) n = 13;
      at[s] = GiNaC::numeric(n, den(rng));
    }
    try {
      const DigitsScope digits(40);
      ApproximateHugePowers approximate(at);
      ex v = approximate(e).subs(at);
      if (GiNaC::is_a<GiNaC::numeric>(v) && v.info(GiNaC::info_flags::crational)) {
        if (!v.is_zero()) return false;  // exact: zero or not
      } else {
        v = GiNaC::evalf(v);
        if (!GiNaC::is_a<GiNaC::numeric>(v)) return false;
        if (GiNaC::abs(GiNaC::ex_to<GiNaC::numeric>(v)) > GiNaC::numeric(1, 1000000000) *
                                                              GiNaC::numeric(1, 1000000000) *
                                                              GiNaC::numeric(1, 100000))
          return false;
        // Tiny, but (2/5)^(10^20) is tiny and not zero: with a power too large
        // to compute exactly, a tiny value decides nothing.
        if (approximate.approximated()) continue;
      }
      ++evaluated;
    } catch (const std::exception&) {
      continue;  // a pole (or a floating-point overflow) at this point: try another
    }
  }
  // Not one point could be evaluated: e is not shown to be zero.
  return evaluated > 0;
}

namespace {

/// Whether e contains none of `vars` (as written: no simplification is attempted).
bool free_of(const ex& e, const std::vector<ex>& vars) {
  for (const ex& v : vars)
    if (e.has(v)) return false;
  return true;
}

/// Whether e is affine in `vars`: each ∂e/∂v is free of them, as written. Not "the second
/// derivatives vanish": 1 − |2y − 1| has the derivative 2(1 − 2y)/|2y − 1|, whose own
/// derivative vanishes wherever it is defined, yet it is two-to-one
/// (tests/validation/models/tent_clock.model).
bool affine_in(const ex& e, const std::vector<ex>& vars) {
  for (const ex& v : vars)
    if (!free_of(e.diff(GiNaC::ex_to<GiNaC::symbol>(v)), vars)) return false;
  return true;
}

/// The guard surface s = 0 solved for one state: the first x_k whose coefficient in ∇s is
/// state-free and not zero and for which x_k − s/c no longer contains x_k (s linear in x_k),
/// as (k, that solution); nullopt if there is none.
std::optional<std::pair<std::size_t, ex>> solve_surface(const IrGuard& g, const std::vector<ex>& X,
                                                        const std::vector<ex>& symbols) {
  for (std::size_t k = 0; k < X.size(); ++k) {
    const ex c = g.gradient[k];
    if (!free_of(c, X) || is_identically_zero(c, symbols)) continue;
    ex solution = simplify(X[k] - g.surface / c);
    if (solution.has(X[k])) continue;
    return std::make_pair(k, solution);
  }
  return std::nullopt;
}

/// "x = 0, p = -1.5": a sampled point with the state names, for warnings.
std::string point_text(const std::vector<std::string>& names, const std::vector<double>& x) {
  std::string text;
  for (std::size_t i = 0; i < x.size(); ++i) {
    char b[64];
    std::snprintf(b, sizeof b, "%.6g", x[i]);
    text += (i ? ", " : "") + names[i] + " = " + b;
  }
  return text;
}

}  // namespace

namespace {

std::vector<ex> jacobian(const std::vector<ex>& f, const std::vector<ex>& x) {
  std::vector<ex> J;
  J.reserve(f.size() * x.size());
  for (const auto& fi : f)
    for (const auto& xj : x) J.push_back(simplify(fi.diff(GiNaC::ex_to<GiNaC::symbol>(xj))));
  return J;
}

ex substitute_state(const ex& e, const std::vector<ex>& from, const std::vector<ex>& to) {
  GiNaC::exmap m;
  for (std::size_t i = 0; i < from.size(); ++i) m[from[i]] = to[i];
  return e.subs(m, GiNaC::subs_options::no_pattern);
}

std::vector<ex> substitute_state(const std::vector<ex>& es, const std::vector<ex>& from,
                                 const std::vector<ex>& to) {
  std::vector<ex> out;
  for (const auto& e : es) out.push_back(substitute_state(e, from, to));
  return out;
}

/// Numeric evaluation at a point with parameters at their defaults.
class Evaluator {
 public:
  explicit Evaluator(const Model& m) : m_(m) {
    for (const auto& p : m.params) params_[p.symbol] = GiNaC::numeric(p.value_d);
  }
  /// e at the state x (NaN where it is not a finite real number, or x is not finite: a reset
  /// image that overflowed, e = 1e308).
  double operator()(const ex& e, const std::vector<double>& x) const {
    for (const double xi : x)
      if (!std::isfinite(xi)) return std::nan("");
    GiNaC::exmap at = params_;
    for (std::size_t i = 0; i < x.size(); ++i) at[m_.state_symbols[i]] = GiNaC::numeric(x[i]);
    try {
      ex v = GiNaC::evalf(e.subs(at));
      if (!GiNaC::is_a<GiNaC::numeric>(v)) return std::nan("");
      const auto& n = GiNaC::ex_to<GiNaC::numeric>(v);
      if (!n.is_real()) return std::nan("");
      return n.to_double();
    } catch (const std::exception&) {
      return std::nan("");
    }
  }

 private:
  const Model& m_;
  GiNaC::exmap params_;
};

/// Whether x is in the closure of {c} (with a small tolerance): guard points
/// lie on the boundaries of mode regions, which strict relations exclude.
bool holds_closure(const Condition& c, double v) {
  constexpr double tol = 1e-9;
  if (c.op == "<" || c.op == "<=") return v <= tol;
  return v >= -tol;
}

}  // namespace

namespace {
HybridSystem derive_within_limits(const Model& m, const SourceText& src, LimitScope& scope);
}  // namespace

HybridSystem derive(const Model& m, const SourceText& src) {
  LimitScope scope(m.limits);
  try {
    return derive_within_limits(m, src, scope);
  } catch (...) {
    scope.rethrow_at_object(src);
  }
}

namespace {

/// The derivation of one model's parts: what they share, and one method per part. A struct:
/// its fields are read by every method (the names the derivation's formulas use).
struct Deriver {
  const Model& m;                      ///< The checked model.
  const SourceText& src;               ///< Its text, for located errors.
  LimitScope& scope;                   ///< The derivation limits and the object being derived.
  const std::vector<ex>& X;            ///< The state symbols.
  const std::vector<ex>& all_symbols;  ///< The state symbols and the parameters.
  std::size_t n = X.size();            ///< The state's dimension.

  /// Mode `ms`: its vector field (Hamilton's equations for a Hamiltonian) and divergence.
  IrMode derive_mode(const ModeSpec& ms) const {
    scope.object("the vector field of mode '" + ms.name + "'", ms.loc);
    IrMode mode;
    mode.name = ms.name;
    mode.where = ms.where;
    if (ms.hamiltonian) {
      const ex& H = *ms.hamiltonian;
      mode.hamiltonian = H;
      mode.flow.assign(n, ex(0));
      for (std::size_t k = 0; k < ms.coordinates.size(); ++k) {
        auto qi = static_cast<std::size_t>(ms.coordinates[k]);
        auto pi = static_cast<std::size_t>(ms.momenta[k]);
        mode.flow[qi] = simplify(H.diff(GiNaC::ex_to<GiNaC::symbol>(X[pi])));
        mode.flow[pi] = simplify(-H.diff(GiNaC::ex_to<GiNaC::symbol>(X[qi])));
      }
    } else {
      for (const auto& f : ms.flow) mode.flow.push_back(simplify(f));
    }
    ex div = 0;
    for (std::size_t i = 0; i < n; ++i) div += mode.flow[i].diff(GiNaC::ex_to<GiNaC::symbol>(X[i]));
    mode.divergence = simplify(div);
    if (is_identically_zero(mode.divergence, all_symbols)) mode.divergence = 0;
    return mode;
  }

  /// The elastic or restitution reset of `gs` (surface `surface`, named `where` in messages):
  /// the momenta's normal component, in the kinetic metric M⁻¹ = ∂²H/∂p∂p, reversed and scaled
  /// by the restitution coefficient. Needs a natural Hamiltonian and a surface in q only.
  std::vector<ex> mechanical_reset(const GuardSpec& gs, const ex& surface,
                                   const std::string& where) const {
    std::vector<ex> reset;
    const ModeSpec& ms = m.modes[static_cast<std::size_t>(gs.from)];
    const ex& H = *ms.hamiltonian;
    const std::size_t k = ms.momenta.size();
    std::vector<ex> q, p;
    for (int i : ms.coordinates) q.push_back(X[static_cast<std::size_t>(i)]);
    for (int i : ms.momenta) p.push_back(X[static_cast<std::size_t>(i)]);
    // M⁻¹ = ∂²H/∂p∂p must not depend on p, and H − ½pᵀM⁻¹p must not either.
    matrix Minv(static_cast<unsigned>(k), static_cast<unsigned>(k));
    for (std::size_t i = 0; i < k; ++i)
      for (std::size_t j = 0; j < k; ++j)
        Minv(static_cast<unsigned>(i), static_cast<unsigned>(j)) = simplify(
            H.diff(GiNaC::ex_to<GiNaC::symbol>(p[i])).diff(GiNaC::ex_to<GiNaC::symbol>(p[j])));
    ex kinetic = 0;
    for (std::size_t i = 0; i < k; ++i)
      for (std::size_t j = 0; j < k; ++j)
        kinetic += p[i] * Minv(static_cast<unsigned>(i), static_cast<unsigned>(j)) * p[j] / 2;
    ex potential = simplify(H - kinetic);
    bool natural = true;
    for (const auto& pk : p) {
      for (std::size_t i = 0; i < k * k; ++i)
        if (!is_identically_zero(Minv.op(i).diff(GiNaC::ex_to<GiNaC::symbol>(pk)), all_symbols))
          natural = false;
      if (!is_identically_zero(potential.diff(GiNaC::ex_to<GiNaC::symbol>(pk)), all_symbols))
        natural = false;
    }
    if (!natural)
      throw src.error(gs.reset_loc,
                      "an elastic/restitution reset needs a natural Hamiltonian "
                      "½ pᵀM(q)⁻¹p + V(q) in mode '" +
                          ms.name + "' (quadratic in the momenta with no linear terms)");
    for (const auto& pk : p)
      if (!is_identically_zero(surface.diff(GiNaC::ex_to<GiNaC::symbol>(pk)), all_symbols))
        throw src.error(gs.surface_loc,
                        "the surface of " + where +
                            " depends on the momenta; an elastic/restitution reset needs a "
                            "surface in the coordinates only");
    std::vector<ex> ds;
    for (const auto& qi : q) ds.push_back(surface.diff(GiNaC::ex_to<GiNaC::symbol>(qi)));
    ex den = 0, vn = 0;
    for (std::size_t i = 0; i < k; ++i)
      for (std::size_t j = 0; j < k; ++j) {
        den += ds[i] * Minv(static_cast<unsigned>(i), static_cast<unsigned>(j)) * ds[j];
        vn += ds[i] * Minv(static_cast<unsigned>(i), static_cast<unsigned>(j)) * p[j];
      }
    if (is_identically_zero(den, all_symbols))
      throw src.error(gs.surface_loc, "the surface of " + where + " has M⁻¹(ds, ds) ≡ 0");
    reset = X;
    for (std::size_t i = 0; i < k; ++i)
      reset[static_cast<std::size_t>(ms.momenta[i])] =
          simplify(p[i] - (1 + gs.restitution) * vn / den * ds[i]);
    return reset;
  }

  /// Guard `gs` of the model whose modes `sys` holds (warnings are appended to it): surface and
  /// gradient, reset Δ, its inverse (closed form when Δ is affine in what it changes), its
  /// injectivity on the guard, and the hybrid Jacobian J (restricted to the surface where s can be
  /// solved for a state).
  IrGuard derive_guard(HybridSystem& sys, const GuardSpec& gs) const {
    scope.object("the surface of guard '" + gs.name + "'", gs.surface_loc);
    IrGuard g;
    g.name = gs.name;
    g.from = gs.from;
    g.to = gs.to;
    g.direction = gs.direction;
    g.surface = simplify(gs.surface);
    for (const auto& xi : X)
      g.gradient.push_back(simplify(g.surface.diff(GiNaC::ex_to<GiNaC::symbol>(xi))));
    const IrMode& before = sys.modes[static_cast<std::size_t>(gs.from)];
    const std::string where = "guard '" + gs.name + "'";
    // ∇s·X⁻, J's denominator; identically 0 where the flow of `before` never crosses S.
    const auto normal_rate = [&] {
      ex den = 0;
      for (std::size_t i = 0; i < n; ++i) den += g.gradient[i] * before.flow[i];
      den = simplify(den);
      if (is_identically_zero(den, all_symbols))
        throw src.error(gs.surface_loc, "the flow of mode '" + before.name +
                                            "' is tangent to the surface of " + where +
                                            " everywhere (∇s·X ≡ 0): it never crosses it");
      return den;
    };
    if (gs.reset_kind == ResetDecl::Kind::Absorb) {
      // The mass that reaches S leaves the system: S and its direction are all there is (no
      // reset, inverse or J: IrGuard::absorbing). The flow must still cross S somewhere.
      g.absorbing = true;
      g.has_inverse = true;  // nothing to invert (rt::GuardInfo: the runtime needs no Newton)
      normal_rate();
      return g;
    }
    const IrMode& after = sys.modes[static_cast<std::size_t>(gs.to)];

    // The reset map Δ.
    scope.object("the reset of guard '" + gs.name + "'", gs.reset_loc);
    switch (gs.reset_kind) {
      case ResetDecl::Kind::Identity:
        g.reset = X;
        break;
      case ResetDecl::Kind::Explicit:
        for (const auto& c : gs.reset) g.reset.push_back(simplify(c));
        break;
      case ResetDecl::Kind::Elastic:
      case ResetDecl::Kind::Restitution:
        g.reset = mechanical_reset(gs, g.surface, where);
        break;
      case ResetDecl::Kind::Absorb:  // returned above: nothing is reset
        throw InternalError("derive_guard: an absorbing guard reached the reset of " + where);
    }
    g.reset_jacobian = jacobian(g.reset, X);

    // Δ⁻¹: closed form when Δ is affine in the variables it changes.
    scope.object("the inverse reset of guard '" + gs.name + "'", gs.reset_loc);
    std::vector<std::size_t> changed;
    for (std::size_t i = 0; i < n; ++i)
      if (!is_identically_zero(g.reset[i] - X[i], all_symbols)) changed.push_back(i);
    // Affine in the changed states (`affine_in`); a piecewise-linear reset such as
    // 1 − |2y − 1| is not, and gets the numeric inverse and the pre-flight's count of
    // pre-images.
    std::vector<ex> changed_states;
    for (std::size_t i : changed) changed_states.push_back(X[i]);
    bool affine = true;
    for (std::size_t i : changed)
      if (!affine_in(g.reset[i], changed_states)) affine = false;
    // What the hybrid flow needs is the reset RESTRICTED TO ITS GUARD S: injective there when
    // DΔ is injective on the tangent spaces of S, i.e. det(DΔᵀDΔ + ∇s∇sᵀ) ≠ 0 (a v with DΔv = 0
    // and ∇s·v = 0 makes the matrix singular; conversely vᵀ(DΔᵀDΔ + ∇s∇sᵀ)v = |DΔv|² + (∇s·v)²
    // = 0 forces both). A reset with a constant component (the sawtooth x ↦ 0 at x = 1, the
    // integrate-and-fire (v, w) ↦ (v_r, w + b) at v = v_th) has det DΔ ≡ 0 but passes: it has
    // no inverse in the whole space (so none for the backward characteristics), and the forward
    // methods need none.
    // The n² entries of DΔ then the n of ∇s (on S where s can be solved for a state x_k with a
    // state-free coefficient, else in the whole space).
    auto injective_on_guard = [&] {
      std::vector<ex> E(g.reset_jacobian);
      E.insert(E.end(), g.gradient.begin(), g.gradient.end());
      if (const auto on_s = solve_surface(g, X, all_symbols)) {
        try {
          std::vector<ex> at_s(E);
          for (auto& e : at_s) e = e.subs(GiNaC::exmap{{X[on_s->first], on_s->second}});
          E = std::move(at_s);
        } catch (const LimitExceeded&) {
          throw;
        } catch (const std::exception&) {
          // A pole on S (GiNaC's pole_error): judge in the whole space instead.
        }
      }
      // G = DΔᵀDΔ + σ²∇s∇sᵀ, σ = ‖DΔ‖_F/‖∇s‖: the two terms on one scale.
      return !singular_at_sampled_points(E, n, all_symbols, [n = n](const auto& v) {
        GiNaC::numeric fd = 0, fg = 0;
        for (std::size_t i = 0; i < n * n; ++i) fd += v[i] * v[i];
        for (std::size_t i = 0; i < n; ++i) fg += v[n * n + i] * v[n * n + i];
        const GiNaC::numeric sigma2 =
            fg.is_zero() ? GiNaC::numeric(1) : (fd.is_zero() ? GiNaC::numeric(1) : fd / fg);
        matrix G(static_cast<unsigned>(n), static_cast<unsigned>(n));
        for (std::size_t i = 0; i < n; ++i)
          for (std::size_t j = 0; j < n; ++j) {
            GiNaC::numeric e = sigma2 * v[n * n + i] * v[n * n + j];
            for (std::size_t k = 0; k < n; ++k) e += v[k * n + i] * v[k * n + j];
            G(static_cast<unsigned>(i), static_cast<unsigned>(j)) = e;
          }
        return G;
      });
    };
    auto singular_everywhere = [&] {
      return singular_at_sampled_points(g.reset_jacobian, n, all_symbols, [n = n](const auto& v) {
        matrix D(static_cast<unsigned>(n), static_cast<unsigned>(n));
        for (std::size_t i = 0; i < n * n; ++i)
          D(static_cast<unsigned>(i / n), static_cast<unsigned>(i % n)) = v[i];
        return D;
      });
    };
    auto on_guard_only = [&] {
      if (!injective_on_guard())
        throw src.error(gs.reset_loc,
                        "the reset of " + where +
                            " collapses its guard (its Jacobian is singular along the guard "
                            "surface: the reset is not locally injective there)");
      g.has_inverse = false;
      g.inverse_on_guard_only = true;
      // One constant component i, with s and the other components affine in the state: Δ
      // maps the plane S affinely and injectively onto the whole plane x_i = Δ_i, so every
      // point y there has exactly one pre-image on S, which Newton on Δ_j(z) = y_j (j ≠ i),
      // s(z) = 0 finds in one step from anywhere (rt::GuardInfo::image_axis). Otherwise the
      // image may be part of the plane, or S curved with sheets where the guard does not fire,
      // and a Newton from the image could fail or land on the wrong sheet: no axis, and the
      // characteristics refuse the guard. (Two constant components would collapse S onto a
      // set of codimension ≥ 2, which injective_on_guard has refused.)
      std::vector<int> constant;
      bool others_affine = affine_in(g.surface, X);
      for (std::size_t i = 0; i < n; ++i) {
        if (free_of(g.reset[i], X))
          constant.push_back(static_cast<int>(i));
        else if (!affine_in(g.reset[i], X))
          others_affine = false;
      }
      if (constant.size() == 1 && others_affine) g.image_axis = constant.front();
    };
    if (changed.empty()) {
      g.has_inverse = true;
      g.reset_inverse = X;
    } else if (affine && singular_everywhere()) {
      on_guard_only();
    } else if (affine) {
      const auto c = static_cast<unsigned>(changed.size());
      matrix A(c, c), rhs(c, 1), unknowns(c, 1);
      for (unsigned i = 0; i < c; ++i) {
        ex b = g.reset[changed[i]];
        for (unsigned j = 0; j < c; ++j) {
          A(i, j) = g.reset_jacobian[changed[i] * n + changed[j]];
          b -= A(i, j) * X[changed[j]];
        }
        rhs(i, 0) = X[changed[i]] - simplify(b);
        unknowns(i, 0) = GiNaC::realsymbol("hybgen_u" + std::to_string(i));
      }
      matrix sol;
      try {
        sol = A.solve(unknowns, rhs, GiNaC::solve_algo::gauss);
      } catch (const LimitExceeded&) {
        throw;
      } catch (const std::exception& e) {
        // Singular after all (the sampled determinant missed it), or GiNaC could not solve.
        throw src.error(gs.reset_loc, "the reset of " + where +
                                          " could not be inverted symbolically (" + e.what() +
                                          "); its Jacobian may be singular");
      }
      g.reset_inverse = X;
      for (unsigned i = 0; i < c; ++i) g.reset_inverse[changed[i]] = simplify(sol(i, 0));
      g.has_inverse = true;
      // Verify Δ(Δ⁻¹(y)) = y exactly.
      auto round_trip = substitute_state(g.reset, X, g.reset_inverse);
      for (std::size_t i = 0; i < n; ++i)
        if (!is_identically_zero(round_trip[i] - X[i], all_symbols))
          throw InternalError("inverse reset of " + where + " failed verification");
    } else if (singular_everywhere()) {
      on_guard_only();
    } else {
      g.has_inverse = false;
      sys.warnings.push_back(where +
                             ": the reset is not affine in the variables it changes; its "
                             "inverse is computed numerically (Newton) at run time");
    }

    // Hybrid Jacobian J = ∇sᵀ adj(DΔ) X⁺(Δx) / ∇sᵀ X⁻(x).
    scope.object("the hybrid Jacobian of guard '" + gs.name + "'", gs.loc);
    matrix DD(static_cast<unsigned>(n), static_cast<unsigned>(n));
    for (std::size_t i = 0; i < n * n; ++i)
      DD(static_cast<unsigned>(i / n), static_cast<unsigned>(i % n)) = g.reset_jacobian[i];
    matrix adj(static_cast<unsigned>(n), static_cast<unsigned>(n));
    for (unsigned i = 0; i < n; ++i)
      for (unsigned j = 0; j < n; ++j) {
        // adj(A)_{ij} = (−1)^{i+j} M_{ji} (minor deleting row j, column i).
        matrix minor(static_cast<unsigned>(n - 1), static_cast<unsigned>(n - 1));
        for (unsigned r = 0, rr = 0; r < n; ++r) {
          if (r == j) continue;
          for (unsigned s = 0, ss = 0; s < n; ++s) {
            if (s == i) continue;
            minor(rr, ss++) = DD(r, s);
          }
          ++rr;
        }
        LimitScope::check_time();
        ex det = n == 1 ? ex(1) : minor.determinant(GiNaC::determinant_algo::laplace);
        adj(i, j) = ((i + j) % 2 ? -det : det);
      }
    std::vector<ex> Xplus = substitute_state(after.flow, X, g.reset);
    ex num = 0;
    for (unsigned i = 0; i < n; ++i) {
      ex row = 0;
      for (unsigned j = 0; j < n; ++j) row += adj(i, j) * Xplus[j];
      num += g.gradient[i] * row;
    }
    const ex den = normal_rate();
    g.hybrid_jacobian = simplify(num / den);
    if (is_identically_zero(g.hybrid_jacobian, all_symbols))
      throw src.error(gs.reset_loc, "the hybrid Jacobian of " + where +
                                        " is identically zero: the reset collapses the flux "
                                        "through the guard");

    // Restrict J to S when s is linear in some x_k with a state-free coefficient.
    g.hybrid_jacobian_on_surface = g.hybrid_jacobian;
    if (const auto on_s = solve_surface(g, X, all_symbols)) {
      // J can have a pole on S (where the flow before the reset is tangent to
      // it: ∇s·X⁻ = 0, e.g. y' = −y on the guard y = 0): GiNaC then throws
      // "division by zero" and J keeps its general form (fuzz finding F9).
      try {
        g.hybrid_jacobian_on_surface =
            simplify(g.hybrid_jacobian.subs(GiNaC::exmap{{X[on_s->first], on_s->second}}));
        g.surface_note = m.state[on_s->first] + " = " + "(solved from s = 0)";
      } catch (const LimitExceeded&) {
        throw;
      } catch (const std::exception&) {
      }
    }
    return g;
  }

  /// The sampled checks of guard `gi` (parameters at their defaults, points inside the domain):
  /// it fires somewhere, J does not vanish there, the reset does not land on a guard that fires
  /// at once, and no mass leaves the state space unnoticed. Appends warnings to `sys`; throws
  /// a located error for a broken hypothesis.
  void sample_guard(HybridSystem& sys, std::size_t gi, Evaluator& eval,
                    std::mt19937_64& rng) const {
    const IrGuard& g = sys.guards[gi];
    const GuardSpec& gs = m.guards[gi];
    const std::string where = "guard '" + g.name + "'";
    const IrMode& before = sys.modes[static_cast<std::size_t>(g.from)];
    // An absorbing guard has no target (its reset checks are skipped below).
    const IrMode& after = sys.modes[static_cast<std::size_t>(g.absorbing ? g.from : g.to)];
    ex lie = 0;
    for (std::size_t i = 0; i < n; ++i) lie += g.gradient[i] * before.flow[i];
    int on_surface = 0, crossing = 0, retrigger = 0, jzero = 0, leaks = 0, wall = 0;
    std::vector<double> leak_point;
    // The rate of change of each support condition along the flow of `before`: where the
    // surface lies on the support's boundary and the guard does not fire, a negative
    // rate (for ≥ / >; positive for ≤ / <) means the flow leaves the state space there.
    std::vector<ex> support_rate;
    std::vector<std::vector<ex>> support_grad;
    for (const auto& c : m.sim.support) {
      ex r = 0;
      support_grad.emplace_back();
      for (std::size_t i = 0; i < n; ++i) {
        support_grad.back().push_back(c.expr.diff(GiNaC::ex_to<GiNaC::symbol>(X[i])));
        r += support_grad.back().back() * before.flow[i];
      }
      support_rate.push_back(r);
    }
    for (int trial = 0; trial < 400 && crossing < 60; ++trial) {
      LimitScope::check_time();
      std::vector<double> x(n);
      for (std::size_t i = 0; i < n; ++i)
        x[i] = std::uniform_real_distribution<double>(m.sim.lo[i], m.sim.hi[i])(rng);
      std::size_t axis = std::uniform_int_distribution<std::size_t>(0, n - 1)(rng);
      // Scan the axis for a sign change of s, then bisect.
      const int pieces = 16;
      double a = m.sim.lo[axis], fa = std::nan("");
      bool found = false;
      for (int k = 0; k <= pieces && !found; ++k) {
        double b = m.sim.lo[axis] + (m.sim.hi[axis] - m.sim.lo[axis]) * k / pieces;
        x[axis] = b;
        double fb = eval(g.surface, x);
        if (fb == 0.0) {  // exactly on the surface (e.g. a surface on the domain's edge)
          found = true;
        } else if (k > 0 && std::isfinite(fa) && std::isfinite(fb) && fa != 0.0 &&
                   (fa < 0) != (fb < 0)) {
          double lo = a, hi = b, flo = fa;
          for (int it = 0; it < 60; ++it) {
            double mid = 0.5 * (lo + hi);
            x[axis] = mid;
            double fm = eval(g.surface, x);
            if ((fm < 0) == (flo < 0))
              lo = mid, flo = fm;
            else
              hi = mid;
          }
          x[axis] = 0.5 * (lo + hi);
          found = true;
        }
        a = b;
        fa = fb;
      }
      if (!found) continue;
      bool inside = true;
      for (const auto& c : m.sim.support)
        if (!holds_closure(c, eval(c.expr, x))) inside = false;
      for (const auto& c : before.where)
        if (!holds_closure(c, eval(c.expr, x))) inside = false;
      if (!inside) continue;
      ++on_surface;
      double rate = eval(lie, x);
      if (!(g.direction == Direction::Decreasing ? rate < 0 : rate > 0)) {
        // The guard does not fire here: does the flow leave the support through S here,
        // with no other guard of this mode firing at x to catch it?
        double scale = 1;
        for (std::size_t i = 0; i < n; ++i) scale = std::max(scale, std::fabs(x[i]));
        bool caught = false;
        for (std::size_t hj = 0; hj < sys.guards.size() && !caught; ++hj) {
          const IrGuard& h = sys.guards[hj];
          if (hj == gi || h.from != g.from) continue;
          double gn = 0, r = 0;
          for (std::size_t i = 0; i < n; ++i) {
            const double d = eval(h.gradient[i], x);
            gn += d * d;
            r += d * eval(before.flow[i], x);
          }
          caught = std::fabs(eval(h.surface, x)) <= 1e-9 * std::sqrt(gn) * scale &&
                   (h.direction == Direction::Decreasing ? r < 0 : r > 0);
        }
        for (std::size_t ci = 0; ci < m.sim.support.size() && rate != 0 && !caught; ++ci) {
          const Condition& c = m.sim.support[ci];
          double cn = 0;
          for (std::size_t i = 0; i < n; ++i) {
            const double d = eval(support_grad[ci][i], x);
            cn += d * d;
          }
          if (!(std::fabs(eval(c.expr, x)) <= 1e-9 * std::sqrt(cn) * scale)) continue;
          const double out = eval(support_rate[ci], x);
          if (c.op == "<" || c.op == "<=" ? out > 0 : out < 0) {
            if (leaks++ == 0) leak_point = x;
            break;
          }
        }
        continue;
      }
      ++crossing;
      if (g.absorbing) continue;  // nothing is reset: no wall, no J, no re-trigger
      std::vector<double> y(n);
      for (std::size_t i = 0; i < n; ++i) y[i] = eval(g.reset[i], x);
      {
        // A wall: the reset maps the crossing back onto the surface, into the same mode.
        double scale = 1;
        for (std::size_t i = 0; i < n; ++i) scale = std::max(scale, std::fabs(y[i]));
        if (g.to == g.from && std::fabs(eval(g.surface, y)) <= 1e-9 * scale) ++wall;
      }
      double J = eval(g.hybrid_jacobian, x);
      if (std::isfinite(J) && std::fabs(J) < 1e-300) ++jzero;
      // H.5: does Δ(x) lie on a guard of the target mode that fires at once?
      for (std::size_t hj = 0; hj < sys.guards.size(); ++hj) {
        const IrGuard& h = sys.guards[hj];
        if (h.from != g.to) continue;
        double sv = eval(h.surface, y);
        double scale = 1;
        for (std::size_t i = 0; i < n; ++i) scale = std::max(scale, std::fabs(y[i]));
        if (!(std::fabs(sv) <= 1e-9 * scale)) continue;
        double r = 0;
        for (std::size_t i = 0; i < n; ++i) {
          r += eval(h.gradient[i], y) * eval(after.flow[i], y);
        }
        if (h.direction == Direction::Decreasing ? r < 0 : r > 0) {
          ++retrigger;
          break;
        }
      }
    }
    // Behind a wall: if every sampled crossing is a wall's, states on its far side (where s
    // has the sign the guard fires into) are never reached from the front; a domain that
    // holds such states (in the support and the mode's region) is most likely a mistake.
    // (Not when the flow leaks through the surface: the declared direction is then in doubt,
    // and with it which side is behind; that warning comes below.)
    bool other_entry = false;  // another guard's reset leads into this mode
    for (std::size_t hj = 0; hj < sys.guards.size(); ++hj)
      if (hj != gi && sys.guards[hj].to == g.from) other_entry = true;
    if (crossing > 0 && wall == crossing && leaks == 0 && !other_entry) {
      std::vector<double> behind;
      for (int trial = 0; trial < 400 && behind.empty(); ++trial) {
        LimitScope::check_time();
        std::vector<double> x(n);
        double scale = 1;
        for (std::size_t i = 0; i < n; ++i) {
          x[i] = std::uniform_real_distribution<double>(m.sim.lo[i], m.sim.hi[i])(rng);
          scale = std::max(scale, std::fabs(x[i]));
        }
        const double sv = eval(g.surface, x);
        if (!(g.direction == Direction::Decreasing ? sv < -1e-9 * scale : sv > 1e-9 * scale))
          continue;
        bool inside = true;
        for (const auto& c : m.sim.support)
          if (!holds_closure(c, eval(c.expr, x))) inside = false;
        for (const auto& c : before.where)
          if (!holds_closure(c, eval(c.expr, x))) inside = false;
        if (inside) behind = x;
      }
      if (!behind.empty()) {
        const std::string point = point_text(m.state, behind);
        sys.warnings.emplace_back(
            where +
                " is a wall (its reset maps the surface onto itself), and the domain "
                "reaches behind it, e.g. (" +
                point +
                "): no state there is reached from the front of the wall, so mass placed "
                "there is not a state of the system; bound the domain at the wall or add a "
                "`support` relation",
            gs.surface_loc);
      }
    }
    if (leaks > 0) {
      const std::string point = point_text(m.state, leak_point);
      const bool dec = g.direction == Direction::Decreasing;
      sys.warnings.emplace_back(
          where + ": at (" + point + ") and " + std::to_string(leaks - 1) +
              " more sampled points the flow of mode '" + before.name +
              "' leaves the support through the surface in the direction the guard does not "
              "fire (declared " +
              (dec ? "decreasing" : "increasing") +
              "): that mass leaves the state space unnoticed; did you mean '" +
              (dec ? "increasing" : "decreasing") + "'?",
          gs.direction_loc);
    }
    if (on_surface == 0) {
      sys.warnings.emplace_back(where +
                                    ": the surface does not meet the simulation domain (with "
                                    "the parameters at their defaults)",
                                gs.surface_loc);
    } else if (crossing == 0) {
      const bool dec = gs.direction == Direction::Decreasing;
      sys.warnings.emplace_back(where +
                                    ": at every sampled point of the surface inside the "
                                    "domain the flow of mode '" +
                                    before.name +
                                    "' crosses it in the other direction, so the guard never "
                                    "fires there: its mass runs on in mode '" +
                                    before.name + "'; did you mean '" +
                                    (dec ? "increasing" : "decreasing") + "'?",
                                gs.direction_loc);
    } else {
      if (jzero == crossing)
        throw src.error(gs.reset_loc, "the hybrid Jacobian of " + where +
                                          " is zero at every sampled crossing point");
      if (retrigger == crossing)
        throw src.error(gs.reset_loc,
                        "the reset of " + where +
                            " lands on a guard surface where the flow triggers that guard "
                            "again at once (beating: the paper's hypothesis H.5, S ∩ Δ(S) = ∅, "
                            "fails)");
      if (retrigger > 0)
        sys.warnings.emplace_back(where + ": at " + std::to_string(retrigger) + " of " +
                                      std::to_string(crossing) +
                                      " sampled crossings the reset lands on a guard that "
                                      "fires again at once (H.5)",
                                  gs.reset_loc);
    }
  }
};

HybridSystem derive_within_limits(const Model& m, const SourceText& src, LimitScope& scope) {
  HybridSystem sys;
  sys.model = &m;
  std::vector<ex> all_symbols = m.state_symbols;
  for (const auto& p : m.params) all_symbols.push_back(p.symbol);
  const Deriver d{m, src, scope, m.state_symbols, all_symbols};
  for (const auto& ms : m.modes) sys.modes.push_back(d.derive_mode(ms));
  for (const auto& gs : m.guards) sys.guards.push_back(d.derive_guard(sys, gs));

  // A reset without an inverse cannot run by a method that inverts the resets (the rule of
  // runtime/include/hybgen/rt/setting_rules.hpp, which check_runnable in run.cpp applies
  // before a run): say so at `check` too when that is the model's method.
  if (m.sim.present)
    for (const auto& g : sys.guards)
      if (g.inverse_on_guard_only && g.image_axis < 0)
        if (const std::string why = rt::inverse_rule(m.sim.settings, g.name); !why.empty())
          sys.warnings.push_back("`run` will refuse this method: " + why);

  // Numerical checks on sampled points of each guard surface (parameters at
  // their defaults, inside the simulation domain).
  if (m.sim.present) {
    scope.object("the sampled checks of the guards", m.sim.loc);
    Evaluator eval(m);
    std::mt19937_64 rng(12345);
    for (std::size_t gi = 0; gi < sys.guards.size(); ++gi) d.sample_guard(sys, gi, eval, rng);
  }
  return sys;
}

}  // namespace

}  // namespace hybgen::gen
