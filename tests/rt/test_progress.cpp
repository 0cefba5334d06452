// Progress reporting (runtime/include/hybgen/rt/progress.hpp): silent for short
// or quiet runs, a line per 10 % on a non-terminal stderr, from many threads.

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "hybgen/rt/progress.hpp"

namespace hybgen::rt {
namespace {

/// Run f with stderr redirected to a temporary file; returns what was written.
template <class F>
std::string capture_stderr(F&& f) {
  char path[] = "/tmp/hybgen_progress_XXXXXX";
  const int fd = ::mkstemp(path);
  EXPECT_GE(fd, 0);
  std::fflush(stderr);
  const int saved = ::dup(STDERR_FILENO);
  ::dup2(fd, STDERR_FILENO);
  f();
  std::fflush(stderr);
  ::dup2(saved, STDERR_FILENO);
  ::close(saved);
  ::close(fd);
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  ::unlink(path);
  return ss.str();
}

std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

TEST(Progress, ShortRunsPrintNothing) {
  const std::string out = capture_stderr([] {
    Progress p("solving", 1000, false);
    for (int i = 0; i < 1000; ++i) p.advance();
  });
  EXPECT_EQ(out, "");
}

TEST(Progress, QuietPrintsNothing) {
  const std::string out = capture_stderr([] {
    Progress p("solving", 100, true);
    for (int i = 0; i < 100; ++i) {
      p.advance();
      std::this_thread::sleep_for(std::chrono::milliseconds(15));
    }
  });
  EXPECT_EQ(out, "");
}

// A 1.5 s run from 4 threads: after the first second, one line per decile
// reached (the file is not a terminal), then a final 100 % line.
TEST(Progress, LongRunsPrintDecilesFromManyThreads) {
  const std::string out = capture_stderr([] {
    Progress p("solving test", 400, false);
    std::vector<std::thread> workers;
    for (int w = 0; w < 4; ++w)
      workers.emplace_back([&p] {
        for (int i = 0; i < 100; ++i) {
          p.advance();
          std::this_thread::sleep_for(std::chrono::milliseconds(15));
        }
      });
    for (auto& t : workers) t.join();
    EXPECT_EQ(p.done(), 400u);
  });
  EXPECT_NE(out.find("hybgen: solving test ["), std::string::npos) << out;
  EXPECT_NE(out.find("100.0%"), std::string::npos) << out;
  EXPECT_EQ(out.find('\r'), std::string::npos) << out;  // not a terminal: no redraws
  // Nothing in the first second (≈ 2/3 of the work), so at most the deciles 6..10.
  EXPECT_GE(count(out, "\n"), 2u) << out;
  EXPECT_LE(count(out, "\n"), 6u) << out;
  EXPECT_EQ(count(out, "  0.0%"), 0u) << out;
}

}  // namespace
}  // namespace hybgen::rt
