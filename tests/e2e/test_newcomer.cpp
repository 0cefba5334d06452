// What a new user trips over, through the command line: malformed --set values refused with
// the form they need, a misspelt key with a suggestion, outputs named after the model file
// (a copied and edited model does not replace the first one's outputs) and no lock file left
// behind, `check` agreeing with `run`, and values at the edges of a setting's range refused or
// run, never a crash. Each test failed on a81ba15; its comments say what it saw there.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "hybgen/rt/exit_codes.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::e2e_dir;
using hybgen::testing::Hybgen;

const Hybgen hybgen{e2e_dir("newcomer") / "cache"};

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(Newcomer, DomainValuesNeedTheirBrackets) {
  // On a81ba15 the first two were taken without a word and the third reported "2.5]".
  for (const auto& [value, why] :
       {std::pair{"[0,3", "does not end with ']'"}, std::pair{"0.5,2.5", "does not start with '['"},
        std::pair{"[0.5,2.5]]", "two numbers separated by one comma"},
        std::pair{"[2,1]", "empty interval"}}) {
    const auto r =
        hybgen(std::string("check models/bouncing_ball.model --set 'domain.x=") + value + "'");
    EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << value << "\n" << r.out;
    EXPECT_TRUE(has(r.out, why)) << value << "\n" << r.out;
  }
  const auto ok = hybgen("check models/bouncing_ball.model --set 'domain.x=[ 0 , 3 ]'");
  EXPECT_EQ(ok.code, exit_status(ExitCode::Success)) << ok.out;
}

TEST(Newcomer, AMisspeltKeyGetsASuggestion) {
  const auto r = hybgen("check models/bouncing_ball.model --set metod=transfer");
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_TRUE(has(r.out, "did you mean 'method'?")) << r.out;
  const auto d = hybgen("check models/bouncing_ball.model --set domian.x=[0,1]");
  EXPECT_TRUE(has(d.out, "did you mean 'domain.x'?")) << d.out;
}

TEST(Newcomer, OutputsAreNamedAfterTheFileAndLeaveNoLock) {
  // Two files with the same `model NAME` (a copy being edited): each run keeps its own
  // folder, out/<file>/, and no out/<file>.lock stays behind.
  const fs::path dir = e2e_dir("newcomer") / "two_files";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string ball = std::string(HYBGEN_SOURCE_DIR) + "/models/bouncing_ball.model";
  fs::copy_file(ball, dir / "a.model");
  fs::copy_file(ball, dir / "b.model");
  const std::string sets = " --set grid=21x21 --set t_end=1 --set dt=0.5 --set outputs=netcdf -q";
  for (const char* f : {"a.model", "b.model"}) {
    const auto r = hybgen(std::string("run ") + f + sets, "cd '" + dir.string() + "' &&");
    ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  }
  EXPECT_TRUE(fs::exists(dir / "out" / "a" / "summary.json"));
  EXPECT_TRUE(fs::exists(dir / "out" / "b" / "summary.json"));
  EXPECT_FALSE(fs::exists(dir / "out" / "bouncing_ball"));
  for (const auto& e : fs::directory_iterator(dir / "out"))
    EXPECT_NE(e.path().extension(), ".lock") << e.path();
  // summary.json is for people too: a time series on one line (a81ba15: one number per line,
  // 709 lines for the shipped ball; hybgen/rt/io/json_text.hpp).
  std::ifstream in(dir / "out" / "a" / "summary.json");
  std::size_t lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  EXPECT_GT(lines, 20u);
  EXPECT_LT(lines, 150u);
}

TEST(Newcomer, CheckAgreesWithRun) {
  // `check --preflight` printed "ok" and then failed with exit 3; `check` said ok to settings
  // that `run` refuses.
  // (A reset out of the support: check passes it, the pre-flight scan refuses it. On a81ba15
  // e = 3/2 on the ball did that; a reset out of the box is now outflow, not a failure.)
  const auto pf = hybgen("check tests/data/failures/reset_outside_support.model --preflight -q");
  EXPECT_EQ(pf.code, exit_status(ExitCode::Numerical)) << pf.out;
  EXPECT_FALSE(has(pf.out, ": ok: model")) << pf.out;
  const auto ranks = hybgen("check models/bouncing_ball.model --set ranks=2");
  EXPECT_EQ(ranks.code, exit_status(ExitCode::UsageError)) << ranks.out;
  EXPECT_TRUE(has(ranks.out, "needs backend=mpi")) << ranks.out;
  const auto marg = hybgen("check models/bouncing_ball.model --set density=marginals");
  EXPECT_EQ(marg.code, exit_status(ExitCode::UsageError)) << marg.out;
  EXPECT_TRUE(has(marg.out, "use method=particles")) << marg.out;
}

TEST(Newcomer, ValuesAtTheEdgesAreRefusedOrRunNeverACrash) {
  // On a81ba15: t_end = 1e15 with dt = 1e-9 ended in std::bad_alloc (exit 70), e = 1e308 in
  // "internal error: floating point overflow" (exit 70).
  const auto frames = hybgen("run models/bouncing_ball.model -q --set t_end=1e15 --set dt=1e-9");
  EXPECT_EQ(frames.code, exit_status(ExitCode::UsageError)) << frames.out;
  EXPECT_TRUE(has(frames.out, "output times")) << frames.out;
  // t_end = 1e300 (a81ba15: killed by SIGSEGV, exit 70) and dt = 1e-9 alone ask for more
  // output times than a run may have, and say so.
  for (const char* sets : {"--set t_end=1e300", "--set dt=1e-9"}) {
    const auto r = hybgen(std::string("run models/bouncing_ball.model -q ") + sets);
    EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << sets << ": " << r.out;
    EXPECT_TRUE(has(r.out, "output times, more than the")) << r.out;
  }
  const auto e = hybgen("run models/bouncing_ball.model -q --set e=1e308 --set grid=21x21");
  EXPECT_EQ(e.code, exit_status(ExitCode::Numerical)) << e.out;
  EXPECT_TRUE(has(e.out, "non-finite reset")) << e.out;
  // The transfer operator's step at the edge of its range: step = 1e-300 asked the march for
  // 2e300 steps and ended in "error: vector::reserve" (exit 70; found 2026-11-30 by running
  // every numeric setting at its extremes through `hybgen run`). Now a loud cap, before anything
  // runs.
  const auto step =
      hybgen("run models/sawtooth.model -q --set method=transfer --set step=1e-300 --set t_end=2");
  EXPECT_EQ(step.code, exit_status(ExitCode::UsageError)) << step.out;
  EXPECT_TRUE(has(step.out, "steps, more than the 1e+07 a run may take")) << step.out;
}

}  // namespace
