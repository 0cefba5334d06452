// Resets that carry mass out of the grid box, through the whole pipeline (`hybgen run` on the
// .model files of tests/validation/models/), against references that do not come from hybgen.
// Such mass has left the computed region as surely as mass crossing a face: every method
// counts it as outflow, and the characteristics' budget measures it on its own with forward
// flows (runtime/include/hybgen/rt/methods/budget/atom.hpp), so that its defect still checks
// the budget. Before, the pre-flight scan refused every such model (exit 3).
//
//  * leap_out: x' = 1 on [0, 1.5], and x ↦ x + 2 at x = 1 (to 3, outside). With
//    I(a, b) = ∫_a^b u0 and u0 = exp(−(x − ½)²/0.02), for t ≤ 1:
//      reset outflow R(t) = I(1 − t, 1)      (what reached the guard),
//      face outflow  F(t) = I(max(1, 1.5 − t), 1.5) − I(−t, 0)
//                    (what started past the guard and left through x = 1.5, minus the inflow
//                    through x = 0 of the density outside the box),
//      mass(t) = I(0, 1.5) − R(t) − F(t).
//  * tilted_floor: a 4-D ball on the floor y = k x with a restitution reset, as a new user
//    writes it, with momenta near (−1.2, −1.2) so that a share of the impacts leaves the
//    momentum box; characteristics against particles (independent: forward Monte Carlo), at
//    e = 0.8 and e = 1, and the other methods run.
//
// Measured (2026-11-29, `ctest -R ResetOutflow -V`): leap_out's reset outflow, outflow and mass
// within 5e-10 of the closed forms by characteristics (budget_tol 1e-8), 1.5e-3 by transfer, 5e-6
// by particles; the tilted floor's outflow, half of it by resets, within 3.6e-3 of the mass
// between characteristics and particles.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <vector>

#include "hybgen/gen/fs.hpp"
#include "support/e2e.hpp"
#include "support/line_closed_forms.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::leap_integral;
using hybgen::testing::leap_outflow;
using hybgen::testing::leap_reset_outflow;

const fs::path kWork = hybgen::testing::e2e_dir("validation_reset_outflow");
const hybgen::testing::Hybgen hybgen_cli{kWork / "cache"};

/// `hybgen run MODEL.model --set method=METHOD SETS` (MODEL: its path in the source tree without
/// the extension) into its own directory; its summary.json (null
/// if the run failed, with the failure reported). The run's output into *out.
nlohmann::json run(const std::string& model, const std::string& name, const std::string& method,
                   const std::string& sets = "", std::string* out = nullptr) {
  const fs::path dir = hybgen::testing::own_dir(kWork) / name;
  fs::remove_all(dir);
  const auto r = hybgen_cli("run " + model + ".model --quiet --out '" + dir.string() +
                            "' --set method=" + method + " --set outputs=netcdf " + sets);
  if (out != nullptr) *out = r.out;
  EXPECT_EQ(r.code, 0) << r.out;
  if (r.code != 0) return nullptr;
  return hybgen::testing::read_json_file(dir / "summary.json");
}

std::vector<double> numbers(const nlohmann::json& a) {
  return a.get<std::vector<double>>();
}

TEST(ResetOutflow, ALeapOutOfTheBoxIsOutflowByEveryMethod) {
  std::string out;
  const nlohmann::json c = run("tests/validation/models/leap_out", "leap_characteristics",
                               "characteristics", "--set budget=full --set budget_tol=1e-8", &out);
  ASSERT_FALSE(c.is_null());
  // The pre-flight scan names the first point reset out of the box, as a warning.
  EXPECT_NE(out.find("the reset carries mass out of the domain (the grid box) at the point (x = "
                     "1) of its surface in mode 'go': Delta = (x = 3)"),
            std::string::npos)
      << out;
  const std::vector<double> times = numbers(c["times"]), outflow = numbers(c["outflow"]),
                            mass = numbers(c["mass"]),
                            reset = numbers(c["budget"]["reset_outflow"]),
                            outflow_error = numbers(c["budget"]["outflow_error"]),
                            mass_error = numbers(c["budget"]["mass_error"]);
  ASSERT_EQ(reset.size(), times.size());
  EXPECT_TRUE(c["budget"]["closes"].get<bool>()) << c["budget"].dump();
  const double mass0 = leap_integral(0.0, 1.5);
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double t = times[k];
    std::printf(
        "leap_out characteristics t = %.1f: reset outflow %.10f (exact %.10f), outflow "
        "%.10f (exact %.10f, estimated error %.1e), mass %.10f (exact %.10f)\n",
        t, reset[k], leap_reset_outflow(t), outflow[k], leap_outflow(t), outflow_error[k], mass[k],
        mass0 - leap_outflow(t));
    // Each estimate covers its error, which is at the budget's tolerance 1e-8 (measured:
    // errors ≤ 5e-10, estimates 2.5e-9 and below).
    const double reset_err = std::fabs(reset[k] - leap_reset_outflow(t)),
                 outflow_err = std::fabs(outflow[k] - leap_outflow(t)),
                 mass_err = std::fabs(mass[k] - (mass0 - leap_outflow(t)));
    EXPECT_LE(reset_err, outflow_error[k]) << t;
    EXPECT_LE(outflow_err, outflow_error[k]) << t;
    EXPECT_LE(mass_err, mass_error[k] + 1e-15) << t;
    for (const double err : {reset_err, outflow_err, mass_err}) EXPECT_LE(err, 1e-8 * mass0) << t;
  }
  EXPECT_GT(reset.back(), 0.5 * mass0);  // most of the mass has leapt out by t = 0.8

  // The forward methods count the same mass as outflow.
  for (const std::string method : {"transfer", "particles"}) {
    const nlohmann::json f = run("tests/validation/models/leap_out", "leap_" + method, method);
    ASSERT_FALSE(f.is_null()) << method;
    const std::vector<double> fo = numbers(f["outflow"]);
    ASSERT_EQ(fo.size(), times.size());
    for (std::size_t k = 0; k < times.size(); ++k) {
      std::printf("leap_out %s t = %.1f: outflow %.6f (exact %.6f)\n", method.c_str(), times[k],
                  fo[k], leap_outflow(times[k]));
      EXPECT_NEAR(fo[k], leap_outflow(times[k]), 1e-2 * mass0) << method << " t = " << times[k];
    }
  }
}

/// ∫_a^b exp(−(x − c)²/0.004) dx.
double narrow_integral(double c, double a, double b) {
  const double s = std::sqrt(0.002);  // 2s² = 0.004
  return s * std::sqrt(std::numbers::pi / 2.0) *
         (std::erf((b - c) / (s * std::numbers::sqrt2)) -
          std::erf((a - c) / (s * std::numbers::sqrt2)));
}

TEST(ResetOutflow, ImagesOnAFaceAndAtomsOutsideTheBoxAreCountedOnce) {
  // Three ways to count a reset twice or not at all, each in closed form (budget_tol 1e-8):
  //  * wrap_onto_face: x' = 1 on [0, 0.8], the guard x = 1 outside, its image the face x = 0,
  //    where the flow enters: the faces' integral counts it as inflow. For t ≤ 1,
  //    mass(t) = I(−t, 0.8 − t) + I(1 − t, 1 − t + min(t, 0.8)) (the flow's and the wrap's
  //    histories). Counted again by the reset outflow, the budget missed the mass by 0.11.
  //  * leap_onto_face: x ↦ x + 1/2 at x = 1/2 onto the face x = 1, where the flow leaves at
  //    once: the faces do not see it. mass(t) = I(−t, 1/2 − t) + I(1/2, max(1/2, 1 − t)).
  //    Counted by nothing, the budget missed all of it (0.11).
  //  * ball_zeno_below: the ball (e = 1/2) whose Zeno point (0, 0) lies below the box
  //    x ≥ 0.3: the mass that comes to rest there left through the face x = 0.3. By t = 4
  //    all of it has: outflow = mass0, atom = 0 (counted in both, the defect was −mass0).
  struct Case {
    const char* model;
    std::function<double(double)> mass;  // the exact mass in the box at t (empty: not known)
    double mass0;
  };
  const std::vector<Case> cases = {
      {"wrap_onto_face",
       [](double t) {
         return narrow_integral(0.4, -t, 0.8 - t) +
                narrow_integral(0.4, 1.0 - t, 1.0 - t + std::min(t, 0.8));
       },
       narrow_integral(0.4, 0.0, 0.8)},
      {"leap_onto_face",
       [](double t) {
         return narrow_integral(0.3, -t, 0.5 - t) +
                narrow_integral(0.3, 0.5, std::max(0.5, 1.0 - t));
       },
       narrow_integral(0.3, 0.0, 1.0)},
      {"ball_zeno_below", {}, 0.02 * std::numbers::pi},
  };
  for (const Case& c : cases) {
    const nlohmann::json s = run(std::string("tests/validation/models/") + c.model, c.model,
                                 "characteristics", "--set budget=full --set budget_tol=1e-8");
    ASSERT_FALSE(s.is_null()) << c.model;
    EXPECT_TRUE(s["budget"]["closes"].get<bool>()) << c.model << ": " << s["budget"].dump();
    const std::vector<double> times = numbers(s["times"]), outflow = numbers(s["outflow"]),
                              atom = numbers(s["atom"]);
    for (std::size_t k = 0; k < times.size(); ++k) {
      const double t = times[k];
      const double exact = c.mass ? c.mass0 - c.mass(t) : (t >= 4.0 ? c.mass0 : outflow[k]);
      std::printf("%s t = %.2f: outflow %.12f (exact %.12f), atom %.1e\n", c.model, t, outflow[k],
                  exact, atom[k]);
      EXPECT_NEAR(outflow[k], exact, 1e-8 * c.mass0) << c.model << " t = " << t;
      EXPECT_EQ(atom[k], 0.0) << c.model << " t = " << t;
    }
  }
}

TEST(ResetOutflow, TheTiltedFloorRunsWithEveryMethodAndItsBudgetsAgree) {
  // Sanitized, e = 0.8 alone: the characteristics' 4-D budget at budget_tol 1e-3 took 34 s of
  // each e's 47 s there (2026-12-01), and e = 1 takes the same code paths.
  const std::vector<const char*> restitutions = hybgen::testing::kSanitized
                                                    ? std::vector<const char*>{"0.8"}
                                                    : std::vector<const char*>{"0.8", "1"};
  for (const char* e : restitutions) {
    const std::string tag = std::string("e") + e;
    std::string out;
    // budget=full: budget=fast's point cap leaves its mass 5 % off in 4-D (within its wide
    // estimate); to 1e-3 it takes about 2 s.
    const nlohmann::json c =
        run("models/tilted_floor", "tilted_characteristics_" + tag, "characteristics",
            std::string("--set e=") + e + " --set budget=full --set budget_tol=1e-3", &out);
    ASSERT_FALSE(c.is_null()) << e;
    EXPECT_NE(out.find("the reset carries mass out of the domain"), std::string::npos) << out;
    EXPECT_TRUE(c["budget"]["closes"].get<bool>()) << c["budget"].dump();
    const std::vector<double> times = numbers(c["times"]), outflow = numbers(c["outflow"]),
                              reset = numbers(c["budget"]["reset_outflow"]),
                              outflow_error = numbers(c["budget"]["outflow_error"]);
    const double mass0 = c["initial_mass"].get<double>();
    // A share of the impacts leaves the momentum box: the term is no rounding-level zero.
    EXPECT_GT(reset.back(), 0.02 * mass0) << e;

    // Particles (forward Monte Carlo, independent of the backward characteristics).
    const nlohmann::json p = run("models/tilted_floor", "tilted_particles_" + tag, "particles",
                                 std::string("--set e=") + e);
    ASSERT_FALSE(p.is_null()) << e;
    const std::vector<double> po = numbers(p["outflow"]);
    ASSERT_EQ(po.size(), times.size());
    for (std::size_t k = 0; k < times.size(); ++k) {
      // 1e6 particles: a share q of the mass counted has a standard error √(q(1 − q)/n).
      const double q = std::clamp(po[k] / mass0, 0.0, 1.0);
      const double sigma = mass0 * std::sqrt(q * (1.0 - q) / 1e6);
      std::printf(
          "tilted floor e = %s t = %.1f: outflow characteristics %.6f (reset %.6f, "
          "estimated error %.1e), particles %.6f (sigma %.1e)\n",
          e, times[k], outflow[k], reset[k], outflow_error[k], po[k], sigma);
      // The budget's estimate covers the difference; so does a bound several times tighter
      // (measured: up to 3.6e-3 of the mass at e = 0.8 and 7e-4 at e = 1, against estimates
      // of 1.5 % and 2.8 % of it).
      const double diff = std::fabs(outflow[k] - po[k]);
      EXPECT_LE(diff, 5.0 * sigma + outflow_error[k]) << "e = " << e << ", t = " << times[k];
      EXPECT_LE(diff, 5.0 * sigma + 5e-3 * mass0) << "e = " << e << ", t = " << times[k];
    }
    // The grid methods run on the same model; none is refused.
    for (const std::string method : {"transfer", "invariant", "escape"}) {
      const nlohmann::json r = run("models/tilted_floor", "tilted_" + method + "_" + tag, method,
                                   std::string("--set e=") + e + " --set grid=9x9x9x9");
      EXPECT_FALSE(r.is_null()) << method << " e = " << e;
    }
  }
}

TEST(ResetOutflow, AResetOnTheSupportsEdgeIsInsideItUpToRounding) {
  // The newcomer's workaround on a81ba15, a second support line |p| ≤ 2, failed at e = 1 on
  // a rounding error: the reset keeps |p| = 2 on the disc's edge and lands at px =
  // -1.9200000000000004, just outside. The scan now takes an image within 1e-9 of the
  // box's size of the support (on the way to its crossing point) as inside it; an image
  // clearly outside still fails (tests/e2e/test_failures.cpp, ResetOutsideTheSupport).
  const std::string text =
      hybgen::gen::read_file(std::string(HYBGEN_SOURCE_DIR) + "/models/tilted_floor.model");
  const std::string with_disc = text.substr(0, text.find("  support y >= k*x")) +
                                "  support y >= k*x\n  support px^2 + py^2 <= 4\n" +
                                text.substr(text.find("  grid "));
  const std::string model =
      hybgen::testing::write_model_file(kWork, "tilted_floor_disc.model", with_disc);
  // On 11⁴ nodes the crossing at (x, y, px, py) = (−3, −1.5, −1.6000000000000001, −1.2) was
  // refused before ("the reset lands outside the support").
  for (const char* e : {"1", "0.8"}) {
    const auto r =
        hybgen_cli("check '" + model + "' --preflight -q --set grid=11x11x11x11 --set e=" + e);
    EXPECT_EQ(r.code, 0) << "e = " << e << ": " << r.out;
    EXPECT_NE(r.out.find("pre-flight scan (t = 0, characteristics, grid of 14641 nodes): ok"),
              std::string::npos)
        << r.out;
  }
  const auto r = hybgen_cli(
      "run '" + model + "' --quiet --out '" + (hybgen::testing::own_dir(kWork) / "disc").string() +
      "' --set grid=11x11x11x11 --set e=1 --set budget=off --set outputs=netcdf");
  EXPECT_EQ(r.code, 0) << r.out;
}

}  // namespace
