// Tests of hybgen/rt/methods/particles.hpp: particle bin masses against the characteristics method
// (an independent method: backward characteristics + adaptive cubature) on the bouncing ball,
// elastic and with e = 0.8; the Zeno atom against its closed form; the budget identity; the
// deposit; reproducibility across runs and thread counts; and the power of the statistical
// test (a 5 % bias must be caught).

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <vector>

#include "bouncing_ball_model.hpp"
#include "hybgen/rt/methods/budget.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "support/ball_closed_form.hpp"
#include "support/rt_setup.hpp"

namespace {

namespace rt = hybgen::rt;
using hybgen::testing::paper_grid;
using Ball = rt::testing::BouncingBall;
using hybgen::testing::zeno_mass;
using P2 = std::array<double, 2>;

rt::ParticleOptions particle_options(std::size_t n, std::uint64_t seed) {
  rt::ParticleOptions o;
  o.particles = n;
  o.seed = seed;
  o.forward.ode.rtol = 1e-10;
  o.forward.ode.atol = 1e-12;
  return o;
}

// ---------------------------------------------------------------------------------------
// Coarse bins: 8 × 8 boxes of [0, 2] × [−2, 2].

constexpr int kBins = 8;
constexpr int kAtom = -2, kOutside = -1;

int bin_of(const P2& x) {
  const double fx = x[0] / 2.0 * kBins, fp = (x[1] + 2.0) / 4.0 * kBins;
  if (!(fx >= 0.0 && fx <= kBins && fp >= 0.0 && fp <= kBins)) return kOutside;
  const int bx = std::min(static_cast<int>(fx), kBins - 1);
  const int bp = std::min(static_cast<int>(fp), kBins - 1);
  return bx * kBins + bp;
}

/// Per particle and output time: its bin (or atom/outside); per particle: weight and start.
struct ParticleBins {
  std::size_t n = 0, K = 0;
  std::vector<std::int16_t> bin;  // [i·K + k]
  std::vector<double> weight;     // [i], 0 for untraced particles
  std::vector<P2> start;          // [i]
};

ParticleBins push(double e, const std::vector<double>& times, std::size_t n, std::uint64_t seed) {
  const std::array<double, 3> par{1.0, 1.0, e};
  const auto opt = particle_options(n, seed);
  const rt::ParticleSampler<Ball> sampler(paper_grid(), par.data(), opt);
  ParticleBins pb;
  pb.n = n;
  pb.K = times.size();
  pb.bin.assign(n * pb.K, kOutside);
  pb.weight.assign(n, 0.0);
  pb.start.assign(n, P2{});
  const auto failure =
      rt::push_particles<Ball>(sampler, times, par.data(), opt.forward,
                               [&](std::size_t i, const rt::ParticleSample<2>& s, std::size_t k,
                                   rt::ParticleFate fate, int, const P2& x) {
                                 pb.weight[i] = s.weight;
                                 pb.start[i] = s.x;
                                 int b = kOutside;
                                 if (fate == rt::ParticleFate::zeno) {
                                   b = bin_of(x) == kOutside ? kOutside : kAtom;
                                 } else if (fate == rt::ParticleFate::state) {
                                   b = bin_of(x);
                                 }
                                 pb.bin[i * pb.K + k] = static_cast<std::int16_t>(b);
                               });
  EXPECT_TRUE(failure.ok()) << rt::describe<Ball>(failure);
  return pb;
}

/// Bin masses and second moments at time k, with every weight multiplied by factor(start).
template <class Factor>
void bin_sums(const ParticleBins& pb, std::size_t k, Factor&& factor, std::vector<double>& P,
              std::vector<double>& S2, double& w1, double& w2) {
  P.assign(kBins * kBins, 0.0);
  S2.assign(kBins * kBins, 0.0);
  w1 = w2 = 0.0;
  for (std::size_t i = 0; i < pb.n; ++i) {
    const double w = pb.weight[i] * factor(pb.start[i]);
    if (w == 0.0) continue;
    w1 += w;
    w2 += w * w;
    const int b = pb.bin[i * pb.K + k];
    if (b < 0) continue;
    P[static_cast<std::size_t>(b)] += w;
    S2[static_cast<std::size_t>(b)] += w * w;
  }
}

/// The characteristics bin masses (adaptive cubature of the exact-to-ODE-tolerance density,
/// budget.hpp) with their estimated errors: [k][bin].
struct CharBins {
  std::vector<double> mass, error;
};

CharBins characteristics_bins(double e, const std::vector<double>& times) {
  const std::array<double, 3> par{1.0, 1.0, e};
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  rt::AdaptiveOptions ao;
  ao.rel_tol = 1e-3;
  ao.max_points = 100000;
  CharBins cb;
  const std::size_t B = kBins * kBins;
  cb.mass.assign(times.size() * B, 0.0);
  cb.error.assign(times.size() * B, 0.0);
  for (int bx = 0; bx < kBins; ++bx) {
    for (int bp = 0; bp < kBins; ++bp) {
      rt::TensorGrid<2> box;
      box.axes = {rt::GridAxis{2.0 * bx / kBins, 2.0 * (bx + 1) / kBins, 2},
                  rt::GridAxis{-2.0 + 4.0 * bp / kBins, -2.0 + 4.0 * (bp + 1) / kBins, 2}};
      rt::TraceFailure<2> failure;
      const rt::AdaptiveMass am = rt::adaptive_mass<Ball>(box, times, par.data(), co, ao, failure);
      EXPECT_TRUE(failure.ok()) << rt::describe<Ball>(failure);
      const auto b = static_cast<std::size_t>(bx * kBins + bp);
      for (std::size_t k = 0; k < times.size(); ++k) {
        cb.mass[k * B + b] = am.mass[k];
        cb.error[k * B + b] = am.error[k];
      }
    }
  }
  return cb;
}

// The statistical comparison. The particle bin mass P_b = Σ_{i in b} w_i is an unbiased
// estimate of the exact bin mass; its variance is estimated by σ̂² = Σ_{i in b} w_i² − P_b²/n
// (sample variance of n i.i.d. terms w_i·1_b; the sampler's stratification only lowers the
// true variance, so σ̂ errs on the safe side). We use σ_b² = max(σ̂², C_b·w̄₂) + ε_b², where
// C_b·w̄₂ (w̄₂ = Σw²/Σw) is the compound-Poisson variance predicted from the characteristics
// mass C_b (guards against an underestimated σ̂ in sparsely hit bins) and ε_b the cubature's
// error estimate of C_b. z_b = (P_b − C_b)/σ_b. Checks per (e, time): every |z_b| ≤ 5 and
// X = Σ_b z_b² ≤ q, the χ²_B quantile at 1 − 1e-5 (Wilson–Hilferty), over the B bins with an
// expected count C_b/w̄ ≥ 30 (normal approximation adequate); the |z| ≤ 5 check covers all
// bins (σ_b floored at w̄). False alarms (normal approximation; the max(·) and ε_b make σ_b
// conservative): per bin P(|Z| > 5) = 5.7e-7, 2·4·64 bins → ≤ 3e-4; χ²: 8·1e-5. Family-wise
// ≤ 4e-4. The seeds are fixed, so the outcome is deterministic; the power is shown below.
struct Comparison {
  double max_z = 0.0;   // max |z_b|
  double chi2 = 0.0;    // X
  double chi2_q = 0.0;  // its threshold q
  int bins = 0;         // B
  bool pass() const { return max_z <= 5.0 && chi2 <= chi2_q; }
};

template <class Factor>
Comparison compare(const ParticleBins& pb, const CharBins& cb, std::size_t k, Factor&& factor) {
  std::vector<double> P, S2;
  double w1 = 0.0, w2 = 0.0;
  bin_sums(pb, k, factor, P, S2, w1, w2);
  const double n = static_cast<double>(pb.n);
  const double wbar = w1 / n, w2bar = w2 / w1;
  const std::size_t B = kBins * kBins;
  Comparison c;
  for (std::size_t b = 0; b < B; ++b) {
    const double C = cb.mass[k * B + b], eps = cb.error[k * B + b];
    const double var_hat = S2[b] - P[b] * P[b] / n;
    const double sigma = std::max(std::sqrt(std::max(var_hat, C * w2bar) + eps * eps), wbar);
    const double z = (P[b] - C) / sigma;
    c.max_z = std::max(c.max_z, std::fabs(z));
    if (C / wbar >= 30.0) {
      c.chi2 += z * z;
      ++c.bins;
    }
  }
  const double B9 = 9.0 * c.bins, za = 4.265;  // z of 1 − 1e-5
  c.chi2_q = c.bins * std::pow(1.0 - 2.0 / B9 + za * std::sqrt(2.0 / B9), 3.0);
  return c;
}

const std::vector<double> kTimes{0.0, 3.0, 6.0, 9.8};
constexpr std::size_t kParticles = 400000;

void check_against_characteristics(double e, std::uint64_t seed) {
  const ParticleBins pb = push(e, kTimes, kParticles, seed);
  const CharBins cb = characteristics_bins(e, kTimes);
  auto one = [](const P2&) { return 1.0; };
  // Power: a 5 % bias of all weights, and one of only the particles starting with p0 > 0
  // (a localised bias, spread over the bins by the flow), must be detected at some time.
  auto global5 = [](const P2&) { return 1.05; };
  auto local5 = [](const P2& x) { return x[1] > 0.0 ? 1.05 : 1.0; };
  bool caught_global = false, caught_local = false;
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    const Comparison c = compare(pb, cb, k, one);
    const Comparison g = compare(pb, cb, k, global5);
    const Comparison l = compare(pb, cb, k, local5);
    std::printf(
        "[ e=%.1f t=%.1f ] max|z| %.2f, chi2 %.1f (q %.1f, %d bins); 5%% bias: max|z| %.1f chi2 "
        "%.0f; 5%% bias on p0>0: max|z| %.1f chi2 %.0f\n",
        e, kTimes[k], c.max_z, c.chi2, c.chi2_q, c.bins, g.max_z, g.chi2, l.max_z, l.chi2);
    EXPECT_LE(c.max_z, 5.0) << "t = " << kTimes[k];
    EXPECT_LE(c.chi2, c.chi2_q) << "t = " << kTimes[k];
    EXPECT_GE(c.bins, 32);
    caught_global = caught_global || !g.pass();
    caught_local = caught_local || !l.pass();
  }
  EXPECT_TRUE(caught_global);
  EXPECT_TRUE(caught_local);
}

// ---------------------------------------------------------------------------------------

TEST(Particles, ElasticBallBinsMatchCharacteristics) {
  check_against_characteristics(1.0, 17);
}

TEST(Particles, ZenoBallBinsMatchCharacteristics) {
  check_against_characteristics(0.8, 23);
}

TEST(Particles, BudgetIdentityAndZenoAtom) {
  // e = 0.8, paper grid, t = 0, 0.2, …, 9.8. The identity mass + outflow + atom = mass0 holds
  // in integers, so in doubles to a few ulps of mass0. The atom is an unbiased estimate of
  // the Zeno mass (every state whose Zeno time is ≤ t is in the box at rest at (0, 0); mass
  // of u0 outside the sampling domain [−2, 4] × [−6, 6] has Zeno times > 25): within 5σ with
  // σ² = max(σ̂², Z·w̄₂) (σ̂ = atom_error/2; Z·w̄₂, w̄₂ = Σw²/Σw, the compound-Poisson variance
  // predicted from the exact Z, for early times when hardly any particle has arrived). False
  // alarm 5.7e-7 per time under normality, 50 times: 3e-5.
  const double e = 0.8;
  const std::array<double, 3> par{1.0, 1.0, e};
  std::vector<double> times;
  for (int k = 0; k < 50; ++k) times.push_back(0.2 * k);
  const auto run =
      rt::solve_particles<Ball>(paper_grid(), times, par.data(), particle_options(200000, 5));
  ASSERT_TRUE(run.ok()) << rt::describe<Ball>(run.failure);
  const auto& b = run.budget;
  // w̄₂ from the weights of the same particles (the sampler is deterministic).
  const rt::ParticleSampler<Ball> sampler(paper_grid(), par.data(), particle_options(200000, 5));
  double w1 = 0.0, w2 = 0.0;
  for (std::size_t i = 0; i < sampler.size(); ++i) {
    const double w = sampler.draw(i).weight;
    w1 += w;
    w2 += w * w;
  }
  const double w2bar = w2 / w1;
  // mass0 = π erf(1) erf(2) (exact) within 5σ of its estimate (σ² ≈ mass0·w̄₂, w̄ ≈ 2.9/n).
  const double exact0 = hybgen::testing::ball_box_mass0();
  EXPECT_NEAR(b.mass0, exact0, 2.5 * b.mass_error[0]);
  EXPECT_EQ(b.mass[0], b.mass0);
  EXPECT_EQ(b.atom[0], 0.0);
  double worst_z = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    EXPECT_NEAR(b.mass[k] + b.outflow[k] + b.atom[k], b.mass0, 4e-16 * b.mass0) << k;
    const double Z = zeno_mass(times[k], e);
    const double sigma =
        std::sqrt(std::max(0.25 * run.atom_error[k] * run.atom_error[k], Z * w2bar));
    if (Z > 0.0) worst_z = std::max(worst_z, std::fabs(b.atom[k] - Z) / sigma);
    EXPECT_LE(std::fabs(b.atom[k] - Z), 5.0 * sigma) << "t = " << times[k];
  }
  std::printf("   atom(9.8) = %.5f ± %.5f (2σ), Zeno mass %.5f; worst |z| %.2f\n", b.atom.back(),
              run.atom_error.back(), zeno_mass(9.8, e), worst_z);
  // The deposit: its trapezoid mass is the particle mass in the box (integer-exact up to
  // the conversion: a few ulps).
  const auto rules = std::array<rt::AxisRule, 2>{rt::trapezoid_rule(paper_grid().axes[0]),
                                                 rt::trapezoid_rule(paper_grid().axes[1])};
  for (std::size_t k = 0; k < times.size(); k += 7) {
    double m = 0.0;
    for (std::size_t i = 0; i < rules[0].nodes.size(); ++i)
      for (std::size_t j = 0; j < rules[1].nodes.size(); ++j)
        m += rules[0].weights[i] * rules[1].weights[j] *
             run.solution.at(k, 0, i * rules[1].nodes.size() + j);
    EXPECT_NEAR(m, b.mass[k], 1e-13 * b.mass0) << k;
  }
  // The elastic ball has no atom: exactly 0.
  const std::array<double, 3> par1{1.0, 1.0, 1.0};
  const auto el =
      rt::solve_particles<Ball>(paper_grid(), times, par1.data(), particle_options(20000, 5));
  ASSERT_TRUE(el.ok());
  for (std::size_t k = 0; k < times.size(); ++k) EXPECT_EQ(el.budget.atom[k], 0.0);
}

TEST(Particles, BudgetAgreesWithTheParticles) {
  // The budget of solve_particles and the sums of push_particles' states are the same
  // particles: equal to the fixed-point rounding (≤ 2⁻⁶¹·n·max w per term, ≪ 1e-12).
  const double e = 0.8;
  const std::array<double, 3> par{1.0, 1.0, e};
  const std::size_t n = 50000;
  const auto run =
      rt::solve_particles<Ball>(paper_grid(), kTimes, par.data(), particle_options(n, 9));
  ASSERT_TRUE(run.ok());
  const ParticleBins pb = push(e, kTimes, n, 9);
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    double mass = 0.0, atom = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const int bn = pb.bin[i * pb.K + k];
      if (pb.weight[i] == 0.0) continue;
      if (bn >= 0) mass += pb.weight[i];
      if (bn == kAtom) atom += pb.weight[i];
    }
    EXPECT_NEAR(run.budget.mass[k], mass, 1e-12) << k;
    EXPECT_NEAR(run.budget.atom[k], atom, 1e-12) << k;
  }
}

TEST(Particles, ReproducibleAcrossRunsAndThreadCounts) {
  const std::array<double, 3> par{1.0, 1.0, 0.8};
  const auto opt = particle_options(30000, 42);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = rt::solve_particles<Ball>(paper_grid(), kTimes, par.data(), opt);
  omp_set_num_threads(std::max(2, threads));
  const auto two = rt::solve_particles<Ball>(paper_grid(), kTimes, par.data(), opt);
  const auto again = rt::solve_particles<Ball>(paper_grid(), kTimes, par.data(), opt);
  omp_set_num_threads(threads);
  ASSERT_TRUE(one.ok() && two.ok() && again.ok());
  EXPECT_TRUE(one.solution.u == two.solution.u);
  EXPECT_TRUE(two.solution.u == again.solution.u);
  for (const auto* r : {&two, &again}) {
    EXPECT_EQ(one.budget.mass0, r->budget.mass0);
    EXPECT_TRUE(one.budget.mass == r->budget.mass);
    EXPECT_TRUE(one.budget.outflow == r->budget.outflow);
    EXPECT_TRUE(one.budget.atom == r->budget.atom);
    EXPECT_TRUE(one.budget.mass_error == r->budget.mass_error);
  }
  // Another seed gives other particles.
  auto opt2 = opt;
  opt2.seed = 43;
  const auto other = rt::solve_particles<Ball>(paper_grid(), kTimes, par.data(), opt2);
  EXPECT_FALSE(other.solution.u == one.solution.u);
  EXPECT_NE(other.budget.mass0, one.budget.mass0);
}

/// Two modes with the same rotation x' = p, p' = −x; guard a → b where x decreases through 0,
/// b → a where x increases through 0, identity resets. u0_a = exp(−4|y − (1, 0)|²),
/// u0_b = 2 exp(−4|y − (0, 1)|²): masses π/4 and π/2 (to e^{−16}: both blobs lie deep inside
/// the box [−3, 3]², and rotation keeps them there).
struct TwoModes {
  static constexpr int n_state = 2, n_param = 0, n_mode = 2, n_guard = 2;
  static constexpr const char* name = "two_modes";
  static constexpr std::array<const char*, 2> state_names{"x", "p"};
  static constexpr std::array<const char*, 0> param_names{};
  static constexpr std::array<double, 0> param_defaults{};
  static constexpr std::array<const char*, 2> mode_names{"a", "b"};
  static constexpr std::array<const char*, 2> guard_names{"ab", "ba"};
  static constexpr std::array<rt::GuardInfo, 2> guards{rt::GuardInfo{0, 1, -1, true},
                                                       rt::GuardInfo{1, 0, +1, true}};
  static void flow(int, const double* x, const double*, double* out) {
    out[0] = x[1];
    out[1] = -x[0];
  }
  static double divergence(int, const double*, const double*) { return 0.0; }
  static double guard_surface(int, const double* x, const double*) { return x[0]; }
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0];
    out[1] = x[1];
  }
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = out[3] = 1.0;
    out[1] = out[2] = 0.0;
  }
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  static double initial_density(int m, const double* x, const double*) {
    const double cx = m == 0 ? 1.0 : 0.0, cp = m == 0 ? 0.0 : 1.0;
    const double r2 = (x[0] - cx) * (x[0] - cx) + (x[1] - cp) * (x[1] - cp);
    return (m == 0 ? 1.0 : 2.0) * std::exp(-4.0 * r2);
  }
  static bool in_support(const double*, const double*) { return true; }
};
static_assert(rt::HybridModel<TwoModes>);

TEST(Particles, TwoModesSampleEachModesMass) {
  // Per-mode masses at t = 0 (trapezoid mass of each mode's deposit) within 5σ of π/4 and
  // π/2, σ² ≤ m·w̄₂ bounded by the i.i.d. compound-Poisson variance with w̄₂ ≤ max w (a
  // conservative σ). Later: at t = π/2 the blob of mode a (centre (1, 0) → (0, −1)) has
  // crossed x = 0 decreasing only in part; the total mass stays π/4 + π/2 (no outflow, no
  // atom, up to the e^{−16} tails).
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{-3.0, 3.0, 61}, rt::GridAxis{-3.0, 3.0, 61}};
  const std::vector<double> times{0.0, 1.0, 2.0, 4.0};
  const auto opt = particle_options(100000, 77);
  const auto run = rt::solve_particles<TwoModes>(grid, times, nullptr, opt);
  ASSERT_TRUE(run.ok());
  const rt::ParticleSampler<TwoModes> sampler(grid, nullptr, opt);
  double wmax = 0.0;
  for (std::size_t i = 0; i < sampler.size(); ++i)
    wmax = std::max(wmax, std::fabs(sampler.draw(i).weight));
  const rt::AxisRule r0 = rt::trapezoid_rule(grid.axes[0]), r1 = rt::trapezoid_rule(grid.axes[1]);
  auto mode_mass = [&](std::size_t k, std::size_t m) {
    double s = 0.0;
    for (std::size_t i = 0; i < r0.nodes.size(); ++i)
      for (std::size_t j = 0; j < r1.nodes.size(); ++j)
        s += r0.weights[i] * r1.weights[j] * run.solution.at(k, m, i * r1.nodes.size() + j);
    return s;
  };
  const double exact[2] = {std::numbers::pi / 4.0, std::numbers::pi / 2.0};
  for (std::size_t m = 0; m < 2; ++m) {
    const double sigma = std::sqrt(exact[m] * wmax);
    EXPECT_NEAR(mode_mass(0, m), exact[m], 5.0 * sigma) << "mode " << m;
  }
  for (std::size_t k = 0; k < times.size(); ++k) {
    EXPECT_NEAR(mode_mass(k, 0) + mode_mass(k, 1), run.budget.mass[k], 1e-13);
    // u0 outside the box (< e^{−16} relative, sampled too) rotates through it: ≤ 1e-8.
    EXPECT_NEAR(run.budget.mass[k], run.budget.mass0, 1e-8);
    EXPECT_EQ(run.budget.atom[k], 0.0);
    EXPECT_NEAR(run.budget.outflow[k], 0.0, 1e-8);
  }
  EXPECT_NEAR(run.budget.mass0, exact[0] + exact[1], 5.0 * std::sqrt(2.4 * wmax));
  // Mode switching happened: at t = 1 part of mode b's blob (which moves right through
  // x = 0 increasing) has switched to a; with identity resets the mode masses differ from t = 0.
  EXPECT_GT(std::fabs(mode_mass(1, 0) - mode_mass(0, 0)), 0.1);
}

/// A chattering model (constant gaps): every particle hits the event cap; the failure names
/// the smallest particle index, its start and the place.
struct Chatter {
  static constexpr int n_state = 2, n_param = 0, n_mode = 1, n_guard = 1;
  static constexpr const char* name = "chatter";
  static constexpr std::array<const char*, 2> state_names{"x", "y"};
  static constexpr std::array<const char*, 0> param_names{};
  static constexpr std::array<double, 0> param_defaults{};
  static constexpr std::array<const char*, 1> mode_names{"only"};
  static constexpr std::array<const char*, 1> guard_names{"wall"};
  static constexpr std::array<rt::GuardInfo, 1> guards{rt::GuardInfo{0, 0, -1, true}};
  static void flow(int, const double*, const double*, double* out) {
    out[0] = -1.0;
    out[1] = 0.0;
  }
  static double divergence(int, const double*, const double*) { return 0.0; }
  static double guard_surface(int, const double* x, const double*) { return x[0]; }
  static void guard_gradient(int, const double*, const double*, double* out) {
    out[0] = 1.0;
    out[1] = 0.0;
  }
  static void reset(int, const double* x, const double*, double* out) {
    out[0] = x[0] + 1e-3;
    out[1] = x[1];
  }
  static void reset_inverse(int, const double* x, const double*, double* out) {
    out[0] = x[0] - 1e-3;
    out[1] = x[1];
  }
  static void reset_jacobian(int, const double*, const double*, double* out) {
    out[0] = out[3] = 1.0;
    out[1] = out[2] = 0.0;
  }
  static double hybrid_jacobian(int, const double*, const double*) { return 1.0; }
  static double initial_density(int, const double* x, const double*) {
    return x[0] >= 0.0 && x[0] <= 1.0 ? 1.0 : 0.0;
  }
  static bool in_support(const double* x, const double*) { return x[0] >= 0.0; }
};
static_assert(rt::HybridModel<Chatter>);

TEST(Particles, EventCapIsReportedWithThePlace) {
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{0.0, 1.0, 11}, rt::GridAxis{0.0, 1.0, 11}};
  auto opt = particle_options(2000, 3);
  opt.forward.max_events = 100;
  const std::vector<double> times{0.0, 2.0};
  const auto run = rt::solve_particles<Chatter>(grid, times, nullptr, opt);
  ASSERT_FALSE(run.ok());
  EXPECT_EQ(run.failure.result.status, rt::ForwardStatus::event_cap);
  // The smallest traced index: the first particle of nonzero weight.
  const rt::ParticleSampler<Chatter> sampler(grid, nullptr, opt);
  std::size_t first = 0;
  while (sampler.draw(first).weight == 0.0) ++first;
  EXPECT_EQ(run.failure.index, first);
  EXPECT_EQ(run.failure.start, sampler.draw(first).x);
  // From x0: events at x0 + j·1e-3; the 101st (j = 100) is the error.
  EXPECT_NEAR(run.failure.result.t_stop, run.failure.start[0] + 0.1, 1e-9);
  const std::string msg = rt::describe<Chatter>(run.failure);
  EXPECT_NE(msg.find("particle " + std::to_string(first)), std::string::npos) << msg;
  EXPECT_NE(msg.find("wall"), std::string::npos) << msg;
}

}  // namespace
