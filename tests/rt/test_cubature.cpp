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

}  // namespace
