// The Impact Lie–Poisson reduction (paper §3, the Chaplygin sleigh of §4.2) at the level of
// densities: particles of the UNREDUCED system, pushed forward by its own flow and projected
// through the reduction map, have the density of the REDUCED system.
//
// Two derivations that share nothing past the model file: the 6-D twin on TSE(2)
// (x, y, th, xdot, ydot, thdot), derived by `hybgen generate --unreduced` in the coordinates
// by Lagrange–d'Alembert with the impulsive corner conditions (its kernels are generated at
// build time, tests/CMakeLists.txt), and the 3-D reduced system (v, ω, θ) derived through
// the Lie algebra (Euler–Poincaré–Suslov, generated/chaplygin/). The reduction map is the
// body velocity π(x, y, th, ẋ, ẏ, θ̇) = (ẋ cos th + ẏ sin th, θ̇, th) and a lift of the
// reduced state onto the constraint w = −ẋ sin th + ẏ cos th = 0 is σ(v, ω, θ) =
// (0, 0, θ, v cos θ, v sin θ, ω). The theorem says π ∘ φᵗ_twin ∘ σ = φᵗ_reduced, so for
// u(t) = the reduced density (characteristics, exact at the nodes to the ODE tolerance)
//     π_# (φᵗ_twin)_# σ_# (u0 dx) = u(t) dx.
// The test integrates both sides over boxes of the reduced space: the left by Monte Carlo
// (importance weights, their sample variance), the right by the trapezoid rule on the
// nodes. Every box must agree within 4.5σ plus the quadrature's error, and the χ² of all
// boxes must be that of chance; a wrong reduction map fails both (the negative control).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <span>
#include <vector>

#include "chaplygin/chaplygin.hpp"
#include "chaplygin_unreduced/chaplygin_unreduced.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/forward.hpp"

namespace {

namespace rt = hybgen::rt;
using Reduced = hybgen_model::chaplygin;         // (v, ω, θ)
using Twin = hybgen_model::chaplygin_unreduced;  // (x, y, th, ẋ, ẏ, θ̇)
using R3 = std::array<double, 3>;
using R6 = std::array<double, 6>;

/// The model's parameters (m, I, a, θ0), the same order in both kernels.
constexpr std::array<double, 4> kPar{1.0, 1.0, 0.5, 1.0};
/// Output times: the start (the lift and the map are inverse), then after impacts.
constexpr std::array<double, 3> kTimes{0.0, 1.0, 2.0};
/// Reference grid: 41 nodes per axis on the reduced box, bins of 10 × 10 × 10 cells.
constexpr int kNodes = 41, kCellsPerBin = 10, kBins = (kNodes - 1) / kCellsPerBin;
constexpr R3 kLo{-1.5, -1.5, -1.0}, kHi{1.5, 1.5, 1.0};

/// σ: the reduced state lifted onto the constraint (group element at x = y = 0).
R6 lift(const R3& r) {
  return {0.0, 0.0, r[2], r[0] * std::cos(r[2]), r[0] * std::sin(r[2]), r[1]};
}

/// π: the body velocity along the edge, the angular velocity and the angle.
R3 reduce(const R6& s) {
  return {s[3] * std::cos(s[2]) + s[4] * std::sin(s[2]), s[5], s[2]};
}

/// A wrong map for the negative control: ẋ in place of the body velocity.
R3 reduce_wrongly(const R6& s) {
  return {s[3], s[5], s[2]};
}

/// The bin of a reduced state, or −1 outside the box.
int bin_of(const R3& r) {
  int b = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    const double f = (r[a] - kLo[a]) / (kHi[a] - kLo[a]) * kBins;
    if (!(f >= 0.0 && f < kBins)) return -1;
    b = b * kBins + static_cast<int>(f);
  }
  return b;
}

/// The right-hand side: ∫ over each bin of the reduced density at each time, by the
/// trapezoid rule on the characteristics' nodes (bins are whole cells).
std::vector<std::vector<double>> reference_bins() {
  rt::TensorGrid<3> grid;
  for (std::size_t a = 0; a < 3; ++a) grid.axes[a] = {kLo[a], kHi[a], kNodes};
  rt::CharacteristicsOptions co;
  co.ode.rtol = 1e-10;
  co.ode.atol = 1e-12;
  const auto sol = rt::solve_grid<Reduced>(grid, kTimes, kPar.data(), co);
  EXPECT_TRUE(sol.ok());
  const int nb = kBins * kBins * kBins;
  std::vector<std::vector<double>> out(kTimes.size(), std::vector<double>(nb, 0.0));
  std::array<double, 3> h{};
  for (std::size_t a = 0; a < 3; ++a) h[a] = (kHi[a] - kLo[a]) / (kNodes - 1);
  for (std::size_t k = 0; k < kTimes.size(); ++k)
    for (int b = 0; b < nb; ++b) {
      const int b0 = b / (kBins * kBins), b1 = (b / kBins) % kBins, b2 = b % kBins;
      double sum = 0.0;
      for (int i = 0; i <= kCellsPerBin; ++i)
        for (int j = 0; j <= kCellsPerBin; ++j)
          for (int l = 0; l <= kCellsPerBin; ++l) {
            const double w = (i == 0 || i == kCellsPerBin ? 0.5 : 1.0) *
                             (j == 0 || j == kCellsPerBin ? 0.5 : 1.0) *
                             (l == 0 || l == kCellsPerBin ? 0.5 : 1.0);
            const std::size_t node = (static_cast<std::size_t>(b0 * kCellsPerBin + i) * kNodes +
                                      static_cast<std::size_t>(b1 * kCellsPerBin + j)) *
                                         kNodes +
                                     static_cast<std::size_t>(b2 * kCellsPerBin + l);
            sum += w * sol.at(k, 0, node);
          }
      out[k][static_cast<std::size_t>(b)] = sum * h[0] * h[1] * h[2];
    }
  return out;
}

/// The left-hand side by Monte Carlo: per time and bin, Σ w and Σ w² over the particles
/// whose projection lands there, for the right map and for the wrong one.
struct Sums {
  std::vector<std::vector<double>> mass, square;  ///< [time][bin]
};

struct Particles {
  Sums right, wrong;
  std::size_t n = 0;
};

Particles push_twin(std::size_t n) {
  // Proposal: uniform on v, ω ∈ [−4, 4] (u0 < e⁻¹⁶ beyond), θ ∈ [−θ0, θ0] (the support);
  // weight u0(x)·|domain|/n. A fixed seed: the same particles every run.
  const R3 lo{-4.0, -4.0, -1.0}, hi{4.0, 4.0, 1.0};
  const double volume = (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]);
  const int nb = kBins * kBins * kBins;
  Particles p;
  p.n = n;
  for (Sums* s : {&p.right, &p.wrong}) {
    s->mass.assign(kTimes.size(), std::vector<double>(nb, 0.0));
    s->square = s->mass;
  }
  std::mt19937_64 rng(20261127);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<R3> starts(n);
  for (auto& x : starts)
    for (std::size_t a = 0; a < 3; ++a) x[a] = lo[a] + (hi[a] - lo[a]) * unit(rng);
  rt::ForwardOptions fo;
  fo.ode.rtol = 1e-10;
  fo.ode.atol = 1e-12;
  fo.max_events = 100000;
  std::vector<int> failed(1, 0);
#pragma omp parallel
  {
    rt::ForwardFlow<Twin> flow(kPar.data(), fo);
    Sums right = p.right, wrong = p.wrong;
    int bad = 0;
#pragma omp for schedule(dynamic, 256)
    for (std::size_t i = 0; i < n; ++i) {
      const double w = Reduced::initial_density(0, starts[i].data(), kPar.data()) * volume /
                       static_cast<double>(n);
      if (w == 0.0) continue;
      auto book = [&](Sums& s, std::size_t k, const R3& r) {
        const int b = bin_of(r);
        if (b < 0) return;
        s.mass[k][static_cast<std::size_t>(b)] += w;
        s.square[k][static_cast<std::size_t>(b)] += w * w;
      };
      const auto res = flow.run(0, lift(starts[i]), std::span<const double>(kTimes),
                                [&](std::size_t k, int, const R6& s) {
                                  book(right, k, reduce(s));
                                  book(wrong, k, reduce_wrongly(s));
                                });
      if (res.status != rt::ForwardStatus::ok) ++bad;
    }
#pragma omp critical
    {
      for (std::size_t k = 0; k < kTimes.size(); ++k)
        for (int b = 0; b < nb; ++b) {
          const auto bu = static_cast<std::size_t>(b);
          p.right.mass[k][bu] += right.mass[k][bu];
          p.right.square[k][bu] += right.square[k][bu];
          p.wrong.mass[k][bu] += wrong.mass[k][bu];
          p.wrong.square[k][bu] += wrong.square[k][bu];
        }
      failed[0] += bad;
    }
  }
  EXPECT_EQ(failed[0], 0) << "twin trajectories that did not reach t = 2";
  return p;
}

/// Per time: the largest |MC − reference| in units of (σ + quadrature allowance), and the
/// χ² per bin.
struct Verdict {
  double worst = 0.0, chi2 = 0.0;
};

Verdict compare(const Sums& s, const std::vector<double>& ref, std::size_t k, std::size_t n) {
  Verdict v;
  double total = 0.0;
  for (const double x : ref) total += x;
  for (std::size_t b = 0; b < ref.size(); ++b) {
    const double m = s.mass[k][b];
    const double var = std::max(s.square[k][b] - m * m / static_cast<double>(n), 0.0);
    // The trapezoid rule's error on 10 cells of a smooth density, an allowance of 1e-4 of the
    // mass: measured below the Monte-Carlo error (without it the χ² per bin is 0.8 to 1.1).
    const double quad = 1e-4 * total;
    const double d = std::fabs(m - ref[b]);
    v.worst = std::max(v.worst, d / (4.5 * std::sqrt(var) + quad));
    v.chi2 += (m - ref[b]) * (m - ref[b]) / (var + quad * quad);
  }
  v.chi2 /= static_cast<double>(ref.size());
  return v;
}

TEST(Reduction, TwinParticlesProjectedHaveTheReducedDensity) {
  const auto ref = reference_bins();
  const Particles p = push_twin(300000);
  for (std::size_t k = 0; k < kTimes.size(); ++k) {
    const Verdict right = compare(p.right, ref[k], k, p.n);
    EXPECT_LE(right.worst, 1.0) << "t = " << kTimes[k];
    // 64 bins: the χ² per bin of chance is 1 ± 0.18; 2 is far outside it.
    EXPECT_LE(right.chi2, 2.0) << "t = " << kTimes[k];
    // The negative control: ẋ is the body velocity only at th = 0, which the flow leaves;
    // at t = 0 the lift puts every particle where both maps differ by cos, which they do too.
    const Verdict wrong = compare(p.wrong, ref[k], k, p.n);
    std::printf("t = %g: worst box %.2f of its allowance, chi2/bin %.2f; wrong map chi2/bin %.3g\n",
                kTimes[k], right.worst, right.chi2, wrong.chi2);
    EXPECT_GT(wrong.chi2, 10.0) << "t = " << kTimes[k] << ": the test cannot tell a wrong map";
  }
}

}  // namespace
