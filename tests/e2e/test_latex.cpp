// End to end: `hybgen derive --format latex --standalone` is a document pdflatex compiles
// (Debian's texlive), for every shipped model and for a made-up one whose names have
// multi-letter subscripts and underscores; each state gets its own derivative and each
// mode's and guard's equations their name. The fragment (the default) stays a fragment.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;
using hybgen::testing::run_hybgen;
using hybgen::testing::run_shell;

const fs::path kWork = hybgen::testing::e2e_dir("e2e_latex");

constexpr const char* kThermostat = R"(model room_heater
parameter T_out = 10, k_loss = 0.5, P_heat = 8
state T_room, t_on
mode heat_on {
  T_room' = -k_loss*(T_room - T_out) + P_heat
  t_on' = 1
}
mode heat_off {
  T_room' = -k_loss*(T_room - T_out)
  t_on' = 0
}
guard switch_off {
  from heat_on to heat_off
  when T_room = 22 increasing
  reset identity
}
guard switch_on {
  from heat_off to heat_on
  when T_room = 18 decreasing
  reset identity
}
)";

/// Whether pdflatex is installed (scripts/setup.sh --tests installs texlive-latex-base).
bool have_pdflatex() {
  return run_shell("command -v pdflatex >/dev/null 2>&1").code == 0;
}

/// Compile `tex` with pdflatex in `dir`; "" on success, else the log's error lines.
std::string pdflatex(const fs::path& dir, const std::string& tex) {
  fs::create_directories(dir);
  { std::ofstream(dir / "doc.tex") << tex; }
  const auto r = run_shell("cd '" + dir.string() +
                           "' && pdflatex -interaction=nonstopmode -halt-on-error doc.tex "
                           ">/dev/null 2>&1; echo $?; grep -A3 '^!' doc.log");
  if (r.out.rfind("0\n", 0) == 0 && fs::exists(dir / "doc.pdf")) return "";
  return r.out;
}

#define REQUIRE_PDFLATEX()                                                                    \
  do {                                                                                        \
    if (!have_pdflatex()) {                                                                   \
      const char* ci = std::getenv("CI");                                                     \
      if (ci && std::string(ci) == "true") FAIL() << "CI has no pdflatex (scripts/setup.sh)"; \
      GTEST_SKIP() << "no pdflatex: install Debian's texlive-latex-base";                     \
    }                                                                                         \
  } while (0)

TEST(Latex, NamesWithSubscriptsAndUnderscoresCompile) {
  REQUIRE_PDFLATEX();
  const std::string model =
      hybgen::testing::write_model_file(kWork, "room_heater.model", kThermostat);
  const auto r = run_hybgen("derive --format latex --standalone '" + model + "'", kWork / "cache");
  ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << r.out;
  const std::string& tex = r.out;
  EXPECT_NE(tex.find("\\documentclass"), std::string::npos);
  // T_out is T with the subscript "out", not T_o followed by "ut".
  EXPECT_NE(tex.find("T_{\\mathrm{out}}"), std::string::npos) << tex;
  EXPECT_EQ(tex.find("\\mathrm{T_out}"), std::string::npos) << tex;
  // Each state its own derivative; each mode and guard named.
  EXPECT_NE(tex.find("\\dot{T}_{\\mathrm{room}} &="), std::string::npos) << tex;
  EXPECT_NE(tex.find("\\dot{t}_{\\mathrm{on}} &="), std::string::npos) << tex;
  // The coefficient 1 of ∂u/∂t_on is a sign, not "+ 1".
  EXPECT_EQ(tex.find("+ 1\\,"), std::string::npos) << tex;
  EXPECT_EQ(tex.find("\\dot x ="), std::string::npos) << tex;
  EXPECT_NE(tex.find("\\text{mode } \\mathrm{heat\\_on}"), std::string::npos) << tex;
  EXPECT_NE(tex.find("\\text{guard } \\mathrm{switch\\_off}\\ (\\mathrm{heat\\_on} \\to "
                     "\\mathrm{heat\\_off})"),
            std::string::npos)
      << tex;
  EXPECT_EQ(pdflatex(hybgen::testing::own_dir(kWork) / "room_heater", tex), "");
}

/// The lines of pdflatex's log in `dir` that report a line wider than the page.
std::string overfull_lines(const fs::path& dir) {
  return run_shell("grep -A1 'Overfull \\\\hbox' '" + (dir / "doc.log").string() + "'").out;
}

// Every shipped model's document, and every validation model's: each compiles, and no line is
// wider than the page (generator/src/latex_lines.cpp breaks long formulas; before it the
// hybrid Jacobian of models/sir_3d.model ran 292 pt past the margin, models/gl3.model's
// equations 1678 pt, models/tilted_floor.model's 22.5 pt).
TEST(Latex, EveryShippedAndValidationModelCompilesWithinThePage) {
  REQUIRE_PDFLATEX();
  std::size_t compiled = 0;
  for (const char* dir : {"models", "tests/validation/models"}) {
    for (const auto& e : fs::directory_iterator(fs::path(HYBGEN_SOURCE_DIR) / dir)) {
      if (e.path().extension() != ".model") continue;
      const std::string name = e.path().stem().string();
      const auto r = run_hybgen(
          "derive --format latex --standalone " + std::string(dir) + "/" + name + ".model",
          kWork / "cache");
      // models/aff1.model is shipped to show a refused hypothesis (exit 1): nothing to typeset.
      if (r.code == exit_status(ExitCode::ModelError) &&
          r.out.find("hypothesis") != std::string::npos)
        continue;
      ASSERT_EQ(r.code, exit_status(ExitCode::Success)) << name << ": " << r.out;
      ++compiled;
      // stderr (warnings) is part of r.out: keep the document only.
      const std::string tex = r.out.substr(r.out.find("% hybgen"));
      EXPECT_EQ(pdflatex(hybgen::testing::own_dir(kWork) / name, tex), "") << name;
      EXPECT_EQ(overfull_lines(hybgen::testing::own_dir(kWork) / name), "") << name;
    }
  }
  EXPECT_GE(compiled, 15u + 30u);
}

TEST(Latex, TheDefaultIsAFragmentAndStandaloneNeedsLatex) {
  const auto frag = run_hybgen("derive --format latex models/bouncing_ball.model", kWork / "cache");
  ASSERT_EQ(frag.code, exit_status(ExitCode::Success)) << frag.out;
  EXPECT_EQ(frag.out.find("\\documentclass"), std::string::npos);
  EXPECT_NE(frag.out.find("\\dot{x} &= "), std::string::npos) << frag.out;
  EXPECT_NE(frag.out.find("\\dot{p} &= "), std::string::npos) << frag.out;
  const auto bad = run_hybgen("derive --standalone models/bouncing_ball.model", kWork / "cache");
  EXPECT_EQ(bad.code, exit_status(ExitCode::UsageError)) << bad.out;
  EXPECT_NE(bad.out.find("--standalone makes a LaTeX document"), std::string::npos) << bad.out;
}

}  // namespace
