// Validation of the shipped models/chaplygin.model (the Chaplygin sleigh with angle impacts,
// paper §4.2, derived by hybgen from SE(2) data with a knife-edge constraint and reduced to
// 3-D) against references written here: the reduced system re-derived by hand from the group
// data of the model file, and an RK4 push-forward of the initial density compared in weak
// form. On the reference side only the Gauss–Legendre nodes (rt::gauss_legendre_rule) come
// from hybgen.
//
// Hand derivation. SE(2) ∋ g(x, y, th) = [[cos th, −sin th, x], [sin th, cos th, y], [0, 0, 1]];
// E_x = e₁₃, E_y = e₂₃, E_th = e₂₁ − e₁₂ (∂g/∂c at 0); their commutators, computed below from
// the matrices (`Algebra`), are [E_th, E_x] = E_y, [E_th, E_y] = −E_x, [E_x, E_y] = 0. Body
// velocity ξ = v E_x + w E_y + ω E_th, ℓ(ξ) = ½ ξᵀ𝕀ξ with 𝕀 = [[m, 0, 0], [0, m, m a],
// [0, m a, I + m a²]], constraint w = 0 (⟨E_y*, ξ⟩ = 0). Euler–Poincaré–Suslov: μ = 𝕀ξ obeys
//   μ' = ad*_ξ μ + λ E_y*,   (ad*_ξ μ)_k = Σ_j ξ_j ⟨μ, [E_j, E_k]⟩
// (the left-invariant sign, checked on so(3) by test_shipped_so3_rigid_body.cpp); the
// multiplier λ enters the E_y* row only, so the E_x* and E_th* rows with ξ = (v, 0, ω) give two
// equations for (v', ω') (`Hand::flow` solves them):
//   m v' = ω μ_y = m a ω²,   (I + m a²) ω' = −v μ_y = −m a v ω,
// i.e. v' = a ω², ω' = −m a v ω/(I + m a²); θ = th has θ' = ξ_th = ω (ġ = gξ and th is the
// rotation angle). div X = ∂ω'/∂ω = −m a v/(I + m a²).
// Walls θ = ±θ0 (guards `turn_right`: s = θ − θ0 increasing, `turn_left`: s = θ + θ0
// decreasing; ∇s = e_θ), cosets of the normal subgroup ℝ² = ker th. The impulse lies in
// span(E_th*) (the annihilator of the translations) plus the constraint's E_y*; so μ_x is kept,
// the constraint w⁺ = 0 holds, and the elastic law gives ω⁺ = −ω: (v, ω, θ) ↦ (v, −ω, θ)
// (v⁺ = μ_x/m = v), DΔ = diag(1, −1, 1) = DΔ⁻¹. Hybrid Jacobian from mass conservation: Δ
// maps the wall to itself with (v, ω)-area scale |−1| = 1 and orientation −1, and the normal
// speed θ' = ω to −ω: J = (−1)(−ω/ω) = 1. u0 = exp(−v² − ω² − θ²) on |θ| ≤ θ0.
//
// Weak form. The energy E = ½ m v² + ½ (I + m a²) ω² is kept by the flow (v v' m + (I + m a²)
// ω ω' = 0) and by the reset. In the coordinates v = r cos ψ/√m, ω = r sin ψ/√(I + m a²)
// (E = r²/2; dv dω = r dr dψ/√(m(I + m a²))) the region Z = {r ≤ r_max, |θ| ≤ θ0} keeps its mass
// and ∫φ u(t) = ∫φ∘Φ_t u0 holds on each fibre r = const. Both sides use ONE product rule:
// 3 Gauss nodes in r on [0, 2] (any rule: it cancels exactly from the difference), equally
// spaced ψ and Gauss–Legendre in θ. The test functions φ ∈ {1, v, θ, v², vθ, θ²} leave out
// ω, which the reset flips, so φ∘Φ_t is continuous in the initial state; and u(t) is continuous
// (elastic walls map the support's edge to itself).
//
// Compared:
//  * the brackets from the matrices; the generated kernel against the hand formulas at 200
//    random states of [−1.5, 1.5]² × [−1.2, 1.2] (flow, divergence, u0, support, both guards,
//    resets, inverses, DΔ) and J at 200 points of each wall, relative 1e-12;
//  * weak form at t = 1, 2 (the model's t_end): the reference pushes u0 at the nodes by RK4
//    (step 0.02, walls located by bisection on the step, then the hand reset at the last point
//    before the wall), the characteristics (rt::evaluate, rtol 1e-10) are evaluated at the
//    same nodes; the difference relative to mass·rms φ (rms from the reference). Half of the
//    mass meets a wall by t = 2. Measured 6.2e-4, 8.2e-5, 2.8e-6, 1.3e-6 on 48 × 24, 96 × 48,
//    192 × 96, 384 × 192 nodes in (ψ, θ): it converges to 0. Asserted < 3e-4 on 96 × 48 and a
//    ratio > 3 from 48 × 24. With a = 0.51 in the characteristics run alone: 7.1e-3.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "chaplygin/chaplygin.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "support/validation_harness.hpp"

namespace {

namespace rt = hybgen::rt;
// From support/validation_harness.hpp.
using hybgen::testing::validation::close;
using hybgen::testing::validation::HandGuard;
/// The generated kernels under test (generated/).
using M = hybgen_model::chaplygin;
/// The state dimension.
constexpr std::size_t N = 3;
/// A state.
using State = std::array<double, N>;  // (v, ω, θ)
/// A 3 × 3 matrix.
using Mat3 = std::array<std::array<double, 3>, 3>;

/// se(2) from the matrices of the model file: C[i][j] = coordinates of [E_i, E_j] in
/// (E_x, E_y, E_th), read off the entries (1,3), (2,3), (2,1) of the commutator.
struct Algebra {
  std::array<std::array<std::array<double, 3>, 3>, 3> C{};  ///< structure constants
  Algebra() {
    std::array<Mat3, 3> e{};
    e[0][0][2] = 1.0;  // ∂g/∂x
    e[1][1][2] = 1.0;  // ∂g/∂y
    e[2][1][0] = 1.0;  // ∂g/∂th = [[0, −1, 0], [1, 0, 0], [0, 0, 0]] at th = 0
    e[2][0][1] = -1.0;
    for (std::size_t i = 0; i < 3; ++i)
      for (std::size_t j = 0; j < 3; ++j) {
        Mat3 c{};
        for (std::size_t r = 0; r < 3; ++r)
          for (std::size_t s = 0; s < 3; ++s)
            for (std::size_t k = 0; k < 3; ++k)
              c[r][s] += e[i][r][k] * e[j][k][s] - e[j][r][k] * e[i][k][s];
        C[i][j] = {c[0][2], c[1][2], c[1][0]};
      }
  }
};

/// The Chaplygin sleigh with angle impacts, derived by hand (see the header).
struct Hand {
  double m = 1.0, I = 1.0, a = 0.5, theta0 = 1.0;  ///< the model's defaults
  static constexpr int n_mode = 1;                 ///< flow
  /// turn_right: θ = θ0 increasing; turn_left: θ = −θ0 decreasing.
  static constexpr std::array<HandGuard, 2> guards{HandGuard{0, 0, +1}, HandGuard{0, 0, -1}};
  Algebra se2;  ///< the brackets
  /// The parameter vector (m, I, a, θ0).
  std::array<double, 4> par() const { return {m, I, a, theta0}; }
  /// 𝕀.
  Mat3 inertia() const { return {{{m, 0.0, 0.0}, {0.0, m, m * a}, {0.0, m * a, I + m * a * a}}}; }
  /// The E_x* and E_th* rows of μ' = ad*_ξ μ + λE_y* with ξ = (v, 0, ω), solved for (v', ω');
  /// θ' = ω.
  State flow(int, const State& x) const {
    const Mat3 in = inertia();
    const std::array<double, 3> xi{x[0], 0.0, x[1]};
    std::array<double, 3> mu{}, ad{};
    for (std::size_t i = 0; i < 3; ++i)
      for (std::size_t j = 0; j < 3; ++j) mu[i] += in[i][j] * xi[j];
    for (std::size_t k = 0; k < 3; ++k)
      for (std::size_t j = 0; j < 3; ++j)
        for (std::size_t i = 0; i < 3; ++i) ad[k] += xi[j] * mu[i] * se2.C[j][k][i];
    // μ_x' = 𝕀_xx v' + 𝕀_xth ω' = ad_x,  μ_th' = 𝕀_thx v' + 𝕀_thth ω' = ad_th.
    const double a11 = in[0][0], a12 = in[0][2], a21 = in[2][0], a22 = in[2][2];
    const double det = a11 * a22 - a12 * a21;
    return {(a22 * ad[0] - a12 * ad[2]) / det, (a11 * ad[2] - a21 * ad[0]) / det, x[1]};
  }
  /// div X = ∂v'/∂v + ∂ω'/∂ω + ∂θ'/∂θ = −m a v/(I + m a²).
  double divergence(int, const State& x) const { return -m * a * x[0] / (I + m * a * a); }
  /// s = θ ∓ θ0.
  double surface(int g, const State& x) const { return g == 0 ? x[2] - theta0 : x[2] + theta0; }
  /// ∇s = e_θ.
  State gradient(int, const State&) const { return {0.0, 0.0, 1.0}; }
  /// ω⁺ = −ω; v⁺ from μ_x⁺ = μ_x: v⁺ = v + (𝕀_xth/𝕀_xx)(ω − ω⁺) = v.
  State reset(int, const State& x) const {
    const Mat3 in = inertia();
    return {x[0] + in[0][2] / in[0][0] * (x[1] + x[1]), -x[1], x[2]};
  }
  /// Δ⁻¹ = Δ.
  State reset_inverse(int g, const State& x) const { return reset(g, x); }
  /// DΔ = diag(1, −1, 1).
  std::array<double, N * N> reset_jacobian(int, const State&) const {
    return {1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0};
  }
  /// J = det(DΔ on the wall) · θ'⁺/θ'⁻.
  double hybrid_jacobian(int g, const State& x) const {
    return -1.0 * flow(0, reset(g, x))[2] / flow(0, x)[2];
  }
  /// |θ| ≤ θ0.
  bool in_support(const State& x) const { return x[2] >= -theta0 && x[2] <= theta0; }
  /// u0.
  double initial(int, const State& x) const {
    return in_support(x) ? std::exp(-x[0] * x[0] - x[1] * x[1] - x[2] * x[2]) : 0.0;
  }
};

// ---------------------------------------------------------------------------------------------
// The weak-form reference: the hand model's RK4 push-forward of a quadrature of u0.

/// One classical RK4 step of the hand model.
State rk4(const Hand& hand, const State& y, double dt) {
  State k1 = hand.flow(0, y), tmp{};
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + 0.5 * dt * k1[a];
  const State k2 = hand.flow(0, tmp);
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + 0.5 * dt * k2[a];
  const State k3 = hand.flow(0, tmp);
  for (std::size_t a = 0; a < N; ++a) tmp[a] = y[a] + dt * k3[a];
  const State k4 = hand.flow(0, tmp);
  State out{};
  for (std::size_t a = 0; a < N; ++a)
    out[a] = y[a] + dt / 6.0 * (k1[a] + 2.0 * k2[a] + 2.0 * k3[a] + k4[a]);
  return out;
}

/// Pushes x forward over time t by RK4 steps of at most dt; a guard whose s_g changes sign in
/// its direction over a (sub)step fires at the crossing located by bisection on the step and
/// the hand reset is applied, at the last bisection point before the crossing (so that a flow
/// turning straight back into the wall meets it again). `resets` counts the resets. Returns
/// false if 64 resets within one step did not exhaust it (a Zeno point; none with these
/// elastic walls, asserted).
bool push(const Hand& hand, State& x, double t, double dt, int& resets) {
  const auto steps = std::max<long>(1, std::lround(std::ceil(t / dt - 1e-9)));
  const double h = t / static_cast<double>(steps);
  for (long n = 0; n < steps; ++n) {
    double left = h;
    for (int hop = 0; hop < 64 && left > 0.0; ++hop) {
      const State y = rk4(hand, x, left);
      int fired = -1;
      double tau = left, before = 0.0;
      for (std::size_t g = 0; g < Hand::guards.size(); ++g) {
        const int gi = static_cast<int>(g), dir = Hand::guards[g].dir;
        const double s0 = hand.surface(gi, x), s1 = hand.surface(gi, y);
        if (!(dir > 0 ? (s0 < 0.0 && s1 >= 0.0) : (s0 > 0.0 && s1 <= 0.0))) continue;
        double a = 0.0, b = left;
        for (int it = 0; it < 60; ++it) {
          const double c = 0.5 * (a + b);
          const double sc = hand.surface(gi, rk4(hand, x, c));
          (dir > 0 ? sc < 0.0 : sc > 0.0) ? a = c : b = c;
        }
        if (b < tau) tau = b, before = a, fired = gi;
      }
      if (fired < 0) {
        x = y;
        left = 0.0;
      } else {
        x = hand.reset(fired, rk4(hand, x, before));
        ++resets;
        left -= tau;
      }
    }
    if (left > 0.0) return false;
  }
  return true;
}

/// The region Z of the header: |θ| ≤ θ0 (the energy is kept, so r needs no test).
bool in_cylinder(const State& x) {
  return x[2] >= -1.0 && x[2] <= 1.0;
}

/// Test functions: 1, v, θ, v², vθ, θ² (no ω).
constexpr std::size_t kPhi = 6;
/// The test functions at x.
std::array<double, kPhi> phis(const State& x) {
  const double v = x[0], th = x[2];
  return {1.0, v, th, v * v, v * th, th * th};
}

/// The names of the test functions.
const char* const kPhiNames[kPhi] = {"1", "v", "theta", "v^2", "v*theta", "theta^2"};

/// ∫φ_k u over Z per output time, and ∫φ_k² u (for the scale of φ_k): [time][k].
struct Moments {
  std::vector<std::array<double, kPhi>> first;   ///< ∫φ u
  std::vector<std::array<double, kPhi>> second;  ///< ∫φ² u
};

/// A product rule over Z in (r, ψ, θ), v = r cos ψ/√m, ω = r sin ψ/√(I + m a²), weight
/// r/√(m(I + m a²)) dr dψ dθ: `r_nodes` Gauss nodes on [0, 2], `angles` equally spaced ψ, and
/// `theta_panels` panels of 4 Gauss nodes on [−θ0, θ0].
struct Rule {
  std::vector<State> x;   ///< nodes
  std::vector<double> w;  ///< weights
};

/// The rule described above.
Rule energy_rule(const Hand& hand, int r_nodes, int angles, int theta_panels) {
  const rt::AxisRule rr = rt::gauss_legendre_rule(0.0, 2.0, 1, r_nodes);
  const rt::AxisRule rt_ = rt::gauss_legendre_rule(-hand.theta0, hand.theta0, theta_panels, 4);
  const double sm = std::sqrt(hand.m), si = std::sqrt(hand.I + hand.m * hand.a * hand.a);
  const double dpsi = 2.0 * std::numbers::pi / angles;
  Rule rule;
  for (std::size_t i = 0; i < rr.nodes.size(); ++i)
    for (int j = 0; j < angles; ++j)
      for (std::size_t k = 0; k < rt_.nodes.size(); ++k) {
        const double r = rr.nodes[i], psi = (j + 0.5) * dpsi;
        rule.x.push_back({r * std::cos(psi) / sm, r * std::sin(psi) / si, rt_.nodes[k]});
        rule.w.push_back(r / (sm * si) * rr.weights[i] * dpsi * rt_.weights[k]);
      }
  return rule;
}

/// The reference at `times` (ascending, > 0): u0 at the nodes of `rule`, each node pushed by
/// RK4 (step dt); `crossed` gets the share of the mass at the last time that has met a wall,
/// `zeno` the share that has reached a Zeno point (an atom, which the density leaves out).
Moments reference(const Hand& hand, const std::vector<double>& times, const Rule& rule, double dt,
                  double& crossed, double& zeno) {
  Moments mom{std::vector<std::array<double, kPhi>>(times.size()),
              std::vector<std::array<double, kPhi>>(times.size())};
  double mass0 = 0.0, mass_last = 0.0, crossed_last = 0.0, zeno_last = 0.0;
#pragma omp parallel
  {
    Moments local = mom;
    double l0 = 0.0, lm = 0.0, lc = 0.0, lz = 0.0;
#pragma omp for schedule(dynamic, 256)
    for (std::size_t j = 0; j < rule.x.size(); ++j) {
      State x = rule.x[j];
      const double w = rule.w[j] * hand.initial(0, x);
      l0 += w;
      int resets = 0;
      double clock = 0.0;
      for (std::size_t k = 0; k < times.size(); ++k) {
        if (!push(hand, x, times[k] - clock, dt, resets)) {
          lz += w;
          break;
        }
        clock = times[k];
        if (!in_cylinder(x)) continue;
        const auto p = phis(x);
        for (std::size_t q = 0; q < kPhi; ++q) {
          local.first[k][q] += w * p[q];
          local.second[k][q] += w * p[q] * p[q];
        }
        if (k + 1 == times.size()) {
          lm += w;
          if (resets > 0) lc += w;
        }
      }
    }
#pragma omp critical(test_shipped_chaplygin)
    {
      for (std::size_t k = 0; k < times.size(); ++k)
        for (std::size_t q = 0; q < kPhi; ++q) {
          mom.first[k][q] += local.first[k][q];
          mom.second[k][q] += local.second[k][q];
        }
      mass0 += l0;
      mass_last += lm;
      crossed_last += lc;
      zeno_last += lz;
    }
  }
  crossed = crossed_last / mass_last;
  zeno = zeno_last / mass0;
  return mom;
}

/// The same moments of the characteristics solution of the generated model at `times`, by the
/// same rule.
Moments characteristics(const std::vector<double>& times, const double* par, const Rule& rule) {
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const auto sol = rt::evaluate<M>(rule.x, times, par, co);
  EXPECT_TRUE(sol.ok()) << rt::describe<M>(sol.failure);
  Moments mom{std::vector<std::array<double, kPhi>>(times.size()),
              std::vector<std::array<double, kPhi>>(times.size())};
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t i = 0; i < rule.x.size(); ++i) {
      const double u = sol.at(k, 0, i) * rule.w[i];
      const auto p = phis(rule.x[i]);
      for (std::size_t q = 0; q < kPhi; ++q) {
        mom.first[k][q] += u * p[q];
        mom.second[k][q] += u * p[q] * p[q];
      }
    }
  return mom;
}

/// Worst |got − ref| / (mass · rms φ) over times and test functions (mass and rms φ =
/// √(∫φ²u/mass) from the reference: |∫φu| ≤ mass · rms φ), printed.
double compare(const Moments& got, const Moments& ref, const std::vector<double>& times) {
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double mass = ref.first[k][0];
    for (std::size_t q = 0; q < kPhi; ++q) {
      const double scale = mass * std::sqrt(ref.second[k][q] / mass);
      const double e = std::fabs(got.first[k][q] - ref.first[k][q]) / scale;
      worst = std::max(worst, e);
      std::printf("[ shipped ] t = %.2f %-14s: %.9f (reference %.9f) diff %.2e\n", times[k],
                  kPhiNames[q], got.first[k][q], ref.first[k][q], e);
    }
  }
  std::printf("[ shipped ] worst relative difference %.3e\n", worst);
  return worst;
}

// ---------------------------------------------------------------------------------------------

// ---------------------------------------------------------------------------------------------

TEST(ShippedChaplygin, AlgebraFromTheMatrices) {
  const Algebra se2;
  // [E_th, E_x] = E_y, [E_th, E_y] = −E_x, [E_x, E_y] = 0, and antisymmetry.
  std::array<std::array<std::array<double, 3>, 3>, 3> want{};
  want[2][0] = {0.0, 1.0, 0.0};
  want[0][2] = {0.0, -1.0, 0.0};
  want[2][1] = {-1.0, 0.0, 0.0};
  want[1][2] = {1.0, 0.0, 0.0};
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j)
      for (std::size_t k = 0; k < 3; ++k) EXPECT_EQ(se2.C[i][j][k], want[i][j][k]) << i << j << k;
  // The hand flow is the paper's: v' = aω², ω' = −m a v ω/(I + m a²), θ' = ω.
  const Hand hand;
  const State x{0.3, -0.7, 0.2}, f = hand.flow(0, x);
  EXPECT_NEAR(f[0], 0.5 * 0.49, 1e-15);
  EXPECT_NEAR(f[1], -0.5 * 0.3 * -0.7 / 1.25, 1e-15);
  EXPECT_EQ(f[2], -0.7);
}

TEST(ShippedChaplygin, KernelMatchesTheHandDerivation) {
  const Hand hand;
  const auto par = hand.par();
  for (std::size_t p = 0; p < par.size(); ++p)
    EXPECT_EQ(M::param_defaults[p], par[p]) << M::param_names[p];
  ASSERT_EQ(M::n_state, static_cast<int>(N));
  ASSERT_EQ(M::n_mode, Hand::n_mode);
  ASSERT_EQ(M::n_guard, static_cast<int>(Hand::guards.size()));
  for (std::size_t g = 0; g < Hand::guards.size(); ++g) {
    EXPECT_EQ(M::guards[g].from, Hand::guards[g].from) << M::guard_names[g];
    EXPECT_EQ(M::guards[g].to, Hand::guards[g].to) << M::guard_names[g];
    EXPECT_EQ(M::guards[g].direction, Hand::guards[g].dir) << M::guard_names[g];
    EXPECT_TRUE(M::guards[g].has_inverse) << M::guard_names[g];
  }
  auto same = [](const double* got, const auto& want, const char* what, int i) {
    for (std::size_t k = 0; k < want.size(); ++k)
      EXPECT_TRUE(close(got[k], want[k])) << what << " " << i << ", component " << k;
  };
  std::mt19937_64 rng(16008);
  std::uniform_real_distribution<double> u(-1.5, 1.5), th(-1.2, 1.2);
  for (int n = 0; n < 200; ++n) {
    const State x{u(rng), u(rng), th(rng)};
    State out{};
    std::array<double, N * N> jac{};
    M::flow(0, x.data(), par.data(), out.data());
    same(out.data(), hand.flow(0, x), "flow", 0);
    EXPECT_TRUE(close(M::divergence(0, x.data(), par.data()), hand.divergence(0, x)));
    EXPECT_TRUE(close(M::initial_density(0, x.data(), par.data()), hand.initial(0, x)));
    EXPECT_EQ(M::in_support(x.data(), par.data()), hand.in_support(x));
    for (int g = 0; g < M::n_guard; ++g) {
      EXPECT_TRUE(close(M::guard_surface(g, x.data(), par.data()), hand.surface(g, x))) << g;
      M::guard_gradient(g, x.data(), par.data(), out.data());
      same(out.data(), hand.gradient(g, x), "gradient of guard", g);
      M::reset(g, x.data(), par.data(), out.data());
      same(out.data(), hand.reset(g, x), "reset of guard", g);
      M::reset_jacobian(g, x.data(), par.data(), jac.data());
      same(jac.data(), hand.reset_jacobian(g, x), "DΔ of guard", g);
      M::reset_inverse(g, x.data(), par.data(), out.data());
      same(out.data(), hand.reset_inverse(g, x), "inverse reset of guard", g);
      const State z{u(rng), u(rng), g == 0 ? hand.theta0 : -hand.theta0};
      EXPECT_TRUE(close(M::hybrid_jacobian(g, z.data(), par.data()), hand.hybrid_jacobian(g, z)))
          << "J of guard " << g;
    }
  }
}

/// The weak-form difference on `angles` × `theta_panels`·4 nodes per energy fibre; `share`
/// gets the share of the mass that has met a wall by the last time.
double weak_form_difference(int angles, int theta_panels, double& share) {
  const Hand hand;
  const std::vector<double> times{1.0, 2.0};
  const Rule rule = energy_rule(hand, 3, angles, theta_panels);
  double zeno = 0.0;
  const Moments ref = reference(hand, times, rule, 0.02, share, zeno);
  std::printf("[ shipped ] %zu nodes: %.3f of the mass has met a wall\n", rule.x.size(), share);
  EXPECT_EQ(zeno, 0.0);
  const auto par = hand.par();
  return compare(characteristics(times, par.data(), rule), ref, times);
}

TEST(ShippedChaplygin, CharacteristicsMatchTheRk4PushForwardInWeakForm) {
  double share = 0.0;
  const double coarse = weak_form_difference(48, 6, share);
  const double fine = weak_form_difference(96, 12, share);
  EXPECT_LT(fine, 3e-4);
  EXPECT_GT(coarse / fine, 3.0);
  EXPECT_GT(share, 0.3);
}

}  // namespace
