// Validation of the shipped models/gl2.model (GL2(R) with impacts on SL2(R), paper §4.3,
// reduced by hybgen to 5-D impact Lie–Poisson equations on gl2* × (SL2\GL2)) against references
// written here: the reduced system re-derived by hand from the group data of the model file,
// an independent backward tracer (pointwise) and an RK4 push-forward of the initial density
// (weak form). On the reference side only the Gauss–Legendre nodes (rt::gauss_legendre_rule)
// come from hybgen.
//
// Hand derivation. Basis of gl2: the matrix units E1 = e₁₁, E2 = e₁₂, E3 = e₂₁, E4 = e₂₂ (the
// row-major ζ = [[ζ1, ζ2], [ζ3, ζ4]], ⟨ζ, ξ⟩ = tr(ζᵀξ) = Σ ζ_k ξ_k); the brackets are computed
// below from the matrices (`Algebra`). h(ζ) = ½ Σ ζ_k², so ξ = ∂h/∂ζ = ζ, and
//   ζ' = ad*_ξ ζ,  (ad*_ξ ζ)_k = Σ_j ξ_j ⟨ζ, [E_j, E_k]⟩   (= ξᵀζ − ζξᵀ = ζᵀζ − ζζᵀ)
// (the left-invariant sign, checked on so(3) by test_shipped_so3_rigid_body.cpp). q = det A − 1:
// Jacobi's formula, d det A = det A · tr(A⁻¹ dA), and A⁻¹Ȧ = ξ give q' = (q + 1) tr ζ.
// div X = Σ_k ∂(ad*_ζ ζ)_k/∂ζ_k + ∂q'/∂q = Σ_j ζ_j tr(ad_{E_j}) + tr ζ = tr ζ (gl2 is unimodular;
// computed below from the structure constants). Guard `impact`: s = q, decreasing (∇s = e_q).
// Σ = {det A = 1} = SL2 = ker det is normal, its algebra sl2 = ker tr; the impulse lies in
// Ann(sl2) = span(tr) = span(E1* + E4*), ζ⁺ = ζ + λ(1, 0, 0, 1), and the restitution law
// tr ξ⁺ = −e tr ξ gives λ = −(1 + e) tr ζ/2:
//   Δ(ζ, q) = (ζ − ((1 + e)/2) tr(ζ) I₂, q),  Δ⁻¹: ζ ↦ ζ − ((1 + e)/(2e)) tr(ζ) I₂
// (tr Δ(ζ) = −e tr ζ).
// Hybrid Jacobian from mass conservation: Δ maps the wall q = 0 to itself with ζ-volume scale
// det(I − ((1 + e)/2) vvᵀ) = 1 − (1 + e) = −e (v = (1, 0, 0, 1)), and the normal speed q' = tr ζ
// (at q = 0) to −e tr ζ: J = (−e)(−e) = e². u0 = exp(−2|ζ|² − 4(q − ½)²) on q ≥ 0.
//
// Structure used for the weak form (from the equations, not from hybgen). Write ζ = cI + S +
// aJ₂ with S = [[p, r], [r, −p]] (symmetric traceless), J₂ = [[0, −1], [1, 0]]: then
// ζᵀζ − ζζᵀ = 2a(SJ₂ − J₂S), so c and a are constant, S turns at the rate −4a (s² = p² + r²
// is kept), q' = 2c(q + 1), and a reset maps c ↦ −ec keeping S, a. (a, s) are invariant and
// the weak-form identity holds on each fibre (a, s) = const; u0 = exp(−4(c² + a² + s²) −
// 4(q − ½)²) does not depend on the angle β of S, nor does u(t). The map (c, a, p, r) ↦ ζ has
// |det| = 4, so dζ dq = 4 s dc da ds dβ dq.
//
// Compared:
//  * the brackets from the matrices; the generated kernel against the hand formulas at 200
//    random states of [−1.5, 1.5]⁴ × [−0.5, 2] (flow, divergence, u0, support, guard, reset,
//    inverse, DΔ) and J at 200 points of the guard, relative 1e-12, for e = 1 and e = 0.8.
//  * pointwise, e = 1 and e = 0.8, t = 0.5 and 1 (the model's t_end): u at 1000 random states
//    of [−1, 1]⁴ × [0, 1] against an independent backward tracer (RK4 on −X, step 1e-3,
//    accumulating ∫div X = ∫tr ζ by Simpson's rule; where q reaches 0 the reversed reset and
//    the weight 1/e²). 21 % (t = 0.5) and 35 % (t = 1) of the points have an impact in their
//    history. Measured 5.6e-11 relative; asserted 1e-6. With e = 1 in the characteristics
//    run and 0.8 in the tracer the difference is 16 to 42 (relative).
//  * weak form, e = 1 and 0.8, t = 0.5 and 1: ∫φu for φ = 1, q, q², the difference relative
//    to mass·rms φ, with ONE product rule for both sides (`fibred_rule`): 2 × 2 Gauss nodes in
//    the invariants (a, s) (they cancel exactly from the difference), one angle β, and the
//    midpoint rule in (c, η = ln(q + 1)) on [−2, 2] × [0, 5.6], where η' = 2c: no state with
//    u0 > e⁻⁴⁹ leaves η ≤ 5.6 by t = 1, and q is kept by the reset, so φ∘Φ_t is continuous.
//    The reference pushes u0 at the nodes by RK4 (step 0.01, the impact by bisection on the
//    step, then the hand reset at the last point before it) through the 5-D hand flow; the
//    characteristics (rt::evaluate, rtol 1e-10) are evaluated at the nodes. 28 % of the mass
//    meets the wall by t = 1. Measured: 1.9e-3, 4.8e-4, 1.2e-4 (e = 1) and 3.8e-3, 5.1e-4,
//    2.4e-4 (e = 0.8) on 40², 80², 160² cells (two angles instead of one: 4.8e-4, 4.2e-4),
//    i.e. the midpoint rule's error at the density's jump across the image of q = 0. Asserted
//    < 1e-3 on 80² and a ratio > 1.5 from 40².

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "gl2/gl2.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "support/validation_harness.hpp"

namespace {

namespace rt = hybgen::rt;
// From support/validation_harness.hpp.
using hybgen::testing::validation::close;
/// The generated kernels under test (generated/).
using M = hybgen_model::gl2;
/// The state dimension.
constexpr std::size_t N = 5;
/// A state.
using State = std::array<double, N>;  // (ζ1, ζ2, ζ3, ζ4, q)
/// A 2 × 2 matrix.
using Mat2 = std::array<std::array<double, 2>, 2>;

/// gl2 from the matrix units: C[i][j] = coordinates of [E_i, E_j] (row-major entries).
struct Algebra {
  std::array<std::array<std::array<double, 4>, 4>, 4> C{};  ///< structure constants
  Algebra() {
    std::array<Mat2, 4> e{};
    for (std::size_t k = 0; k < 4; ++k) e[k][k / 2][k % 2] = 1.0;
    for (std::size_t i = 0; i < 4; ++i)
      for (std::size_t j = 0; j < 4; ++j)
        for (std::size_t r = 0; r < 2; ++r)
          for (std::size_t s = 0; s < 2; ++s)
            for (std::size_t k = 0; k < 2; ++k)
              C[i][j][2 * r + s] += e[i][r][k] * e[j][k][s] - e[j][r][k] * e[i][k][s];
  }
};

/// The reduced GL2 impact system, derived by hand (see the header).
struct Hand {
  double e = 1.0;  ///< coefficient of restitution (the model's default)
  Algebra gl2;     ///< the brackets
  /// The parameter vector (e).
  std::array<double, 1> par() const { return {e}; }
  /// ζ' = ad*_ζ ζ, q' = (q + 1) tr ζ.
  State flow(const State& x) const {
    State out{};
    for (std::size_t k = 0; k < 4; ++k)
      for (std::size_t j = 0; j < 4; ++j)
        for (std::size_t i = 0; i < 4; ++i) out[k] += x[j] * x[i] * gl2.C[j][k][i];
    out[4] = (x[4] + 1.0) * (x[0] + x[3]);
    return out;
  }
  /// div X = Σ_k ∂(ad*_ζ ζ)_k/∂ζ_k + ∂q'/∂q = Σ_{j,k} ζ_j C[j][k][k] + Σ_{k,i} ζ_i C[k][k][i]
  /// + tr ζ (the sums vanish: gl2 is unimodular and [E_k, E_k] = 0).
  double divergence(const State& x) const {
    double d = x[0] + x[3];  // ∂q'/∂q
    for (std::size_t k = 0; k < 4; ++k)
      for (std::size_t j = 0; j < 4; ++j) d += x[j] * gl2.C[j][k][k] + x[j] * gl2.C[k][k][j];
    return d;
  }
  /// s = q.
  double surface(const State& x) const { return x[4]; }
  /// Δ.
  State reset(const State& x) const {
    const double l = -(1.0 + e) / 2.0 * (x[0] + x[3]);
    return {x[0] + l, x[1], x[2], x[3] + l, x[4]};
  }
  /// Δ⁻¹ (tr Δ(ζ) = −e tr ζ, so ζ = y + ((1 + e)/2) tr(ζ) I = y − ((1 + e)/(2e)) tr(y) I).
  State reset_inverse(const State& x) const {
    const double l = -(1.0 + e) / (2.0 * e) * (x[0] + x[3]);
    return {x[0] + l, x[1], x[2], x[3] + l, x[4]};
  }
  /// DΔ.
  std::array<double, N * N> reset_jacobian() const {
    std::array<double, N * N> d{};
    for (std::size_t i = 0; i < N; ++i) d[i * N + i] = 1.0;
    for (const std::size_t i : {0u, 3u})
      for (const std::size_t j : {0u, 3u}) d[i * N + j] -= (1.0 + e) / 2.0;
    return d;
  }
  /// J = det(DΔ on the wall) · q'⁺/q'⁻ = (1 − (1 + e)) · q'⁺/q'⁻.
  double hybrid_jacobian(const State& x) const {
    return (1.0 - (1.0 + e)) * flow(reset(x))[4] / flow(x)[4];
  }
  /// q ≥ 0.
  bool in_support(const State& x) const { return x[4] >= 0.0; }
  /// u0.
  double initial(const State& x) const {
    if (!in_support(x)) return 0.0;
    double z2 = 0.0;
    for (std::size_t k = 0; k < 4; ++k) z2 += x[k] * x[k];
    const double b = x[4] - 0.5;
    return std::exp(-2.0 * z2 - 4.0 * b * b);
  }
};

/// One classical RK4 step of the hand flow (dt < 0: backward).
State rk4(const Hand& hand, const State& y, double dt) {
  State k1 = hand.flow(y), tmp{};
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + 0.5 * dt * k1[a];
  const State k2 = hand.flow(tmp);
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + 0.5 * dt * k2[a];
  const State k3 = hand.flow(tmp);
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + dt * k3[a];
  const State k4 = hand.flow(tmp);
  State out{};
  for (std::size_t a = 0; a < N; ++a)
    out[a] = y[a] + dt / 6.0 * (k1[a] + 2.0 * k2[a] + 2.0 * k3[a] + k4[a]);
  return out;
}

/// Pushes x forward over time t by RK4 steps of at most dt; when q falls through 0 within a
/// step, the crossing is located by bisection on the step and the hand reset applied at the
/// last point before it. `resets` counts the resets.
void push(const Hand& hand, State& x, double t, double dt, int& resets) {
  const auto steps = std::max<long>(1, std::lround(std::ceil(t / dt - 1e-9)));
  const double h = t / static_cast<double>(steps);
  for (long n = 0; n < steps; ++n) {
    double left = h;
    for (int hop = 0; hop < 8 && left > 0.0; ++hop) {
      const State y = rk4(hand, x, left);
      if (!(x[4] > 0.0 && y[4] <= 0.0)) {
        x = y;
        left = 0.0;
        continue;
      }
      double a = 0.0, b = left;
      for (int it = 0; it < 60; ++it) {
        const double c = 0.5 * (a + b);
        (rk4(hand, x, c)[4] > 0.0 ? a : b) = c;
      }
      x = hand.reset(rk4(hand, x, a));
      ++resets;
      left -= a;
    }
  }
}

/// u(t, y) by an independent backward tracer: RK4 on y' = −X (step h) with I = ∫div X; where
/// the backward path reaches q = 0 (forward: it left the wall after an impact) the reversed
/// reset Δ⁻¹ and the weight 1/e²; the straight continuation leaves the support.
double backward_density(const Hand& hand, State x, double t, double h, int& resets) {
  resets = 0;
  double weight = 1.0, integral = 0.0;
  const auto steps = std::max<long>(1, std::lround(std::ceil(t / h - 1e-9)));
  const double dt = t / static_cast<double>(steps);
  // The divergence integral by Simpson's rule on each (sub)step.
  auto simpson = [&](const State& y0, double len) {
    return len / 6.0 *
           (hand.divergence(y0) + 4.0 * hand.divergence(rk4(hand, y0, -0.5 * len)) +
            hand.divergence(rk4(hand, y0, -len)));
  };
  for (long n = 0; n < steps; ++n) {
    double left = dt;
    for (int hop = 0; hop < 8 && left > 0.0; ++hop) {
      const State y = rk4(hand, x, -left);
      if (!(y[4] <= 0.0)) {
        integral += simpson(x, left);
        x = y;
        left = 0.0;
        continue;
      }
      double a = 0.0, b = left;
      for (int it = 0; it < 60; ++it) {
        const double c = 0.5 * (a + b);
        (rk4(hand, x, -c)[4] > 0.0 ? a : b) = c;
      }
      integral += simpson(x, a);
      x = hand.reset_inverse(rk4(hand, x, -a));
      weight /= hand.e * hand.e;
      ++resets;
      left -= a;
    }
  }
  return weight * std::exp(-integral) * hand.initial(x);
}

// ---------------------------------------------------------------------------------------------

TEST(ShippedGl2, AlgebraFromTheMatrices) {
  // ad*_ξ ζ = ξᵀζ − ζξᵀ for the pairing tr(ζᵀξ), at a random ξ, ζ.
  const Algebra g;
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::array<double, 4> xi{}, zeta{};
  for (auto& v : xi) v = u(rng);
  for (auto& v : zeta) v = u(rng);
  std::array<double, 4> ad{};
  for (std::size_t k = 0; k < 4; ++k)
    for (std::size_t j = 0; j < 4; ++j)
      for (std::size_t i = 0; i < 4; ++i) ad[k] += xi[j] * zeta[i] * g.C[j][k][i];
  for (std::size_t r = 0; r < 2; ++r)
    for (std::size_t s = 0; s < 2; ++s) {
      double want = 0.0;
      for (std::size_t k = 0; k < 2; ++k)
        want += xi[2 * k + r] * zeta[2 * k + s] - zeta[2 * r + k] * xi[2 * s + k];
      EXPECT_NEAR(ad[2 * r + s], want, 1e-15) << r << s;
    }
}

TEST(ShippedGl2, KernelMatchesTheHandDerivation) {
  Hand hand;
  EXPECT_EQ(M::param_defaults[0], hand.e);
  ASSERT_EQ(M::n_state, static_cast<int>(N));
  ASSERT_EQ(M::n_mode, 1);
  ASSERT_EQ(M::n_guard, 1);
  EXPECT_EQ(M::guards[0].from, 0);
  EXPECT_EQ(M::guards[0].to, 0);
  EXPECT_EQ(M::guards[0].direction, -1);
  EXPECT_TRUE(M::guards[0].has_inverse);
  auto same = [](const double* got, const auto& want, const char* what) {
    for (std::size_t k = 0; k < want.size(); ++k)
      EXPECT_TRUE(close(got[k], want[k])) << what << ", component " << k;
  };
  std::mt19937_64 rng(16008);
  std::uniform_real_distribution<double> z(-1.5, 1.5), q(-0.5, 2.0);
  for (const double e : {1.0, 0.8}) {
    hand.e = e;
    const auto par = hand.par();
    for (int n = 0; n < 200; ++n) {
      const State x{z(rng), z(rng), z(rng), z(rng), q(rng)};
      State out{};
      std::array<double, N * N> jac{};
      M::flow(0, x.data(), par.data(), out.data());
      same(out.data(), hand.flow(x), "flow");
      EXPECT_TRUE(close(M::divergence(0, x.data(), par.data()), hand.divergence(x)));
      EXPECT_TRUE(close(M::initial_density(0, x.data(), par.data()), hand.initial(x)));
      EXPECT_EQ(M::in_support(x.data(), par.data()), hand.in_support(x));
      EXPECT_TRUE(close(M::guard_surface(0, x.data(), par.data()), hand.surface(x)));
      M::guard_gradient(0, x.data(), par.data(), out.data());
      same(out.data(), State{0.0, 0.0, 0.0, 0.0, 1.0}, "gradient");
      M::reset(0, x.data(), par.data(), out.data());
      same(out.data(), hand.reset(x), "reset");
      M::reset_inverse(0, x.data(), par.data(), out.data());
      same(out.data(), hand.reset_inverse(x), "inverse reset");
      M::reset_jacobian(0, x.data(), par.data(), jac.data());
      same(jac.data(), hand.reset_jacobian(), "DΔ");
      const State w{z(rng), z(rng), z(rng), z(rng), 0.0};
      EXPECT_TRUE(close(M::hybrid_jacobian(0, w.data(), par.data()), hand.hybrid_jacobian(w)));
    }
  }
}

TEST(ShippedGl2, CharacteristicsMatchABackwardTracerPointwise) {
  Hand hand;
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> z(-1.0, 1.0), q(0.0, 1.0);
  std::vector<State> pts;
  for (int i = 0; i < 1000; ++i) pts.push_back({z(rng), z(rng), z(rng), z(rng), q(rng)});
  const std::vector<double> times{0.5, 1.0};
  for (const double e : {1.0, 0.8}) {
    hand.e = e;
    const auto par = hand.par();
    rt::CharacteristicsOptions co;
    co.ode.rtol = 1e-11;
    co.ode.atol = 1e-13;
    const auto sol = rt::evaluate<M>(pts, times, par.data(), co);
    ASSERT_TRUE(sol.ok()) << rt::describe<M>(sol.failure);
    for (std::size_t k = 0; k < times.size(); ++k) {
      double worst = 0.0;
      int reset = 0;
      for (std::size_t i = 0; i < pts.size(); ++i) {
        int n = 0;
        const double want = backward_density(hand, pts[i], times[k], 1e-3, n);
        const double got = sol.at(k, 0, i);
        const double err = std::fabs(got - want) / std::max(want, 1e-3);
        worst = std::max(worst, err);
        EXPECT_LT(err, 1e-6) << "e = " << e << ", t = " << times[k] << ", point " << i << ": "
                             << got << " vs " << want << " (" << n << " backward resets)";
        reset += n > 0;
      }
      std::printf(
          "[ shipped ] e = %.1f, t = %.1f: %d of %zu points have an impact in their "
          "history; worst relative difference %.2e\n",
          e, times[k], reset, pts.size(), worst);
      EXPECT_GT(reset, 100);
    }
  }
}

/// A product rule shared by both sides of the weak form, in (a, s, β, c, η), η = ln(q + 1):
/// 2 × 2 Gauss nodes in the invariants a ∈ [−1, 1], s ∈ [0, 1.5], `angles` equally spaced β,
/// and the midpoint rule on `cells` × `cells` cells of (c, η) ∈ [−2, 2] × [0, 5.6]; ζ = cI + S +
/// aJ₂, S = s[[cos β, sin β], [sin β, −cos β]], weight 4 s e^η da ds dβ dc dη. η' = 2c, so no
/// state of the rule with u0 > e⁻⁴⁹ (q0 ≤ 4) leaves η ≤ 5.6 by t = 1: Z = {η ≤ 5.6} keeps the
/// mass, and φ ∈ {1, q, q²} (q is kept by the reset) makes φ∘Φ_t continuous.
struct Rule {
  std::vector<State> x;   ///< nodes
  std::vector<double> w;  ///< weights
};

/// The rule described above.
Rule fibred_rule(int angles, int cells) {
  const rt::AxisRule ra = rt::gauss_legendre_rule(-1.0, 1.0, 1, 2);
  const rt::AxisRule rs = rt::gauss_legendre_rule(0.0, 1.5, 1, 2);
  const double db = 2.0 * std::numbers::pi / angles, dc = 4.0 / cells, de = 5.6 / cells;
  Rule rule;
  for (std::size_t i = 0; i < ra.nodes.size(); ++i)
    for (std::size_t j = 0; j < rs.nodes.size(); ++j)
      for (int k = 0; k < angles; ++k)
        for (int l = 0; l < cells; ++l)
          for (int n = 0; n < cells; ++n) {
            const double a = ra.nodes[i], sv = rs.nodes[j], beta = (k + 0.25) * db;
            const double c = -2.0 + (l + 0.5) * dc, eta = (n + 0.5) * de;
            const double p = sv * std::cos(beta), r = sv * std::sin(beta);
            rule.x.push_back({c + p, r - a, r + a, c - p, std::exp(eta) - 1.0});
            rule.w.push_back(4.0 * sv * ra.weights[i] * rs.weights[j] * db * dc * de *
                             std::exp(eta));
          }
  return rule;
}

/// ∫φ u for φ = 1, q, q² at each time, and ∫φ² u: [time][k].
struct Moments {
  std::vector<std::array<double, 3>> first;   ///< ∫φ u
  std::vector<std::array<double, 3>> second;  ///< ∫φ² u
};

/// Adds w·φ(q) to the first moments at time k, and w·φ(q)² to the second.
void add(Moments& m, std::size_t k, double w, double q) {
  const std::array<double, 3> p{1.0, q, q * q};
  for (std::size_t i = 0; i < 3; ++i) {
    m.first[k][i] += w * p[i];
    m.second[k][i] += w * p[i] * p[i];
  }
}

/// The weak-form difference at restitution e on `fibred_rule(angles, cells)`, t = 0.5 and 1,
/// relative to mass·rms φ; `share` gets the share of the mass that has met the wall by t = 1.
double weak_form_difference(double e, int angles, int cells, double& share) {
  Hand hand;
  hand.e = e;
  const Rule rule = fibred_rule(angles, cells);
  const std::vector<double> times{0.5, 1.0};
  Moments ref{std::vector<std::array<double, 3>>(2), std::vector<std::array<double, 3>>(2)};
  double crossed = 0.0, total = 0.0;
#pragma omp parallel
  {
    Moments local = ref;
    double lc = 0.0, lt = 0.0;
#pragma omp for schedule(dynamic, 256)
    for (std::size_t j = 0; j < rule.x.size(); ++j) {
      const double w = rule.w[j] * hand.initial(rule.x[j]);
      if (!(w > 0.0)) continue;
      State x = rule.x[j];
      int resets = 0;
      double clock = 0.0;
      for (std::size_t k = 0; k < times.size(); ++k) {
        push(hand, x, times[k] - clock, 0.01, resets);
        clock = times[k];
        add(local, k, w, x[4]);
      }
      lt += w;
      if (resets > 0) lc += w;
    }
#pragma omp critical(test_shipped_gl2)
    {
      for (std::size_t k = 0; k < 2; ++k)
        for (std::size_t i = 0; i < 3; ++i) {
          ref.first[k][i] += local.first[k][i];
          ref.second[k][i] += local.second[k][i];
        }
      crossed += lc;
      total += lt;
    }
  }
  share = crossed / total;
  const auto par = hand.par();
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const auto sol = rt::evaluate<M>(rule.x, times, par.data(), co);
  EXPECT_TRUE(sol.ok()) << rt::describe<M>(sol.failure);
  Moments got = ref;
  for (auto& v : got.first) v = {};
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t i = 0; i < rule.x.size(); ++i)
      add(got, k, sol.at(k, 0, i) * rule.w[i], rule.x[i][4]);
  double worst = 0.0;
  const char* names[3] = {"1", "q", "q^2"};
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double mass = ref.first[k][0];
    for (std::size_t i = 0; i < 3; ++i) {
      const double d = std::fabs(got.first[k][i] - ref.first[k][i]) /
                       (mass * std::sqrt(ref.second[k][i] / mass));
      worst = std::max(worst, d);
      std::printf("[ shipped ] e = %.1f, t = %.1f, phi %-3s: %.9f (reference %.9f) diff %.2e\n", e,
                  times[k], names[i], got.first[k][i], ref.first[k][i], d);
    }
  }
  std::printf("[ shipped ] e = %.1f, %zu nodes, %.3f of the mass has met the wall: worst %.3e\n", e,
              rule.x.size(), share, worst);
  return worst;
}

TEST(ShippedGl2, CharacteristicsMatchTheRk4PushForwardInWeakForm) {
  double share = 0.0;
  for (const double e : {1.0, 0.8}) {
    const double coarse = weak_form_difference(e, 1, 40, share);
    const double fine = weak_form_difference(e, 1, 80, share);
    EXPECT_LT(fine, 1e-3) << e;
    EXPECT_GT(coarse / fine, 1.5) << e;
    EXPECT_GT(share, 0.25) << e;
  }
}

}  // namespace
