// Validation of the cell averages of characteristics (the setting `values`;
// runtime/include/hybgen/rt/methods/budget/cell_averages.hpp) through the whole pipeline:
// `hybgen run` on .model files whose flows concentrate the density far below the grid's
// spacing, the frames read back from the .npy files, against cell masses in closed form.
//
// The models are clocks x' = 1 on the circle [0, 1) (support x ≥ 0) whose reset at x = 1
// sends x to 0 and contracts another coordinate; with k the turns a point at (t, x) has made
// since time 0 (the k with x − t + k ∈ [0, 1)) and g(s) = 1 + cos(2πs)/2:
//  * tests/validation/models/contracting_wrap.model (2-D): y' = 0, reset y ↦ y/2 (|J| = 1/2),
//        u(t, x, y) = g(x − t + k) · 2^k h(2^k y),
//  * tests/validation/models/contracting_clock_3d.model (3-D): y' = −y, z' = 0, reset
//    z ↦ z/2 (divergence −1),
//        u(t, x, y, z) = g(x − t + k) · e^t h(e^t y) · 2^k h(2^k z),
// with h the normal density of standard deviation σ = 0.3 over the whole line (the mass with
// |y| > 1 at t = 0 is outside the grid box, and the resets carry some of it in). A dual cell
// C = [x₀, x₁] × Π[a, b] then holds, exactly,
//     m(C) = Σ_pieces (G(x − t + k)|_{x₀'}^{x₁'}) · Π_axes (Φ(s·b/σ) − Φ(s·a/σ)),
// over the pieces of [x₀, x₁] on which k is constant (k changes where x − t is an integer:
// there the density jumps, and a cell may straddle the jump), with G(s) = s + sin(2πs)/(4π)
// the primitive of g, Φ the standard normal distribution function and s the axis's scale
// (2^k, or e^t).
//
// Asserted, per frame: the cell averages' relative L1 error Σ|m − m_exact|/Σ m_exact is below
// the estimate in summary.json's values.error (coverage) and below the tolerance, and the
// estimate is at most 50× the error or within the tolerance (1e-2 of the mass with the
// default budget=fast, 3e-4 with budget=full). The cubature stops once its estimate is below
// the tolerance, and the estimate is of the coarser level's error (budget/cubature.hpp), so
// where the three-node rule converges fast the true error is far below it (4.8e-7 against
// 3.6e-3 at t = 3 with budget=fast). The node values of the same run (values=nodes) miss by
// orders of magnitude more: the reason the cell averages exist.

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_cell_averages");
const fs::path kCache = kWork / "cache";
const std::string kModels = std::string(HYBGEN_SOURCE_DIR) + "/tests/validation/models/";
constexpr double kSigma = 0.3;
constexpr double kPi = 3.14159265358979323846;

/// `hybgen run MODEL --quiet EXTRA` with .npy frames into its own directory: summary.json
/// (null when the run failed; the output is in the test's message).
json run(const std::string& model, const std::string& tag, const std::string& extra) {
  return hybgen::testing::run_summary(kModels + model + ".model",
                                      hybgen::testing::own_dir(kWork) / tag,
                                      "--set outputs=npy " + extra, kCache);
}

/// Φ, the standard normal distribution function.
double normal_cdf(double s) {
  return 0.5 * std::erfc(-s / std::sqrt(2.0));
}

/// The primitive of g(s) = 1 + cos(2πs)/2.
double clock_primitive(double s) {
  return s + std::sin(2.0 * kPi * s) / (4.0 * kPi);
}

/// One model of the family: its file, its grid and, for k turns at time t, the scale of each
/// transverse axis (u's factor along it is scale·h(scale·y)).
struct Clock {
  std::string model;
  std::vector<int> nodes;  ///< Nodes per axis, x first; x ∈ [0, 1], the others [−1, 1].
  double (*scale)(std::size_t axis, int k, double t);
};

/// The exact mass of the dual cell of node `flat` at time t (the file comment).
double cell_mass(const Clock& c, std::size_t flat, double t) {
  const std::size_t D = c.nodes.size();
  std::vector<double> lo(D), hi(D);
  std::size_t rem = flat;
  for (std::size_t a = D; a-- > 0;) {
    const int n = c.nodes[a];
    const auto i = static_cast<int>(rem % static_cast<std::size_t>(n));
    rem /= static_cast<std::size_t>(n);
    const double min = a == 0 ? 0.0 : -1.0, max = 1.0, h = (max - min) / (n - 1);
    const double y = min + i * h;
    lo[a] = std::max(min, y - h / 2), hi[a] = std::min(max, y + h / 2);
  }
  // The pieces of [lo0, hi0] between the points where x − t is an integer.
  std::vector<double> cuts{lo[0]};
  for (double x = std::ceil(lo[0] - t) + t; x < hi[0]; x += 1.0)
    if (x > lo[0]) cuts.push_back(x);
  cuts.push_back(hi[0]);
  double m = 0.0;
  for (std::size_t p = 0; p + 1 < cuts.size(); ++p) {
    const double mid = 0.5 * (cuts[p] + cuts[p + 1]);
    const int k = static_cast<int>(std::ceil(t - mid));  // x − t + k ∈ [0, 1)
    double f = clock_primitive(cuts[p + 1] - t + k) - clock_primitive(cuts[p] - t + k);
    for (std::size_t a = 1; a < D; ++a) {
      const double s = c.scale(a, k, t) / kSigma;
      f *= normal_cdf(s * hi[a]) - normal_cdf(s * lo[a]);
    }
    m += f;
  }
  return m;
}

/// The volume of the dual cell of node `flat` (the trapezoid weight).
double cell_volume(const Clock& c, std::size_t flat) {
  double v = 1.0;
  std::size_t rem = flat;
  for (std::size_t a = c.nodes.size(); a-- > 0;) {
    const int n = c.nodes[a];
    const auto i = static_cast<int>(rem % static_cast<std::size_t>(n));
    rem /= static_cast<std::size_t>(n);
    const double h = (a == 0 ? 1.0 : 2.0) / (n - 1);
    v *= (i == 0 || i == n - 1) ? h / 2 : h;
  }
  return v;
}

/// Σ|m − m_exact| / Σ m_exact of frame `k` at time t, the run's values times the cells'
/// volumes (for node values: their trapezoid masses).
double relative_l1(const Clock& c, const fs::path& dir, std::size_t k, double t) {
  char name[32];
  std::snprintf(name, sizeof name, "u_%04zu.npy", k);
  const std::vector<double> u = hybgen::rt::read_npy((dir / name).string()).data;
  double diff = 0.0, total = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i) {
    const double exact = cell_mass(c, i, t);
    diff += std::fabs(u[i] * cell_volume(c, i) - exact);
    total += exact;
  }
  return diff / total;
}

/// Runs the model with the default values=auto and with values=nodes, and checks every
/// frame's error and estimate (the file comment).
void check_clock(const Clock& c, const std::string& extra, double tol) {
  const json cells = run(c.model, c.model + "_cells", extra);
  const json nodes = run(c.model, c.model + "_nodes", extra + " --set values=nodes");
  ASSERT_FALSE(cells.is_null());
  ASSERT_FALSE(nodes.is_null());
  ASSERT_EQ(cells["values"]["kind"], "cells") << cells["values"].dump();
  EXPECT_EQ(nodes["values"]["kind"], "nodes");
  const std::vector<double> times = cells["times"];
  const std::vector<double> estimate = cells["values"]["error"];
  ASSERT_EQ(estimate.size(), times.size());
  double worst_node = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double err =
        relative_l1(c, hybgen::testing::own_dir(kWork) / (c.model + "_cells"), k, times[k]);
    const double node_err =
        relative_l1(c, hybgen::testing::own_dir(kWork) / (c.model + "_nodes"), k, times[k]);
    worst_node = std::max(worst_node, node_err);
    std::printf("[ cells ] %s t = %g: cell averages %.3e (estimate %.3e, %.1fx), nodes %.3e\n",
                c.model.c_str(), times[k], err, estimate[k], estimate[k] / err, node_err);
    EXPECT_LE(err, estimate[k]) << "t = " << times[k];
    EXPECT_LE(estimate[k], std::max(50.0 * err, tol)) << "t = " << times[k];
    EXPECT_LE(err, tol) << "t = " << times[k];
  }
  EXPECT_GT(worst_node, 0.5) << "the node values should be speckle at the last frames";
}

TEST(CellAverages, AClockThatHalvesItsSecondCoordinateAtEveryTurn) {
  const Clock clock{
      "contracting_wrap", {41, 41}, [](std::size_t, int k, double) { return std::exp2(k); }};
  check_clock(clock, "", 1e-2);
  check_clock(clock, "--set budget=full", 3e-4);
}

TEST(CellAverages, AThreeDimensionalClockThatContractsTwoWays) {
  check_clock(
      {"contracting_clock_3d",
       {13, 13, 13},
       [](std::size_t axis, int k, double t) { return axis == 1 ? std::exp(t) : std::exp2(k); }},
      "--set grid=13x13x13", 1e-2);
}

/// contracting_wrap's E[x] and E[y²] over the grid box (|y| ≤ 1) at time t: along y in closed
/// form (N(0, s²) with s = σ/2^k on [−1, 1] has mass M = 2Φ(a) − 1 and second moment
/// s²(M − 2aφ(a)), a = 1/s), along x by Simpson on the pieces where k is constant.
std::array<double, 2> wrap_means(double t) {
  std::vector<double> cuts{0.0};
  for (double x = std::ceil(-t) + t; x < 1.0; x += 1.0)
    if (x > 0.0) cuts.push_back(x);
  cuts.push_back(1.0);
  double mass = 0.0, mx = 0.0, my2 = 0.0;
  for (std::size_t p = 0; p + 1 < cuts.size(); ++p) {
    const double lo = cuts[p], hi = cuts[p + 1];
    const int k = static_cast<int>(std::ceil(t - 0.5 * (lo + hi)));
    const double sd = kSigma / std::exp2(k), a = 1.0 / sd;
    const double M = 2.0 * normal_cdf(a) - 1.0;
    const double S = sd * sd * (M - 2.0 * a * std::exp(-a * a / 2) / std::sqrt(2.0 * kPi));
    constexpr int kPanels = 2000;
    const double h = (hi - lo) / kPanels;
    for (int i = 0; i <= kPanels; ++i) {
      const double x = lo + i * h, w = h / 3 * (i == 0 || i == kPanels ? 1 : i % 2 ? 4 : 2);
      const double g = 1.0 + std::cos(2.0 * kPi * (x - t + k)) / 2.0;
      mass += w * g * M, mx += w * x * g * M, my2 += w * g * S;
    }
  }
  return {mx / mass, my2 / mass};
}

TEST(CellAverages, MeansOverCellAveragesAreIntegratedWithThem) {
  // The observables of a run whose values are cell averages (budget/cell_averages.hpp): the
  // cubature integrates f·u over every cell beside u, so E[f] = ∫ f u / ∫ u with its
  // estimates of both. E[y²] is the hard case: by t = 6 all the mass sits within a tenth of
  // the cells of the row y = 0, where the node value of y² is 0 (putting each cell's mass at
  // its node gave 8.7e-11 against 2.2e-5). Asserted: covered at every frame, and at most 100×
  // the error or within the tolerance, 1e-2 of the mean (the cubature stops at its tolerance
  // and its three-node rule is often far better: E[x] = 1/2 by symmetry to 1e-9 with an
  // estimate of 1.8e-3; E[y²] at t = 6 to 1.2e-5 of itself, estimated at 5.4e-3 of itself).
  const json s = run("contracting_wrap", "contracting_wrap_means",
                     "--set 'observe.x=x' --set 'observe.y2=y^2'");
  ASSERT_FALSE(s.is_null());
  ASSERT_EQ(s["values"]["kind"], "cells");
  const std::vector<double> times = s["times"];
  for (std::size_t k = 0; k < times.size(); ++k) {
    const std::array<double, 2> exact = wrap_means(times[k]);
    for (std::size_t i = 0; i < 2; ++i) {
      const char* name = i == 0 ? "x" : "y2";
      const double value = s["observables"][name]["values"][k].get<double>();
      const double error = s["observables"][name]["errors"][k].get<double>();
      const double truth = std::fabs(value - exact[i]);
      std::printf("[ cells ] t = %g: E[%s] = %.6g +/- %.1e against %.6g: off by %.1e (%.0fx)\n",
                  times[k], name, value, error, exact[i], truth, error / truth);
      EXPECT_LE(truth, error) << name << " at t = " << times[k];
      EXPECT_LE(error, std::max(100.0 * truth, 1e-2 * std::fabs(exact[i])))
          << name << " at t = " << times[k];
    }
  }
}

}  // namespace
