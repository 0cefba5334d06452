#pragma once
/// \file progress.hpp
/// Progress of a long computation on stderr: silent for the first second (short
/// runs print nothing), then a bar redrawn in place on a terminal, or a line per
/// 10 % when stderr is a file or a pipe (CI logs). Thread-safe: workers call
/// `advance` from inside OpenMP loops; whichever thread sees that it is time to
/// draw does so (try-lock, never waits), so the cost per call is one atomic add
/// and, at most every 1/8 s, one clock read per thread.

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdio>
#include <mutex>
#include <string>

namespace hybgen::rt {

/// A progress reporter for `total` units of work labelled `label`.
class Progress {
 public:
  using Clock = std::chrono::steady_clock;  ///< The clock of elapsed times.
  using Now = Clock::time_point (*)();      ///< A clock: Clock::now, or a test's own.

  /// Start counting; `quiet` (or total == 0) disables all output. `now` reads the time
  /// (tests pass a clock they advance themselves, so that no test depends on sleeping).
  Progress(std::string label, std::size_t total, bool quiet, Now now = &Clock::now)
      : label_(std::move(label)),
        total_(total),
        quiet_(quiet || total == 0),
        tty_(::isatty(STDERR_FILENO) == 1),
        now_(now),
        start_(now()) {}
  /// Ends the line of a bar that was drawn.
  ~Progress() { finish(); }
  Progress(const Progress&) = delete;             ///< Not copyable.
  Progress& operator=(const Progress&) = delete;  ///< Not assignable.

  /// Add `n` done units (any thread).
  void advance(std::size_t n = 1) {
    const std::size_t done = done_.fetch_add(n, std::memory_order_relaxed) + n;
    if (quiet_) return;
    // Cheap pre-check: look at the clock only every 1/64 of the work or so.
    if (done % std::max<std::size_t>(1, total_ / 512) >= n && done != total_) return;
    draw(done, false);
  }

  /// Draw the final state (if anything was drawn) and end the line; idempotent.
  void finish() {
    if (quiet_ || finished_.exchange(true)) return;
    if (drawn_) draw(done_.load(), true);
  }

  /// Units done so far.
  [[nodiscard]] std::size_t done() const { return done_.load(std::memory_order_relaxed); }

 private:
  void draw(std::size_t done, bool final) {
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return;
    const double t = std::chrono::duration<double>(now_() - start_).count();
    const double frac = std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
    if (final && complete_drawn_) return;  // the 100 % line is already there
    if (frac >= 1.0 && (drawn_ || t >= 1.0)) final = true;
    if (!final && (t < 1.0 || t - last_draw_ < 0.125)) return;
    if (!tty_) {  // a line per 10 %
      const int decile = static_cast<int>(frac * 10.0);
      if (!final && decile <= last_decile_) return;
      last_decile_ = decile;
    }
    last_draw_ = t;
    drawn_ = true;
    complete_drawn_ = frac >= 1.0;
    const double eta = frac > 0 ? t * (1.0 - frac) / frac : 0.0;
    char bar[41];
    const int fill = static_cast<int>(frac * 40.0);
    for (int i = 0; i < 40; ++i) bar[i] = i < fill ? '#' : '.';
    bar[40] = '\0';
    std::fprintf(
        stderr, "%shybgen: %s [%s] %5.1f%%  %.1f s elapsed%s", tty_ ? "\r" : "", label_.c_str(),
        bar, 100.0 * frac, t,
        final ? ""
              : (", about " + std::to_string(static_cast<long>(eta + 0.5)) + " s left").c_str());
    std::fputs(tty_ && !final ? "   " : "\n", stderr);
    std::fflush(stderr);
  }

  std::string label_;
  std::size_t total_;
  bool quiet_;
  bool tty_;
  Now now_;
  Clock::time_point start_;
  std::atomic<std::size_t> done_{0};
  std::atomic<bool> finished_{false};
  std::mutex mutex_;
  double last_draw_ = -1.0;
  int last_decile_ = -1;
  bool drawn_ = false;
  bool complete_drawn_ = false;
};

}  // namespace hybgen::rt
