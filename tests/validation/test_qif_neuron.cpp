// Validation: the quadratic integrate-and-fire (QIF) neuron, a model hybgen does not ship,
// against closed forms derived here (none of them comes from hybgen).
//
// One state v (membrane potential), one mode v' = f(v) = v² + I with I = 1 > 0 (the neuron
// fires periodically), state space [v_r, v_p] = [−1, 3]. Guard `spike`: s = v − v_p
// increasing, reset to v_r. The reset is written as the translation v ↦ v − (v_p − v_r), which
// is v_r on the guard (the same hybrid system as the constant reset v ↦ v_r, but with an
// inverse, so the backward characteristics apply: docs/outputs.md refuses them for a constant
// reset). DΔ = 1, so J = ∇sᵀ adj(DΔ) X⁺ / ∇sᵀ X⁻ = f(v_r)/f(v_p) = 2/10 = 1/5: every spike
// multiplies the density by 5. div X = f′(v) = 2v.
//
// Closed forms. The phase θ(v) = ∫_{v_r}^{v} dv/f = atan v − atan v_r = atan v + π/4 runs
// from 0 at v_r to the period T = θ(v_p) = atan 3 + π/4, and v(θ) = tan(θ − π/4). In 1-D
// Liouville gives d/dt [u(t, v(t))·f(v(t))] = 0 along the flow (u̇ = −f′u, ḟ = f′f), and the
// jump condition u⁺ = u⁻/|J| = u⁻·f(v_p)/f(v_r) keeps the flux q = u·f across the spike: q is
// carried unchanged along the phase, which rotates at unit speed. Hence
//   invariant density:      u*(v) = (1/T)/(v² + I)            (flux conservation, unit mass),
//   any initial flux q0(θ): u(t, v) = q0(θ(v) − t mod T)/(v² + I),
//   mean potential:         ⟨v⟩(t) = ∫_0^T q0(θ − t) tan(θ − π/4) dθ.
// u* varies by a factor 10 on the state space (f from 1 at v = 0 to 10 at v_p).
// q0(θ) = (1 + ½ sin 2πθ/T)/T (unit mass).
//
// Compared:
//  * characteristics (solve_grid, 201 nodes, t = 0.7, 2.5, 5.1: up to three spikes back):
//    max error relative to max u below 1e-8 (docs/methods.md: the ODE tolerance, rtol 1e-10 here;
//    measured 2.6e-10).
//  * invariant (hat, h = 0.05, 201 and 401 nodes): λ₁ = 1 to 1e-9 (a closed system: the box
//    is the state space and the spike maps it onto itself) and u* in relative L1 (docs/methods.md:
//    O(Δx²) per step plus the error of sub-cells straddling the spike; figures at the test).
//  * transfer (hat, h = 0.05, 201 and 401 nodes): the wave q0 marched to t = 3 (about 1.5
//    periods) against the closed form, relative L1, with the convergence ratio (figures at
//    the test).
//  * particles (10⁵): the mass and ⟨v⟩ at t = 0, 0.7, 2.5, 5.1 (the cloud-in-cell deposit
//    keeps linear moments exactly) within 5σ, σ² ≤ ∫φ²u·Σw²/Σw.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/invariant.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "hybgen/rt/methods/transfer.hpp"

namespace {

namespace rt = hybgen::rt;

/// The drive I, the reset potential v_r and the peak v_p.
constexpr double kI = 1.0, kVr = -1.0, kVp = 3.0;

/// f(v) = v² + I.
double rate(double v) {
  return v * v + kI;
}

/// The phase θ(v) = atan v − atan v_r (I = 1).
double phase(double v) {
  return std::atan(v) - std::atan(kVr);
}

/// The period T = θ(v_p).
const double kPeriod = phase(kVp);

/// v(θ), the inverse of `phase`.
double potential(double theta) {
  return std::tan(theta + std::atan(kVr));
}

/// The QIF neuron as a generated model would be (written by hand).
struct Qif {
  static constexpr int n_state = 1;                                  ///< v
  static constexpr int n_param = 0;                                  ///< none
  static constexpr int n_mode = 1;                                   ///< one mode
  static constexpr int n_guard = 1;                                  ///< spike
  static constexpr const char* name = "qif_neuron";                  ///< Model name.
  static constexpr std::array<const char*, 1> state_names{"v"};      ///< State names.
  static constexpr std::array<const char*, 0> param_names{};         ///< No parameters.
  static constexpr std::array<double, 0> param_defaults{};           ///< No parameters.
  static constexpr std::array<const char*, 1> mode_names{"charge"};  ///< Mode names.
  static constexpr std::array<const char*, 1> guard_names{"spike"};  ///< Guard names.
  /// spike: increasing, closed-form inverse (a translation).
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, +1, true}};
  /// X = v² + I.
  static void flow(int, const double* x, const double*, double* out) { out[0] = rate(x[0]); }
  /// div X = 2v.
  static double divergence(int, const double* x, const double*) { return 2.0 * x[0]; }
  /// s = v − v_p.
  static double guard_surface(int, const double* x, const double*) { return x[0] - kVp; }
  /// ∇s = 1.
  static void guard_gradient(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// Δ(v) = v − (v_p − v_r) (v_r on the guard).
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0] - (kVp - kVr);
  }
  /// Δ⁻¹(v) = v + (v_p − v_r).
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0] + (kVp - kVr);
  }
  /// DΔ = 1.
  static void reset_jacobian(int, const double*, const double*, double* out) { out[0] = 1.0; }
  /// J = f(Δv)/f(v) on the guard: f(v_r)/f(v_p).
  static double hybrid_jacobian(int, const double* x, const double*) {
    return rate(x[0] - (kVp - kVr)) / rate(x[0]);
  }
  /// The initial flux over the phase; null: the invariant one, 1/T.
  static inline double (*q0)(double theta) = nullptr;
  /// u0(v) = q0(θ(v))/f(v) on the state space, 0 outside it.
  static double initial_density(int, const double* x, const double*) {
    if (!in_support(x, nullptr)) return 0.0;
    return (q0 ? q0(phase(x[0])) : 1.0 / kPeriod) / rate(x[0]);
  }
  /// The state space [v_r, v_p].
  static bool in_support(const double* x, const double*) { return x[0] >= kVr && x[0] <= kVp; }
};
static_assert(rt::HybridModel<Qif>);

/// The flux wave q0(θ) = (1 + ½ sin 2πθ/T)/T.
double wave(double theta) {
  return (1.0 + 0.5 * std::sin(2.0 * std::numbers::pi * theta / kPeriod)) / kPeriod;
}

/// The exact density of the initial flux `q` at time t.
double exact(double (*q)(double), double t, double v) {
  const double th = std::fmod(std::fmod(phase(v) - t, kPeriod) + kPeriod, kPeriod);
  return q(th) / rate(v);
}

/// ∫ u(t), ∫ v u(t) and ∫ v² u(t) for the initial flux `q`, by composite Gauss–Legendre over
/// the phase.
std::array<double, 3> exact_moments(double (*q)(double), double t) {
  const auto rule = rt::gauss_legendre_rule(0.0, kPeriod, 400, 6);
  std::array<double, 3> m{};
  for (std::size_t i = 0; i < rule.nodes.size(); ++i) {
    const double th = rule.nodes[i];
    const double qq = q(std::fmod(std::fmod(th - t, kPeriod) + kPeriod, kPeriod));
    m[0] += rule.weights[i] * qq;
    m[1] += rule.weights[i] * qq * potential(th);
    m[2] += rule.weights[i] * qq * potential(th) * potential(th);
  }
  return m;
}

/// The grid of [v_r, v_p] with n nodes.
rt::TensorGrid<1> line(int n) {
  rt::TensorGrid<1> g;
  g.axes = {rt::GridAxis{kVr, kVp, n}};
  return g;
}

/// Relative L1 distance Σ w|u − v| / Σ w|v|.
double rel_l1(const std::vector<double>& w, const double* u, const std::vector<double>& v) {
  double num = 0.0, den = 0.0;
  for (std::size_t r = 0; r < v.size(); ++r) {
    num += w[r] * std::fabs(u[r] - v[r]);
    den += w[r] * std::fabs(v[r]);
  }
  return num / den;
}

/// The output times.
const std::vector<double> kTimes{0.0, 0.7, 2.5, 5.1};

TEST(QifNeuron, ClosedFormsAreConsistent) {
  // The phase against a direct quadrature of dv/f, the invariant density's mass, and the
  // wave's mass and mean at t = 0 against a fine midpoint rule in v.
  const auto r = rt::gauss_legendre_rule(kVr, kVp, 200, 6);
  double th = 0.0, mass = 0.0;
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    th += r.weights[i] / rate(r.nodes[i]);
    mass += r.weights[i] / (kPeriod * rate(r.nodes[i]));
  }
  EXPECT_NEAR(th, kPeriod, 1e-13);
  EXPECT_NEAR(mass, 1.0, 1e-13);
  EXPECT_NEAR(potential(phase(2.3)), 2.3, 1e-13);
  const int n = 400000;
  double m0 = 0.0, m1 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double v = kVr + (kVp - kVr) * (i + 0.5) / n;
    const double u = exact(wave, 0.0, v) * (kVp - kVr) / n;
    m0 += u;
    m1 += u * v;
  }
  const auto ref = exact_moments(wave, 0.0);
  EXPECT_NEAR(m0, 1.0, 1e-9);
  EXPECT_NEAR(ref[0], 1.0, 1e-13);
  EXPECT_NEAR(m1, ref[1], 1e-9);
}

TEST(QifNeuron, CharacteristicsFollowTheFluxWave) {
  Qif::q0 = wave;
  const auto grid = line(201);
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const auto sol = rt::solve_grid<Qif>(grid, kTimes, nullptr, co);
  ASSERT_TRUE(sol.ok()) << rt::describe<Qif>(sol.failure);
  double worst = 0.0, umax = 0.0;
  for (std::size_t k = 0; k < kTimes.size(); ++k)
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const double v = grid.node(i)[0], ue = exact(wave, kTimes[k], v);
      umax = std::max(umax, ue);
      worst = std::max(worst, std::fabs(sol.at(k, 0, i) - ue));
    }
  std::printf("[ qif ] characteristics 201 nodes: max error %.2e (max u %.3f)\n", worst, umax);
  EXPECT_LT(worst, 1e-8 * umax);
  Qif::q0 = nullptr;
}

TEST(QifNeuron, InvariantDensityIsTheFluxConservingOne) {
  // Measured: λ₁ − 1 = −3e-15, 9e-15; relative L1 4.50e-4 (201 nodes), 1.28e-4 (401): ratio
  // 3.5, second order (docs/methods.md's O(Δx²)). Asserted: λ₁ = 1 to 1e-9, < 1.5e-3 at 201 nodes,
  // then a ratio > 2.5.
  Qif::q0 = nullptr;
  double prev = 0.0;
  for (const int n : {201, 401}) {
    const auto grid = line(n);
    rt::TransferOptions o;
    o.step = 0.05;
    const auto op = rt::assemble_transfer<Qif>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    for (std::size_t r = 0; r < op.size(); ++r) {
      ASSERT_EQ(op.outflow[r], 0.0) << r;
      ASSERT_EQ(op.atom[r], 0.0) << r;
    }
    const auto inv = rt::invariant_density(op);
    ASSERT_TRUE(inv.converged);
    std::vector<double> ref(op.size());
    for (std::size_t i = 0; i < op.size(); ++i) ref[i] = 1.0 / (kPeriod * rate(grid.node(i)[0]));
    const double err = rel_l1(op.weight, inv.density.data(), ref);
    const double lam = inv.eigenvalues[0].real();
    std::printf("[ qif ] invariant %d nodes h=0.05 (%s): lambda1 - 1 = %.2e, rel L1 %.3e\n", n,
                inv.method.c_str(), lam - 1.0, err);
    EXPECT_NEAR(lam, 1.0, 1e-9);
    EXPECT_GE(inv.min_value, 0.0);
    if (prev == 0.0) {
      EXPECT_LT(err, 1.5e-3);
    } else {
      EXPECT_GT(prev / err, 2.5);
    }
    prev = err;
  }
}

TEST(QifNeuron, TransferMarchesTheFluxWave) {
  // The wave marched to t = 3 (60 steps, one or two spikes per state). Measured: relative L1
  // 5.93e-3 (201 nodes), 1.50e-3 (401): ratio 3.95, second order; 16 samples per cell instead
  // of 4 change neither (5.92e-3, 1.50e-3): unlike the thermostat's switches, the sub-cells
  // straddling the spike cost nothing visible here. Asserted: < 1.2e-2, then a ratio > 3; the
  // mass kept to rounding (a closed system).
  Qif::q0 = wave;
  const std::vector<double> times{0.0, 3.0};
  double prev = 0.0;
  for (const int n : {201, 401}) {
    const auto grid = line(n);
    std::vector<double> ref(grid.size());
    for (std::size_t i = 0; i < grid.size(); ++i) ref[i] = exact(wave, 3.0, grid.node(i)[0]);
    rt::TransferOptions o;
    o.step = 0.05;
    const auto op = rt::assemble_transfer<Qif>(grid, nullptr, o);
    ASSERT_TRUE(op.ok()) << op.failure_message;
    const auto run = rt::march(op, rt::initial_vector<Qif>(grid, nullptr), times);
    ASSERT_TRUE(run.ok()) << run.failure;
    const double err = rel_l1(op.weight, run.solution.u.data() + op.size(), ref);
    std::printf("[ qif ] transfer %d nodes h=0.05: t = 3 rel L1 %.3e, mass %.15f -> %.15f\n", n,
                err, run.budget.mass0, run.budget.mass[1]);
    EXPECT_NEAR(run.budget.mass[1], run.budget.mass0, 1e-13);
    EXPECT_EQ(run.budget.outflow[1], 0.0);
    if (prev == 0.0) {
      EXPECT_LT(err, 1.2e-2);
    } else {
      EXPECT_GT(prev / err, 3.0);
    }
    prev = err;
  }
  Qif::q0 = nullptr;
}

TEST(QifNeuron, ParticleMeanPotential) {
  Qif::q0 = wave;
  const auto grid = line(201);
  rt::ParticleOptions po;
  po.particles = 100000;
  po.seed = 29;
  po.forward.ode.rtol = 1e-8;  // far below the Monte-Carlo error (~1e-3)
  po.forward.ode.atol = 1e-10;
  const auto run = rt::solve_particles<Qif>(grid, kTimes, nullptr, po);
  ASSERT_TRUE(run.failure.ok()) << rt::describe<Qif>(run.failure);
  const auto& b = run.budget;
  const double s2 = 0.25 * b.mass_error[0] * b.mass_error[0] +
                    b.mass0 * b.mass0 / static_cast<double>(po.particles);
  const double w2bar = s2 / b.mass0;
  const auto w = rt::detail::trapezoid_weights(grid, 1);
  double worst = 0.0;
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    std::array<double, 2> got{};
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const double m = w[i] * run.solution.at(k, 0, i);
      got[0] += m;
      got[1] += m * grid.node(i)[0];
    }
    const auto ref = exact_moments(wave, kTimes[k]);
    for (std::size_t a = 0; a < 2; ++a) {
      // σ² ≤ ∫φ²u·Σw²/Σw (the compound-Poisson bound), ∫φ²u = mass for φ = 1, ∫v²u for φ = v.
      const double z = std::fabs(got[a] - ref[a]) / std::sqrt(ref[2 * a] * w2bar);
      worst = std::max(worst, z);
      EXPECT_LE(z, 5.0) << "t = " << kTimes[k] << ", moment " << a;
    }
    std::printf("[ qif ] particles t = %.1f: mass %.6f (exact %.6f), <v> %.6f (exact %.6f)\n",
                kTimes[k], got[0], ref[0], got[1], ref[1]);
  }
  std::printf("[ qif ] particles: worst |z| %.2f\n", worst);
  Qif::q0 = nullptr;
}

}  // namespace
