#pragma once
/// \file report.hpp
/// `report.html`: the run on one page, offline. The model and its hash, the derived
/// equations typeset by KaTeX (Debian's libjs-katex, copied beside the report into
/// `katex/`), the density with a time slider and a play button over the frame pictures,
/// the mass budget's plot and final values, the spectrum for `invariant`, the timings and
/// the files. Opened with `#selftest` it checks itself: every equation rendered, and the
/// slider shows the last frame when moved there; the result is the page's title
/// (tests/e2e/test_report.cpp reads it in headless Chromium).

#include <string>
#include <vector>

#include "hybgen/rt/io/run_record.hpp"

namespace hybgen::rt {

/// KaTeX's directory: $HYBGEN_KATEX_DIR when set, else Debian's /usr/share/javascript/katex.
std::string katex_directory();

/// The display equations of a LaTeX fragment as `hybgen derive --format latex` prints it:
/// the contents of each \[ … \], without its % comment lines.
std::vector<std::string> display_equations(const std::string& latex);

/// Writes `dir`/report.html for `run`, whose files `files` lists (relative names), and
/// copies KaTeX into `dir`/katex. Returns a warning ("" when none): without KaTeX the
/// equations are shown as LaTeX source. Throws std::runtime_error naming a file it cannot
/// write.
std::string write_report(const RunRecord& run, const std::vector<std::string>& files,
                         const std::string& dir);

}  // namespace hybgen::rt
