// The check lattice's sum of a step with its jumps located along the lattice's lines
// (runtime/include/hybgen/rt/methods/budget/step_lines.hpp), against integrals in closed form.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <span>
#include <vector>

#include "hybgen/rt/methods/budget/step_lines.hpp"

namespace {

using hybgen::rt::detail::kMaxStepHalvings;
using hybgen::rt::detail::locate_steps;

// A lattice of n points per axis on [lo, hi]^N in C order, with its trapezoid weights.
template <std::size_t N>
struct Lattice {
  std::array<std::size_t, N> shape{};
  std::array<double, N> spacing{}, lo{}, hi{};
  std::vector<std::array<double, N>> x;
  std::vector<double> w;
  Lattice(std::size_t n, double a, double b) {
    shape.fill(n);
    spacing.fill((b - a) / static_cast<double>(n - 1));
    lo.fill(a);
    hi.fill(b);
    std::size_t total = 1;
    for (std::size_t k = 0; k < N; ++k) total *= n;
    for (std::size_t j = 0; j < total; ++j) {
      std::array<double, N> p{};
      double wj = 1.0;
      std::size_t rem = j;
      for (std::size_t k = N; k-- > 0;) {
        const std::size_t i = rem % n;
        rem /= n;
        p[k] = a + static_cast<double>(i) * spacing[k];
        wj *= (i == 0 || i == n - 1 ? 0.5 : 1.0) * spacing[k];
      }
      x.push_back(p);
      w.push_back(wj);
    }
  }
};

// A step integrand of V slots: f(x, q) for the values and c(x, q) for the counts, 2V values
// per point as locate_steps reads them; `calls` counts the points evaluated.
template <std::size_t N, class F, class C>
struct Step {
  std::size_t V;
  F f;
  C c;
  std::size_t calls = 0;
  void fill(std::span<const std::array<double, N>> p, std::vector<double>& out) {
    out.assign(p.size() * 2 * V, 0.0);
    for (std::size_t i = 0; i < p.size(); ++i)
      for (std::size_t q = 0; q < V; ++q) {
        out[i * 2 * V + q] = f(p[i], q);
        out[i * 2 * V + V + q] = c(p[i], q);
      }
    calls += p.size();
  }
  // The lattice's trapezoid sums (first), then corrected (second).
  std::pair<std::vector<double>, std::vector<double>> sums(const Lattice<N>& L,
                                                           std::size_t max_evals,
                                                           std::size_t* used = nullptr,
                                                           double target = 0.0) {
    std::vector<double> v;
    fill(L.x, v);
    std::vector<double> s(V, 0.0);
    for (std::size_t j = 0; j < L.x.size(); ++j)
      for (std::size_t q = 0; q < V; ++q) s[q] += L.w[j] * v[j * 2 * V + q];
    std::vector<double> corrected = s;
    calls = 0;
    const std::size_t n = locate_steps<N>(
        std::span<const std::array<double, N>>(L.x), L.shape, L.spacing, L.lo, L.hi, v, V,
        [&](std::span<const std::array<double, N>> p, std::vector<double>& out) {
          fill(p, out);
          return true;
        },
        target, max_evals, corrected);
    EXPECT_EQ(n, calls);
    if (used != nullptr) *used = n;
    return {s, corrected};
  }
};
template <std::size_t N, class F, class C>
Step<N, F, C> step(std::size_t V, F f, C c) {
  return {V, f, c};
}

/// Where exp_step jumps: 1/√7, between the nodes of the lattices below.
const double kJump = 1.0 / std::sqrt(7.0);

/// One slot on [0, 1]: e^x·[x ≥ kJump], its count [x ≥ kJump].
auto exp_step() {
  return step<1>(
      1,
      [](const std::array<double, 1>& x, std::size_t) {
        return x[0] >= kJump ? std::exp(x[0]) : 0.0;
      },
      [](const std::array<double, 1>& x, std::size_t) { return x[0] >= kJump ? 1.0 : 0.0; });
}

TEST(StepLines, OneJumpInOneDimensionIsHeldToItsLastHalving) {
  // ∫₀¹ e^x·[x ≥ s] dx = e − e^s, s = 1/√7 between nodes: the trapezoid rule puts the jump
  // at its segment's midpoint, off by up to h/2; halved kMaxStepHalvings times, by at most
  // h·2^(−11) (times the jump e^s), beside the smooth part's O(h²).
  auto st = exp_step();
  const Lattice<1> L(33, 0.0, 1.0);
  std::size_t used = 0;
  const auto [plain, located] = st.sums(L, 1000, &used);
  const double exact = std::numbers::e - std::exp(kJump), h = L.spacing[0];
  const double smooth = h * h / 12.0 * std::numbers::e;         // the trapezoid rule's e^x term
  EXPECT_EQ(used, static_cast<std::size_t>(kMaxStepHalvings));  // one segment per halving
  EXPECT_GT(std::fabs(plain[0] - exact), 1e-3 * h);             // the jump between nodes counts
  EXPECT_LE(std::fabs(located[0] - exact),
            std::exp(kJump) * h * std::ldexp(1.0, -kMaxStepHalvings - 1) + 2.0 * smooth);
}

TEST(StepLines, ADiscsLinesAreIntegratedExactly) {
  // ∫∫ e^(−r²)·[r ≤ R] over [−1, 1]², R = 0.77 inside it, as lines along x₁: the line at x₀
  // (|x₀| < R) holds F(x₀) = e^(−x₀²)·√π·erf(√(R² − x₀²)). The lattice's trapezoid sum is off
  // from the same rule over the exact F(x₀) by about the circle's length times h,
  // erratically (each line's rule puts its jumps at their segments' midpoints): 1.3 h², 3.6 h²
  // and 6.6 h² here; with the jumps located, by the smooth part's O(h²) and 2^(−10)·h of each
  // jump alone: 0.17 h² on all three lattices. What is left
  // of the error is the transverse rule's over F, which has square-root ends at x₀ = ±R:
  // O(h^(3/2)), below 2·F's coefficient there, 2·√(2R)·e^(−R²), times h^(3/2) at each end.
  const double R = 0.77;
  const double exact = std::numbers::pi * (1.0 - std::exp(-R * R));
  for (const std::size_t n : {33u, 65u, 129u}) {
    auto st = step<2>(
        1,
        [=](const std::array<double, 2>& x, std::size_t) {
          const double r2 = x[0] * x[0] + x[1] * x[1];
          return r2 <= R * R ? std::exp(-r2) : 0.0;
        },
        [=](const std::array<double, 2>& x, std::size_t) {
          return x[0] * x[0] + x[1] * x[1] <= R * R ? 1.0 : 0.0;
        });
    const Lattice<2> L(n, -1.0, 1.0);
    std::size_t used = 0;
    const auto [plain, located] = st.sums(L, 100 * n, &used);
    const double h = L.spacing[0];
    double lines = 0.0;  // the transverse trapezoid rule over the exact F
    for (std::size_t i = 0; i < n; ++i) {
      const double x0 = L.lo[0] + static_cast<double>(i) * h;
      const double w = (i == 0 || i + 1 == n ? 0.5 : 1.0) * h;
      if (std::fabs(x0) < R)
        lines += w * std::exp(-x0 * x0) * std::sqrt(std::numbers::pi) *
                 std::erf(std::sqrt(R * R - x0 * x0));
    }
    std::printf(
        "[ step lines ] disc on %zu²: off the lines' exact integrals by %.2e (lattice) and "
        "%.2e (located, %zu more points); off the disc's integral by %.2e and %.2e\n",
        n, plain[0] - lines, located[0] - lines, used, plain[0] - exact, located[0] - exact);
    EXPECT_GT(std::fabs(plain[0] - lines), 0.25 * h * h) << n;
    EXPECT_LE(std::fabs(located[0] - lines), 0.25 * h * h) << n;
    EXPECT_LE(std::fabs(located[0] - exact),
              4.0 * std::sqrt(2.0 * R) * std::exp(-R * R) * std::pow(h, 1.5))
        << n;
  }
}

TEST(StepLines, EachSlotHasItsOwnJumpsAndTheCapHolds) {
  // Two slots on [0, 1]², located together: a half plane x₁ ≥ 0.3 + 0.2 x₀, whose lines'
  // integrals 0.7 − 0.2 x₀ are linear, so that the located sum is its integral 0.6 up to
  // 2^(−10)·h per line; and a count of 2 on the strip |x₁ − 0.55| ≤ 0.2 − 0.1 x₀ (lines of
  // 2·(0.4 − 0.2 x₀), ∫ = 0.6). Under a cap of fewer points than one halving needs, nothing
  // is evaluated and the sums stay the lattice's.
  auto in = [](const std::array<double, 2>& x, std::size_t q) {
    if (q == 0) return x[1] >= 0.3 + 0.2 * x[0] ? 1.0 : 0.0;
    return std::fabs(x[1] - 0.55) <= 0.2 - 0.1 * x[0] ? 2.0 : 0.0;
  };
  auto st = step<2>(2, in, in);
  const Lattice<2> L(41, 0.0, 1.0);
  const std::array<double, 2> exact = {0.6, 0.6};
  std::size_t used = 0;
  const auto [plain, located] = st.sums(L, 1u << 20, &used);
  const double h = L.spacing[0];
  for (std::size_t q = 0; q < 2; ++q) {
    std::printf("[ step lines ] slot %zu: lattice %.2e off, located %.2e off\n", q,
                plain[q] - exact[q], located[q] - exact[q]);
    EXPECT_GT(std::fabs(plain[q] - exact[q]), 1e-4) << q;
    EXPECT_LE(std::fabs(located[q] - exact[q]), 4.0 * h * std::ldexp(1.0, -kMaxStepHalvings)) << q;
  }
  // The first halving alone needs one point per line the half plane's edge crosses (41).
  const auto [plain_capped, capped] = st.sums(L, 40, &used);
  EXPECT_EQ(used, 0u);
  EXPECT_EQ(capped, plain_capped);
  // A cap between levels stops at the last whole level within it.
  st.sums(L, 200, &used);
  EXPECT_LE(used, 200u);
  EXPECT_GT(used, 0u);
}

TEST(StepLines, AFailedEvaluationKeepsWhatWasLocatedBefore) {
  const Lattice<1> L(9, 0.0, 1.0);
  std::vector<double> v;
  for (const auto& x : L.x) {
    v.push_back(x[0] >= 0.3 ? 1.0 : 0.0);
    v.push_back(x[0] >= 0.3 ? 1.0 : 0.0);
  }
  std::vector<double> sums = {0.0};
  int calls = 0;
  const std::size_t used = locate_steps<1>(
      std::span<const std::array<double, 1>>(L.x), L.shape, L.spacing, L.lo, L.hi, v, 1,
      [&](std::span<const std::array<double, 1>> p, std::vector<double>& out) {
        if (++calls > 2) return false;
        for (std::size_t i = 0; i < p.size(); ++i) {
          out[2 * i] = p[i][0] >= 0.3 ? 1.0 : 0.0;
          out[2 * i + 1] = out[2 * i];
        }
        return true;
      },
      0.0, 100, sums);
  EXPECT_EQ(used, 2u);
  // Two halvings of [0.25, 0.375], then a failure: the jump at 0.3, which the lattice's
  // trapezoid rule put at 0.3125, is put at 0.296875, the midpoint of [0.28125, 0.3125]; the
  // sum (of 1 from the jump on) gains the difference.
  EXPECT_NEAR(sums[0], 0.3125 - 0.296875, 1e-15);
}

TEST(StepLines, HalvingStopsOnceWhatIsLeftIsWithinTheTarget) {
  // One jump of e^s on [0, 1], s = 1/√7, 33 nodes: what its segment can still be off by is
  // ℓ/2·e^s, 0.0284 on the lattice, halved by each halving; a target of 0.01 stops after two
  // (0.0071), a target above 0.0284 before any.
  auto st = exp_step();
  const Lattice<1> L(33, 0.0, 1.0);
  std::size_t used = 0;
  st.sums(L, 1000, &used, 0.01);
  EXPECT_EQ(used, 2u);
  st.sums(L, 1000, &used, 0.03);
  EXPECT_EQ(used, 0u);
}

}  // namespace
