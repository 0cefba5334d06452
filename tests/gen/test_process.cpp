// Runners as child processes (generator/src/process.cpp): exit codes, the environment a
// child gets, several children at once, a child killed by a signal, and an interrupt
// forwarded to every child.

#include "hybgen/gen/process.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"

namespace {

namespace fs = std::filesystem;
using namespace hybgen::gen;

/// A shell script in a fresh file, run as `/bin/sh SCRIPT`.
std::string script(const std::string& name, const std::string& body) {
  const fs::path dir =
      fs::temp_directory_path() / ("hybgen_test_process_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path p = dir / name;
  std::ofstream(p) << body;
  return p.string();
}

TEST(Process, ExitCodeAndEnvironment) {
  const fs::path out = fs::path(script("env.out", "")).replace_extension(".txt");
  const InterruptGuard guard;
  const std::string s = script("env.sh", "printf '%s' \"$OMP_NUM_THREADS:$HYBGEN_TEST_X\" > '" +
                                             out.string() + "'\nexit 3\n");
  EXPECT_EQ(run_process("/bin/sh", s, guard, {{"OMP_NUM_THREADS", "1"}, {"HYBGEN_TEST_X", "y"}}),
            3);
  EXPECT_EQ(read_file(out.string()), "1:y");
  EXPECT_EQ(run_process("/bin/sh", script("ok.sh", "exit 0\n"), guard), 0);
  EXPECT_EQ(interrupt_signal(), 0);
}

TEST(Process, AChildKilledBySignalIsSeventy) {
  const InterruptGuard guard;
  EXPECT_EQ(run_process("/bin/sh", script("kill.sh", "kill -KILL $$\n"), guard),
            hybgen::rt::exit_status(ExitCode::Internal));
  // A runner that cannot be executed at all: the child says so and exits 70.
  EXPECT_EQ(run_process("/nonexistent/runner", "x", guard),
            hybgen::rt::exit_status(ExitCode::Internal));
}

TEST(Process, SeveralChildrenAreWaitedForInAnyOrder) {
  const InterruptGuard guard;
  std::set<pid_t> started;
  for (const char* code : {"5", "6", "7"})
    started.insert(start_process(
        "/bin/sh", script(std::string(code) + ".sh", std::string("exit ") + code), guard));
  std::set<int> codes;
  for (int i = 0; i < 3; ++i) {
    const auto [pid, rc] = wait_process();
    EXPECT_EQ(started.count(pid), 1u);
    codes.insert(rc);
  }
  EXPECT_EQ(codes, (std::set<int>{5, 6, 7}));
}

TEST(Process, AnInterruptIsForwardedToEveryChildAndRecorded) {
  const fs::path marker = fs::path(script("m", "")).parent_path();
  std::vector<pid_t> pids;
  {
    const InterruptGuard guard;
    // Each child says it has started (so that the signal does not arrive before the shell
    // runs) and then sleeps; SIGTERM ends it.
    for (int i = 0; i < 2; ++i) {
      const std::string ready = (marker / ("ready" + std::to_string(i))).string();
      fs::remove(ready);
      pids.push_back(start_process(
          "/bin/sh",
          script("sleep" + std::to_string(i) + ".sh", "touch '" + ready + "'\nexec sleep 30\n"),
          guard));
    }
    for (int i = 0; i < 2; ++i)
      for (int k = 0; k < 500 && !fs::exists(marker / ("ready" + std::to_string(i))); ++k)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const auto t0 = std::chrono::steady_clock::now();
    ::raise(SIGTERM);  // caught by the guard: hybgen lives on, both children get it
    EXPECT_EQ(interrupt_signal(), SIGTERM);
    for (int i = 0; i < 2; ++i) EXPECT_EQ(wait_process().second, 128 + SIGTERM);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(20));  // not slept out
    // Interrupted: nothing more is started.
    EXPECT_EQ(start_process("/bin/sh", script("never.sh", "exit 0\n"), guard), -1);
  }
  // The guard is gone: the disposition is the default again, and a new guard starts clean.
  const InterruptGuard again;
  EXPECT_EQ(interrupt_signal(), 0);
}

}  // namespace
