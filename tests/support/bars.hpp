#pragma once
/// \file bars.hpp
/// How the tests judge a reported error bar against the true error of its value, frame by
/// frame (docs/hardening.md, "Calibrated bars"):
///  * it covers: |error| ≤ cover·bar + floor (cover 1 by default; more for a bar that is an
///    estimate of a standard deviation, which a run's error may exceed now and then);
///  * it is tight: at most kBarRatio times |error|, or within `asked`, the width the run was
///    asked for (e2e.hpp, `asked_width`). An adaptive cubature stops as soon as its estimate
///    meets the tolerance, so a bar below it says "as accurate as asked" and no more, however
///    much smaller the error is by luck (a smooth density at t = 0, a term whose error passes
///    through 0 between frames). A bar wider than what was asked has to be earned by an error
///    within kBarRatio of it.
/// The error of a deterministic method is not a sample, but over many frames it behaves like
/// one (where a jump falls between the nodes): `rms_z`, the root mean square of 2·error/bar,
/// is near 1 for a bar that is 2σ of its errors, and catches bars inflated evenly below what
/// was asked, which the frame rule cannot.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace hybgen::testing {

/// A bar wider than what was asked is at most this times its error.
inline constexpr double kBarRatio = 10.0;

/// The errors and bars of one reported quantity, frame by frame.
struct BarSeries {
  std::string name;                ///< What the printout and the failures call it.
  std::vector<double> error, bar;  ///< value − exact, and the reported bar, per frame.

  /// The frames of `values` ± `bars` at `times` against exact(t); with `skip_exact_zeros`,
  /// leaving out the frames whose exact value is 0 (a Monte-Carlo term that is exactly 0 has
  /// no randomness to calibrate).
  void add(const nlohmann::json& times, const nlohmann::json& values, const nlohmann::json& bars,
           const std::function<double(double)>& exact, bool skip_exact_zeros = false) {
    ASSERT_EQ(values.size(), times.size()) << name;
    ASSERT_EQ(bars.size(), times.size()) << name;
    for (std::size_t k = 0; k < times.size(); ++k) {
      const double ref = exact(times[k].get<double>());
      if (skip_exact_zeros && ref == 0.0) continue;
      error.push_back(values[k].get<double>() - ref);
      bar.push_back(bars[k].get<double>());
    }
  }

  /// The root mean square of z = 2·error/bar (error/σ̂ for a 2σ bar) over the frames.
  double rms_z() const {
    double z2 = 0.0;
    for (std::size_t i = 0; i < error.size(); ++i) {
      const double z = 2.0 * error[i] / bar[i];
      z2 += z * z;
    }
    return error.empty() ? 0.0 : std::sqrt(z2 / static_cast<double>(error.size()));
  }
};

/// What `expect_bars_cover_and_tight` saw.
struct BarVerdict {
  std::size_t frames = 0;  ///< Frames judged.
  std::size_t wide = 0;    ///< Of them, bars wider than what was asked.
  double widest = 0.0;     ///< The largest bar/|error| among those.
  double rms = 0.0;        ///< rms_z over all frames.
};

/// Judge every frame of `s` by the file comment's two rules (a failure names the frame) and
/// print one line of what was found.
inline BarVerdict expect_bars_cover_and_tight(const BarSeries& s, double asked, double cover = 1.0,
                                              double floor = 0.0) {
  BarVerdict v;
  v.frames = s.error.size();
  for (std::size_t i = 0; i < s.error.size(); ++i) {
    const double err = std::fabs(s.error[i]), bar = s.bar[i];
    EXPECT_LE(err, cover * bar + floor)
        << s.name << " frame " << i << ": the bar " << bar << " does not cover the error " << err;
    if (bar <= asked) continue;
    ++v.wide;
    v.widest = std::max(v.widest, err > 0.0 ? bar / err : HUGE_VAL);
    EXPECT_LE(bar, kBarRatio * err)
        << s.name << " frame " << i << ": a bar " << bar << " wider than what was asked (" << asked
        << ") and " << kBarRatio << "x its error " << err;
  }
  v.rms = s.rms_z();
  char widest[48] = "-";
  if (v.wide > 0) std::snprintf(widest, sizeof widest, "%.1f", v.widest);
  std::printf(
      "[ bars ] %s: %zu frames, %zu with a bar wider than %.1e (what was asked), largest "
      "bar/error among them %s; RMS of 2 error/bar %.3f\n",
      s.name.c_str(), v.frames, v.wide, asked, widest, v.rms);
  return v;
}

}  // namespace hybgen::testing
