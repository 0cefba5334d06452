// Validation: method=coherent (runtime/include/hybgen/rt/methods/coherent.hpp and its solve
// function in methods.hpp) through the whole pipeline — `hybgen run FILE` on .model files hybgen
// does not ship — against references that do not come from hybgen:
//   fold_halves.model    (written for the almost-invariant sets) a clock that applies a fold
//                        map g once per unit time; over one tick the pairs are exactly
//                        coherent: A = g⁻¹([0, 1/2]) with B = [0, 1/2], and its mirror image.
//                        The sets are checked against g computed here, the ratios against 1 and
//                        against samples pushed through g here;
//   two_cycles.model     (written for the almost-invariant sets) two thermostat cycles that
//                        never meet: each cycle is a pair carried exactly, its initial set in
//                        mode heat and its final set in both modes;
//   coherent_ball.model  two blobs of a bouncing ball with restitution 0.8: each blob and its
//                        image are a pair carried exactly; the images are checked by tracing
//                        every node back through the closed-form flight and bounce.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "support/e2e.hpp"
#include "support/fold_map.hpp"
#include "support/netcdf_series.hpp"

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_coherent");

/// tests/validation/models/`name`.model.
std::string model(const std::string& name) {
  return std::string(HYBGEN_SOURCE_DIR) + "/tests/validation/models/" + name + ".model";
}

/// Runs `name` with `sets` into its own directory: the summary, and run.nc's set_label
/// ([time][node], the two times 0 and t_end).
json run(const std::string& name, const std::string& sets, std::vector<int>& labels) {
  const fs::path dir = hybgen::testing::own_dir(kWork) / name;
  json s = hybgen::testing::run_summary(
      model(name), dir, "--set method=coherent " + sets + " --set outputs=netcdf+png",
      kWork / "cache");
  if (!s.is_null()) {
    labels = hybgen::testing::nc_ints(dir / "run.nc", "set_label");
    EXPECT_TRUE(fs::exists(dir / "sets.png"));
  }
  return s;
}

using hybgen::testing::fold;

TEST(CoherentPairs, AFoldMapsPairsAreThePreimagesOfTheHalves) {
  // Over one tick the transport is g in x (the identity in c), and the initial density is
  // uniform. g maps A = {x : g(x) < 1/2} into [0, 1/2] and its complement into [1/2, 1], so
  // (A, [0, 1/2]) and its mirror image are carried exactly: forward = backward = 1. A is
  // [0, 1/2] without (1/(12P), 1/6 + (P − 1/2)/(6P)), the points near 1/6 that g throws
  // above 1/2, with the mirror image of that interval: by the symmetry, each set has mass 1/2.
  // (The halves themselves, the almost-invariant sets, are carried with probability 0.939
  // only: g throws an interval of length (P − 1/2)/(3P) of each half over.)
  std::vector<int> label;
  const json s = run("fold_halves", "", label);
  ASSERT_FALSE(s.is_null());
  EXPECT_EQ(s["method"], "coherent");
  const json& c = s["coherent"];
  ASSERT_EQ(c["sets"].size(), 2u) << c.dump();
  ASSERT_EQ(s["times"].size(), 2u);
  EXPECT_EQ(s["times"][1].get<double>(), 1.0);
  // run.nc: set_label over (time, x, c), 240 × 5 nodes, x slowest.
  constexpr int nx = 240, nc = 5;
  ASSERT_EQ(label.size(), 2u * nx * nc);
  const auto at = [&](int frame, int i, int j) {
    return label[static_cast<std::size_t>((frame * nx + i) * nc + j)];
  };
  const double P = 0.55, dx = 1.0 / (nx - 1);
  const int left = at(1, nx / 4, 0), right = at(1, 3 * nx / 4, 0);
  EXPECT_GT(left, 0);
  EXPECT_GT(right, 0);
  EXPECT_NE(left, right);
  // The ends of A's pieces (and their mirror images), away from which every node is decided.
  const double a1 = 1.0 / (12.0 * P), a2 = 1.0 / 6.0 + (P - 0.5) / (6.0 * P);
  const std::array<double, 5> edges = {a1, a2, 0.5, 1.0 - a2, 1.0 - a1};
  int checked = 0;
  for (int i = 0; i < nx; ++i) {
    const double x = i * dx;
    for (int j = 0; j < nc; ++j) {
      EXPECT_EQ(at(0, i, j), at(0, i, 0)) << "x = " << x;
      EXPECT_EQ(at(1, i, j), at(1, i, 0)) << "x = " << x;
    }
    bool far = true;
    for (const double e : edges) far = far && std::fabs(x - e) > 1.5 * dx;
    if (far) {
      EXPECT_EQ(at(0, i, 0), fold(x, P) < 0.5 ? left : right) << "t = 0, x = " << x;
      ++checked;
    }
    if (std::fabs(x - 0.5) > 1.5 * dx) {
      EXPECT_EQ(at(1, i, 0), x < 0.5 ? left : right) << "t = 1, x = " << x;
    }
  }
  EXPECT_GT(checked, 200);
  // The ratios of the sets found, by samples pushed through g here: a sample's set is the
  // label of its nearest node (each node's dual cell), at t = 0 for x and at t = 1 for g(x).
  std::mt19937_64 rng(2026);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const auto set_at = [&](int frame, double x) {
    return at(frame, static_cast<int>(std::lround(x / dx)), 0);
  };
  constexpr int kSamples = 2000000;
  std::array<double, 3> in_a{}, in_b{}, both{};
  for (int n = 0; n < kSamples; ++n) {
    const double x = U(rng);
    const int a = set_at(0, x), b = set_at(1, fold(x, P));
    in_a[static_cast<std::size_t>(a)] += 1.0;
    in_b[static_cast<std::size_t>(b)] += 1.0;
    if (a == b) both[static_cast<std::size_t>(a)] += 1.0;
  }
  double coherence = 0.0;
  for (const json& pair : c["sets"]) {
    const auto k = pair["set"].get<std::size_t>();
    const double fwd = pair["forward"].get<double>(), bwd = pair["backward"].get<double>();
    const double fwd_bar = pair["forward_error"].get<double>();
    const double bwd_bar = pair["backward_error"].get<double>();
    const double fwd_ref = both[k] / in_a[k], bwd_ref = both[k] / in_b[k];
    // Binomial standard errors of the sample ratios.
    const double fwd_sigma = std::sqrt(fwd_ref * (1.0 - fwd_ref) / in_a[k]) + 1.0 / kSamples;
    const double bwd_sigma = std::sqrt(bwd_ref * (1.0 - bwd_ref) / in_b[k]) + 1.0 / kSamples;
    std::printf(
        "pair %zu: forward %.6f +/- %.1e (samples %.6f, exact sets 1), backward %.6f +/- %.1e "
        "(samples %.6f); masses %.6f, %.6f\n",
        k, fwd, fwd_bar, fwd_ref, bwd, bwd_bar, bwd_ref, pair["initial_mass"].get<double>(),
        pair["final_mass"].get<double>());
    // Against the exact sets' ratio 1: the bar covers the error and is not ten times wider.
    EXPECT_LE(1.0 - fwd, fwd_bar) << pair.dump();
    EXPECT_LE(fwd_bar, 10.0 * (1.0 - fwd)) << pair.dump();
    EXPECT_LE(1.0 - bwd, bwd_bar) << pair.dump();
    EXPECT_LE(bwd_bar, 10.0 * (1.0 - bwd)) << pair.dump();
    // Against the samples' ratios of the sets found.
    EXPECT_LE(std::fabs(fwd - fwd_ref), fwd_bar + 4.0 * fwd_sigma) << pair.dump();
    EXPECT_LE(std::fabs(bwd - bwd_ref), bwd_bar + 4.0 * bwd_sigma) << pair.dump();
    EXPECT_NEAR(pair["initial_mass"].get<double>(), 0.5, 1e-9) << pair.dump();
    EXPECT_NEAR(pair["final_mass"].get<double>(), 0.5, 1e-9) << pair.dump();
    coherence += std::sqrt(fwd_ref * bwd_ref);
  }
  // Better than the halves (forward = backward = 1 − leak), and within the bound of the
  // singular values.
  const double leak = (P - 0.5) / (3.0 * P) / 0.5;  // the fraction of a half thrown over
  const double halves = 2.0 * (1.0 - leak);
  EXPECT_GT(coherence, halves + 0.05) << c.dump();
  EXPECT_LE(c["coherence_sum"].get<double>(), c["bound"].get<double>() + 1e-9);
  EXPECT_TRUE(c["converged"].get<bool>());
}

TEST(CoherentPairs, TwoCyclesThatNeverMeetArePairsInBothModes) {
  // T' = 1 (heat) and T' = −1 (cool), switching at 2 and 1 in the lower cycle and at 4 and 3
  // in the upper one; the initial density is 1 in mode heat on both cycles' intervals. Over
  // t_end = 1 each cycle's mass stays in it (it moves to mode cool), so the pairs are the
  // cycles, carried exactly, with half the mass each.
  std::vector<int> label;
  const json s = run("two_cycles", "", label);
  ASSERT_FALSE(s.is_null());
  const json& c = s["coherent"];
  ASSERT_EQ(c["sets"].size(), 2u) << c.dump();
  double total = 0.0;
  for (const json& pair : c["sets"]) {
    EXPECT_NEAR(pair["forward"].get<double>(), 1.0, 1e-9) << pair.dump();
    EXPECT_NEAR(pair["backward"].get<double>(), 1.0, 1e-9) << pair.dump();
    EXPECT_NEAR(pair["initial_mass"].get<double>(), pair["final_mass"].get<double>(), 1e-12);
    // The exact mass of a cycle is 1 (the density 1 on an interval of length 1); the nodes'
    // trapezoid sum gives the cells at the interval's ends whole (1.025 on this grid), within
    // the bar (twice the halved grid's difference: 0.05), which is not ten times wider.
    const double m = pair["initial_mass"].get<double>();
    const double bar = pair["initial_mass_error"].get<double>();
    EXPECT_LE(std::fabs(m - 1.0), bar) << pair.dump();
    EXPECT_LE(bar, 10.0 * std::fabs(m - 1.0)) << pair.dump();
    EXPECT_EQ(pair["initial_mode_mass"]["cool"].get<double>(), 0.0) << pair.dump();
    EXPECT_GT(pair["final_mode_mass"]["cool"].get<double>(), 0.0) << pair.dump();
    total += pair["initial_mass"].get<double>();
  }
  EXPECT_NEAR(total, s["initial_mass"].get<double>(), 1e-12);
  EXPECT_GE(c["components"].get<int>(), 2) << c.dump();
  // run.nc: set_label over (time, mode, T), 161 nodes on [0.5, 4.5], spacing 0.025.
  constexpr int n = 161;
  ASSERT_EQ(label.size(), 2u * 2u * n);
  const auto at = [&](int frame, int mode, int i) {
    return label[static_cast<std::size_t>((frame * 2 + mode) * n + i)];
  };
  const auto node = [](double T) { return static_cast<int>(std::lround((T - 0.5) / 0.025)); };
  const int low = at(0, 0, node(1.5)), high = at(0, 0, node(3.5));
  EXPECT_GT(low, 0);
  EXPECT_GT(high, 0);
  EXPECT_NE(low, high);
  EXPECT_EQ(at(1, 1, node(1.5)), low);  // the cycles' mass is cooling at t = 1
  EXPECT_EQ(at(1, 1, node(3.5)), high);
  for (int frame = 0; frame < 2; ++frame)
    for (int m = 0; m < 2; ++m)
      for (int i = 0; i < n; ++i) {
        const double T = 0.5 + 0.025 * i;
        const int l = at(frame, m, i);
        const bool between = T < 0.95 || (T > 2.05 && T < 2.95) || T > 4.05;
        if (between || (frame == 0 && m == 1)) {
          EXPECT_EQ(l, 0) << "frame " << frame << ", mode " << m << ", T = " << T;
        } else if (l != 0 && T > 1.05 && T < 1.95) {
          EXPECT_EQ(l, low) << "frame " << frame << ", mode " << m << ", T = " << T;
        } else if (l != 0 && T > 3.05 && T < 3.95) {
          EXPECT_EQ(l, high) << "frame " << frame << ", mode " << m << ", T = " << T;
        }
      }
}

/// The bouncing ball of coherent_ball.model (x' = p, p' = −1; at x = 0 with p < 0, p ↦ −e p)
/// traced BACK from (x, p) over the time `t`, in closed form: the foot of the characteristic.
std::array<double, 2> ball_foot(double x, double p, double t, double e) {
  // Backward in time τ: x(τ) = x − p τ − τ²/2, p(τ) = p + τ; it meets the ground (x = 0,
  // moving up in forward time) at τ = −p + √(p² + 2x), where the bounce is undone:
  // p = −p(τ)/e (the velocity before the impact).
  for (int bounce = 0; bounce < 1000 && t > 0.0; ++bounce) {
    const double hit = -p + std::sqrt(p * p + 2.0 * std::max(x, 0.0));
    if (hit >= t || !(hit > 0.0 || p > 0.0)) {
      x = x - p * t - 0.5 * t * t, p = p + t;
      return {x, p};
    }
    p = -(p + hit) / e, x = 0.0, t -= hit;
  }
  return {x, p};
}

TEST(CoherentPairs, TwoBlobsOfABouncingBallAreCarriedWhole) {
  // dt = 0.5 asks for output times that the method does not take: it transports over
  // [0, t_end] in one step and writes the two ends.
  std::vector<int> label;
  const json s = run("coherent_ball", "--set dt=0.5", label);
  ASSERT_FALSE(s.is_null());
  const json& c = s["coherent"];
  EXPECT_EQ(c["step"].get<double>(), 2.0) << c.dump();
  ASSERT_EQ(s["times"].size(), 2u);
  ASSERT_EQ(c["sets"].size(), 2u) << c.dump();
  constexpr int n = 161;
  ASSERT_EQ(label.size(), 2u * n * n);
  const double dx = 2.0 / (n - 1), dp = 4.0 / (n - 1), r = 0.25, e = 0.8, t_end = 2.0;
  const std::array<std::array<double, 2>, 2> centre = {{{1.2, 0.0}, {0.5, 1.0}}};
  const auto distance = [&](std::size_t blob, double x, double p) {
    return std::hypot(x - centre[blob][0], p - centre[blob][1]);
  };
  const auto at = [&](int frame, int i, int j) {
    return label[static_cast<std::size_t>((frame * n + i) * n + j)];
  };
  // Pair 1 is the heavier blob (unit mass), pair 2 the other (1/2): pairs are ranked by mass.
  for (const json& pair : c["sets"]) {
    const auto k = pair["set"].get<std::size_t>();
    const double mass = k == 1 ? 1.0 : 0.5;
    // Carried whole: no mass of the blob ends elsewhere, none of another comes in.
    EXPECT_NEAR(pair["forward"].get<double>(), 1.0, 1e-9) << pair.dump();
    EXPECT_NEAR(pair["backward"].get<double>(), 1.0, 1e-9) << pair.dump();
    // The masses: the nodes' quadrature of the blob, at both times (no mass leaves the box).
    // The bar is first order (twice the halved grid's difference), the quadrature of the C¹
    // blob converges faster: the bar covers the error and stays within 1e-3 of the mass.
    for (const char* key : {"initial_mass", "final_mass"}) {
      const double m = pair[key].get<double>();
      const double bar = pair[std::string(key) + "_error"].get<double>();
      std::printf("pair %zu: %s %.8f +/- %.1e (exact %.1f)\n", k, key, m, bar, mass);
      EXPECT_LE(std::fabs(m - mass), bar) << pair.dump();
      EXPECT_LE(bar, 1e-3 * mass) << pair.dump();
    }
  }
  EXPECT_GE(c["components"].get<int>(), 2) << c.dump();
  EXPECT_NEAR(c["bound"].get<double>(), 2.0, 1e-9);
  // At t = 0 the pairs' sets are the blobs (a margin of 2 % of the radius where the density
  // falls below the floor of coherent.hpp).
  const auto blob_of = [&](double x, double p) {
    for (std::size_t b = 0; b < 2; ++b)
      if (distance(b, x, p) < 0.98 * r) return static_cast<int>(b + 1);
    return distance(0, x, p) > r && distance(1, x, p) > r ? 0 : -1;
  };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const int want = blob_of(i * dx, -2.0 + j * dp);
      if (want >= 0) {
        EXPECT_EQ(at(0, i, j), want) << "t = 0, x = " << i * dx << ", p = " << -2.0 + j * dp;
      }
    }
  // At t_end: a node whose neighbourhood (a cell each way) traces back into blob k lies in
  // the image of blob k, and must carry label k; a node that carries label k must lie within
  // a cell of that image (the hat deposit spreads a sample's mass to the nodes around it),
  // so some point within a cell of it traces back into blob k dilated by a cell.
  int inside = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double x = i * dx, p = -2.0 + j * dp;
      std::array<bool, 2> all_in = {true, true}, any_near = {false, false};
      for (const double a : {-1.0, -0.5, 0.0, 0.5, 1.0})
        for (const double b : {-1.0, -0.5, 0.0, 0.5, 1.0}) {
          const double y = std::max(x + a * dx, 0.0), q = p + b * dp;
          const std::array<double, 2> foot = ball_foot(y, q, t_end, e);
          for (std::size_t k = 0; k < 2; ++k) {
            const double d = distance(k, foot[0], foot[1]);
            all_in[k] = all_in[k] && d < 0.98 * r;
            any_near[k] = any_near[k] || d < r + dp;
          }
        }
      const int l = at(1, i, j);
      for (std::size_t k = 0; k < 2; ++k)
        if (all_in[k]) {
          EXPECT_EQ(l, static_cast<int>(k + 1)) << "t = 2, x = " << x << ", p = " << p;
          ++inside;
        }
      if (l > 0) {
        EXPECT_TRUE(any_near[static_cast<std::size_t>(l - 1)])
            << "t = 2, x = " << x << ", p = " << p << " carries pair " << l;
      }
    }
  EXPECT_GT(inside, 300);
}

}  // namespace
