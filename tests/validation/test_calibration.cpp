// Calibrated error bars (docs/hardening.md, "Calibrated bars"). Of `method=particles`: the
// budget's Monte-Carlo terms — the mass in the box, the atom at a Zeno point, the mass a trap
// absorbed — against closed forms that do not come from hybgen, over several seeds, through
// `hybgen run` on tests/validation/models/*.model:
//  * leap_out: the mass in the box (support/line_closed_forms.hpp);
//  * shuttle_trap: the mass absorbed by its trap and the mass left (the same file);
//  * zeno_ball (e = 0.6): the atom at the Zeno point, the mass of the initial states at rest
//    by t (support/ball_closed_form.hpp: zeno_mass).
// Each reported bar is 2σ̂. A bar that covers its error is easy (make it huge); a bar that
// means something is 2σ of the error: z = error/σ̂ over many frames has a root mean square
// near 1. Asserted, over all frames whose exact value is not 0 (a term that is exactly 0 has
// no randomness): the RMS of z lies in [kZRmsLow, kZRmsHigh] — the 2σ bars at most 4× the
// errors' RMS (RMS z ≥ 0.5; exact 2σ bars give 1) and not narrow (RMS z ≤ 1.5) —, at least
// 90 % of the errors lie within their bar and every one within twice it (4σ).
//
// Before (901a646), the mass, atom and absorbed bars were the i.i.d. formula, which ignores
// the stratification of the sample (each particle draws from its own slice of the proposal:
// runtime/include/hybgen/rt/methods/particles.hpp): RMS z 0.28, 0.29 and 0.29 on these runs
// (HYBGEN_UNDER_TEST=<901a646's hybgen>), every error within 0.34 of its bar. Now the
// collapsed strata: 0.81, 0.85 and 1.04; 71 of 72, 24 of 24 and 17 of 18 errors within their
// bars, the largest at 1.04× its bar (2026-11-30, `ctest -R Calibration -V`).

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "support/ball_closed_form.hpp"
#include "support/bars.hpp"
#include "support/e2e.hpp"
#include "support/line_closed_forms.hpp"

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_calibration");
const hybgen::testing::Hybgen hybgen_cli{kWork / "cache"};

constexpr int kSeeds = 6;              ///< Runs per model, seeds 1..kSeeds.
constexpr double kZRmsLow = 0.5;       ///< 2σ bars at most 4× the errors' RMS.
constexpr double kZRmsHigh = 1.5;      ///< Bars not narrower than the errors' spread.
constexpr double kCoveredShare = 0.9;  ///< Of the errors within their (2σ) bar.
/// The budget's cubature bars (deterministic, not 2σ): RMS of 2·error/bar at least this, the
/// bars at most about 17× the errors' RMS.
constexpr double kBudgetZRmsLow = 0.12;

/// `hybgen run tests/validation/models/MODEL.model --set method=particles` with `seed` and
/// 100000 particles into its own directory; its summary.json.
json run_particles(const std::string& model, int seed) {
  const fs::path out = hybgen::testing::own_dir(kWork) / (model + "_" + std::to_string(seed));
  fs::remove_all(out);
  const auto r = hybgen_cli(
      "run tests/validation/models/" + model + ".model --quiet --out '" + out.string() +
      "' --set method=particles --set particles=100000 --set seed=" + std::to_string(seed) +
      " --set outputs=netcdf");
  EXPECT_EQ(r.code, 0) << r.out;
  if (r.code != 0) return json::object();
  return hybgen::testing::read_json_file(out / "summary.json");
}

/// Errors and their bars of one Monte-Carlo term, collected over runs (exact zeros left out).
struct Term : hybgen::testing::BarSeries {
  /// Add the frames of `values` ± `bars` against exact(t).
  void add(const json& times, const json& values, const json& bars,
           const std::function<double(double)>& exact) {
    BarSeries::add(times, values, bars, exact, true);
  }

  /// The calibration's assertions (file comment), with what they measured.
  void expect_calibrated() const {
    ASSERT_GE(error.size(), 10u) << name << ": too few frames to judge";
    double widest = 0.0;
    std::size_t covered = 0;
    for (std::size_t i = 0; i < error.size(); ++i) {
      ASSERT_GT(bar[i], 0.0) << name << " frame " << i;
      if (std::fabs(error[i]) <= bar[i]) ++covered;
      widest = std::max(widest, std::fabs(error[i]) / bar[i]);
      EXPECT_LE(std::fabs(error[i]), 2.0 * bar[i]) << name << " frame " << i << ": beyond 4σ";
    }
    const double n = static_cast<double>(error.size());
    const double rms = rms_z();
    std::printf(
        "[ calibration ] %s: %zu frames, RMS of error/sigma %.2f, %zu within their 2-sigma bar, "
        "largest |error|/bar %.2f\n",
        name.c_str(), error.size(), rms, covered, widest);
    EXPECT_GE(rms, kZRmsLow) << name << ": bars wider than 4x the errors' RMS";
    EXPECT_LE(rms, kZRmsHigh) << name << ": bars narrower than the errors";
    EXPECT_GE(static_cast<double>(covered), kCoveredShare * n) << name;
  }
};

TEST(Calibration, ParticleBudgetBarsAreTwoSigmaOfTheirErrors) {
  Term mass, absorbed, atom;
  mass.name = "mass in the box (leap_out, shuttle_trap)";
  absorbed.name = "mass absorbed by the trap (shuttle_trap)";
  atom.name = "atom at the Zeno point (zeno_ball)";
  for (int seed = 1; seed <= kSeeds; ++seed) {
    const json leap = run_particles("leap_out", seed);
    ASSERT_TRUE(leap.contains("mass_error")) << leap.dump();
    mass.add(leap["times"], leap["mass"], leap["mass_error"], hybgen::testing::leap_mass);

    const json shuttle = run_particles("shuttle_trap", seed);
    ASSERT_TRUE(shuttle.contains("absorbed")) << shuttle.dump();
    const double mass0 = hybgen::testing::shuttle_bump_mass_above(0.0);
    mass.add(shuttle["times"], shuttle["mass"], shuttle["mass_error"],
             [mass0](double t) { return mass0 - hybgen::testing::shuttle_absorbed(t); });
    absorbed.add(shuttle["times"], shuttle["absorbed"]["trap"]["values"],
                 shuttle["absorbed"]["trap"]["errors"], hybgen::testing::shuttle_absorbed);

    const json zeno = run_particles("zeno_ball", seed);
    ASSERT_TRUE(zeno.contains("atom_error")) << zeno.dump();
    atom.add(zeno["times"], zeno["atom"], zeno["atom_error"],
             [](double t) { return t > 0.0 ? hybgen::testing::zeno_mass(t, 0.6) : 0.0; });
  }
  mass.expect_calibrated();
  absorbed.expect_calibrated();
  atom.expect_calibrated();
}

TEST(Calibration, TheBudgetsCubatureBarsOnALeapOutOfTheBox) {
  // The characteristics' budget (adaptive cubature, budget/cubature.hpp) on leap_out at 33
  // output times (dt = 0.025), at `fast`, `full` and `full` to budget_tol 1e-6, against the
  // closed forms of the mass in the box and the outflow (support/line_closed_forms.hpp), and
  // the defect against 0 (leap_out loses mass only through its faces and its reset). Judged
  // frame by frame (support/bars.hpp): every bar covers its error (the defect too, stricter
  // than the run's own closure test, which allows it twice its bar: methods.hpp,
  // kDefectFactor), and a bar wider than twice the tolerance asked (three times for the
  // defect, the sum of its three terms' tolerances: the drop mass0 − mass, the outflow, the
  // atom) is at most 10× its error; and over the frames the RMS of 2·error/bar is at least
  // kBudgetZRmsLow. At t = 0 the drop is exactly 0, and so is its share of the defect's bar.
  //
  // Measured (2026-12-02, `ctest -R Calibration.TheBudgets -V`): every bar of the mass and
  // the outflow within twice what was asked at the three tolerances, RMS of 2·error/bar
  // 0.16–0.41 (the bars about 5–12× the errors' RMS); single bars are up to 10⁵× errors that
  // are 0 by luck (t = 0, where a smooth density is integrated to 1e-6 of the tolerance).
  // The defect's bar was the sum mass0_error + mass_error + outflow_error + atom_error; at
  // `fast`, 13 of its 33 frames were beyond twice what was asked, 5.1e-3 at t = 0 for a defect
  // that is exactly 0: the two masses' errors counted twice. It now takes the drop
  // mass0 − mass as one integral (budget/volume.hpp): 2.5e-4 at t = 0, and the widest 5.1e-3
  // at t = 0.125 (the two masses' estimates do not cancel where the density has moved), 0.68
  // of the defect's tolerance and 1.02 times twice the tolerance of one term.
  struct Budget {
    const char* label;
    const char* dir;  // under the test's own directory
    const char* sets;
  };
  for (const Budget& b : {Budget{"fast", "leap_budget_fast", "--set budget=fast"},
                          Budget{"full", "leap_budget_full", "--set budget=full"},
                          Budget{"full to 1e-6", "leap_budget_full_tight",
                                 "--set budget=full --set budget_tol=1e-6"}}) {
    const fs::path out = hybgen::testing::own_dir(kWork) / b.dir;
    fs::remove_all(out);
    const auto r =
        hybgen_cli("run tests/validation/models/leap_out.model --quiet --out '" + out.string() +
                   "' " + b.sets + " --set dt=0.025 --set outputs=netcdf");
    ASSERT_EQ(r.code, 0) << r.out;
    const json s = hybgen::testing::read_json_file(out / "summary.json");
    ASSERT_TRUE(s["budget"]["closes"].get<bool>()) << s["budget"].dump();
    const double asked = hybgen::testing::asked_width(s);
    // t = 0: the defect's bar is the outflow's and the atom's, nothing of the masses'.
    ASSERT_EQ(s["times"][0].get<double>(), 0.0);
    EXPECT_EQ(s["budget"]["defect_error"][0].get<double>(),
              s["budget"]["outflow_error"][0].get<double>() + s["atom_error"][0].get<double>())
        << b.label;
    for (const std::string term : {"mass", "outflow", "defect"}) {
      hybgen::testing::BarSeries t;
      t.name = term + " by characteristics, budget " + b.label;
      if (term == "defect")
        t.add(s["times"], s["budget"]["defect"], s["budget"]["defect_error"],
              [](double) { return 0.0; });
      else
        t.add(s["times"], s[term], s["budget"][term + "_error"],
              term == "mass" ? hybgen::testing::leap_mass : hybgen::testing::leap_outflow);
      ASSERT_EQ(t.error.size(), 33u) << t.name;
      // The defect sums three measured terms, each asked for rel_tol·mass: its tolerance is
      // their sum.
      const hybgen::testing::BarVerdict v = hybgen::testing::expect_bars_cover_and_tight(
          t, term == "defect" ? hybgen::testing::asked_width(s, 0.0, 3.0) : asked);
      // The defect's true value is 0: its errors do not behave as a sample of its bar's.
      if (term != "defect") {
        EXPECT_GE(v.rms, kBudgetZRmsLow) << t.name << ": bars wider than about 17x the errors' RMS";
      }
    }
  }
}

TEST(Calibration, TheForwardFlowsBarsOnImpactsAndTraps) {
  // The impacts on the guards and the masses the traps absorbed, by characteristics: the
  // budget's forward flows integrated by their own cubature (budget/atom.hpp), each bar at
  // least twice the cubature's distance from its check lattice's sum (collect_step). Every
  // bar covers its error, and is at most kBarRatio times it (support/bars.hpp) or within twice the
  // tolerance the run asked for (support/e2e.hpp, asked_width).
  //  * shuttle_trap (budget=full): the turn's impacts (the mass that started above 1 − t) and
  //    the trap's (absorbed);
  //  * ball_impacts (budget=full): the elastic ball's bounces, several per point;
  //  * absorb_growth (budget=fast): the trap on the box's face.
  // Before the check lattice was finer than the grid's nodes (fine_lattice,
  // budget/check_points.hpp) its floor was the nodes' own error, beyond what was asked: the
  // shuttle's bars were 400–800× its errors at the frames whose jump lay on a node, 2.8e-3
  // for a tolerance of 6.4e-5. Before the lattice's jumps were located along its lines
  // (budget/step_lines.hpp), 10 of the ball's 48 bars were beyond twice what was asked, at
  // 14–60× their errors (one 1300×): the floor of a two-dimensional lattice whose sum is off
  // by about the jump's length times its spacing. Now (2026-12-02, `ctest -R
  // Calibration.TheForwardFlows -V`) every bar of the four is within twice what was asked
  // (the ball's widest 6.5e-5, for 4.2e-5 asked, is 16.5× an error of 3.9e-6; its largest
  // error, 2.2e-5, has a bar of 3.9e-5). Before, this test judged the bars beyond twice what
  // was asked by their RMS of 2·error/bar (at least 0.05), not frame by frame.
  struct Case {
    const char* model;
    const char* sets;
    const char* group;  // "impacts" or "absorbed"
    const char* guard;
    std::function<double(double)> exact;
  };
  const double t_turn = 1.0;  // shuttle_trap: up turns at x = 1, so x0 turns at 1 − x0
  const std::vector<Case> cases = {
      {"shuttle_trap", "--set budget=full --set dt=0.05", "impacts", "turn",
       [=](double t) { return hybgen::testing::shuttle_bump_mass_above(t_turn - t); }},
      {"shuttle_trap", "--set budget=full --set dt=0.05", "absorbed", "trap",
       hybgen::testing::shuttle_absorbed},
      {"ball_impacts", "--set budget=full --set dt=0.125", "impacts", "ground",
       [](double t) { return hybgen::testing::ball_impacts(t, 1.0, 1.0, 0.15); }},
      {"absorb_growth", "--set dt=0.05", "absorbed", "trap", hybgen::testing::growth_absorbed},
  };
  for (const Case& c : cases) {
    const fs::path out = hybgen::testing::own_dir(kWork) / (std::string(c.model) + "_" + c.guard);
    fs::remove_all(out);
    const auto r = hybgen_cli("run tests/validation/models/" + std::string(c.model) +
                              ".model --quiet --out '" + out.string() + "' " + c.sets);
    ASSERT_EQ(r.code, 0) << r.out;
    const json s = hybgen::testing::read_json_file(out / "summary.json");
    ASSERT_TRUE(s.contains(c.group) && s[c.group].contains(c.guard)) << s.dump();
    const json& a = s[c.group][c.guard];
    hybgen::testing::BarSeries all;
    all.name = std::string(c.group) + " on '" + c.guard + "' (" + c.model + ")";
    all.add(s["times"], a["values"], a["errors"], c.exact, true);
    ASSERT_GE(all.error.size(), 10u) << all.name;
    hybgen::testing::expect_bars_cover_and_tight(all, hybgen::testing::asked_width(s));
  }
}

}  // namespace
