// Differential test of `derive` on random models (docs/hardening.md).
//
// Size: one differential test, whose checks (flows, guards, inverses, J from first principles,
// the error bounds that decide a disagreement) share the evaluation of one random model.
//
// tests/support/random_model.hpp draws well-formed general models (1–4 states, 1–3 modes,
// 1–3 guards; polynomial/trigonometric flows, affine and mildly nonlinear surfaces, affine,
// nonlinear and constant-component resets) and keeps them as expression trees that it
// evaluates in double precision, in dual numbers (exact derivatives up to rounding) and in a
// running error bound, all without hybgen. Each model's text goes through the pipeline
// (parse -> check -> derive); derive's IR is evaluated at 30 significant digits with GiNaC at
// the same double inputs (so its own rounding is ~1e-28 relative and negligible) and
// compared with the trees:
//  - every mode's flow X and its divergence div X = Σ ∂Xⁱ/∂xⁱ (dual numbers on the tree), at
//    random points of the domain;
//  - on each guard, at points z of S = {s = 0} inside the domain (s solved for the surface's
//    pivot state by bisection): s, ∇s, Δ(z), DΔ(z) (dual numbers);
//  - derive's classification of the inverse against the reset's construction (closed form iff
//    Δ is affine in the states it changes; none when it has a constant component; numeric
//    otherwise, with its warning); when derive gives a closed-form Δ⁻¹: Δ(Δ⁻¹(y)) = y and
//    Δ⁻¹(y) = z for y = Δ(z) (the resets of that kind are injective in the whole space);
//  - the hybrid Jacobian from first principles: with v_1 … v_{n−1} an orthonormal basis of
//    T_zS = ∇s(z)^⊥ (Householder), X⁻ = X_from(z), X⁺ = X_to(Δ(z)),
//        J = det[DΔ v_1, …, DΔ v_{n−1}, X⁺] / det[v_1, …, v_{n−1}, X⁻],
//    the factor by which the flux of n-volume through S changes across the reset. This is
//    hybgen's convention, signed (README "Derived equations": J = ∇sᵀ adj(DΔ) X⁺(Δx) /
//    ∇sᵀ X⁻(x), "equal to docs/design.md's determinant quotient for every tangent basis";
//    derive.hpp proves the identity; the transport uses 1/|J|, docs/methods.md).
//    SignConventionOnShippedModels pins it on the shipped ball (J = e²), a 1-D thermostat
//    with an identity reset (J = X⁺/X⁻ < 0) and the shipped sawtooth (J = 1/2). Both J
//    (general) and J with s = 0 substituted (hybrid_jacobian_on_surface) are compared.
// A model derive refuses must be refused with a located gen::ModelError, never another
// exception; refusals are counted by reason, the models built to collapse their guard must be
// refused, and at least 85 % of the others must be accepted, so the test cannot pass
// vacuously.
//
// Tolerances. An ErrorBound evaluation bounds, to first order, the rounding error e of the
// double evaluation of a tree (and, run on duals, of its derivative) including the rounding
// of decimal constants (hybgen reads 0.3 as 3/10): |exact − computed| ≤ e. Comparisons of
// values and derivatives allow 16e (second-order terms, libm's last ulp) plus 1e-24 times the
// magnitude bound for GiNaC's 30-digit evaluation. For J = N/D, N = det[DΔ v, X⁺],
// D = det[v, X⁻], the absolute error bounds e_∇s, e_DΔ (Frobenius), e_X⁻ and e_X⁺ (X⁺ fed
// with Δ(z)'s error bound) tilt the basis v by θ = e_∇s/‖∇s‖ + 16nu, perturb each column
// DΔ v_c by c = ‖DΔ‖_F(θ + nu) + e_DΔ, and by Hadamard's bound (orthonormal v)
//     |δN| ≤ (n−1) c ‖DΔ‖_F^{n−2} ‖X⁺‖ + ‖DΔ‖_F^{n−1} (e_X⁺ + 16nu ‖X⁺‖),
//     |δD| ≤ (n−1) θ ‖X⁻‖ + e_X⁻ + 16nu ‖X⁻‖        (16nu: Householder and LU rounding),
// so |δJ| ≤ (|δN| + |J| |δD|) / |D|, allowed 16 times. The bound is absolute, not relative:
// X⁺(Δz) can be exactly 0 in double while derive's exact value is not (seed 1008795 of the
// first campaign: p1 + (−0.2) + (−0.9) = 0 in double with p1 = 1.1; derive, with p1 the
// double nearest 1.1 and exact decimals, gets J = 7e-15). Near grazing (|D| → 0) the
// tolerance grows like J's condition number, as it must. J with s = 0 substituted equals J
// at the point z* ∈ S with the solved state moved by |s(z)|/|∂s/∂x_k| (z is on S only to
// rounding); that shift times a central difference of J (at 30 digits) is added. The inverse: |Δ(w)
// − y| ≤ 16(e_Δ(w) + Σ_j |∂_jΔ|u|w_j|) (w rounded to double); |w − z| ≤ 16‖DΔ(z)⁻¹‖_∞ ‖e_Δ(z)‖_∞ +
// 16u‖z‖_∞. Wrong derivations change values by O(1) relative; these tolerances are ~1e-13 relative.
//
// HYBGEN_RANDOM_MODELS (default 300) sets the number of models, HYBGEN_RANDOM_SEED (default
// 1) the seed of the first; model i has seed SEED + i, so a failure printed with seed S is
// reproduced by HYBGEN_RANDOM_SEED=S HYBGEN_RANDOM_MODELS=1.

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/parse.hpp"
#include "support/pipeline.hpp"
#include "support/random_model.hpp"

namespace hybgen::testing {
namespace {

using GiNaC::ex;
using Vec = std::vector<double>;
using Matrix = std::vector<Vec>;
constexpr double kU = kUnitRoundoff;

std::uint64_t env_or(const char* name, std::uint64_t fallback) {
  const char* v = std::getenv(name);
  if (v == nullptr || *v == '\0') return fallback;
  return std::strtoull(v, nullptr, 0);
}

std::string read_model(const std::string& name) {
  std::ifstream in(std::string(HYBGEN_SOURCE_DIR) + "/models/" + name);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string show(const Vec& x) {
  std::string s = "(";
  char b[40];
  for (std::size_t i = 0; i < x.size(); ++i) {
    std::snprintf(b, sizeof b, "%.17g", x[i]);
    s += (i ? ", " : "") + std::string(b);
  }
  return s + ")";
}

std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

/// Sets GiNaC::Digits for one scope.
class DigitsScope {
 public:
  explicit DigitsScope(long digits) : saved_(GiNaC::Digits) { GiNaC::Digits = digits; }
  ~DigitsScope() { GiNaC::Digits = saved_; }
  DigitsScope(const DigitsScope&) = delete;
  DigitsScope& operator=(const DigitsScope&) = delete;

 private:
  long saved_;
};

/// derive's expressions at a point, at 30 significant digits from the exact double inputs
/// (parameters at their value_d, as derive's own sampled checks use them). NaN if the
/// expression cannot be evaluated there (a pole) or is not real.
class IrEvaluator {
 public:
  explicit IrEvaluator(const gen::Model* m) : m_(m) {}
  double operator()(const ex& e, const Vec& x) const {
    const DigitsScope digits(30);
    GiNaC::exmap at;
    for (const auto& p : m_->params) at[p.symbol] = GiNaC::numeric(p.value_d);
    for (std::size_t i = 0; i < x.size(); ++i) at[m_->state_symbols[i]] = GiNaC::numeric(x[i]);
    try {
      const ex v = GiNaC::evalf(e.subs(at));
      if (!GiNaC::is_a<GiNaC::numeric>(v)) return std::nan("");
      const auto& n = GiNaC::ex_to<GiNaC::numeric>(v);
      if (!n.is_real()) return std::nan("");
      return n.to_double();
    } catch (const std::exception&) {
      return std::nan("");
    }
  }

 private:
  const gen::Model* m_;
};

// ------------------------------------------------------------- tree evaluation helpers

/// Parameter values in the four scalar types (constants: derivative 0; hybgen substitutes
/// the same doubles, so no error).
struct ParamValues {
  Vec d;
  std::vector<ErrorBound> e;
  std::vector<Dual<double>> dd;
  std::vector<Dual<ErrorBound>> de;
  explicit ParamValues(const Vec& p) : d(p) {
    for (double v : p) {
      e.push_back({std::fabs(v), 0.0});
      dd.push_back({v, 0.0});
      de.push_back({{std::fabs(v), 0.0}, {0.0, 0.0}});
    }
  }
};

/// A double and its rounding error bound.
struct Bounded {
  double v = 0;
  ErrorBound b;
};

/// t at x (x given with absolute errors xe, default exact).
Bounded value(const Tree& t, const Vec& x, const ParamValues& p, const Vec& xe = {}) {
  std::vector<ErrorBound> xb;
  for (std::size_t i = 0; i < x.size(); ++i)
    xb.push_back({std::fabs(x[i]), xe.empty() ? 0 : xe[i]});
  return {evaluate<double>(t, x, p.d), evaluate<ErrorBound>(t, xb, p.e)};
}

/// ∂t/∂x_j at x by forward-mode dual numbers, with its rounding error bound.
Bounded derivative(const Tree& t, const Vec& x, std::size_t j, const ParamValues& p) {
  std::vector<Dual<double>> xd;
  std::vector<Dual<ErrorBound>> xb;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double seed = i == j ? 1.0 : 0.0;
    xd.push_back({x[i], seed});
    xb.push_back({{std::fabs(x[i]), 0.0}, {seed, 0.0}});
  }
  return {evaluate<Dual<double>>(t, xd, p.dd).d, evaluate<Dual<ErrorBound>>(t, xb, p.de).d};
}

// ------------------------------------------------------------- small dense linear algebra

double det(Matrix a) {
  const std::size_t n = a.size();
  double d = 1;
  for (std::size_t c = 0; c < n; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < n; ++r)
      if (std::fabs(a[r][c]) > std::fabs(a[piv][c])) piv = r;
    if (a[piv][c] == 0) return 0;
    if (piv != c) std::swap(a[piv], a[c]), d = -d;
    d *= a[c][c];
    for (std::size_t r = c + 1; r < n; ++r) {
      const double f = a[r][c] / a[c][c];
      for (std::size_t k = c; k < n; ++k) a[r][k] -= f * a[c][k];
    }
  }
  return d;
}

/// ‖A⁻¹‖_∞ by Gauss–Jordan with partial pivoting; nullopt if (numerically) singular.
std::optional<double> inverse_norm(Matrix a) {
  const std::size_t n = a.size();
  Matrix inv(n, Vec(n, 0.0));
  for (std::size_t i = 0; i < n; ++i) inv[i][i] = 1;
  for (std::size_t c = 0; c < n; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < n; ++r)
      if (std::fabs(a[r][c]) > std::fabs(a[piv][c])) piv = r;
    if (std::fabs(a[piv][c]) < 1e-13) return std::nullopt;
    std::swap(a[piv], a[c]);
    std::swap(inv[piv], inv[c]);
    const double d = a[c][c];
    for (std::size_t k = 0; k < n; ++k) a[c][k] /= d, inv[c][k] /= d;
    for (std::size_t r = 0; r < n; ++r) {
      if (r == c) continue;
      const double f = a[r][c];
      for (std::size_t k = 0; k < n; ++k) a[r][k] -= f * a[c][k], inv[r][k] -= f * inv[c][k];
    }
  }
  double m = 0;
  for (const auto& row : inv) {
    double s = 0;
    for (double v : row) s += std::fabs(v);
    m = std::max(m, s);
  }
  return m;
}

double norm(const Vec& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s);
}

/// An orthonormal basis of g^⊥ (g ≠ 0): columns 2…n of the Householder reflection that
/// maps g to a multiple of e_1.
Matrix tangent_basis(const Vec& g) {
  const std::size_t n = g.size();
  Vec w = g;
  w[0] += (g[0] >= 0 ? 1.0 : -1.0) * norm(g);
  const double ww = [&] {
    double s = 0;
    for (double x : w) s += x * x;
    return s;
  }();
  Matrix basis;
  for (std::size_t c = 1; c < n; ++c) {
    Vec v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = (i == c ? 1.0 : 0.0) - 2 * w[i] * w[c] / ww;
    basis.push_back(v);
  }
  return basis;
}

// ------------------------------------------------------------- J from first principles

/// The hybrid Jacobian at z from its definition, and the tolerance it is known to.
struct FirstPrinciples {
  double J = std::nan("");  ///< det[DΔ v, X⁺] / det[v, X⁻].
  double tol = 0;           ///< Bound on its rounding error (file comment).
  double sin_angle = 0;     ///< |n̂·X⁻|/‖X⁻‖: how far from grazing.
  Vec y;                    ///< Δ(z).
  Vec y_err;                ///< Its rounding error bounds.
  Matrix D;                 ///< DΔ(z).
};

FirstPrinciples first_principles_jacobian(const Tree& s, const std::vector<Tree>& reset,
                                          const std::vector<Tree>& from_flow,
                                          const std::vector<Tree>& to_flow, const ParamValues& p,
                                          const Vec& z) {
  const std::size_t n = z.size();
  FirstPrinciples out;
  Vec g(n), eg(n), xm(n), exm(n), xp(n), exp_(n);
  out.D.assign(n, Vec(n));
  double normA2 = 0, errA2 = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const Bounded d = derivative(s, z, j, p);
    g[j] = d.v, eg[j] = d.b.e;
  }
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < n; ++j) {
      const Bounded d = derivative(reset[i], z, j, p);
      out.D[i][j] = d.v;
      normA2 += d.v * d.v;
      errA2 += d.b.e * d.b.e;
    }
    const Bounded y = value(reset[i], z, p);
    out.y.push_back(y.v);
    out.y_err.push_back(y.b.e);
    const Bounded m = value(from_flow[i], z, p);
    xm[i] = m.v, exm[i] = m.b.e;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const Bounded v = value(to_flow[i], out.y, p, out.y_err);
    xp[i] = v.v, exp_[i] = v.b.e;
  }
  const Matrix V = tangent_basis(g);
  Matrix num(n, Vec(n)), den(n, Vec(n));
  for (std::size_t c = 0; c + 1 < n; ++c)
    for (std::size_t i = 0; i < n; ++i) {
      double a = 0;
      for (std::size_t k = 0; k < n; ++k) a += out.D[i][k] * V[c][k];
      num[i][c] = a;
      den[i][c] = V[c][i];
    }
  for (std::size_t i = 0; i < n; ++i) num[i][n - 1] = xp[i], den[i][n - 1] = xm[i];
  const double N = det(num), Dn = det(den);
  out.J = N / Dn;
  // Absolute first-order perturbation bounds of the two determinants (file comment).
  const double nd = static_cast<double>(n), normA = std::sqrt(normA2);
  const double theta = norm(eg) / norm(g) + 16 * nd * kU;              // angle error of the basis v
  const double column = normA * (theta + nd * kU) + std::sqrt(errA2);  // error of DΔ v_c
  const double a_pow = std::pow(normA, nd - 1);
  const double dN = (nd - 1) * column * (n >= 2 ? std::pow(normA, nd - 2) : 0.0) * norm(xp) +
                    a_pow * norm(exp_) + 16 * nd * kU * a_pow * norm(xp);
  const double dD = (nd - 1) * theta * norm(xm) + norm(exm) + 16 * nd * kU * norm(xm);
  out.tol = 16 * (dN + std::fabs(out.J) * dD) / std::fabs(Dn);
  out.sin_angle = norm(xm) > 0 ? std::fabs(Dn) / norm(xm) : 0.0;
  return out;
}

// ------------------------------------------------------------- points

/// Uniform in [0, 1) from the engine (portable, unlike std distributions).
double uniform(std::mt19937_64& rng) {
  return static_cast<double>(rng() >> 11) * 0x1p-53;
}

Vec random_point(const RandomModel& rm, std::mt19937_64& rng) {
  Vec x;
  for (std::size_t i = 0; i < rm.lo.size(); ++i)
    x.push_back(rm.lo[i] + uniform(rng) * (rm.hi[i] - rm.lo[i]));
  return x;
}

/// A point of S inside the domain: the other states drawn at random, s = 0 solved for the
/// pivot x_k (s is strictly monotone in x_k) by scanning its domain interval for a sign change
/// and bisecting to adjacent doubles. nullopt if 60 draws miss the domain.
std::optional<Vec> point_on_guard(const RandomModel& rm, const RandomGuard& g, const ParamValues& p,
                                  std::mt19937_64& rng) {
  const auto k = static_cast<std::size_t>(g.pivot);
  for (int attempt = 0; attempt < 60; ++attempt) {
    Vec x = random_point(rm, rng);
    auto s_at = [&](double t) {
      x[k] = t;
      return evaluate<double>(g.surface, x, p.d);
    };
    const int pieces = 16;
    double a = rm.lo[k], fa = s_at(a);
    for (int i = 1; i <= pieces; ++i) {
      const double b = rm.lo[k] + (rm.hi[k] - rm.lo[k]) * i / pieces, fb = s_at(b);
      if (fa == 0) {
        x[k] = a;
        return x;
      }
      if ((fa < 0) != (fb < 0)) {
        double lo = a, hi = b, flo = fa;
        for (int it = 0; it < 200; ++it) {
          const double mid = 0.5 * (lo + hi);
          if (mid <= lo || mid >= hi) break;
          const double fm = s_at(mid);
          if (fm == 0) {
            lo = hi = mid;
            break;
          }
          if ((fm < 0) == (flo < 0))
            lo = mid, flo = fm;
          else
            hi = mid;
        }
        x[k] = std::fabs(s_at(lo)) <= std::fabs(s_at(hi)) ? lo : hi;
        return x;
      }
      a = b, fa = fb;
    }
  }
  return std::nullopt;
}

// ------------------------------------------------------------- one model

/// What the campaign counts.
struct Tally {
  long models = 0, accepted = 0, refused = 0, expected_refusals = 0, failing = 0;
  long guard_points = 0, grazing_skipped = 0, guards_without_points = 0;
  long refusals_confirmed = 0;
  std::map<std::string, long> checks;           ///< Comparisons made, per quantity.
  std::map<std::string, double> worst;          ///< Largest |derive − tree| / tolerance.
  std::map<std::string, long> refusal_reasons;  ///< Refusals per reason.
  std::map<std::string, long> inverse_kinds;    ///< derive's inverse classification.
  double slowest = 0;
  std::uint64_t slowest_seed = 0;
};

const char* kind_name(InverseExpectation k) {
  switch (k) {
    case InverseExpectation::ClosedForm:
      return "closed form";
    case InverseExpectation::Numeric:
      return "numeric (Newton)";
    case InverseExpectation::OnGuardOnly:
      return "none (injective on the guard only)";
    case InverseExpectation::Collapses:
      return "refusal (collapses its guard)";
  }
  return "?";
}

/// Comparisons of derive's numbers with the trees' for one model; failures go to `fail`.
class ModelChecker {
 public:
  ModelChecker(const RandomModel& rm, const gen::Model* model, Tally& tally,
               std::vector<std::string>& fail)
      : rm_(rm),
        ir_(model),
        p_(rm.parameter_values()),
        tally_(tally),
        fail_(fail),
        rng_(rm.seed ^ 0x9e3779b97f4a7c15ULL) {}

  /// Every check of an accepted model.
  void run(const Pipeline& pl) {
    const gen::HybridSystem& sys = pl.sys;
    if (sys.modes.size() != rm_.modes.size() || sys.guards.size() != rm_.guards.size() ||
        pl.model.state.size() != rm_.states.size()) {
      fail_.push_back("the IR's shape differs from the model's");
      return;
    }
    for (std::size_t m = 0; m < rm_.modes.size(); ++m) check_mode(rm_.modes[m], sys.modes[m]);
    for (std::size_t g = 0; g < rm_.guards.size(); ++g)
      check_guard(rm_.guards[g], sys.guards[g], sys.warnings);
  }

  /// Whether the trees confirm derive's reason for refusing the model (bare message): a flow
  /// tangent to a guard everywhere, J ≡ 0 or zero at the crossings, or beating (H.5). ""
  /// when confirmed, nullopt when the reason is not one of these or no point could be
  /// tested, else what contradicts it.
  std::optional<std::string> contradicts_refusal(const std::string& bare) {
    const auto q = bare.find("guard '");
    if (q == std::string::npos) return std::nullopt;
    const std::string name = bare.substr(q + 7, bare.find('\'', q + 7) - q - 7);
    const RandomGuard* g = nullptr;
    for (const auto& h : rm_.guards)
      if (h.name == name) g = &h;
    if (g == nullptr) return "the refusal names no guard of the model";
    const auto& from = rm_.modes[static_cast<std::size_t>(g->from)].flow;
    const auto& to = rm_.modes[static_cast<std::size_t>(g->to)].flow;
    if (bare.find("never crosses") != std::string::npos) {
      // ∇s·X⁻ ≡ 0: it must vanish (to rounding) at random points.
      for (int trial = 0; trial < 5; ++trial) {
        const Vec x = random_point(rm_, rng_);
        const auto [v, b] = flux(*g, from, x);
        if (std::fabs(v) > 16 * b.e + 1e-300)
          return "derive says the flow never crosses guard " + name + ", but ∇s·X = " + num(v) +
                 " at " + show(x);
      }
      return "";
    }
    const bool zero = bare.find("identically zero") != std::string::npos ||
                      bare.find("zero at every sampled") != std::string::npos;
    const bool beating = bare.find("H.5") != std::string::npos;
    if (!zero && !beating) return std::nullopt;
    bool tested = false;
    for (int trial = 0; trial < 3; ++trial) {
      const auto z = point_on_guard(rm_, *g, p_, rng_);
      if (!z) break;
      const auto [rate, rate_b] = flux(*g, from, *z);
      if (!(std::fabs(rate) > 16 * rate_b.e) || (rate < 0) != g->decreasing) continue;
      tested = true;
      const FirstPrinciples fp = first_principles_jacobian(g->surface, g->reset, from, to, p_, *z);
      if (zero && std::fabs(fp.J) > fp.tol)
        return "derive says J of guard " + name + " is zero, but J = " + num(fp.J) + " at " +
               show(*z);
      if (beating) {
        // Δ(z) on a surface of the target mode whose guard fires there (derive's criterion:
        // |s| ≤ 1e-9 max(1, |y|∞), ∇s·X in the firing direction).
        bool fires = false;
        double scale = 1;
        for (double v : fp.y) scale = std::max(scale, std::fabs(v));
        for (const auto& h : rm_.guards) {
          if (h.from != g->to) continue;
          if (!(std::fabs(evaluate<double>(h.surface, fp.y, p_.d)) <= 1e-9 * scale)) continue;
          const double r = flux(h, to, fp.y).first;
          if (h.decreasing ? r < 0 : r > 0) fires = true;
        }
        if (!fires)
          return "derive says guard " + name + " beats (H.5), but its reset takes " + show(*z) +
                 " to " + show(fp.y) + ", where no guard fires";
      }
    }
    if (!tested) return std::nullopt;
    return "";
  }

 private:
  /// ∇s·X at x with its error bound.
  std::pair<double, ErrorBound> flux(const RandomGuard& g, const std::vector<Tree>& flow,
                                     const Vec& x) {
    double v = 0;
    ErrorBound b;
    for (std::size_t j = 0; j < x.size(); ++j) {
      const Bounded d = derivative(g.surface, x, j, p_), f = value(flow[j], x, p_);
      v += d.v * f.v;
      b = b + d.b * f.b;
    }
    return {v, b};
  }

  /// Records |got − want| against tol under `kind`; a failure unless within it.
  void expect_close(const std::string& kind, double got, double want, double tol,
                    const std::string& what) {
    ++tally_.checks[kind];
    const double diff = std::fabs(got - want);  // NaN if derive's value is not finite
    const double ratio = diff == 0 ? 0.0 : diff / tol;
    if (ratio <= 1) {
      tally_.worst[kind] = std::max(tally_.worst[kind], ratio);
      return;
    }
    fail_.push_back(what + ": expected " + num(want) + ", derive " + num(got) +
                    " (|Δ| = " + num(std::fabs(got - want)) + ", tolerance " + num(tol) + ")");
  }

  /// derive's value of e at x (30 digits) against a bounded double evaluation.
  void expect_value(const std::string& kind, const ex& e, const Vec& x, const Bounded& want,
                    const std::string& what) {
    expect_close(kind, ir_(e, x), want.v, 16 * want.b.e + 1e-24 * want.b.m + 1e-300, what);
  }

  void check_mode(const RandomMode& md, const gen::IrMode& im) {
    const std::size_t n = rm_.states.size();
    for (int trial = 0; trial < 4; ++trial) {
      const Vec x = random_point(rm_, rng_);
      Bounded div;
      for (std::size_t i = 0; i < n; ++i) {
        expect_value("flow", im.flow[i], x, value(md.flow[i], x, p_),
                     "mode " + md.name + ": " + rm_.states[i] + "' at " + show(x));
        const Bounded d = derivative(md.flow[i], x, i, p_);
        div.v += d.v;
        div.b = div.b + d.b;
      }
      expect_value("divergence", im.divergence, x, div,
                   "mode " + md.name + ": div X at " + show(x));
    }
  }

  void check_guard(const RandomGuard& g, const gen::IrGuard& ig,
                   const std::vector<gen::DeriveWarning>& warnings) {
    const std::size_t n = rm_.states.size();
    const std::string where = "guard " + g.name + " (" + g.kind + ")";
    // derive's classification of the inverse against the reset's construction.
    const InverseExpectation got_kind = ig.has_inverse             ? InverseExpectation::ClosedForm
                                        : ig.inverse_on_guard_only ? InverseExpectation::OnGuardOnly
                                                                   : InverseExpectation::Numeric;
    ++tally_.inverse_kinds[kind_name(got_kind)];
    if (got_kind != g.inverse || (ig.has_inverse && ig.inverse_on_guard_only))
      fail_.push_back(where + ": expected inverse " + kind_name(g.inverse) + ", derive gave " +
                      kind_name(got_kind));
    if (got_kind == InverseExpectation::Numeric &&
        std::none_of(warnings.begin(), warnings.end(), [&](const gen::DeriveWarning& w) {
          return w.text.find("guard '" + g.name + "'") != std::string::npos &&
                 w.text.find("numerically") != std::string::npos;
        }))
      fail_.push_back(where + ": a numeric inverse without its warning");
    const auto& from = rm_.modes[static_cast<std::size_t>(g.from)].flow;
    const auto& to = rm_.modes[static_cast<std::size_t>(g.to)].flow;
    int points = 0;
    for (int trial = 0; trial < 3; ++trial) {
      const auto z_opt = point_on_guard(rm_, g, p_, rng_);
      if (!z_opt) break;
      const Vec& z = *z_opt;
      ++points;
      ++tally_.guard_points;
      const std::string at = " at z = " + show(z);
      expect_value("s", ig.surface, z, value(g.surface, z, p_), where + ": s" + at);
      for (std::size_t j = 0; j < n; ++j) {
        expect_value("grad s", ig.gradient[j], z, derivative(g.surface, z, j, p_),
                     where + ": ds/d" + rm_.states[j] + at);
        expect_value("reset", ig.reset[j], z, value(g.reset[j], z, p_),
                     where + ": reset component " + rm_.states[j] + at);
        for (std::size_t k = 0; k < n; ++k)
          expect_value("reset Jacobian", ig.reset_jacobian[j * n + k], z,
                       derivative(g.reset[j], z, k, p_),
                       where + ": DΔ[" + std::to_string(j) + "][" + std::to_string(k) + "]" + at);
      }
      // The hybrid Jacobian from first principles.
      const FirstPrinciples fp = first_principles_jacobian(g.surface, g.reset, from, to, p_, z);
      if (!(fp.sin_angle > 1e-6) || !std::isfinite(fp.J)) {
        ++tally_.grazing_skipped;  // (nearly) tangent flow: J is (nearly) a pole here
      } else {
        expect_close("J", ir_(ig.hybrid_jacobian, z), fp.J, fp.tol + 1e-20 * std::fabs(fp.J),
                     where + ": J" + at);
        check_jacobian_on_surface(g, ig, z, fp, where + ": J on s = 0" + at);
      }
      if (ig.has_inverse) check_inverse(g, ig, z, fp, where + ": inverse" + at);
    }
    if (points == 0) ++tally_.guards_without_points;
  }

  /// J with the solved state substituted (when derive could solve s = 0 for one).
  void check_jacobian_on_surface(const RandomGuard& g, const gen::IrGuard& ig, const Vec& z,
                                 const FirstPrinciples& fp, const std::string& what) {
    if (ig.surface_note.empty()) return;
    const std::string name = ig.surface_note.substr(0, ig.surface_note.find(" = "));
    std::size_t k = 0;
    while (k < rm_.states.size() && rm_.states[k] != name) ++k;
    if (k == rm_.states.size()) {
      fail_.push_back(what + ": surface_note names no state: " + ig.surface_note);
      return;
    }
    // z is on S to rounding; the substituted J is J at z* = z − (s(z)/∂_k s) e_k.
    const double dsk = derivative(g.surface, z, k, p_).v;
    const double shift = std::fabs(ir_(ig.surface, z)) / std::fabs(dsk);
    const double h = 1e-6 * std::max(1.0, std::fabs(z[k]));
    Vec zp = z, zm = z;
    zp[k] += h, zm[k] -= h;
    const double dJ = (ir_(ig.hybrid_jacobian, zp) - ir_(ig.hybrid_jacobian, zm)) / (2 * h);
    expect_close("J on s = 0", ir_(ig.hybrid_jacobian_on_surface, z), fp.J,
                 fp.tol + 4 * std::fabs(dJ) * shift + 1e-20 * std::fabs(fp.J),
                 what + " (" + ig.surface_note + ")");
  }

  /// Δ(Δ⁻¹(y)) = y and Δ⁻¹(y) = z for y = Δ(z), with derive's closed-form Δ⁻¹.
  void check_inverse(const RandomGuard& g, const gen::IrGuard& ig, const Vec& z,
                     const FirstPrinciples& fp, const std::string& what) {
    const std::size_t n = z.size();
    Vec w(n);
    for (std::size_t i = 0; i < n; ++i) w[i] = ir_(ig.reset_inverse[i], fp.y);
    for (std::size_t i = 0; i < n; ++i) {
      const Bounded r = value(g.reset[i], w, p_);
      double slope = 0;  // w is rounded to double: |Δ(w_d) − Δ(w)| ≤ Σ_j |∂_jΔ| u|w_j|
      for (std::size_t j = 0; j < n; ++j)
        slope += derivative(g.reset[i], w, j, p_).b.m * kU * std::fabs(w[j]);
      expect_close("inverse: D(Dinv(y))", r.v, fp.y[i], 16 * (r.b.e + slope) + 1e-300,
                   what + ": Δ(Δ⁻¹(y))[" + std::to_string(i) + "] for y = " + show(fp.y) +
                       ", Δ⁻¹(y) = " + show(w));
    }
    if (const auto inv = inverse_norm(fp.D)) {
      double ey = 0, zn = 0;
      for (std::size_t i = 0; i < n; ++i) {
        ey = std::max(ey, fp.y_err[i]);
        zn = std::max(zn, std::fabs(z[i]));
      }
      for (std::size_t i = 0; i < n; ++i)
        expect_close("inverse: Dinv(D(z))", w[i], z[i], 16 * (*inv * ey + kU * zn) + 1e-300,
                     what + ": Δ⁻¹(Δ(z))[" + std::to_string(i) + "]");
    }
  }

  const RandomModel& rm_;
  IrEvaluator ir_;
  ParamValues p_;
  Tally& tally_;
  std::vector<std::string>& fail_;
  std::mt19937_64 rng_;
};

/// The first bit of a refusal's message, as a histogram key.
std::string reason_key(const std::string& bare) {
  for (const char* k : {"never crosses", "identically zero", "zero at every sampled",
                        "collapses its guard", "H.5", "could not be inverted", "limit"})
    if (bare.find(k) != std::string::npos) return k;
  return bare.substr(0, 60);
}

TEST(DeriveRandom, AgreesWithTreeEvaluation) {
  const std::uint64_t count = env_or("HYBGEN_RANDOM_MODELS", 300);
  const std::uint64_t base = env_or("HYBGEN_RANDOM_SEED", 1);
  const bool verbose = env_or("HYBGEN_RANDOM_VERBOSE", 0) != 0;  // print refused models
  Tally t;
  const auto start = std::chrono::steady_clock::now();
  for (std::uint64_t i = 0; i < count; ++i) {
    const std::uint64_t seed = base + i;
    const RandomModel rm = random_model(seed);
    std::vector<std::string> fail;
    ++t.models;
    if (rm.expect_refusal) ++t.expected_refusals;
    const auto t0 = std::chrono::steady_clock::now();
    std::optional<Pipeline> pl;
    std::string refusal;
    try {
      pl.emplace("random.model", rm.text);
    } catch (const gen::ModelError& e) {
      ++t.refused;
      refusal = e.bare_message();
      ++t.refusal_reasons[(rm.expect_refusal ? "(built to be refused) " : "") +
                          reason_key(refusal)];
      const std::string what = e.what();
      const long lines = std::count(rm.text.begin(), rm.text.end(), '\n');
      if (e.loc().line < 1 || e.loc().line > lines || e.loc().col < 1 ||
          what.rfind("random.model:" + std::to_string(e.loc().line) + ":", 0) != 0)
        fail.push_back("refused without a location: " + what);
      if (verbose && !rm.expect_refusal)
        std::printf("[random models] seed %llu refused: %s\n%s",
                    static_cast<unsigned long long>(seed), what.c_str(), rm.text.c_str());
    } catch (const gen::Error& e) {
      fail.push_back(std::string("a hybgen error other than ModelError: ") + e.what());
    } catch (const std::exception& e) {
      fail.push_back(std::string("an exception that is not a hybgen error: ") + e.what());
    } catch (...) {
      fail.push_back("a non-standard exception");
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (seconds > t.slowest) t.slowest = seconds, t.slowest_seed = seed;
    // A model of this size derives in well under a second; 30 s is a hang by any measure
    // (and far below ctest's 900 s timeout, so the seed gets printed).
    if (seconds > 30) fail.push_back("derive took " + num(seconds) + " s");
    if (pl) {
      ++t.accepted;
      if (rm.expect_refusal)
        fail.push_back(
            "derive accepted a reset that collapses its guard (a tangent direction of "
            "the guard is in the kernel of DΔ)");
      else
        ModelChecker(rm, &pl->model, t, fail).run(*pl);
    } else if (!refusal.empty() && !rm.expect_refusal) {
      const auto why = ModelChecker(rm, nullptr, t, fail).contradicts_refusal(refusal);
      if (why && !why->empty())
        fail.push_back("refused (" + refusal + "), but " + *why);
      else if (why)
        ++t.refusals_confirmed;
    }
    if (!fail.empty()) {
      ++t.failing;
      std::string msg = "seed " + std::to_string(seed) +
                        " (reproduce: HYBGEN_RANDOM_SEED=" + std::to_string(seed) +
                        " HYBGEN_RANDOM_MODELS=1)\n";
      for (std::size_t f = 0; f < fail.size() && f < 12; ++f) msg += "  " + fail[f] + "\n";
      if (fail.size() > 12) msg += "  … and " + std::to_string(fail.size() - 12) + " more\n";
      if (t.failing <= 20) msg += "model text:\n" + rm.text;
      ADD_FAILURE() << msg;
    }
  }
  const double total =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "[random models] %ld models (seeds %llu…) in %.1f s: %ld accepted, %ld refused (%ld built "
      "to be refused; of the others %ld with the reason confirmed by the trees), %ld failing\n",
      t.models, static_cast<unsigned long long>(base), total, t.accepted, t.refused,
      t.expected_refusals, t.refusals_confirmed, t.failing);
  std::printf(
      "[random models] %ld guard points, %ld near-grazing skipped, %ld guards without a "
      "point in the domain\n",
      t.guard_points, t.grazing_skipped, t.guards_without_points);
  for (const auto& [k, v] : t.checks)
    std::printf("[random models] check %-20s %8ld, worst |derive - reference| / tolerance %.3g\n",
                k.c_str(), v, t.worst[k]);
  for (const auto& [k, v] : t.inverse_kinds)
    std::printf("[random models] inverse %s: %ld\n", k.c_str(), v);
  for (const auto& [k, v] : t.refusal_reasons)
    std::printf("[random models] refused: %s: %ld\n", k.c_str(), v);
  std::printf("[random models] slowest model: seed %llu, %.2f s\n",
              static_cast<unsigned long long>(t.slowest_seed), t.slowest);
  EXPECT_EQ(t.failing, 0);
  // Not vacuous: most models not built to be refused are accepted, and were checked.
  const long eligible = t.models - t.expected_refusals;
  EXPECT_GE(static_cast<double>(t.accepted), 0.85 * static_cast<double>(eligible))
      << "too many random models were refused";
  if (eligible >= 20) {
    EXPECT_GE(t.checks["J"], t.accepted);
    EXPECT_GT(t.checks["inverse: D(Dinv(y))"], 0);
    EXPECT_GT(t.inverse_kinds["numeric (Newton)"], 0);
    EXPECT_GT(t.inverse_kinds["none (injective on the guard only)"], 0);
  }
}

// ------------------------------------------------------------- the convention

/// J at z from first principles for hand-written trees, and derive's J (general and on S).
struct Convention {
  FirstPrinciples fp;
  double derive_J = 0;
  double derive_J_on_surface = 0;
};

Convention convention_at(const Pipeline& pl, std::size_t gi, const Tree& s,
                         const std::vector<Tree>& reset, const std::vector<Tree>& from,
                         const std::vector<Tree>& to, const Vec& params, const Vec& z) {
  Convention c;
  const ParamValues p(params);
  c.fp = first_principles_jacobian(s, reset, from, to, p, z);
  const IrEvaluator ir(&pl.model);
  c.derive_J = ir(pl.sys.guards.at(gi).hybrid_jacobian, z);
  c.derive_J_on_surface = ir(pl.sys.guards.at(gi).hybrid_jacobian_on_surface, z);
  return c;
}

TEST(DeriveRandom, SignConventionOnShippedModels) {
  // The bouncing ball (models/bouncing_ball.model) with e = 0.8: X = (p/m, −m g) with the
  // shipped m = g = 1, Δ(x, p) = (x, −e p), s = x. In 2-D with v = (0, 1) spanning T S:
  // det[DΔ v, X⁺] / det[v, X⁻] = det[(0, −e), (−e p, −1)] / det[(0, 1), (p, −1)]
  // = (−e²p)/(−p) = e² (README "Derived equations": J = e²).
  {
    std::string text = read_model("bouncing_ball.model");
    text.replace(text.find("parameter e = 1"), 15, "parameter e = 0.8");
    const Pipeline pl("models/bouncing_ball.model", text);
    ASSERT_EQ(pl.model.params.size(), 3u);
    ASSERT_EQ(pl.model.params[0].value_d, 1.0);  // m: the trees below assume m = g = 1
    ASSERT_EQ(pl.model.params[1].value_d, 1.0);  // g
    const std::vector<Tree> flow{state(1), constant(-1, 0)};
    const std::vector<Tree> reset{state(0), neg(mul(parameter(0), state(1)))};
    for (double p : {-0.3, -1.0, -1.7}) {
      const Convention c = convention_at(pl, 0, state(0), reset, flow, flow, {0.8}, {0.0, p});
      EXPECT_NEAR(c.fp.J, 0.64, c.fp.tol);
      EXPECT_NEAR(c.derive_J, c.fp.J, c.fp.tol);
      EXPECT_NEAR(c.derive_J_on_surface, c.fp.J, c.fp.tol);
    }
  }
  // A 1-D thermostat with identity resets: J = X⁺/X⁻, signed. Heating x' = 2 − x switches
  // off at x = 1.5 (X⁻ = 0.5) to cooling x' = −x (X⁺ = −1.5): J = −3; cooling switches on at
  // x = 0.5 (X⁻ = −0.5, X⁺ = 1.5): J = −3. The sign records that the flux reverses; the
  // density transport divides by |J| (docs/methods.md).
  {
    const Pipeline pl("thermostat.model", R"(state x
mode heat { x' = 2 - x }
mode cool { x' = -x }
guard off { from heat to cool; when x = 1.5 increasing; reset identity }
guard on { from cool to heat; when x = 0.5 decreasing; reset identity }
)");
    const std::vector<Tree> heat{sub(constant(2, 0), state(0))}, cool{neg(state(0))};
    const Convention off =
        convention_at(pl, 0, sub(state(0), constant(15, 1)), {state(0)}, heat, cool, {}, {1.5});
    EXPECT_NEAR(off.fp.J, -3.0, off.fp.tol);
    EXPECT_NEAR(off.derive_J, off.fp.J, off.fp.tol);
    const Convention on =
        convention_at(pl, 1, sub(state(0), constant(5, 1)), {state(0)}, cool, heat, {}, {0.5});
    EXPECT_NEAR(on.fp.J, -3.0, on.fp.tol);
    EXPECT_NEAR(on.derive_J, on.fp.J, on.fp.tol);
  }
  // The sawtooth (models/sawtooth.model): x' = 1 + x, x ↦ 0 at x = 1, so
  // J = X(Δx)/X(x) = (1 + 0)/(1 + 1) = 1/2 (the model file's comment).
  {
    const Pipeline pl("models/sawtooth.model", read_model("sawtooth.model"));
    const std::vector<Tree> flow{add(constant(1, 0), state(0))};
    const Convention c = convention_at(pl, 0, sub(state(0), constant(1, 0)), {constant(0, 0)}, flow,
                                       flow, {}, {1.0});
    EXPECT_NEAR(c.fp.J, 0.5, c.fp.tol);
    EXPECT_NEAR(c.derive_J, c.fp.J, c.fp.tol);
  }
}

TEST(DeriveRandom, GeneratorIsDeterministicAndParses) {
  // The same seed gives the same text (so a printed seed reproduces a failure), different
  // seeds give different models, and the printed text parses and checks (it is the language
  // hybgen reads; derive may still refuse a model, which the campaign counts).
  for (std::uint64_t seed : {1ULL, 2ULL, 77ULL, 123456789ULL}) {
    const RandomModel a = random_model(seed), b = random_model(seed);
    EXPECT_EQ(a.text, b.text);
    EXPECT_NE(a.text, random_model(seed + 1).text);
    const gen::SourceText src("random.model", a.text);
    EXPECT_NO_THROW((void)gen::check(gen::parse(src), src)) << a.text;
  }
}

}  // namespace
}  // namespace hybgen::testing
