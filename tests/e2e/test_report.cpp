// End to end: report.html (runtime/src/io/report.cpp) in headless Chromium, and the
// animation (runtime/src/io/animation.cpp). The page checks itself when opened with
// #selftest: every equation typeset by KaTeX (copied beside the report: no network), and
// the slider, moved to its end, shows the last frame; the result is the page's title,
// which Chromium's --dump-dom prints. Also: a screenshot is taken, a run without KaTeX
// still writes the report (equations as LaTeX source) and says why, and the output
// directory with the report's katex/ is replaced by the next run but not when a user's file
// is in it.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "support/e2e.hpp"
#include "support/files.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::read_json_file;
using hybgen::testing::read_text;
using hybgen::testing::run_hybgen;
using hybgen::testing::run_shell;

const fs::path kWork = hybgen::testing::e2e_dir("e2e_report");

std::string chromium() {
  for (const char* c : {"chromium", "chromium-browser", "google-chrome"})
    if (run_shell(std::string("command -v ") + c + " >/dev/null 2>&1").code == 0) return c;
  return "";
}

/// Chromium headless as root in a sandbox-less container, with no network (the flags the
/// machine's notes give), a fresh profile, and time for the page's script.
std::string headless(const std::string& browser, const std::string& args) {
  const fs::path profile = hybgen::testing::own_dir(kWork) / "profile";
  fs::remove_all(profile);
  return "timeout 120 " + browser +
         " --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
         "--disable-background-networking --disable-component-update --disable-sync "
         "--user-data-dir='" +
         profile.string() + "' --virtual-time-budget=10000 " + args + " 2>/dev/null";
}

const std::string kRun =
    "run models/bouncing_ball.model --set grid=31x31 --set t_end=2 --set dt=0.5 --quiet ";

TEST(Report, RendersItsEquationsAndItsSliderMovesTheFrames) {
  const fs::path out = hybgen::testing::own_dir(kWork) / "ball";
  fs::remove_all(out);
  const auto r = run_hybgen(kRun + "--out '" + out.string() + "'", kWork / "cache");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  for (const char* f : {"report.html", "katex/katex.min.js", "katex/katex.min.css", "animation.gif",
                        "density.pdf", "budget.png", "u_0004.png"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  const auto s = read_json_file(out / "summary.json");
  EXPECT_EQ(s["outputs"]["report"], "report.html");
  // What derive checked is on the page: the ball's reset has a closed-form inverse.
  const std::string page = read_text(out / "report.html");
  EXPECT_NE(page.find("<h2>Hypotheses and checks</h2>"), std::string::npos);
  EXPECT_NE(page.find("guard <code>ground</code>: the reset has a closed-form inverse"),
            std::string::npos);
  // The animation: GIF89a, one graphic control block per frame (5 frames).
  const std::string gif = read_text(out / "animation.gif");
  EXPECT_EQ(gif.rfind("GIF89a", 0), 0u);
  std::size_t frames = 0;
  for (auto p = gif.find("\x21\xF9\x04"); p != std::string::npos;
       p = gif.find("\x21\xF9\x04", p + 1))
    ++frames;
  EXPECT_EQ(frames, 5u);

  const std::string browser = chromium();
  if (browser.empty()) {
    const char* ci = std::getenv("CI");
    if (ci && std::string(ci) == "true") FAIL() << "CI has no chromium (scripts/setup.sh --tests)";
    GTEST_SKIP() << "no chromium: install Debian's chromium to test the report";
  }
  const std::string url = "file://" + fs::absolute(out / "report.html").string();
  const auto dom = run_shell(headless(browser, "--dump-dom '" + url + "#selftest'"));
  EXPECT_NE(dom.out.find("<title>selftest ok: 3 equations rendered, 0 failed, frame u_0004.png"),
            std::string::npos)
      << dom.out.substr(0, 2000);
  EXPECT_NE(dom.out.find("class=\"katex-display\""), std::string::npos);
  // A screenshot of the page as a reader sees it.
  const fs::path shot = hybgen::testing::own_dir(kWork) / "report.png";
  fs::remove(shot);
  (void)run_shell(headless(
      browser, "--window-size=1200,2000 --screenshot='" + shot.string() + "' '" + url + "'"));
  ASSERT_TRUE(fs::exists(shot));
  EXPECT_GT(fs::file_size(shot), 50000u);
}

TEST(Report, WithoutKatexTheEquationsAreSourceAndTheRunSaysWhy) {
  const fs::path out = hybgen::testing::own_dir(kWork) / "no_katex";
  fs::remove_all(out);
  // HYBGEN_KATEX_DIR points the runner at a directory without KaTeX.
  const auto r2 = run_hybgen(kRun + "--set outputs=png+html --out '" + out.string() + "'",
                             kWork / "cache", "HYBGEN_KATEX_DIR=/nonexistent");
  ASSERT_EQ(r2.code, exit_status(ExitCode::Success)) << r2.out;
  EXPECT_NE(r2.out.find("warning: report.html shows the equations as LaTeX source"),
            std::string::npos)
      << r2.out;
  const std::string page = read_text(out / "report.html");
  EXPECT_NE(page.find("<pre>  \\text{mode } \\mathrm{flight}"), std::string::npos);
  EXPECT_FALSE(fs::exists(out / "katex"));
}

TEST(Report, TheNextRunReplacesTheReportButNotAUsersFile) {
  const fs::path out = hybgen::testing::own_dir(kWork) / "replace";
  fs::remove_all(out);
  ASSERT_EQ(run_hybgen(kRun + "--out '" + out.string() + "'", kWork / "cache").code,
            exit_status(ExitCode::Success));
  ASSERT_EQ(run_hybgen(kRun + "--out '" + out.string() + "'", kWork / "cache").code,
            exit_status(ExitCode::Success));
  std::ofstream(out / "katex" / "notes.txt") << "mine";
  const auto r = run_hybgen(kRun + "--out '" + out.string() + "'", kWork / "cache");
  EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << r.out;
  EXPECT_NE(r.out.find("katex/notes.txt"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(out / "katex" / "notes.txt"));
}

}  // namespace
