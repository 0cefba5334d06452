// run_record.hpp: what a distributed run's writers rely on. A marginal summed from the parts
// of any split of the nodes is the marginal of the whole (to rounding), the figure pairs are
// the setting's, and a guard's planes come out the same from any split of the nodes and
// are drawn exactly where its surface function does not depend on the other axes.

#include "hybgen/rt/io/run_record.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

namespace {

using hybgen::rt::figure_pairs;
using hybgen::rt::GridAxis;
using hybgen::rt::GuardPlanes;
using hybgen::rt::marginal;
using hybgen::rt::marginal_part;

const std::vector<GridAxis> kAxes{{0.0, 1.0, 5}, {-1.0, 1.0, 4}, {0.0, 2.0, 3}};

/// A function of the nodes of kAxes, C order.
std::vector<double> field(double (*f)(double, double, double)) {
  std::vector<double> u;
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 3; ++k) u.push_back(f(0.25 * i, -1.0 + 2.0 * j / 3.0, 1.0 * k));
  return u;
}

TEST(RunRecord, MarginalsOfPartsSumToTheMarginalOfTheWhole) {
  const std::vector<double> u =
      field([](double x, double y, double z) { return 1.0 + x * x + std::sin(y) * z; });
  for (const std::vector<std::size_t>& keep :
       {std::vector<std::size_t>{}, {0}, {2}, {0, 1}, {2, 0}, {0, 1, 2}}) {
    const std::vector<double> whole = marginal(u, kAxes, keep);
    for (std::size_t cut : {0u, 1u, 7u, 30u, 59u, 60u}) {
      std::vector<double> sum = marginal_part(std::span(u).subspan(0, cut), 0, kAxes, keep);
      const std::vector<double> rest = marginal_part(std::span(u).subspan(cut), cut, kAxes, keep);
      ASSERT_EQ(sum.size(), whole.size());
      for (std::size_t i = 0; i < sum.size(); ++i) {
        sum[i] += rest[i];
        EXPECT_NEAR(sum[i], whole[i], 1e-14 * (1.0 + std::fabs(whole[i]))) << "cut " << cut;
      }
    }
  }
  // The integral of 1 is the box's volume, 1 · 2 · 2.
  const std::vector<double> one(60, 1.0);
  EXPECT_NEAR(marginal(one, kAxes, {}).front(), 4.0, 1e-14);
}

TEST(RunRecord, FigurePairsAreThoseOfTheSettingOrEveryAxis) {
  using Pairs = std::vector<std::pair<std::size_t, std::size_t>>;
  EXPECT_EQ(figure_pairs(3, {}), (Pairs{{0, 1}, {0, 2}, {1, 2}}));
  EXPECT_EQ(figure_pairs(4, {3, 1}), (Pairs{{3, 1}}));
  EXPECT_EQ(figure_pairs(2, {1}), (Pairs{{0, 1}}));
  EXPECT_TRUE(figure_pairs(1, {}).empty());
}

TEST(RunRecord, GuardPlanesAreDrawnWhereTheGuardDependsOnThePairOnly) {
  // s = x − 0.5: drawn on (x, y) and (x, z), not on (y, z), where it varies with x.
  const std::vector<double> s = field([](double x, double, double) { return x - 0.5; });
  const auto pairs = figure_pairs(3, {});
  GuardPlanes whole(kAxes, pairs);
  whole.add(0, s);
  EXPECT_FALSE(whole.plane(0).empty());
  EXPECT_FALSE(whole.plane(1).empty());
  EXPECT_TRUE(whole.plane(2).empty());
  // On (x, y): s at the node (x_i, y_j) is x_i − 0.5 whatever z.
  const std::vector<double> p = whole.plane(0);
  ASSERT_EQ(p.size(), 20u);
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 4; ++j)
      EXPECT_DOUBLE_EQ(p[static_cast<std::size_t>(i * 4 + j)], 0.25 * i - 0.5);
  // Two ranks' pieces, combined as the runner combines them (the maximum of the negated
  // extremes), give the same planes.
  GuardPlanes a(kAxes, pairs), b(kAxes, pairs);
  a.add(0, std::span(s).subspan(0, 23));
  b.add(23, std::span(s).subspan(23));
  std::vector<double> va = a.negated_extremes();
  const std::vector<double> vb = b.negated_extremes();
  for (std::size_t i = 0; i < va.size(); ++i) va[i] = std::max(va[i], vb[i]);
  a.set_negated_extremes(va);
  for (std::size_t q = 0; q < pairs.size(); ++q) EXPECT_EQ(a.plane(q), whole.plane(q)) << q;
  // A guard that depends on z by more than 1e-9 of its range is not drawn on (x, y).
  const std::vector<double> t =
      field([](double x, double, double z) { return x - 0.5 + 1e-6 * z; });
  GuardPlanes tilted(kAxes, pairs);
  tilted.add(0, t);
  EXPECT_TRUE(tilted.plane(0).empty());
  EXPECT_FALSE(tilted.plane(1).empty());
}

}  // namespace
