// End to end: every numerical failure class (docs/hardening.md) provoked by a tiny model of
// tests/data/failures/ (exit 3 and the message: what, which guard/mode, where, when), and
// "nothing lost, nothing half-written": staged outputs swapped into place only on success,
// the output-directory lock, a full disk, a corrupted build cache, a failed compile (exit 4
// with the compiler log's path).

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "hybgen/gen/fs.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::read_json_file;
using hybgen::testing::run_hybgen;
using nlohmann::json;

const std::string kSrc = HYBGEN_SOURCE_DIR;
const fs::path kWork = e2e_dir("e2e_failures");

using Result = hybgen::testing::ShellResult;  // out: stdout (+ stderr where merged)

/// `prefix hybgen args` (prefix: environment assignments or shell set-up ending in "&&") from
/// the source directory with this test's cache (support/e2e.hpp).
const hybgen::testing::Hybgen hybgen{kWork / "cache"};

/// Names in the directory of `out` that begin with out's name followed by `.partial-` or
/// `.old-` (a staging or old directory left behind).
std::vector<std::string> leftovers(const fs::path& out) {
  std::vector<std::string> v;
  const std::string name = out.filename().string();
  for (const auto& e : fs::directory_iterator(out.parent_path())) {
    const std::string n = e.path().filename().string();
    if (n.rfind(name + ".partial-", 0) == 0 || n.rfind(name + ".old-", 0) == 0) v.push_back(n);
  }
  return v;
}

/// After a run `r` into `out` that failed or was stopped: it said that the previous outputs
/// are unchanged, they are (summary.json reads `summary` as before), and no staging or old
/// directory is left beside `out`.
void expect_previous_outputs_kept(const Result& r, const fs::path& out,
                                  const std::string& summary) {
  EXPECT_NE(r.out.find("the previous outputs in '" + out.string() + "' are unchanged"),
            std::string::npos)
      << r.out;
  EXPECT_EQ(hybgen::gen::read_file((out / "summary.json").string()), summary);
  EXPECT_TRUE(leftovers(out).empty());
}

/// A fresh output directory for test `name`: removed, with the leftovers of earlier runs
/// of the test beside it (a stale `.partial-<pid>` would name another process).
fs::path fresh_out(const std::string& name) {
  const fs::path out = hybgen::testing::own_dir(kWork) / "runs" / name;
  fs::create_directories(out.parent_path());
  fs::remove_all(out);
  for (const auto& n : leftovers(out)) fs::remove_all(out.parent_path() / n);
  return out;
}

/// Run a failure model of tests/data/failures into a fresh directory: exit 3, every
/// fragment in the message, nothing written, and the output says so.
std::string expect_failure(const std::string& model, const std::vector<std::string>& fragments,
                           const std::string& sets = "") {
  const fs::path out = fresh_out("fail_" + model);
  const Result r = hybgen("run tests/data/failures/" + model + ".model --quiet --out '" +
                          out.string() + "' " + sets);
  EXPECT_EQ(r.code, exit_status(ExitCode::Numerical)) << r.out;
  EXPECT_NE(r.out.find("hybgen: numerical failure: "), std::string::npos) << r.out;
  for (const auto& f : fragments) EXPECT_NE(r.out.find(f), std::string::npos) << f << "\n" << r.out;
  EXPECT_FALSE(fs::exists(out)) << "a failed first run must not create its output directory";
  EXPECT_NE(r.out.find("nothing was written to '" + out.string() + "'"), std::string::npos)
      << r.out;
  EXPECT_TRUE(leftovers(out).empty());
  std::printf("[ message ] %s\n", r.out.c_str());
  return r.out;
}

/// The number printed after `key` in `text` (NaN if absent).
double number_after(const std::string& text, const std::string& key) {
  const std::size_t at = text.find(key);
  if (at == std::string::npos) return std::nan("");
  return std::strtod(text.c_str() + at + key.size(), nullptr);
}

// ---------------------------------------------------------------------------------------
// 4. Numerical failures, each named with its place and time (exit 3).

TEST(NumericalFailure, NonFiniteFlowAndDivergence) {
  // Backward x(τ) = 1/2 − τ from the node (1/2, −1): log(x) is −inf at τ = 1/2. The trace
  // stops at the last finite state before it; there x + τ = 1/2 exactly (x' = −1 is
  // integrated exactly by Runge–Kutta up to rounding), and x is within the last step of 0.
  const std::string msg = expect_failure(
      "nan_flow", {"characteristic from (x = 0.5, y = -1) in mode 'm' failed: non-finite vector "
                   "field or divergence at backward time tau = ",
                   "mode 'm', after 0 resets"});
  const double tau = number_after(msg, "tau = "), x = number_after(msg, "state (x = ");
  EXPECT_NEAR(tau + x, 0.5, 1e-12) << msg;
  EXPECT_GE(x, 0.0);
  EXPECT_LE(x, 1e-2);
}

TEST(NumericalFailure, NegativeInitialDensity) {
  // u0 = x − 1/2: the first node in C order (x slowest) is (0, −1), where u0 = −1/2.
  expect_failure("negative_initial", {"pre-flight scan of the initial density at t = 0: negative "
                                      "initial density u0 = -0.5 at the grid node (x = 0, p = "
                                      "-1) in mode 'm'"});
}

TEST(NumericalFailure, NonFiniteInitialDensity) {
  expect_failure("nan_initial", {"pre-flight scan of the initial density at t = 0: non-finite "
                                 "initial density u0 = inf at the grid node (x = 0, p = -1) in "
                                 "mode 'm'"});
}

// A reset that lands outside the grid box is no failure: its mass is outflow
// (tests/validation/test_reset_outflow.cpp).

TEST(NumericalFailure, ResetOutsideTheSupport) {
  // Δ(0, −2) = (−1/2, 2), and the support is x ≥ 0.
  expect_failure("reset_outside_support",
                 {"pre-flight scan of guard 'ground' at t = 0: the reset lands outside the "
                  "support (the state space) at the point (x = 0, p = -2) of its surface in "
                  "mode 'flight': Delta = (x = -0.5, p = 2)"});
}

TEST(NumericalFailure, TwoGuardsOfOneModeThatFireAtTheSameStates) {
  // 2x + 2 = 0 decreasing and −x − 1 = 0 increasing are the line x = −1 crossed leftwards:
  // every crossing fires both, so neither reset is the model's. The first edge crossing in C
  // order (x slowest) is on the first node row y = 0.
  expect_failure("guards_overlap",
                 {"pre-flight scan of guard 'left' at t = 0: two guards of one mode fire at the "
                  "same state at the point (x = -1, y = 0) of its surface in mode 'drift': guard "
                  "'also_left' fires there too, so the model does not say which reset applies",
                  "give the guards surfaces that do not overlap, or make them one guard"});
  // In 1-D the guard is that point: the whole guard overlaps.
  expect_failure("guards_overlap_1d", {"two guards of one mode fire at the same state at the "
                                       "point (x = -1) of its surface in mode 'drift': guard "
                                       "'also_left' fires there too"});
  // By every method: the forward ones would take one guard, the characteristics both.
  expect_failure("guards_overlap", {"guard 'also_left' fires there too"}, "--set method=particles");
}

TEST(NumericalFailure, GuardsThatMeetAtACornerAreANote) {
  // x = 0 and y = 0 both fire at (0, 0) only: measure zero on each wall, so a warning.
  const fs::path out = fresh_out("corner_walls");
  const Result r =
      hybgen("run tests/data/corner_walls.model --set outputs=npy --out '" + out.string() + "'");
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_NE(r.out.find("two guards of one mode fire at the same state at the point (x = 0, y = "
                       "0)"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("at an isolated point only"), std::string::npos) << r.out;
}

TEST(NumericalFailure, ResetBackOnItsGuard) {
  // p ↦ −p/2 − 1/2 keeps p < 0 for p > −1. The ground nodes are p_j = −2 + 4j/19; the first
  // one above −1 is p_5 = −18/19, sent to −1/38, still moving down through x = 0.
  expect_failure(
      "reset_on_guard",
      {"pre-flight scan of guard 'ground' at t = 0: the reset lands on a guard that fires again "
       "at once (instantaneous re-trigger) at the point (x = 0, p = -0.9473684210526",
       "Delta = (x = 0, p = -0.02631578947368", "is on guard 'ground' of mode 'flight'"});
}

TEST(NumericalFailure, ZeroHybridJacobianAtACrossing) {
  // J = (p + 1)/(2p) (derived by hand: ∇s = (1, 0), adj DΔ = diag(−1/2, 1), X⁺_x(Δx) = p⁺)
  // vanishes at the ground node p = −1 of the 21×21 grid, the first with J = 0.
  expect_failure("zero_jacobian",
                 {"pre-flight scan of guard 'ground' at t = 0: zero or non-finite hybrid "
                  "Jacobian at the point (x = 0, p = -1) of its surface in mode 'flight': J = 0"});
}

TEST(NumericalFailure, NonFiniteHybridJacobianAtACrossing) {
  // J = 9/8 + 3p/32 − √(p + 2)/2 − p/(8√(p + 2)) (derived by hand in the model's comment) is
  // +inf at the first ground node p = −2, where dΔ_p/dp = −inf.
  expect_failure("nan_jacobian",
                 {"pre-flight scan of guard 'ground' at t = 0: zero or non-finite hybrid "
                  "Jacobian at the point (x = 0, p = -2) of its surface in mode 'flight': "
                  "J = inf"});
}

TEST(NumericalFailure, Grazing) {
  expect_failure("grazing", {"pre-flight scan of guard 'g' at t = 0: grazing: the flow is tangent "
                             "to the guard at a crossing at the point (x = 0, y = 0) of its "
                             "surface in mode 'm'",
                             "the orbit crosses the surface there"});
}

TEST(NumericalFailure, GrazingMetMidTraceOutsideTheGridBox) {
  // The pre-flight scan passes (the box [1/2, 3/2] × [−1/2, 3/2] meets the guard y = 0 only
  // at transversal crossings); the characteristic of the node (1, 1) reaches the tangency
  // (0, 0), outside the box, at τ = 1 (after the reversed reset at its start, at
  // Δ⁻¹(1, 1) = (1, 0)). x = 1 − τ exactly along it, and
  // the tangency criterion 3x²/√(1 + 9x⁴) ≤ 1e-8 bounds |x| < 1.1e-4 (rt test_failures.cpp).
  const std::string msg = expect_failure(
      "grazing_midtrace",
      {"characteristic from (x = 1, y = 1) in mode 'm' failed: grazing: the flow is tangent to "
       "the guard at a crossing at guard 'g' at backward time tau = ",
       "mode 'm', after 1 resets: |grad s . X| / (|grad s| |X|) = ",
       "there, and the orbit crosses the surface"});
  EXPECT_EQ(msg.find("pre-flight"), std::string::npos) << msg;
  const double tau = number_after(msg, "tau = "), x = number_after(msg, "state (x = ");
  EXPECT_NEAR(tau, 1.0, 1.1e-4) << msg;
  EXPECT_NEAR(x, 0.0, 1.1e-4) << msg;
  EXPECT_LE(number_after(msg, "|grad s . X| / (|grad s| |X|) = "), 1e-8) << msg;
}

TEST(NumericalFailure, NewtonInverseDoesNotConverge) {
  expect_failure("newton", {"pre-flight scan of guard 'ground' at t = 0: Newton iteration for the "
                            "inverse reset did not converge at the point (x = 0, p = -2) of its "
                            "surface in mode 'flight': Delta = (x = 0, p = 1.66072307669"});
}

TEST(NumericalFailure, EventCapWithTheStateWhereItHappened) {
  // The first node in C order that crosses 4 resets by t = 4: (0, −0.4), period 0.8 (it
  // bounces with |p| = 0.4 from the ground), so the 4th backward reset is at τ = 3.2, at
  // the state (0, −0.4) (forward: the impact).
  const std::string msg = expect_failure(
      "zeno_cap", {"characteristic from (x = 0, p = -0.4",
                   "in mode 'flight' failed: too many "
                   "resets on one characteristic (max_events) at guard 'ground' at backward time "
                   "tau = ",
                   "state (x = 0, p = -0.3999", "after 4 resets"});
  EXPECT_NEAR(number_after(msg, "tau = "), 3.2, 1e-9) << msg;
  // The cap is a setting: with room for the resets the same model runs.
  const fs::path out = fresh_out("zeno_cap_raised");
  const Result r = hybgen(
      "run tests/data/failures/zeno_cap.model --quiet --set max_events=100 "
      "--set t_end=1 --out '" +
      out.string() + "'");
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
}

// ---------------------------------------------------------------------------------------
// 5. Nothing lost, nothing half-written.

TEST(NothingLost, FailedRunLeavesThePreviousOutputsAndASuccessReplacesThemWhole) {
  const fs::path out = fresh_out("staged");
  const std::string run = "run models/bouncing_ball.model --quiet --out '" + out.string() +
                          "' --set outputs=netcdf+npy ";
  Result r = hybgen(run + "--set grid=21x21 --set t_end=1 --set dt=0.25");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const std::string summary = hybgen::gen::read_file((out / "summary.json").string());
  ASSERT_TRUE(fs::exists(out / "u_0004.npy"));
  ASSERT_TRUE(fs::exists(out / "config.json"));
  EXPECT_EQ(read_json_file(out / "config.json")["out_dir"], out.string());
  // A failing run (e = 1e308: the reset's image is not finite) into the same directory.
  r = hybgen(run + "--set grid=21x21 --set t_end=1 --set dt=0.5 --set e=1e308");
  EXPECT_EQ(r.code, exit_status(ExitCode::Numerical)) << r.out;
  expect_previous_outputs_kept(r, out, summary);
  EXPECT_TRUE(fs::exists(out / "u_0004.npy"));
  // A successful run replaces the directory as a whole: no stale frame survives.
  r = hybgen(run + "--set grid=11x11 --set t_end=1 --set dt=0.5");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const json s = read_json_file(out / "summary.json");
  EXPECT_EQ(s["grid"]["axes"][0]["n"], 11);
  EXPECT_EQ(s["files"], json({"u_0000.npy", "u_0001.npy", "u_0002.npy"}));
  EXPECT_FALSE(fs::exists(out / "u_0004.npy"));
  EXPECT_TRUE(fs::exists(out / "config.json"));
  EXPECT_TRUE(leftovers(out).empty());
}

TEST(NothingLost, OutputsOfARunKilledMidSwapAreRestored) {
  // A run killed between the two renames of the swap's fallback (OUT → OUT.old-<pid>, then
  // staging → OUT) leaves no OUT, its complete old outputs in OUT.old-<pid> and its new ones
  // in OUT.partial-<pid>. Staged here by hand; the next run restores the old outputs, so
  // that a failing next run still leaves them in OUT.
  const fs::path out = fresh_out("killed_mid_swap");
  const std::string run = "run models/bouncing_ball.model --quiet --out '" + out.string() + "' ";
  Result r = hybgen(run + "--set grid=21x21 --set t_end=1 --set dt=0.5");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const std::string summary = hybgen::gen::read_file((out / "summary.json").string());
  const fs::path old = out.string() + ".old-4242", staging = out.string() + ".partial-4242";
  fs::rename(out, old);
  fs::create_directories(staging);
  std::ofstream(staging / "summary.json") << "{}\n";
  r = hybgen(run + "--set grid=21x21 --set t_end=1 --set dt=0.5 --set e=1e308");
  EXPECT_EQ(r.code, exit_status(ExitCode::Numerical)) << r.out;
  EXPECT_NE(r.out.find("hybgen: restored the outputs of an interrupted run from '" + old.string() +
                       "' to '" + out.string() + "'"),
            std::string::npos)
      << r.out;
  expect_previous_outputs_kept(r, out, summary);
}

TEST(NothingLost, ADirectoryWithOtherFilesIsNotReplaced) {
  const fs::path out = fresh_out("foreign");
  fs::create_directories(out);
  std::ofstream(out / "notes.txt") << "mine\n";
  const Result r = hybgen(
      "run models/bouncing_ball.model --quiet --set grid=11x11 --set t_end=1 "
      "--out '" +
      out.string() + "'");
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("refusing to replace '" + out.string() + "': it holds 'notes.txt'"),
            std::string::npos)
      << r.out;
  EXPECT_TRUE(fs::exists(out / "notes.txt"));
  // Nor the current directory, even when it holds nothing but outputs.
  fs::remove(out / "notes.txt");
  std::ofstream(out / "summary.json") << "{}\n";
  const Result here =
      hybgen("run '" + kSrc + "/models/bouncing_ball.model' --quiet --set grid=11x11 --out .",
             "cd '" + out.string() + "' &&");
  EXPECT_EQ(here.code, exit_status(ExitCode::UsageError)) << here.out;
  EXPECT_NE(here.out.find("refusing to replace '.': it is (or contains) the current directory"),
            std::string::npos)
      << here.out;
  EXPECT_TRUE(fs::exists(out / "summary.json"));
}

TEST(NothingLost, ARunIntoALockedDirectoryIsRefused) {
  const fs::path out = fresh_out("locked");
  const std::string lock = out.string() + ".lock";
  const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);  // this process plays the other run
  const std::string run =
      "run models/bouncing_ball.model --quiet --set grid=11x11 --set t_end=1 "
      "--out '" +
      out.string() + "'";
  Result r = hybgen(run);
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("hybgen: error: another hybgen run is writing to '" + out.string() + "'"),
            std::string::npos)
      << r.out;
  EXPECT_FALSE(fs::exists(out));
  ::close(fd);  // releases the lock
  r = hybgen(run);
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
}

TEST(NothingLost, TwoConcurrentRunsIntoOneDirectoryDoNotInterleave) {
  // Warm the cache so that both runs reach the lock at about the same time.
  const fs::path out = fresh_out("race");
  const std::string run =
      "run models/bouncing_ball.model --quiet --set grid=151x151 --out '" + out.string() + "'";
  ASSERT_EQ(hybgen(run).code, exit_status(ExitCode::Success));
  Result a, b;
  std::thread ta([&] { a = hybgen(run); }), tb([&] { b = hybgen(run); });
  ta.join();
  tb.join();
  // Each run either completed or was refused with the lock's message; at least one completed.
  for (const Result* r : {&a, &b}) {
    EXPECT_TRUE(r->code == exit_status(ExitCode::Success) ||
                r->code == exit_status(ExitCode::UsageError))
        << r->out;
    if (r->code == exit_status(ExitCode::UsageError)) {
      EXPECT_NE(r->out.find("another hybgen run is writing to"), std::string::npos) << r->out;
    }
  }
  EXPECT_TRUE(a.code == exit_status(ExitCode::Success) || b.code == exit_status(ExitCode::Success));
  std::printf("[ race ] exit codes %d and %d\n", a.code, b.code);
  const json s = read_json_file(out / "summary.json");
  for (const auto& f : s["files"]) EXPECT_TRUE(fs::exists(out / f.get<std::string>())) << f;
  EXPECT_TRUE(leftovers(out).empty());
}

TEST(NothingLost, AnInterruptedRunRemovesItsStagingAndKeepsThePreviousOutputs) {
  // SIGTERM to hybgen (as a batch system sends it; Ctrl-C's SIGINT takes the same path,
  // but a test run from a background job may have SIGINT ignored) while the runner works
  // on a 2049² grid for some seconds: forwarded to the runner, then the staging directory
  // is removed, the previous outputs stay, and hybgen ends by the signal itself (the shell
  // that ran it exits 128 + 15).
  const fs::path out = fresh_out("interrupted");
  const std::string run = "run models/bouncing_ball.model --quiet --out '" + out.string() + "' ";
  ASSERT_EQ(hybgen(run + "--set grid=21x21 --set t_end=1 --set dt=0.5").code,
            exit_status(ExitCode::Success));
  const std::string summary = hybgen::gen::read_file((out / "summary.json").string());
  Result r;
  std::thread t([&] { r = hybgen(run + "--set grid=2049x2049 --set t_end=10 --set dt=5"); });
  // The staging directory OUT.partial-<pid> names hybgen's pid; its config.json is written
  // just before the runner starts.
  pid_t pid = 0;
  for (int i = 0; i < 3000 && pid == 0; ++i) {
    for (const auto& e : fs::directory_iterator(out.parent_path())) {
      const std::string n = e.path().filename().string(), prefix = "interrupted.partial-";
      if (n.rfind(prefix, 0) == 0 && fs::exists(e.path() / "config.json"))
        pid = static_cast<pid_t>(std::stol(n.substr(prefix.size())));
    }
    if (pid == 0) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  if (pid != 0) ::kill(pid, SIGTERM);
  t.join();
  ASSERT_NE(pid, 0) << "the run never staged its outputs\n" << r.out;
  EXPECT_EQ(r.code, 128 + SIGTERM) << r.out;
  EXPECT_NE(r.out.find("hybgen: interrupted by signal 15 (Terminated); the previous outputs in '" +
                       out.string() + "' are unchanged"),
            std::string::npos)
      << r.out;
  expect_previous_outputs_kept(r, out, summary);
}

TEST(NothingLost, AFullDiskIsAClearErrorAndKeepsThePreviousOutputs) {
  // RLIMIT_FSIZE (ulimit -f, with SIGXFSZ ignored so that write() fails with EFBIG) stands
  // in for a full disk: no root, no mount. A 101×101 .npy is 81 728 bytes, over the limit of
  // 40 blocks (20 KiB in dash's 512-byte blocks, 40 KiB in bash's 1 KiB); config.json is
  // ~1 KiB. The cache is warmed first (the compiler's output would exceed the limit).
  const fs::path out = fresh_out("full_disk");
  const std::string run =
      "run models/bouncing_ball.model --quiet --set grid=101x101 --set "
      "t_end=1 --set dt=0.5 --out '" +
      out.string() + "'";
  ASSERT_EQ(hybgen(run).code, exit_status(ExitCode::Success));
  const std::string summary = hybgen::gen::read_file((out / "summary.json").string());
  const Result r = hybgen(run + " --set outputs=npy", "trap '' XFSZ && ulimit -f 40 &&");
  EXPECT_EQ(r.code, exit_status(ExitCode::Internal))
      << r.out;  // runner.hpp: I/O failures exit 70, naming the file
  EXPECT_NE(r.out.find("cannot write '"), std::string::npos) << r.out;
  // Frames are written in parallel: whichever crosses the limit first is named.
  EXPECT_NE(r.out.find(".npy': File too large"), std::string::npos) << r.out;
  expect_previous_outputs_kept(r, out, summary);
  std::printf("[ message ] %s\n", r.out.c_str());
  // run.nc (HDF5 underneath) fails the same way: exit 70 naming the file, nothing kept.
  const Result nc = hybgen(run + " --set outputs=netcdf", "trap '' XFSZ && ulimit -f 40 &&");
  EXPECT_EQ(nc.code, exit_status(ExitCode::Internal)) << nc.out;
  EXPECT_NE(nc.out.find("/run.nc': "), std::string::npos) << nc.out;
  EXPECT_EQ(nc.out.find("killed by signal"), std::string::npos) << nc.out;
  expect_previous_outputs_kept(nc, out, summary);
  std::printf("[ message ] %s\n", nc.out.c_str());
}

TEST(NothingLost, ACorruptedBuildCacheEntryIsRebuilt) {
  const std::string cache = (kWork / "cache_corrupt").string();
  fs::remove_all(cache);
  const std::string build = "build models/bouncing_ball.model";
  Result r = run_hybgen(build, cache);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const std::string exe = r.out.substr(r.out.rfind('\n', r.out.size() - 2) + 1,
                                       r.out.size() - r.out.rfind('\n', r.out.size() - 2) - 2);
  ASSERT_TRUE(fs::exists(exe)) << exe;
  const auto size = fs::file_size(exe);
  r = run_hybgen(build, cache);
  EXPECT_NE(r.out.find("(cached)"), std::string::npos) << r.out;
  // Truncated: rebuilt, not run.
  fs::resize_file(exe, size / 2);
  r = run_hybgen(build, cache);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_EQ(r.out.find("(cached)"), std::string::npos) << r.out;
  EXPECT_EQ(fs::file_size(exe), size);
  // Corrupted in place (same size, one byte changed): rebuilt too.
  {
    std::fstream f(exe, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(size / 2));
    char c = 0;
    f.seekg(static_cast<std::streamoff>(size / 2));
    f.get(c);
    f.seekp(static_cast<std::streamoff>(size / 2));
    f.put(static_cast<char>(c ^ 0x5a));
  }
  r = run_hybgen(build, cache);
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  EXPECT_EQ(r.out.find("(cached)"), std::string::npos) << r.out;
  // The rebuilt runner works.
  const fs::path out = fresh_out("after_corrupt");
  r = run_hybgen("run models/bouncing_ball.model --quiet --set grid=11x11 --set t_end=1 --out '" +
                     out.string() + "'",
                 cache);
  EXPECT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
}

TEST(NothingLost, AFailedCompileExitsFourWithTheLogPath) {
  // HYBGEN_CXX replaces the runner's compiler and is part of the cache key: /bin/false
  // "compiles" nothing, even with a warm cache for the real compiler.
  const fs::path out = fresh_out("compile_fails");
  const Result r =
      hybgen("run models/bouncing_ball.model --quiet --set grid=11x11 --out '" + out.string() + "'",
             "HYBGEN_CXX=/bin/false");
  EXPECT_EQ(r.code, exit_status(ExitCode::BuildFailed)) << r.out;
  const std::string key = "compiler log: ";
  const std::size_t at = r.out.find(key);
  ASSERT_NE(at, std::string::npos) << r.out;
  const std::string log = r.out.substr(at + key.size(), r.out.find('\n', at) - at - key.size());
  ASSERT_TRUE(fs::exists(log)) << log;
  EXPECT_EQ(fs::path(log).filename(), "build.log");
  EXPECT_NE(hybgen::gen::read_file(log).find("$ '/bin/false' "), std::string::npos);
  EXPECT_FALSE(fs::exists(out));
  std::printf("[ message ] %s\n", r.out.c_str());
}

}  // namespace
