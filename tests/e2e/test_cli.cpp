// End to end: the `hybgen` executable on good and bad input, the docs/design.md
// contracts (derive JSON, run outputs, exit codes), every shipped model run on
// a small grid, and the bouncing ball against its closed-form density.

#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "hybgen/gen/fs.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "hybgen/rt/settings.hpp"
#include "support/ball_closed_form.hpp"
#include "support/e2e.hpp"
#include "support/model_texts.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;
using hybgen::testing::write_model_file;
using nlohmann::json;

const fs::path kWork = e2e_dir("e2e");

using Result = hybgen::testing::ShellResult;  // out: stdout (+ stderr where merged)

/// hybgen with this test's cache (support/e2e.hpp).
const hybgen::testing::Hybgen hybgen{kWork / "cache"};

const std::vector<std::string> kModels = {"bouncing_ball", "sir", "sir_3d", "filippov",
                                          "chaplygin_energy"};
/// Every shipped general hybrid model (the Lie-group ones: tests/e2e/test_lie_models.cpp).
const std::vector<std::string> kHybridModels = {
    "bouncing_ball", "sir",        "sir_3d",       "filippov",          "chaplygin_energy",
    "sawtooth",      "thermostat", "tilted_floor", "integrate_and_fire"};

TEST(Cli, CheckEveryShippedModel) {
  for (const auto& m : kHybridModels) {
    Result r = hybgen("check models/" + m + ".model");
    EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << m << "\n" << r.out;
    EXPECT_NE(r.out.find("ok"), std::string::npos) << r.out;
  }
}

TEST(Cli, AGuardDeclaredTheWrongWayIsAWarningWithItsPlaceAndTheFix) {
  // support/model_texts.hpp's thermostat with its switch off declared the wrong way: check
  // exits 0 (the model is well formed) and warns at the direction word with the source line, a
  // caret and "did you mean 'increasing'?".
  const std::string path =
      write_model_file(kWork, "wrong_way.model", hybgen::testing::kWrongWayThermostat);
  const Result r = hybgen("check '" + path + "'");
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_NE(r.out.find("wrong_way.model:11:14: warning: guard 'off'"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("did you mean 'increasing'?"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  when T = 2 decreasing\n" + std::string(15, ' ') + "^"), std::string::npos)
      << r.out;
}

TEST(Cli, DeriveJsonContract) {
  for (const auto& m : kHybridModels) {
    Result r = hybgen("derive models/" + m + ".model --format json");
    ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
    json j = json::parse(r.out.substr(0, r.out.rfind('}') + 1));
    EXPECT_EQ(j["model"], m);
    EXPECT_EQ(j["kind"], "hybrid");
    EXPECT_TRUE(j["reduction"].is_null());
    ASSERT_TRUE(j["state"].is_array());
    for (const auto& md : j["modes"]) {
      EXPECT_TRUE(md["name"].is_string());
      EXPECT_EQ(md["flow"].size(), j["state"].size());
      EXPECT_TRUE(md["divergence"].is_string());
    }
    for (const auto& g : j["guards"]) {
      for (const char* key : {"name", "from", "to", "surface", "direction", "hybrid_jacobian"})
        EXPECT_TRUE(g[key].is_string()) << key;
      EXPECT_EQ(g["reset"].size(), j["state"].size());
      EXPECT_TRUE(g["direction"] == "decreasing" || g["direction"] == "increasing");
    }
  }
  // The example of docs/design.md, literally.
  Result r = hybgen("derive models/bouncing_ball.model --format json");
  json j = json::parse(r.out);
  EXPECT_EQ(j["state"], json({"x", "p"}));
  EXPECT_EQ(j["parameters"], json({{"m", 1}, {"g", 1}, {"e", 1}}));
  EXPECT_EQ(j["modes"][0]["flow"], json({"p/m", "-g*m"}));
  EXPECT_EQ(j["modes"][0]["divergence"], "0");
  EXPECT_EQ(j["guards"][0]["surface"], "x");
  EXPECT_EQ(j["guards"][0]["reset"], json({"x", "-e*p"}));
  EXPECT_EQ(j["guards"][0]["reset_inverse"], json({"x", "-p/e"}));
  EXPECT_EQ(j["guards"][0]["hybrid_jacobian"], "e^2");
}

TEST(Cli, DeriveTextAndLatex) {
  Result t = hybgen("derive models/sir.model");
  ASSERT_EQ(t.code, exit_status(ExitCode::Success)) << t.out;
  EXPECT_NE(t.out.find("hybrid Jacobian"), std::string::npos);
  EXPECT_NE(t.out.find("Frobenius-Perron"), std::string::npos);
  Result l = hybgen("derive models/bouncing_ball.model --format latex");
  ASSERT_EQ(l.code, exit_status(ExitCode::Success)) << l.out;
  EXPECT_NE(l.out.find("\\begin{cases}"), std::string::npos);
  EXPECT_NE(l.out.find("\\frac{\\partial u}{\\partial t}"), std::string::npos);
}

TEST(Cli, BrokenModelsExitOneWithLocation) {
  struct Case {
    std::string text, where, fragment;
  };
  const std::vector<Case> cases = {
      {"state x\nmode a { x' = 1 +* 2 }\n", ":2:", "error:"},
      {"state x\nmode a { x' = y }\n", ":2:15: error: unknown name 'y'", ""},
      {"", ":1:1: error: the model file is empty", ""},
      {"state x\nmode a { x' = 1 }\n# caf\xe9\n", ":3:", "not valid UTF-8"},
      {"state x\nmode a { x' = -1 }\nguard g { when x = 0 decreasing; reset (x, x) }\n",
       ":3:40:", "2 components"},
      {"state x\nmode a { x' = -1 }\nguard g { from b; when x = 0 decreasing; reset identity }\n",
       ":3:16:", "unknown mode 'b'"},
      {"parameter k = 1e999\nstate x\nmode a { x' = k }\n", ":1:15:", "out of range"},
  };
  int k = 0;
  for (const auto& c : cases) {
    std::string path = write_model_file(kWork, "bad" + std::to_string(k++) + ".model", c.text);
    Result r = hybgen("check '" + path + "'");
    EXPECT_EQ(r.code, exit_status(ExitCode::ModelError)) << r.out;
    EXPECT_NE(r.out.find(path + c.where), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(c.fragment), std::string::npos) << r.out;
  }
}

// The "10-D inverse" of the derivation limits (docs/hardening.md): a reset x ↦ A x with a dense
// 10×10 matrix of parameters. Its closed-form inverse needs det A, 10! = 3,628,800 terms, in one
// GiNaC call that the derivation's own time checks cannot interrupt; the watchdog ends it at 1.5 ·
// derive_seconds + 5 s with a located error naming the object and the setting (everything before
// det A takes ~0.01 s).
TEST(Cli, DenseTenDimensionalInverseEndsAtTheWatchdog) {
  constexpr int n = 10;
  std::ostringstream m;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) m << "parameter a" << i << '_' << j << " = " << (i == j) << "\n";
  m << "state x0";
  for (int i = 1; i < n; ++i) m << ", x" << i;
  m << "\nmode m {\n  x0' = -1\n";
  for (int i = 1; i < n; ++i) m << "  x" << i << "' = x" << i - 1 << "\n";
  m << "}\nguard g {\n  when x0 = 0 decreasing\n  reset (";
  for (int i = 0; i < n; ++i) {
    m << (i ? ", " : "");
    for (int j = 0; j < n; ++j) m << (j ? "+" : "") << 'a' << i << '_' << j << "*x" << j;
  }
  m << ")\n}\n";
  const std::string path = write_model_file(kWork, "dense10.model", m.str());
  const auto t0 = std::chrono::steady_clock::now();
  const Result r = hybgen("derive '" + path + "' --set derive_seconds=1");
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.code, exit_status(ExitCode::ModelError)) << r.out;
  EXPECT_NE(r.out.find(path + ":" + std::to_string(n * n + n + 6) +
                       ":3: error: deriving the inverse reset of guard 'g' took longer than "
                       "6.5 s, inside one symbolic operation (derive_seconds = 1 s"),
            std::string::npos)
      << r.out;
  EXPECT_LT(secs, 60.0) << "the watchdog did not end the derivation";
}

TEST(Cli, BadCommandLinesExitTwo) {
  EXPECT_EQ(hybgen("").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("frobnicate models/sir.model").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("check").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("check no/such/file.model").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("derive models/sir.model --format yaml").code,
            exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("run models/sir.model --set nosuch=1").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("run models/sir.model --set grid=3").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("run models/sir.model --set beta=abc").code, exit_status(ExitCode::UsageError));
  EXPECT_EQ(hybgen("--help").code, exit_status(ExitCode::Success));
}

fs::path run_dir(const std::string& name) {
  return hybgen::testing::own_dir(kWork) / "runs" / name;
}

/// The runs these tests read arrays of: run.nc and pictures (the default) and the .npy
/// frames (on request).
const std::string kWithArrays = " --set outputs=netcdf+png+npy";

/// Run a model into a fresh directory; return its summary.
json run(const std::string& model, const std::string& tag, const std::string& sets) {
  fs::path out = run_dir(tag);
  fs::remove_all(out);
  Result r = hybgen("run models/" + model + ".model --quiet --out '" + out.string() + "' " + sets +
                    kWithArrays);
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  return read_json_file(out / "summary.json");
}

void check_run_outputs(const json& s, const fs::path& out, std::size_t dims) {
  for (const char* key :
       {"model", "method", "grid", "times", "files", "mass", "outflow", "seconds"})
    EXPECT_TRUE(s.contains(key)) << key;
  ASSERT_EQ(s["grid"]["axes"].size(), dims);
  std::vector<std::size_t> shape;
  for (const auto& a : s["grid"]["axes"]) {
    EXPECT_TRUE(a.contains("name") && a.contains("min") && a.contains("max"));
    shape.push_back(a["n"].get<std::size_t>());
  }
  EXPECT_EQ(s["files"].size(), s["times"].size());
  EXPECT_EQ(s["mass"].size(), s["times"].size());
  EXPECT_EQ(s["outflow"].size(), s["times"].size());
  for (const char* k : {"derive", "build", "solve"}) EXPECT_TRUE(s["seconds"][k].is_number());
  EXPECT_EQ(s["outputs"]["netcdf"], "run.nc");
  EXPECT_TRUE(fs::exists(out / "run.nc"));
  for (const auto& f : s["files"]) {
    auto arr = hybgen::rt::read_npy((out / f.get<std::string>()).string());
    EXPECT_EQ(arr.shape, shape);
    for (double v : arr.data) EXPECT_TRUE(std::isfinite(v));
    std::string png = (out / f.get<std::string>()).replace_extension(".png").string();
    EXPECT_TRUE(fs::exists(png)) << png;
  }
}

TEST(Cli, RunEveryShippedModelOnASmallGrid) {
  const std::map<std::string, std::string> grids = {{"bouncing_ball", "21x21"},
                                                    {"sir", "21x21"},
                                                    {"sir_3d", "9x9x9"},
                                                    {"filippov", "21x21"},
                                                    {"chaplygin_energy", "21x21"}};
  for (const auto& m : kModels) {
    SCOPED_TRACE(m);
    json s = run(m, "small_" + m, "--set grid=" + grids.at(m) + " --set t_end=1 --set dt=0.5");
    check_run_outputs(s, run_dir("small_" + m), m == "sir_3d" ? 3u : 2u);
    EXPECT_EQ(s["times"].size(), 3u);
  }
}

/// The worst relative L1 error, over the output times of a run of the elastic ball on an
/// n×n grid of [0, 2] × [−2, 2], against the closed form. The node (0, 0) is the Zeno
/// point: stripes of every phase meet there and the density has no limit (the closed
/// form's period 2 v0 is 0), so it is left out (n odd puts a node there).
double ball_worst_relative_l1(const json& s, const fs::path& out, std::size_t n) {
  double worst = 0;
  const double h = 1.0 / static_cast<double>(n - 1);
  for (std::size_t k = 0; k < s["times"].size(); ++k) {
    const double t = s["times"][k];
    auto arr = hybgen::rt::read_npy((out / s["files"][k].get<std::string>()).string());
    EXPECT_EQ(arr.shape, (std::vector<std::size_t>{n, n}));
    if (arr.shape != std::vector<std::size_t>{n, n}) return 1.0;
    double err = 0, norm = 0;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j) {
        const double x = 2.0 * static_cast<double>(i) * h;
        const double p = -2 + 4.0 * static_cast<double>(j) * h;
        if (i == 0 && 2 * j == n - 1) continue;
        const double ue = hybgen::testing::ball_exact_elastic(x, p, t);
        err += std::fabs(arr.data[i * n + j] - ue);
        norm += std::fabs(ue);
      }
    worst = std::max(worst, err / norm);
  }
  return worst;
}

TEST(Cli, BouncingBallPaperConfigurationMatchesClosedForm) {
  json s = run("bouncing_ball", "paper", "--set t_end=9.8 --set dt=0.2");
  ASSERT_EQ(s["times"].size(), 50u);
  const double worst = ball_worst_relative_l1(s, run_dir("paper"), 75);
  std::printf(
      "bouncing ball 75x75, 50 outputs to t=9.8: worst relative L1 error %.3e, solve %.4f s\n",
      worst, s["seconds"]["solve"].get<double>());
  EXPECT_LE(worst, 1e-4);
}

// A dyadic grid (h = 1/32 in x, 1/16 in p) with outputs every 0.5: many backward
// characteristics meet the ground exactly at an output time (x(τ) = x + p τ − τ²/2 has
// dyadic roots), a tie between the straight history and the reset one. Each such node must
// get one of its two one-sided values, never their sum or 0 (tests/rt/test_ties.cpp checks
// the tracer node by node; this checks the runner that users run). Tolerance: far above the
// ~1e-14 of a correct run, far below the ~1e-4 of a tie decided both ways at some nodes.
TEST(Cli, BouncingBallDyadicGridTiesAreDecidedOnce) {
  json s = run("bouncing_ball", "dyadic", "--set grid=65x65 --set t_end=10 --set dt=0.5");
  ASSERT_EQ(s["times"].size(), 21u);
  const double worst = ball_worst_relative_l1(s, run_dir("dyadic"), 65);
  std::printf("bouncing ball 65x65, 21 outputs to t=10: worst relative L1 error %.3e\n", worst);
  EXPECT_LE(worst, 1e-9);
}

TEST(Cli, RestitutionMassBudget) {
  json s = run("bouncing_ball", "restitution", "--set e=0.8 --set budget=full");
  ASSERT_TRUE(s.contains("atom"));
  const auto& times = s["times"];
  const auto& atom = s["atom"];
  const double m0 = s["initial_mass"];
  // mass + outflow + atom = initial mass is how the atom is defined; what is
  // checked is that the atom is the mass that has come to rest at the Zeno
  // point, computed independently in closed form.
  double worst = 0;
  for (std::size_t k = 0; k < times.size(); ++k) {
    double z = hybgen::testing::zeno_mass(times[k].get<double>(), 0.8);
    worst = std::max(worst, std::fabs(atom[k].get<double>() - z) / m0);
  }
  std::printf(
      "restitution e=0.8: final atom %.6f, closed-form Zeno mass %.6f, worst |diff|/m0 %.2e\n",
      atom.back().get<double>(), hybgen::testing::zeno_mass(times.back().get<double>(), 0.8),
      worst);
  EXPECT_GT(hybgen::testing::zeno_mass(10, 0.8), 0.1 * m0);  // the check is not vacuous
  EXPECT_LE(worst, 2e-3);
}

/// The runner's path: the last line hybgen build printed on stdout.
std::string built_runner(const Result& r) {
  std::string out = r.out;
  while (!out.empty() && out.back() == '\n') out.pop_back();
  return out.substr(out.rfind('\n') + 1);
}

TEST(Cli, ParameterValuesReuseTheRunner) {
  // Parameters are read at run time (the runner's configuration), so a new value must not
  // compile a new runner: the header the runner is built from carries the file's defaults.
  // Before, --set e=… put the value into the header and so into the cache key.
  const Result a = hybgen("build models/bouncing_ball.model --set e=0.55");
  ASSERT_EQ(a.code, exit_status(ExitCode::Success)) << a.out;
  const Result b = hybgen("build models/bouncing_ball.model --set e=0.8 --set g=2");
  ASSERT_EQ(b.code, exit_status(ExitCode::Success)) << b.out;
  EXPECT_EQ(built_runner(a), built_runner(b));
  EXPECT_NE(b.out.find("runner (cached)"), std::string::npos) << b.out;
  // ... and the run uses the values it was given, not the header's (RestitutionMassBudget
  // checks the physics of e = 0.8 with this runner: the atom against the closed form).
  const json s =
      run("bouncing_ball", "reuse", "--set e=0.8 --set g=2 --set grid=21x21 --set t_end=1");
  EXPECT_EQ(s["parameters"]["e"].get<double>(), 0.8);
  EXPECT_EQ(s["parameters"]["g"].get<double>(), 2.0);
}

TEST(Cli, BuildVerboseNamesTheCompilerCommandOfACachedRunner) {
  // `hybgen build -v` says how the runner it hands over was compiled, also when it comes
  // from the cache (a81ba15 printed "runner (cached) PATH" and nothing of the command, which
  // it had printed only on the miss).
  const Result first = hybgen("build models/bouncing_ball.model");
  ASSERT_EQ(first.code, exit_status(ExitCode::Success)) << first.out;
  const Result again = hybgen("build -v models/bouncing_ball.model");
  ASSERT_EQ(again.code, exit_status(ExitCode::Success)) << again.out;
  EXPECT_NE(again.out.find("cached runner "), std::string::npos) << again.out;
  EXPECT_NE(again.out.find(", compiled by: "), std::string::npos) << again.out;
  EXPECT_NE(again.out.find("-std=c++20"), std::string::npos) << again.out;
  EXPECT_EQ(built_runner(first), built_runner(again));
}

TEST(Cli, OneRunnerForEveryMethodAndValue) {
  // One runner per model (generator/src/build.cpp): parameter values, the method and every
  // setting are read at run time, so after the first build nothing compiles. A private
  // cache, so that the count of its entries is this test's.
  const fs::path cache = kWork / "cache_one_runner";
  fs::remove_all(cache);
  auto go = [&](const std::string& sets) {
    const fs::path out = run_dir("one_runner");
    fs::remove_all(out);
    return run_hybgen("run models/bouncing_ball.model --out '" + out.string() +
                          "' --set grid=21x21 --set t_end=1 " + sets,
                      cache);
  };
  const Result first = go("--set e=0.55");
  ASSERT_EQ(first.code, exit_status(ExitCode::Success)) << first.out;
  EXPECT_NE(first.out.find("runner (built in"), std::string::npos) << first.out;
  for (const char* sets : {"--set e=0.8", "--set method=transfer",
                           "--set method=particles "
                           "--set particles=20000",
                           "--set method=invariant --set scheme=hat"}) {
    const Result r = go(sets);
    ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << sets << "\n" << r.out;
    EXPECT_NE(r.out.find("runner (cached)"), std::string::npos) << sets << "\n" << r.out;
  }
  std::size_t entries = 0;
  for (const auto& e : fs::directory_iterator(cache)) entries += e.is_directory() ? 1 : 0;
  EXPECT_EQ(entries, 1u);
}

TEST(Cli, InlineRuntimeAgreesWithTheLibrary) {
  // --inline-runtime compiles the whole runtime with the kernels inlined (the path of models
  // outside the library's shapes, build.cpp): the same densities to rounding. Rounding
  // differs (the compiler contracts a*b+c differently once a kernel is inlined), and at t = 2
  // one node of this grid, (x, p) = (2/15, 0), lies within rounding of the curve where the
  // density jumps (the backward characteristic ends at x = 0, t = 0: one bounce more or
  // less, a factor 1/e^2): there the two runners may take either side. So: every node at
  // t = 1, and all but 1 % of the nodes at t = 2.
  const std::string sets = "--set e=0.8 --set grid=31x31 --set t_end=2 --set dt=1";
  const json a = run("bouncing_ball", "library", sets);
  const json b = run("bouncing_ball", "inline", sets + " --inline-runtime");
  for (const char* frame : {"u_0001.npy", "u_0002.npy"}) {
    const auto ua = hybgen::rt::read_npy((run_dir("library") / frame).string());
    const auto ub = hybgen::rt::read_npy((run_dir("inline") / frame).string());
    ASSERT_EQ(ua.data.size(), ub.data.size());
    double peak = 0;
    for (double v : ua.data) peak = std::max(peak, std::fabs(v));
    std::size_t differ = 0;
    for (std::size_t i = 0; i < ua.data.size(); ++i)
      differ += std::fabs(ua.data[i] - ub.data[i]) > 1e-9 * peak ? 1 : 0;
    EXPECT_GT(peak, 0.1) << frame;
    EXPECT_LE(differ, std::string(frame) == "u_0001.npy" ? 0 : ua.data.size() / 100) << frame;
  }
  EXPECT_NEAR(a["atom"].back().get<double>(), b["atom"].back().get<double>(), 1e-9);
}

TEST(Cli, RunHelpListsEverySetting) {
  const Result r = hybgen("run --help");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  for (const auto& s : hybgen::rt::kSettings)
    EXPECT_NE(r.out.find("  " + std::string(s.name) + " "), std::string::npos) << s.name;
}

TEST(Cli, TransferNeverCreatesMassThroughTheCommandLine) {
  // The issue's own command: the ball with e = 0.8 on 301², method transfer (the default
  // scheme). The withdrawn interpolating scheme took its grid mass from 2.6 to 3e14 with exit
  // 0. Checked from summary.json alone: the mass never exceeds the initial mass, and mass +
  // outflow + atom = initial mass to 1e-12, with the conservation defects reported.
  json s =
      run("bouncing_ball", "transfer_e08", "--set e=0.8 --set grid=301x301 --set method=transfer");
  ASSERT_TRUE(s.contains("transfer")) << s.dump();
  EXPECT_EQ(s["transfer"]["scheme"], "hat");
  EXPECT_LE(s["transfer"]["column_defect"].get<double>(), 1e-12);
  EXPECT_LE(s["transfer"]["budget_defect"].get<double>(), 1e-12);
  const double m0 = s["initial_mass"];
  for (std::size_t k = 0; k < s["times"].size(); ++k) {
    const double m = s["mass"][k], out = s["outflow"][k], atom = s["atom"][k];
    EXPECT_LE(m, m0 * (1.0 + 1e-13)) << "t = " << s["times"][k];
    EXPECT_NEAR(m + out + atom, m0, 1e-12 * m0) << "t = " << s["times"][k];
  }
  std::printf("transfer e=0.8 301^2: mass %.6f -> %.6f, outflow %.6f, atom %.6f\n", m0,
              s["mass"].back().get<double>(), s["outflow"].back().get<double>(),
              s["atom"].back().get<double>());
  // The withdrawn schemes are refused with the reason, before anything is built.
  for (const char* old : {"interpolate", "conservative", "cell"}) {
    Result r = hybgen(std::string("check models/bouncing_ball.model --set scheme=") + old);
    EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
    EXPECT_NE(r.out.find("was withdrawn"), std::string::npos) << r.out;
  }
}

TEST(Cli, ThermostatInvariantDensityThroughTheCommandLine) {
  // A model hybgen does not ship (tests/validation/test_thermostat.cpp has the same system
  // and the derivation of its closed form): heating x' = 4 − x to x = 2, cooling x' = −1.5x to
  // x = 1; the invariant density is u_m = (1/P)/|f_m| with P = ln(3/2) + ln(2)/1.5. Through
  // `hybgen run … method=invariant` on 401 nodes: λ₁ within 1e-9 of 1 (a closed system) and
  // the density per mode (invariant_on.npy, invariant_off.npy) within 1 % in relative L1.
  const std::string path = write_model_file(kWork, "thermostat.model", R"(model thermostat
state x
mode on  { x' = 4 - x }
mode off { x' = -1.5*x }
guard cut  { from on to off  when x = 2 increasing  reset identity }
guard heat { from off to on  when x = 1 decreasing  reset identity }
simulation { domain x in [1, 2]; grid 401; initial on: 1; t_end 1; dt 0.05; method invariant }
)");
  fs::path out = run_dir("thermostat");
  fs::remove_all(out);
  Result r = hybgen("run '" + path + "' --quiet --out '" + out.string() + "'" + kWithArrays);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  json s = read_json_file(out / "summary.json");
  const double lam = s["invariant"]["eigenvalues"][0]["re"];
  EXPECT_NEAR(lam, 1.0, 1e-9);
  const double P = std::log(1.5) + std::log(2.0) / 1.5;
  double num = 0.0, den = 0.0;
  for (const char* mode : {"on", "off"}) {
    auto arr = hybgen::rt::read_npy((out / (std::string("invariant_") + mode + ".npy")).string());
    ASSERT_EQ(arr.data.size(), 401u);
    for (std::size_t i = 0; i < 401; ++i) {
      const double x = 1.0 + static_cast<double>(i) / 400.0;
      const double w = (i == 0 || i == 400) ? 0.5 : 1.0;
      const double exact = 1.0 / P / (mode[1] == 'n' ? 4.0 - x : 1.5 * x);
      num += w * std::fabs(arr.data[i] - exact);
      den += w * exact;
    }
  }
  std::printf("thermostat invariant (CLI): lambda1 - 1 = %.2e, rel L1 %.3e\n", lam - 1.0,
              num / den);
  EXPECT_LT(num / den, 1e-2);
}

TEST(Cli, SawtoothConstantResetRunsBackwardAndForward) {
  // models/sawtooth.model: x' = 1 + x on [0, 1], x ↦ 0 at x = 1. The reset is constant: no
  // inverse in the whole line, injective on its guard (a point). derive says so in its
  // contract ("reset_inverse_kind": "guard") with J = X(0)/X(1) = 1/2. The characteristics
  // invert it on the guard: from u0 = 1 the flux u·(1 + x) = e^s, s = ln(1 + x), is carried
  // around the period ln 2, u(x, t) = exp((s − t) mod ln 2)/(1 + x), which jumps where
  // s ≡ t (nodes within 1e-9 of it left out). A reset singular without a constant component,
  // (x + y, x + y) at x = 1 (injective on the guard, whose tangent e_y goes to (1, 1)), is
  // still refused by the characteristics, located, naming the forward methods. The invariant
  // density on 401 nodes is the closed form u = 1/(ln 2 (1 + x)) (the flux u·x' is constant)
  // within 1 % in relative L1, λ₁ = 1.
  Result d = hybgen("derive models/sawtooth.model --format json");
  ASSERT_EQ(d.code, exit_status(ExitCode::Success)) << d.out;
  json j = json::parse(d.out.substr(0, d.out.rfind('}') + 1));
  EXPECT_EQ(j["guards"][0]["reset_inverse_kind"], "guard");
  EXPECT_TRUE(j["guards"][0]["reset_inverse"].is_null());
  EXPECT_EQ(j["guards"][0]["hybrid_jacobian"], "1/2");
  const json sc =
      run("sawtooth", "sawtooth_char", "--set method=characteristics --set t_end=1 --set dt=0.5");
  ASSERT_EQ(sc["times"].size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    const double t = sc["times"][k].get<double>();
    char frame[32];
    std::snprintf(frame, sizeof frame, "u_%04zu.npy", k);
    const auto u = hybgen::rt::read_npy((run_dir("sawtooth_char") / frame).string());
    ASSERT_EQ(u.data.size(), 401u);
    double worst = 0.0;
    for (std::size_t i = 0; i < 401; ++i) {
      const double x = static_cast<double>(i) / 400.0, s = std::log1p(x);
      const double phase = std::fmod(s - t + 10.0 * std::log(2.0), std::log(2.0));
      if (phase < 1e-9 || std::log(2.0) - phase < 1e-9) continue;  // on the jump
      const double exact = std::exp(phase) / (1.0 + x);
      worst = std::max(worst, std::fabs(u.data[i] - exact) / exact);
    }
    EXPECT_LE(worst, 1e-8) << "t = " << t;
  }
  const std::string singular = write_model_file(kWork, "singular_reset.model", R"(model singular
state x, y
mode a {
  x' = 1 + x
  y' = -y
}
guard g {
  when x = 1 increasing
  reset (x + y, x + y)
}
simulation {
  domain x in [0, 1]
  domain y in [-1, 1]
  grid 21x21
  initial exp(-x^2 - y^2)
  t_end 1
  method characteristics
}
)");
  Result c =
      hybgen("run '" + singular + "' --quiet --out '" + run_dir("singular_char").string() + "'");
  EXPECT_EQ(c.code, exit_status(ExitCode::ModelError)) << c.out;
  EXPECT_NE(c.out.find("singular_reset.model:9:3: error: the reset of guard 'g' has no "
                       "inverse in the whole state space"),
            std::string::npos)
      << c.out;
  EXPECT_NE(c.out.find("method=transfer"), std::string::npos) << c.out;
  json s = run("sawtooth", "sawtooth", "");
  const double lam = s["invariant"]["eigenvalues"][0]["re"];
  EXPECT_NEAR(lam, 1.0, 1e-9);
  auto arr = hybgen::rt::read_npy((run_dir("sawtooth") / "invariant.npy").string());
  ASSERT_EQ(arr.data.size(), 401u);
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < 401; ++i) {
    const double x = static_cast<double>(i) / 400.0, w = (i == 0 || i == 400) ? 0.5 : 1.0;
    const double exact = 1.0 / (std::log(2.0) * (1.0 + x));
    num += w * std::fabs(arr.data[i] - exact);
    den += w * exact;
  }
  std::printf("sawtooth invariant (CLI): lambda1 - 1 = %.2e, rel L1 %.3e\n", lam - 1.0, num / den);
  EXPECT_LT(num / den, 1e-2);
}

/// The spiking cycle of models/integrate_and_fire.model (I = 2, tau = 2, b = 0.3), integrated
/// here by classical RK4 (step 1e-5, the threshold crossing by linear interpolation), not by
/// hybgen: the fraction of one period spent in each dual cell of the model's grid, 129 nodes on
/// [0, 1] for v (axis 0) and 167 on [0, 1.3] for w (axis 1).
std::array<std::vector<double>, 2> if_cycle_marginals() {
  const std::array<std::size_t, 2> n{129, 167};
  const std::array<double, 2> top{1.0, 1.3};
  const double I = 2.0, tau = 2.0, b = 0.3, h = 1e-5;
  auto f = [&](double v, double w, double& dv, double& dw) {
    dv = I - v - w;
    dw = -w / tau;
  };
  auto step = [&](double& v, double& w) {
    double k1v, k1w, k2v, k2w, k3v, k3w, k4v, k4w;
    f(v, w, k1v, k1w);
    f(v + 0.5 * h * k1v, w + 0.5 * h * k1w, k2v, k2w);
    f(v + 0.5 * h * k2v, w + 0.5 * h * k2w, k3v, k3w);
    f(v + h * k3v, w + h * k3w, k4v, k4w);
    v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    w += h / 6 * (k1w + 2 * k2w + 2 * k3w + k4w);
  };
  std::array<std::vector<double>, 2> m{std::vector<double>(n[0], 0.0),
                                       std::vector<double>(n[1], 0.0)};
  double w0 = 0.5;
  for (int cycle = 0; cycle < 40; ++cycle) {  // settle: w⁺ contracts by e^{−T/τ} ≈ 0.57
    const bool last = cycle == 39;
    double v = 0.0, w = w0, total = 0.0;
    for (;;) {
      const double vp = v, wp = w;
      step(v, w);
      double dt = h;
      if (v >= 1.0) {  // the threshold within this step: keep the part before it
        const double s = (1.0 - vp) / (v - vp);
        dt = s * h;
        w = wp + s * (w - wp);
        v = 1.0;
      }
      if (last)
        for (std::size_t a = 0; a < 2; ++a) {
          const double x = a == 0 ? 0.5 * (vp + v) : 0.5 * (wp + w);
          const auto k =
              static_cast<std::size_t>(std::lround(x / top[a] * static_cast<double>(n[a] - 1)));
          m[a][std::min(k, n[a] - 1)] += dt;
        }
      total += dt;
      if (v >= 1.0) break;
    }
    w0 = w + b;
    if (last)
      for (auto& axis : m)
        for (double& x : axis) x /= total;
  }
  return m;
}

TEST(Cli, IntegrateAndFireInvariantDensityFollowsTheSpikingCycle) {
  // models/integrate_and_fire.model: (v, w) ↦ (0, w + b) at v = 1 has no inverse in the
  // plane (constant v) and is injective on the threshold. Its invariant density by `method
  // invariant` on the model's 129 × 167 grid: λ₁ = 1 (every trajectory stays in the box and settles
  // on the cycle), and the v and w marginals (trapezoid masses per node) against the fraction
  // of the period the cycle spends in each dual cell, computed above by an independent RK4
  // integration. Measured total-variation distances: v 1.8e-3, w 7.2e-2 (the cycle is a curve;
  // the operator smears it over a few cells across, which the w marginal sees). Asserted:
  // v < 1e-2, w < 0.1.
  json s = run("integrate_and_fire", "integrate_and_fire", "");
  const double lam = s["invariant"]["eigenvalues"][0]["re"];
  EXPECT_NEAR(lam, 1.0, 1e-9);
  auto arr = hybgen::rt::read_npy((run_dir("integrate_and_fire") / "invariant.npy").string());
  const std::size_t nv = 129, nw = 167;
  ASSERT_EQ(arr.shape, (std::vector<std::size_t>{nv, nw}));
  std::array<std::vector<double>, 2> got{std::vector<double>(nv, 0.0),
                                         std::vector<double>(nw, 0.0)};
  double total = 0.0;
  for (std::size_t i = 0; i < nv; ++i)
    for (std::size_t j = 0; j < nw; ++j) {
      const double wi = (i == 0 || i == nv - 1) ? 0.5 : 1.0;
      const double wj = (j == 0 || j == nw - 1) ? 0.5 : 1.0;
      const double mass = wi * wj * arr.data[i * nw + j];
      got[0][i] += mass;
      got[1][j] += mass;
      total += mass;
    }
  const auto ref = if_cycle_marginals();
  for (int a = 0; a < 2; ++a) {
    double tv = 0.0;
    for (std::size_t k = 0; k < got[static_cast<std::size_t>(a)].size(); ++k)
      tv += std::fabs(got[static_cast<std::size_t>(a)][k] / total -
                      ref[static_cast<std::size_t>(a)][k]);
    std::printf("integrate-and-fire invariant (CLI): %s-marginal TV distance %.3e\n",
                a == 0 ? "v" : "w", tv);
    EXPECT_LT(tv, a == 0 ? 1e-2 : 0.1) << (a == 0 ? "v" : "w");
  }
}

// `check --preflight` runs the run's pre-flight scan (building the ball's runner, shared with
// the other tests through the cache) and says what the run would say: with e = 3/2 the reset at
// (0, −2) lands at p = 3, outside the box, which is a warning (its mass is outflow) and passes;
// a reset that lands outside the support fails with the run's message and exit code. Before,
// check passed both and only `run` refused.
TEST(Cli, CheckPreflightAgreesWithRun) {
  Result ok = hybgen("check models/bouncing_ball.model --preflight -q");
  EXPECT_EQ(ok.code, exit_status(ExitCode::Success)) << ok.out;
  EXPECT_NE(ok.out.find("pre-flight scan (t = 0, characteristics, grid of 5625 nodes): ok"),
            std::string::npos)
      << ok.out;
  Result out = hybgen("check models/bouncing_ball.model --preflight -q --set e=3/2");
  EXPECT_EQ(out.code, exit_status(ExitCode::Success)) << out.out;
  EXPECT_NE(out.out.find("the reset carries mass out of the domain (the grid box) at the point "
                         "(x = 0, p = -2)"),
            std::string::npos)
      << out.out;
  EXPECT_NE(out.out.find("ok, 1 guard(s), 1 resetting mass out of the box"), std::string::npos)
      << out.out;
  Result bad = hybgen("check tests/data/failures/reset_outside_support.model --preflight -q");
  EXPECT_EQ(bad.code, exit_status(ExitCode::Numerical)) << bad.out;
  EXPECT_NE(bad.out.find("the reset lands outside the support (the state space) at the point "
                         "(x = 0, p = -2)"),
            std::string::npos)
      << bad.out;
  Result plain = hybgen("check tests/data/failures/reset_outside_support.model");
  EXPECT_EQ(plain.code, exit_status(ExitCode::Success))
      << plain.out;  // without --preflight: no runner, no scan
}

TEST(Cli, NumericalFailureExitsThree) {
  // On the Chaplygin energy surface |v| ≤ √(2E/m) = √2; widening the domain to
  // |v| ≤ 2 asks for θ' = √(negative): the vector field is not finite there,
  // which is reported with the state, the mode and the time, not hidden.
  fs::path out = run_dir("failure");
  Result r = hybgen(
      "run models/chaplygin_energy.model --quiet --set domain.v=[-2,2] "
      "--set grid=11x11 --out '" +
      out.string() + "'");
  EXPECT_EQ(r.code, exit_status(ExitCode::Numerical)) << r.out;
  EXPECT_NE(r.out.find("numerical failure"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("non-finite vector field"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("v = -2"), std::string::npos) << r.out;
}

TEST(Cli, DegenerateParameterIsAModelError) {
  // e = 0: every impact ends at p = 0, J = e² = 0 at every crossing.
  Result r = hybgen("check models/bouncing_ball.model --set e=0");
  EXPECT_EQ(r.code, exit_status(ExitCode::ModelError)) << r.out;
  EXPECT_NE(r.out.find("models/bouncing_ball.model:20:3: error: the hybrid Jacobian"),
            std::string::npos)
      << r.out;
}

TEST(Cli, OneDimensionalModelGivesLinePlots) {
  std::string path = write_model_file(kWork, "decay.model",
                                      R"(# x' = -x on [0, 2]; at x = 1/2 the state jumps up by 1.
state x
mode m { x' = -x }
guard kick { when x = 0.5 decreasing; reset (x + 1) }
simulation { domain x in [0, 2]; grid 101; initial exp(-(x - 1)^2); t_end 1; dt 0.5 }
)");
  fs::path out = run_dir("decay");
  fs::remove_all(out);
  Result r = hybgen("run '" + path + "' --quiet --out '" + out.string() + "'" + kWithArrays);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  json s = read_json_file(out / "summary.json");
  check_run_outputs(s, out, 1);
  auto arr = hybgen::rt::read_npy((out / "u_0002.npy").string());  // t = 1
  auto u0 = [](double x) { return std::exp(-(x - 1) * (x - 1)); };
  const double E = std::exp(1.0);  // exp(−∫div) = e^t with div = −1
  // x = 0.1 (node 5): the backward path 0.1 e^τ stays below 1/2: u = u0(0.1 e) e.
  EXPECT_NEAR(arr.data[5], u0(0.1 * E) * E, 1e-9);
  // x = 0.3 (node 15): the backward path reaches the guard x = 1/2 at τ = ln(5/3)
  // the way it fires, so no history stays in this mode: u = 0.
  EXPECT_NEAR(arr.data[15], 0.0, 1e-12);
  // x = 1.2 (node 60): two histories. Straight back: u0(1.2 e) e. Through the
  // reset image x = 1.5 at τ = ln 1.25, pre-image 0.5, then 0.5 e^{1 − ln 1.25}
  // = 0.4 e, with 1/|J| and J = X⁺(1.5)/X⁻(0.5) = (−1.5)/(−0.5) = 3.
  EXPECT_NEAR(arr.data[60], u0(1.2 * E) * E + u0(0.4 * E) * E / 3, 1e-9);
}

TEST(Cli, TwoConcurrentRunsBothSucceed) {
  // A fresh cache so that both runs build at the same time.
  std::string cache = (kWork / "cache_concurrent").string();
  fs::remove_all(cache);
  auto one = [&](int k, int* code) {
    std::string out = run_dir("concurrent" + std::to_string(k)).string();
    *code =
        run_hybgen("run models/filippov.model --quiet --set grid=15x15 --out '" + out + "'", cache)
            .code;
  };
  int a = -1, b = -1;
  std::thread ta(one, 1, &a), tb(one, 2, &b);
  ta.join();
  tb.join();
  EXPECT_EQ(a, exit_status(ExitCode::Success));
  EXPECT_EQ(b, exit_status(ExitCode::Success));
}

}  // namespace
