// Progress reporting (runtime/include/hybgen/rt/io/progress.hpp): silent for short
// or quiet runs, a line per 10 % on a non-terminal stderr, from many threads. The time is
// a fake clock that the tests advance themselves: nothing here sleeps or depends on the
// machine's speed.

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <barrier>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "hybgen/rt/io/progress.hpp"

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

/// A fake clock: `fake_now` returns the epoch plus `fake_ms` milliseconds.
std::atomic<long> fake_ms{0};
Progress::Clock::time_point fake_now() {
  return Progress::Clock::time_point{} + std::chrono::milliseconds(fake_ms.load());
}

std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

TEST(Progress, ShortRunsPrintNothing) {
  // 1000 units within 0.999 s of fake time: nothing, not even the final line.
  fake_ms = 0;
  const std::string out = capture_stderr([] {
    Progress p("solving", 1000, false, &fake_now);
    for (int i = 0; i < 1000; ++i) {
      fake_ms = i;
      p.advance();
    }
  });
  EXPECT_EQ(out, "");
}

TEST(Progress, QuietPrintsNothing) {
  fake_ms = 0;
  const std::string out = capture_stderr([] {
    Progress p("solving", 100, true, &fake_now);
    for (int i = 0; i < 100; ++i) {
      fake_ms = 15 * i;
      p.advance();
    }
  });
  EXPECT_EQ(out, "");
}

// A 1.5 s run (fake time: 15 ms per round of 4 units) from 4 threads: after the first
// second, one line per decile reached (the file is not a terminal), then a final 100 % line.
// The threads advance in lock-step rounds (a barrier per round), so the fake time of unit u
// is 15·(u/4) ms and the output is the same on every machine: nothing before 1 s (the first
// 268 units, 67 %), then, at least 1/8 s apart, the deciles 6, 7, 8, 9 (rounds 67, 76, 85,
// 94) and 100 %.
TEST(Progress, LongRunsPrintDecilesFromManyThreads) {
  fake_ms = 0;
  const std::string out = capture_stderr([] {
    Progress p("solving test", 400, false, &fake_now);
    std::barrier round(4, []() noexcept { fake_ms += 15; });
    std::vector<std::thread> workers;
    for (int w = 0; w < 4; ++w)
      workers.emplace_back([&p, &round] {
        for (int i = 0; i < 100; ++i) {
          p.advance();
          round.arrive_and_wait();
        }
      });
    for (auto& t : workers) t.join();
    EXPECT_EQ(p.done(), 400u);
  });
  EXPECT_NE(out.find("hybgen: solving test ["), std::string::npos) << out;
  EXPECT_NE(out.find("100.0%"), std::string::npos) << out;
  EXPECT_EQ(out.find('\r'), std::string::npos) << out;  // not a terminal: no redraws
  // Nothing in the first second (2/3 of the work), so the deciles 6 … 9 and the final line.
  EXPECT_EQ(count(out, "\n"), 5u) << out;
  EXPECT_EQ(count(out, "  0.0%"), 0u) << out;
  EXPECT_NE(out.find("1.0 s elapsed"), std::string::npos) << out;
}

// A run of 10¹⁰ units at 10⁵ a second (the particle method's 1e10 on a 1-D model): the
// first line comes after the first second, at 0.0 %, with the time left in hours, and then
// one a minute although no tenth is reached (not a terminal), and times over two minutes in
// minutes. Before, the clock was looked
// at every 1/512 of the work, first after 20 minutes here.
TEST(Progress, AVeryLongRunSaysSoAtOnceAndEveryMinute) {
  fake_ms = 0;
  const std::string out = capture_stderr([] {
    Progress p("particles", 10'000'000'000ULL, false, &fake_now);
    for (int i = 1; i <= 13000; ++i) {  // 10 ms of fake time per 1000 units: 130 s
      fake_ms = 10L * i;
      p.advance(1000);
    }
  });
  // At 1 s, 61 s and 121 s, and the last line when it ends (at 130 s).
  EXPECT_EQ(count(out, "\n"), 4u) << out;
  EXPECT_NE(out.find("  0.0%  1.0 s elapsed, about 27.8 h left"), std::string::npos) << out;
  EXPECT_NE(out.find("61.0 s elapsed, about 27.8 h left"), std::string::npos) << out;
  EXPECT_NE(out.find("2 min elapsed, about 27.7 h left"), std::string::npos) << out;
}

// restart(): a stage before the work (the particles' drawing pass) is not counted in the
// work's elapsed time or its rate.
TEST(Progress, RestartCountsFromThen) {
  fake_ms = 0;
  const std::string out = capture_stderr([] {
    Progress p("pushing", 100, false, &fake_now);
    fake_ms = 30000;  // 30 s of another stage
    p.restart();
    for (int i = 1; i <= 100; ++i) {
      fake_ms = 30000 + 20L * i;  // 2 s for the 100 units
      p.advance();
    }
  });
  EXPECT_NE(out.find("100.0%  2.0 s elapsed"), std::string::npos) << out;
  EXPECT_EQ(out.find("32.0 s"), std::string::npos) << out;
}

}  // namespace
}  // namespace hybgen::rt
