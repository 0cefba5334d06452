// The adaptive cubature's per-root integrals (runtime/include/hybgen/rt/methods/budget/
// cubature.hpp, `per_root`), on which the cell averages of characteristics rest
// (budget/cell_averages.hpp): each root box's integral with its own error estimate, the stop
// test on their L1 sum, and check points handed to their roots by hint.
//
// The integrand is a narrow normal density in 2-D, N((0.3, 0.61), 0.02²·I) (slot 0) and the
// same centred at (0.555, 0.125) (slot 1), over the 10 × 10 dual cells of an 11 × 11 grid on
// [0, 1]²: a cell holds the product of the normal distribution function's differences over
// its sides, in closed form. The first centre is 0.5σ from a node: with the two-node Gauss rule
// (order 2) its cell's nodes straddle it symmetrically in x, the null rule sees nothing along
// x, the cell is split along y only, and the estimate was 6e-5 against an L1 error of 0.28;
// the three-node rule that the cell averages use has the centre among its nodes.
//
// The same blindness at the budget's own order (4 nodes per axis) in 4-D: a Gaussian even
// about the box's centre along an axis has no degree-3 component along it; from one initial
// cell the null rule never split the box along that axis (AFourDimensionalGaussianIsSeenFrom
// TheFirstLevel).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include "hybgen/rt/methods/budget/cubature.hpp"

namespace {

using hybgen::rt::AdaptiveOptions;
using hybgen::rt::detail::AdaptiveCubature;
using hybgen::rt::detail::Cell;
using hybgen::rt::detail::CheckPoints;

constexpr double kSigma = 0.02;
constexpr std::array<std::array<double, 2>, 2> kCentre = {{{0.3, 0.61}, {0.555, 0.125}}};

double normal(double x, double c) {
  return std::exp(-0.5 * (x - c) * (x - c) / (kSigma * kSigma)) / (std::sqrt(2 * M_PI) * kSigma);
}
double normal_cdf(double x, double c) {
  return 0.5 * std::erfc(-(x - c) / (kSigma * std::sqrt(2.0)));
}

/// Both slots at a batch's points: U[i·2 + k].
struct Gaussians {
  std::size_t points = 0;  ///< Points evaluated.
  bool operator()(std::span<const Cell<2>>, std::span<const std::array<double, 2>> pts, std::size_t,
                  std::vector<double>& U) {
    for (std::size_t i = 0; i < pts.size(); ++i)
      for (std::size_t k = 0; k < 2; ++k)
        U[i * 2 + k] = normal(pts[i][0], kCentre[k][0]) * normal(pts[i][1], kCentre[k][1]);
    points += pts.size();
    return true;
  }
};

/// The dual cells of the 11 × 11 grid on [0, 1]² (spacing 0.1), in C order.
std::vector<Cell<2>> dual_cells() {
  std::vector<Cell<2>> roots;
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 10; ++j) {
      Cell<2> c;
      const std::array<double, 2> y = {0.1 * i, 0.1 * j};
      for (std::size_t a = 0; a < 2; ++a) {
        c.lo[a] = std::max(0.0, y[a] - 0.05);
        c.hi[a] = std::min(1.0, y[a] + 0.05);
      }
      roots.push_back(c);
    }
  return roots;
}

/// The grid's nodes with both slots' values, hinted to their own dual cells when `hint`.
CheckPoints<2> node_checks(bool hint) {
  CheckPoints<2> checks;
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 10; ++j) {
      const std::array<double, 2> y = {0.1 * i, 0.1 * j};
      checks.x.push_back(y);
      for (std::size_t k = 0; k < 2; ++k)
        checks.v.push_back(normal(y[0], kCentre[k][0]) * normal(y[1], kCentre[k][1]));
      if (hint) checks.root.push_back(checks.x.size() - 1);
    }
  checks.spacing = {0.1, 0.1};
  return checks;
}

TEST(Cubature, PerRootIntegralsCarryErrorsThatCoverTheirL1Error) {
  AdaptiveOptions aopt;
  aopt.rel_tol = 1e-4;
  aopt.order = 3;
  aopt.root_parts = 1;
  aopt.max_points = 200000;
  const std::vector<Cell<2>> roots = dual_cells();
  const CheckPoints<2> checks = node_checks(true);
  Gaussians values;
  AdaptiveCubature<2, Gaussians> cub(roots, 2, 2, aopt, 1.0, values, &checks, 0, true);
  ASSERT_TRUE(cub.run());
  EXPECT_TRUE(cub.converged());
  for (std::size_t k = 0; k < 2; ++k) {
    double l1 = 0.0, sum = 0.0;
    for (std::size_t r = 0; r < roots.size(); ++r) {
      const Cell<2>& c = roots[r];
      double exact = 1.0;
      for (std::size_t a = 0; a < 2; ++a)
        exact *= normal_cdf(c.hi[a], kCentre[k][a]) - normal_cdf(c.lo[a], kCentre[k][a]);
      l1 += std::fabs(cub.root_integral(r, k) - exact);
      sum += cub.root_integral(r, k);
    }
    std::printf("[ cubature ] slot %zu: L1 error %.3e, estimate %.3e (%.1fx), %zu points\n", k, l1,
                cub.l1_error(k), cub.l1_error(k) / l1, cub.points());
    EXPECT_LE(l1, cub.l1_error(k));        // covered
    EXPECT_LE(cub.l1_error(k), 1e-4);      // the target: rel_tol × scale
    EXPECT_LE(cub.l1_error(k), 100 * l1);  // and not absurdly wide
    EXPECT_NEAR(sum, cub.integral(k), 1e-12);
  }
}

TEST(Cubature, HintedCheckPointsGoWhereAScanPutsThem) {
  AdaptiveOptions aopt;
  aopt.rel_tol = 1e-3;
  aopt.order = 3;
  aopt.root_parts = 1;
  const std::vector<Cell<2>> roots = dual_cells();
  const CheckPoints<2> hinted = node_checks(true), scanned = node_checks(false);
  Gaussians v1, v2;
  AdaptiveCubature<2, Gaussians> a(roots, 2, 2, aopt, 1.0, v1, &hinted, 0, true);
  AdaptiveCubature<2, Gaussians> b(roots, 2, 2, aopt, 1.0, v2, &scanned, 0, true);
  ASSERT_TRUE(a.run());
  ASSERT_TRUE(b.run());
  EXPECT_EQ(v1.points, v2.points);
  for (std::size_t r = 0; r < roots.size(); ++r)
    for (std::size_t k = 0; k < 2; ++k) {
      EXPECT_EQ(a.root_integral(r, k), b.root_integral(r, k)) << r;
      EXPECT_EQ(a.root_error(r, k), b.root_error(r, k)) << r;
    }
}

/// A 4-D Gaussian exp(−Σ_a w_a (x_a − c_a)²) on the box [lo, hi].
struct Gaussian4 {
  std::array<double, 4> c, w, lo, hi;
  double at(const std::array<double, 4>& x) const {
    double s = 0.0;
    for (std::size_t a = 0; a < 4; ++a) s += w[a] * (x[a] - c[a]) * (x[a] - c[a]);
    return std::exp(-s);
  }
  double exact() const {  // the product of the axes' erf integrals
    double v = 1.0;
    for (std::size_t a = 0; a < 4; ++a) {
      const double r = std::sqrt(w[a]);
      v *= std::sqrt(M_PI) / (2.0 * r) *
           (std::erf(r * (hi[a] - c[a])) - std::erf(r * (lo[a] - c[a])));
    }
    return v;
  }
};

/// Its values at a batch's points (one slot).
struct Gaussian4Values {
  const Gaussian4* g = nullptr;
  bool operator()(std::span<const Cell<4>>, std::span<const std::array<double, 4>> pts, std::size_t,
                  std::vector<double>& U) {
    for (std::size_t i = 0; i < pts.size(); ++i) U[i] = g->at(pts[i]);
    return true;
  }
};

// The budget's settings at budget=fast (methods.hpp: 20000 points, rel_tol 1e-2, order 4) on
// 4-D Gaussians with the nodes of a 7⁴ grid as check points. The first is the initial density
// of the differential campaign's random model 2531 (tests/support/random_run_model.hpp), centred
// 0.01 from the box's centre along x0: when the first level of cells could take only a quarter
// of the cap, it was ONE cell, and the cubature stopped "converged" at 0.3005 against 0.3357
// with an estimate of 4.3e-3 (8× short), never having split x0. The others were not built
// around the fix: one centred exactly on every axis (0.2080 against 0.2736 with an estimate of
// 2.7e-5 before), one off centre. From 2⁴ initial cells all three are within 1e-4; all stop
// at the point cap, where the estimate is the discrepancies of the last parents (the file
// comment of cubature.hpp), wide where the leaves' rule is far better than their parents':
// measured 209×, 910× and 50× the error, the second 3.9e-2 of a mass 0.27 — the cap's known
// cost, bounded here at 2000×.
TEST(Cubature, AFourDimensionalGaussianIsSeenFromTheFirstLevel) {
  const std::array<Gaussian4, 3> cases = {{
      {{1.01, -0.33, -0.55, -1.07}, {2.8, 7.2, 5.7, 7.5}, {-0.5, -2, -1.5, -2}, {2.5, 1, 0.5, 0.5}},
      {{0, 0, 0, 0}, {6, 6, 6, 6}, {-1, -1, -1, -1}, {1, 1, 1, 1}},
      {{0.3, 0.7, 0.45, 0.2}, {20, 8, 40, 12}, {0, 0, 0, 0}, {1, 1, 1, 1}},
  }};
  for (const Gaussian4& g : cases) {
    AdaptiveOptions aopt;
    aopt.rel_tol = 1e-2;
    aopt.max_points = 20000;
    CheckPoints<4> checks;
    for (std::size_t a = 0; a < 4; ++a) checks.spacing[a] = (g.hi[a] - g.lo[a]) / 6;
    for (int i = 0; i < 7 * 7 * 7 * 7; ++i) {
      std::array<double, 4> y{};
      for (std::size_t a = 0, r = static_cast<std::size_t>(i); a < 4; ++a, r /= 7)
        y[a] = g.lo[a] + static_cast<double>(r % 7) * checks.spacing[a];
      checks.x.push_back(y);
      checks.v.push_back(g.at(y));
    }
    Cell<4> root;
    root.lo = g.lo;
    root.hi = g.hi;
    Gaussian4Values values{&g};
    AdaptiveCubature<4, Gaussian4Values> cub({root}, 1, 1, aopt, 0.0, values, &checks);
    ASSERT_TRUE(cub.run());
    const double err = std::fabs(cub.integral(0) - g.exact());
    std::printf("[ cubature ] 4-D Gaussian: %.6f against %.6f, error %.2e, estimate %.2e (%.1fx)\n",
                cub.integral(0), g.exact(), err, cub.error(0), cub.error(0) / err);
    EXPECT_LE(err, cub.error(0));         // covered
    EXPECT_LE(err, 1e-3 * g.exact());     // measured: 2.2e-4 of the mass at most
    EXPECT_LE(cub.error(0), 2000 * err);  // and not wider than measured
  }
}

}  // namespace
