#pragma once
/// \file progress.hpp
/// Progress of a long computation on stderr: silent for the first second (short
/// runs print nothing), then a bar redrawn in place on a terminal, or a line per
/// 10 % (and one a minute when a tenth takes longer) when stderr is a file or a
/// pipe (CI logs); times over two minutes in minutes, over two hours in hours.
/// Thread-safe: workers call `advance` from inside OpenMP loops; whichever thread
/// sees that it is time to draw does so (try-lock, never waits), so the cost per
/// call is one atomic add and, about every 1/32 s, a clock read.

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
    // Cheap pre-check: look at the clock only when the units done reach `next_check_`, which
    // each look sets about 1/32 s ahead at the rate observed. (A fixed share of the work,
    // as before, left a run of 10¹⁰ particles without a word for minutes: 1/512 of it.)
    if (done < next_check_.load(std::memory_order_relaxed) && done != total_) return;
    draw(done, false);
  }

  /// Count the time from now (before any unit is done: a stage that precedes the work, such
  /// as the particles' drawing pass, is not part of its rate).
  void restart() { start_ = now_(); }

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
    // The next look at the clock: about 1/32 s of work ahead at the rate so far (twice the
    // units done while no time has passed).
    const double ahead = t > 0.0 ? static_cast<double>(done) / t / 32.0 : static_cast<double>(done);
    next_check_.store(done + static_cast<std::size_t>(std::clamp(ahead, 1.0, 1e15)),
                      std::memory_order_relaxed);
    const double frac = std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
    if (final && complete_drawn_) return;  // the 100 % line is already there
    if (frac >= 1.0 && (drawn_ || t >= 1.0)) final = true;
    if (!final && (t < 1.0 || t - last_draw_ < 0.125)) return;
    if (!tty_) {  // a line per 10 %, and one a minute when a tenth takes longer
      const int decile = static_cast<int>(frac * 10.0);
      if (!final && decile <= last_decile_ && t - last_draw_ < 60.0) return;
      last_decile_ = std::max(last_decile_, decile);
    }
    last_draw_ = t;
    drawn_ = true;
    complete_drawn_ = frac >= 1.0;
    const double eta = frac > 0 ? t * (1.0 - frac) / frac : 0.0;
    char bar[41];
    const int fill = static_cast<int>(frac * 40.0);
    for (int i = 0; i < 40; ++i) bar[i] = i < fill ? '#' : '.';
    bar[40] = '\0';
    std::fprintf(stderr, "%shybgen: %s [%s] %5.1f%%  %s elapsed%s", tty_ ? "\r" : "",
                 label_.c_str(), bar, 100.0 * frac, duration(t).c_str(),
                 final ? "" : (", about " + duration(eta) + " left").c_str());
    std::fputs(tty_ && !final ? "   " : "\n", stderr);
    std::fflush(stderr);
  }

  /// Seconds as a person reads them: "12.3 s" below two minutes, "14 min" below two hours,
  /// then "3.5 h".
  static std::string duration(double s) {
    char b[32];
    if (s < 120.0)
      std::snprintf(b, sizeof b, "%.1f s", s);
    else if (s < 7200.0)
      std::snprintf(b, sizeof b, "%.0f min", s / 60.0);
    else
      std::snprintf(b, sizeof b, "%.1f h", s / 3600.0);
    return b;
  }

  std::string label_;
  std::size_t total_;
  bool quiet_;
  bool tty_;
  Now now_;
  Clock::time_point start_;
  std::atomic<std::size_t> done_{0};
  std::atomic<std::size_t> next_check_{1};  ///< See advance().
  std::atomic<bool> finished_{false};
  std::mutex mutex_;
  double last_draw_ = -1.0;
  int last_decile_ = -1;
  bool drawn_ = false;
  bool complete_drawn_ = false;
};

}  // namespace hybgen::rt
