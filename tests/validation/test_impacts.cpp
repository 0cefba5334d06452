/// \file test_impacts.cpp
/// The impacts on the guards (runtime/include/hybgen/rt/methods/impacts.hpp): the mass that has
/// crossed each guard by each output time, counted once per crossing, and its mean rate between
/// output times, through `hybgen run` on .model files, against closed forms written here and in
/// tests/support/ (none comes from hybgen):
///  * shuttle_trap (two modes, a turn and an absorbing trap): a point x0 turns at t = 1 − x0 and
///    is absorbed at 7/4 − x0, so the turn's impacts by t are the initial mass on [1 − t, ∞) and
///    the trap's the absorbed mass (tests/support/line_closed_forms.hpp);
///  * ball_impacts (an elastic ball, several bounces each): Σ over n of the mass whose n-th
///    impact comes by t (tests/support/ball_closed_form.hpp, ball_impacts);
///  * zeno_ball (restitution 0.6): mass reaches the Zeno point at every t > 0 (from x0 near 0
///    the ball comes to rest at once), so its impacts are infinite from the first frame after 0.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "support/ball_closed_form.hpp"
#include "support/e2e.hpp"
#include "support/line_closed_forms.hpp"
#include "support/netcdf_series.hpp"

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const fs::path kWork = hybgen::testing::e2e_dir("validation_impacts");

/// `hybgen run tests/validation/models/MODEL.model --set method=METHOD SETS` into this test's
/// directory `dir`; its summary.json (null on a failed run).
json run(const std::string& dir, const std::string& model, const std::string& method,
         const std::string& sets = "") {
  return hybgen::testing::run_summary("tests/validation/models/" + model + ".model",
                                      hybgen::testing::own_dir(kWork) / dir,
                                      "--set method=" + method + " " + sets, kWork / "cache");
}

/// How closely a method's impacts must follow the closed form.
struct Bound {
  double cover;  ///< Each error within cover × its bar plus `floor` (methods with bars).
  double width;  ///< Each bar at most width × the true error, or within `floor` or what was
                 ///< asked (`asked_width`).
  double floor;  ///< Absolute slack: the closed form's quadrature, or a bar-less method's error.
};

/// summary["impacts"][guard] against exact(t): the values (and the rates against the closed
/// form's difference quotients) within the bound; without bars (transfer) within `floor`.
/// Returns the largest error of the values.
template <class Exact>
double expect_impacts(const json& s, const std::string& guard, Exact exact, const std::string& what,
                      const Bound& b) {
  EXPECT_TRUE(s.contains("impacts") && s["impacts"].contains(guard)) << what;
  if (!s.contains("impacts") || !s["impacts"].contains(guard)) return HUGE_VAL;
  const json& a = s["impacts"][guard];
  const json& times = s["times"];
  EXPECT_TRUE(a["infinite_from"].is_null()) << what;
  const bool bars = a["errors"].is_array();
  const double asked = hybgen::testing::asked_width(s);
  double worst = 0.0, prev_t = 0.0, prev_ref = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    const double t = times[k].get<double>(), ref = exact(t);
    const double v = a["values"][k].get<double>(), d = std::fabs(v - ref);
    const double e = bars ? a["errors"][k].get<double>() : 0.0;
    std::printf("[ impacts ] %s: '%s' by t = %.2f: %.8f +/- %.1e (exact %.8f)\n", what.c_str(),
                guard.c_str(), t, v, e, ref);
    EXPECT_LE(d, b.cover * e + b.floor) << what << " t = " << t;
    if (bars) {
      EXPECT_LE(e, std::max({b.width * d, b.floor, asked})) << what << " t = " << t << ": too wide";
    }
    worst = std::max(worst, d);
    // The mean rate over (t_{k−1}, t_k]: null at t = 0, else the difference quotient.
    if (t > prev_t) {
      const double rate = a["rate"][k].get<double>(), exact_rate = (ref - prev_ref) / (t - prev_t);
      const double re = bars ? a["rate_errors"][k].get<double>() : 0.0;
      EXPECT_LE(std::fabs(rate - exact_rate), b.cover * re + 2.0 * b.floor / (t - prev_t))
          << what << " rate at t = " << t;
    } else {
      EXPECT_TRUE(a["rate"][k].is_null()) << what << " t = " << t;
    }
    prev_t = t, prev_ref = ref;
  }
  std::printf("[ impacts ] %s: largest error of the impacts on '%s' %.2e\n", what.c_str(),
              guard.c_str(), worst);
  return worst;
}

double turn_impacts(double t) {
  return hybgen::testing::shuttle_bump_mass_above(1.0 - t);
}

TEST(Impacts, TheShuttleCountsItsTurnAndItsTrap) {
  // Characteristics (the budget's forward flows, budget=full), particles (2σ: within twice) and
  // transfer (no bars: within 2 % of the mass, its diffusion over the grid's 241 nodes).
  const double mass = hybgen::testing::shuttle_bump_mass_above(0.0);
  const json c = run("shuttle_characteristics", "shuttle_trap", "characteristics",
                     "--set budget=full --set outputs=netcdf");
  ASSERT_FALSE(c.empty());
  // The cubature's bars: 15–28× the errors here, the cubature's own estimate within the
  // tolerance asked (6.4e-5). On the grid's nodes as the check lattice (before
  // budget/check_points.hpp's fine_lattice) the floor made them 400–800× at t = 0.5 and 0.75,
  // where the jump sits on a node (docs/hardening.md, "Calibrated bars").
  expect_impacts(c, "turn", turn_impacts, "characteristics", {1.0, 10.0, 1e-9});
  expect_impacts(c, "trap", hybgen::testing::shuttle_absorbed, "characteristics",
                 {1.0, 10.0, 1e-9});
  // An absorbing guard's impacts are its absorbed mass, and run.nc holds the series.
  EXPECT_EQ(c["impacts"]["trap"]["values"], c["absorbed"]["trap"]["values"]);
  const fs::path nc = hybgen::testing::own_dir(kWork) / "shuttle_characteristics" / "run.nc";
  EXPECT_EQ(hybgen::testing::nc_values(nc, "impacts_turn"),
            c["impacts"]["turn"]["values"].get<std::vector<double>>());
  EXPECT_EQ(hybgen::testing::nc_values(nc, "impacts_turn_error"),
            c["impacts"]["turn"]["errors"].get<std::vector<double>>());
  const std::vector<double> rate = hybgen::testing::nc_values(nc, "impact_rate_turn");
  ASSERT_EQ(rate.size(), c["times"].size());
  EXPECT_TRUE(std::isnan(rate[0]));  // no interval before t = 0
  EXPECT_EQ(rate[3], c["impacts"]["turn"]["rate"][3].get<double>());

  const json p = run("shuttle_particles", "shuttle_trap", "particles", "--set particles=200000");
  ASSERT_FALSE(p.empty());
  // A count of 0 has a bar of one particle's mass in n (2/n of the mass: 2e-6 here).
  expect_impacts(p, "turn", turn_impacts, "particles", {2.0, 1e3, 2e-5 * mass});
  expect_impacts(p, "trap", hybgen::testing::shuttle_absorbed, "particles",
                 {2.0, 1e3, 2e-5 * mass});

  const json t = run("shuttle_transfer", "shuttle_trap", "transfer");
  ASSERT_FALSE(t.empty());
  expect_impacts(t, "turn", turn_impacts, "transfer", {0.0, 0.0, 0.02 * mass});
  expect_impacts(t, "trap", hybgen::testing::shuttle_absorbed, "transfer", {0.0, 0.0, 0.02 * mass});
}

/// ball_impacts.model's closed form: elastic, u0 about (1, 0) with σ = 0.15.
double elastic_ball_impacts(double t) {
  return hybgen::testing::ball_impacts(t, 1.0, 1.0, 0.15);
}

TEST(Impacts, AnElasticBallCountsEveryBounce) {
  // The helper agrees with the Zeno mass of ball_closed_form.hpp where both apply (c = (1 +
  // e)/(1 − e), the paper's u0: σ² = 1/2), a check of the quadrature on its own.
  for (const double t : {0.5, 2.0, 5.0})
    EXPECT_NEAR(hybgen::testing::ball_impact_mass(t, 4.0, 1.0, std::sqrt(0.5)),
                hybgen::testing::zeno_mass(t, 0.6), 1e-12);
  // By t = 6 most of the mass has landed twice: impacts count every bounce (more than the mass).
  const double mass = 2.0 * M_PI * 0.15 * 0.15;
  ASSERT_GT(elastic_ball_impacts(6.0), 1.5 * mass);
  const json c =
      run("ball_characteristics", "ball_impacts", "characteristics", "--set budget=full");
  ASSERT_FALSE(c.empty());
  // Before the check lattice's jumps were located (budget/step_lines.hpp), its floor made the
  // bars up to 60× their errors beyond what was asked; now each is within what was asked or
  // 10× its error (the largest error is 2.7e-5, 4.2e-5 asked, at t = 4.25).
  expect_impacts(c, "ground", elastic_ball_impacts, "ball, characteristics", {1.0, 10.0, 1e-9});
  const json p = run("ball_particles", "ball_impacts", "particles", "--set particles=200000");
  ASSERT_FALSE(p.empty());
  expect_impacts(p, "ground", elastic_ball_impacts, "ball, particles", {2.0, 1e3, 2e-5 * mass});
  const json t = run("ball_transfer", "ball_impacts", "transfer");
  ASSERT_FALSE(t.empty());
  expect_impacts(t, "ground", elastic_ball_impacts, "ball, transfer", {0.0, 0.0, 0.03 * mass});
}

TEST(Impacts, AZenoBallsImpactsAreInfiniteOnceMassIsAtRest) {
  // zeno_ball: from x0 → 0 with p0 < 0 the Zeno time p0 + 4 v1 → 0, where u0 ≈ e^(−1): some mass
  // is at rest by every t > 0, and the impacts on the ground are infinite there. Every method
  // says so from the first frame after t = 0 (dt = 0.5) instead of a finite count.
  for (const std::string method : {"characteristics", "particles", "transfer"}) {
    const json s = run("zeno_" + method, "zeno_ball", method,
                       "--set dt=0.5 --set t_end=2 --set particles=100000");
    ASSERT_FALSE(s.empty()) << method;
    ASSERT_GT(hybgen::testing::zeno_mass(0.5, 0.6), 0.0);
    const json& a = s["impacts"]["ground"];
    ASSERT_TRUE(a["infinite_from"].is_number()) << method << ": " << a.dump();
    EXPECT_DOUBLE_EQ(a["infinite_from"].get<double>(), 0.5) << method;
    EXPECT_EQ(a["values"][0].get<double>(), 0.0) << method;
    for (std::size_t k = 1; k < s["times"].size(); ++k) {
      EXPECT_TRUE(a["values"][k].is_null()) << method << " frame " << k;
      EXPECT_TRUE(a["rate"][k].is_null()) << method << " frame " << k;
    }
  }
}

}  // namespace
