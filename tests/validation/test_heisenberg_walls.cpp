// Validation through `hybgen run` of a reduced Lie-group model: the Heisenberg group with
// inelastic walls, tests/validation/models/heisenberg_walls.model, against a backward tracer
// written here from the group's structure alone (no derived equation of hybgen's is used).
//
// The group: g(x, y, z) = [[1, x, z], [0, 1, y], [0, 0, 1]], E_x = e₁₂, E_y = e₂₃, E_z = e₁₃,
// [E_x, E_y] = e₁₃ = E_z, the other brackets 0. For the left-invariant h(ζ) = |ζ|²/2 the body
// momenta follow Lie–Poisson, ζ' = ad*_{∂h/∂ζ} ζ, (ad*_ξ ζ)(η) = ζ([ξ, η]) with ξ = ζ:
//   ζ_x' = ζ([ξ, E_x]) = −ζ_y ζ_z,  ζ_y' = ζ([ξ, E_y]) = ζ_x ζ_z,  ζ_z' = 0,
// and q = x (a homomorphism: x(g g') = x + x') moves by ġ = g ξ: q' = ξ^x = ζ_x. So ζ_z = c is
// constant, (ζ_x, ζ_y) turns at rate c and q integrates ζ_x in closed form (`flow`). The walls
// q = ±1 (cosets of the normal subgroup K = {x = 0}) reset ζ ↦ ζ − (1 + e)(ζ·dφ)dφ/|dφ|²,
// dφ = dx = (1, 0, 0): ζ_x ↦ −e ζ_x. div X = 0 (∂ζ_x'/∂ζ_x = ∂ζ_y'/∂ζ_y = 0). Across a wall
// the mass flux is continuous: the states dζ at ζ_x on the wall, crossing at the rate
// u⁻|ζ_x| dζ, land on e dζ at −e ζ_x and leave at the rate u⁺ e|ζ_x| e dζ, so u⁺ = u⁻/e²
// (J = e², as derive prints it). Hence u(t, s) = u0(s0)/e^{2k}, s0 the backward trace of s
// through k walls.
//
// Nodes left out (counted): on a wall (|q| = 1, two-valued), traces whose last wall is
// within 1e-9 of t = 0 (a tie), and traces that graze a wall (|ζ_x| < 1e-3 there, or |q|
// within 1e-4 of 1 without crossing between the scan's points).

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/cycle_closed_forms.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using State = std::array<double, 4>;  // (ζ_x, ζ_y, ζ_z, q)

const fs::path kWork = hybgen::testing::e2e_dir("validation_heisenberg_walls");
const std::string kModel =
    std::string(HYBGEN_SOURCE_DIR) + "/tests/validation/models/heisenberg_walls.model";
constexpr double kE = 0.8;
constexpr std::array<int, 4> kNodes{13, 13, 9, 17};
constexpr std::array<double, 4> kLo{-1.5, -1.5, -1.5, -1.0}, kHi{1.5, 1.5, 1.5, 1.0};

double u0(const State& s) {
  return std::exp(-2 * (s[0] - 0.5) * (s[0] - 0.5) - 2 * s[1] * s[1] -
                  2 * (s[2] - 0.5) * (s[2] - 0.5) - 4 * s[3] * s[3]);
}

/// The flow over time h (either sign): the rotation of (ζ_x, ζ_y) by c h and q + ∫ζ_x.
State flow(const State& s, double h) {
  const double c = s[2], C = std::cos(c * h), S = std::sin(c * h);
  State r{s[0] * C - s[1] * S, s[0] * S + s[1] * C, c, 0.0};
  if (std::fabs(c * h) > 1e-6)
    r[3] = s[3] + (s[0] * S + s[1] * (C - 1)) / c;
  else  // sin(ch)/c and (cos(ch) − 1)/c by their series
    r[3] = s[3] + s[0] * h * (1 - c * c * h * h / 6) - s[1] * c * h * h / 2;
  return r;
}

/// u(t, s) by the backward trace through `walls` impacts; false if the node is undecidable
/// (the file comment).
bool density(State s, double t, double& u, int& walls) {
  double factor = 1.0, left = t;
  for (walls = 0; walls <= 50; ++walls) {
    // The first backward time τ ≤ left at which |q| reaches 1: a scan, then bisection.
    // A local maximum of |q| within 1e-4 of 1 between scan points is a graze: undecidable.
    constexpr double kScan = 2e-3;
    double a = 0.0, hit = -1.0, q1 = std::fabs(s[3]), q2 = -1.0;
    for (double b = kScan;; b += kScan) {
      const double tb = std::min(b, left);
      const double qb = std::fabs(flow(s, -tb)[3]);
      if (qb >= 1.0) {
        hit = tb;
        break;
      }
      if (q1 > q2 && q1 >= qb && q1 > 1.0 - 1e-4 && a > 0.0) return false;
      q2 = q1, q1 = qb;
      a = tb;
      if (tb >= left) break;
    }
    if (hit < 0) {
      u = factor * u0(flow(s, -left));
      return true;
    }
    for (int i = 0; i < 100; ++i) {
      const double m = 0.5 * (a + hit);
      (std::fabs(flow(s, -m)[3]) >= 1.0 ? hit : a) = m;
    }
    if (left - hit < 1e-9) return false;  // the trace ends on a wall: a tie
    State w = flow(s, -hit);
    if (std::fabs(w[0]) < 1e-3) return false;  // a nearly tangent impact
    w[3] = w[3] > 0 ? 1.0 : -1.0;
    w[0] = -w[0] / kE;  // Δ⁻¹ on the wall: the state before the impact
    factor /= kE * kE;
    s = w;
    left -= hit;
  }
  return false;
}

TEST(HeisenbergWalls, CharacteristicsAreTheBracketsBackwardTraceAtEveryNode) {
  const nlohmann::json sum =
      hybgen::testing::run_summary(kModel, hybgen::testing::own_dir(kWork) / "run",
                                   "--set outputs=npy --set values=nodes", kWork / "cache");
  ASSERT_FALSE(sum.is_null());
  const auto times = sum["times"].get<std::vector<double>>();
  ASSERT_EQ(times.size(), 5u);
  std::size_t total = 1;
  for (const int n : kNodes) total *= static_cast<std::size_t>(n);
  for (std::size_t k = 0; k < times.size(); ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "u_%04zu.npy", k);
    const std::vector<double> uh =
        hybgen::rt::read_npy((hybgen::testing::own_dir(kWork) / "run" / name).string()).data;
    ASSERT_EQ(uh.size(), total);
    double num = 0, den = 0, worst = 0, top = 0;
    long left_out = 0, walls_crossed = 0;
    for (std::size_t i = 0; i < total; ++i) {
      State s{};
      std::size_t rem = i;
      bool on_wall = false;
      for (std::size_t a = 4; a-- > 0;) {
        const int n = kNodes[a];
        const auto j = static_cast<int>(rem % static_cast<std::size_t>(n));
        rem /= static_cast<std::size_t>(n);
        s[a] = hybgen::testing::grid_node(kLo[a], kHi[a], n, j);
        if (a == 3 && (j == 0 || j == n - 1)) on_wall = true;
      }
      double ur = 0;
      int walls = 0;
      if (on_wall || !density(s, times[k], ur, walls)) {
        ++left_out;
        continue;
      }
      walls_crossed += walls > 0 ? 1 : 0;
      num += std::fabs(uh[i] - ur), den += std::fabs(ur);
      worst = std::max(worst, std::fabs(uh[i] - ur));
      top = std::max(top, std::fabs(ur));
    }
    std::printf(
        "[ heisenberg walls ] t = %g: relative L1 %.2e, largest difference %.2e of the frame's "
        "maximum %.3f; %ld nodes left out, %ld traced through a wall\n",
        times[k], num / den, worst / top, top, left_out, walls_crossed);
    EXPECT_LE(num / den, 1e-8) << "t = " << times[k];
    EXPECT_LE(worst, 1e-7 * top) << "t = " << times[k];
    EXPECT_LT(left_out, static_cast<long>(total / 5)) << "t = " << times[k];
    if (k > 0) {
      EXPECT_GT(walls_crossed, 100) << "t = " << times[k];  // the walls are tested
    }
  }
}

}  // namespace
