// The sweep's axes, points, labels and table (generator/src/sweep.cpp); the runs themselves
// are tests/e2e/test_sweep.cpp.

#include "hybgen/gen/sweep.hpp"

#include <gtest/gtest.h>

#include <cstdlib>

#include "hybgen/gen/errors.hpp"

namespace {

using namespace hybgen::gen;

TEST(Sweep, RangeHasBothEndsAndEqualSteps) {
  const SweepSpec s = parse_sweep({"e=0.5:1.0:6", "t_end=5"});
  ASSERT_EQ(s.axes.size(), 1u);
  EXPECT_EQ(s.axes[0].key, "e");
  // a + (b − a)·i/(N − 1) to 15 significant digits: what the point runs with is what its
  // row and directory show.
  EXPECT_EQ(s.axes[0].values, (std::vector<std::string>{"0.5", "0.6", "0.7", "0.8", "0.9", "1"}));
  // Without the rounding these would read 0.30000000000000004, 0.7000000000000001 and
  // 0.7999999999999999, and 2e+05 in scientific notation.
  EXPECT_EQ(parse_sweep({"e=0.1:1:10"}).axes[0].values,
            (std::vector<std::string>{"0.1", "0.2", "0.3", "0.4", "0.5", "0.6", "0.7", "0.8", "0.9",
                                      "1"}));
  EXPECT_EQ(parse_sweep({"n=1e5:1e6:4"}).axes[0].values,
            (std::vector<std::string>{"100000", "400000", "700000", "1000000"}));
  EXPECT_EQ(s.fixed, std::vector<std::string>{"t_end=5"});
  // One value, and a descending range.
  EXPECT_EQ(parse_sweep({"e=0.25:9:1"}).axes[0].values, std::vector<std::string>{"0.25"});
  EXPECT_EQ(parse_sweep({"e=1:0:3"}).axes[0].values, (std::vector<std::string>{"1", "0.5", "0"}));
}

TEST(Sweep, ListsKeepBracketsTogether) {
  const SweepSpec s =
      parse_sweep({"method=characteristics,transfer", "domain.x=[0,1],[0, 2]", "grid=21x21"});
  ASSERT_EQ(s.axes.size(), 2u);
  EXPECT_EQ(s.axes[0].values, (std::vector<std::string>{"characteristics", "transfer"}));
  EXPECT_EQ(s.axes[1].values, (std::vector<std::string>{"[0,1]", "[0, 2]"}));
  EXPECT_EQ(s.fixed, std::vector<std::string>{"grid=21x21"});
  // Braces (quoted on a command line) are the same list; a lone bracket pair is one value.
  EXPECT_EQ(parse_sweep({"e={0.5, 0.7}"}).axes[0].values, (std::vector<std::string>{"0.5", "0.7"}));
  EXPECT_EQ(parse_sweep({"domain.x=[0,1]", "e=1,2"}).fixed,
            std::vector<std::string>{"domain.x=[0,1]"});
}

TEST(Sweep, RefusesWhatIsNotASweep) {
  for (const std::vector<std::string>& bad : std::vector<std::vector<std::string>>{
           {"e=0.5"},                   // no axis
           {"e=0.5:1"},                 // range without N
           {"e=0.5:1:0"},               // N < 1
           {"e=0.5:1:2.5"},             // N not whole
           {"e=a:1:3"},                 // not a number
           {"e=0:1:3:4"},               // too many fields
           {"e=0:1:20000"},             // more than kMaxSweepPoints values
           {"e=0:1:200", "g=0:1:200"},  // more than kMaxSweepPoints points
           {"e=1,,2"},                  // empty element
           {"e=0:1:3", "e=2"},          // a key twice (a shell's expansion of e={1,2})
           {"novalue"}}) {
    EXPECT_THROW(parse_sweep(bad), UsageError) << bad.front();
  }
}

TEST(Sweep, PointsAreTheProductFirstAxisSlowest) {
  const auto pts = sweep_points(parse_sweep({"a=1,2", "b=x,y,z"}));
  ASSERT_EQ(pts.size(), 6u);
  EXPECT_EQ(pts[0], (std::vector<std::string>{"a=1", "b=x"}));
  EXPECT_EQ(pts[2], (std::vector<std::string>{"a=1", "b=z"}));
  EXPECT_EQ(pts[3], (std::vector<std::string>{"a=2", "b=x"}));
  EXPECT_EQ(pts[5], (std::vector<std::string>{"a=2", "b=z"}));
}

TEST(Sweep, LabelsArePaddedAndSafe) {
  EXPECT_EQ(sweep_label(3, 12, {"e=0.7"}), "03_e=0.7");
  EXPECT_EQ(sweep_label(0, 1, {"e=1"}), "0_e=1");
  EXPECT_EQ(sweep_label(7, 8, {"domain.x=[0, 1]", "m=a/b"}), "7_domain.x=_0__1__m=a_b");
}

TEST(Sweep, RowTakesTheFinalTimeAndTheMethodsFields) {
  const nlohmann::json chars = nlohmann::json::parse(R"({
    "method": "characteristics", "times": [0, 1, 2], "initial_mass": 3.0,
    "mass": [3.0, 2.5, 2.0], "outflow": [0, 0.4, 0.9], "atom": [0, 0.1, 0.1],
    "atom_error": [0, 0.01, 0.02],
    "absorbed": {"trap": {"values": [0, 0.25, 0.5], "errors": [0, 0.001, 0.002]}},
    "budget": {"mass_error": [0.1, 0.2, 0.3], "outflow_error": [0, 0, 0.05],
               "defect": [0, 0, 0.0], "defect_error": [0, 0, 0.4], "closes": false,
               "converged": false},
    "seconds": {"derive": 0.5, "build": 1.5, "solve": 2.5}})");
  const auto r = sweep_row(chars);
  EXPECT_EQ(r["method"], "characteristics");
  EXPECT_EQ(r["t"], 2);
  EXPECT_EQ(r["initial_mass"], 3.0);
  EXPECT_EQ(r["mass"], 2.0);
  EXPECT_EQ(r["outflow"], 0.9);
  EXPECT_EQ(r["outflow_error"], 0.05);
  EXPECT_EQ(r["atom"], 0.1);
  EXPECT_EQ(r["atom_error"], 0.02);
  EXPECT_EQ(r["mass_error"], 0.3);
  EXPECT_EQ(r["unaccounted_error"], 0.4);
  EXPECT_EQ(r["budget_closes"], false);
  EXPECT_EQ(r["budget_converged"], false);
  EXPECT_EQ(r["seconds_build"], 1.5);
  EXPECT_EQ(r["absorbed_trap"], 0.5);
  EXPECT_EQ(r["absorbed_trap_error"], 0.002);
  EXPECT_FALSE(r.contains("spectral_gap"));

  const nlohmann::json inv = nlohmann::json::parse(R"({
    "method": "invariant", "times": [], "initial_mass": 0, "mass": [],
    "invariant": {"spectral_gap": 0.25, "decay_rate": 1.5,
                  "eigenvalues": [{"re": 1, "im": 0, "abs": 1}, {"re": 0, "im": 0.75, "abs": 0.75}]}})");
  const auto ri = sweep_row(inv);
  EXPECT_FALSE(ri.contains("initial_mass"));  // no evolution, no mass budget
  EXPECT_FALSE(ri.contains("t"));
  EXPECT_EQ(ri["spectral_gap"], 0.25);
  EXPECT_EQ(ri["abs_lambda2"], 0.75);
  EXPECT_FALSE(ri.contains("escape_rate"));

  const nlohmann::json esc = nlohmann::json::parse(R"({
    "method": "escape", "times": [], "initial_mass": 0, "mass": [],
    "escape": {"rate": 2.5, "rate_error": 0.125, "lambda1": 0.9}})");
  const auto re = sweep_row(esc);
  EXPECT_EQ(re["escape_rate"], 2.5);
  EXPECT_EQ(re["escape_rate_error"], 0.125);
  EXPECT_FALSE(re.contains("spectral_gap"));

  // method=coherent: each pair's masses and ratios with their errors (pairK_…), beside the
  // budget at t_end; a missing error (no coarse counterpart) leaves its cell empty.
  const nlohmann::json coh = nlohmann::json::parse(R"({
    "method": "coherent", "times": [0, 2], "initial_mass": 1.5, "mass": [1.5, 1.5],
    "coherent": {"sets": [
      {"set": 1, "initial_mass": 1.0, "initial_mass_error": 0.5, "final_mass": 0.75,
       "final_mass_error": 0.25, "forward": 0.875, "forward_error": 0.0625, "backward": 0.625,
       "backward_error": null},
      {"set": 2, "initial_mass": 0.5, "forward": 0.5, "backward": 0.25}]}})");
  const auto rc = sweep_row(coh);
  EXPECT_EQ(rc["t"], 2);
  EXPECT_EQ(rc["pair1_initial_mass"], 1.0);
  EXPECT_EQ(rc["pair1_initial_mass_error"], 0.5);
  EXPECT_EQ(rc["pair1_final_mass"], 0.75);
  EXPECT_EQ(rc["pair1_forward"], 0.875);
  EXPECT_EQ(rc["pair1_forward_error"], 0.0625);
  EXPECT_EQ(rc["pair1_backward"], 0.625);
  EXPECT_FALSE(rc.contains("pair1_backward_error"));
  EXPECT_EQ(rc["pair2_forward"], 0.5);
  EXPECT_EQ(rc["pair2_backward"], 0.25);
  EXPECT_FALSE(rc.contains("set1_mass"));
}

TEST(Sweep, CsvHasEveryColumnAndExactNumbers) {
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  rows.push_back({{"point", 0}, {"e", 0.1}, {"status", "ok"}});
  rows.push_back({{"point", 1}, {"e", 1.0 / 3.0}, {"note", "a, \"b\""}});
  const std::string csv = sweep_csv(rows);
  EXPECT_EQ(csv,
            "point,e,status,note\n"
            "0,0.1,ok,\n"
            "1,0.3333333333333333,,\"a, \"\"b\"\"\"\n");
  EXPECT_EQ(std::strtod("0.3333333333333333", nullptr), 1.0 / 3.0);  // exact: reads back
  nlohmann::ordered_json cr = nlohmann::ordered_json::array();
  cr.push_back({{"note", "a\rb"}});
  EXPECT_EQ(sweep_csv(cr), "note\n\"a\rb\"\n");
}

}  // namespace
