// The settings table (runtime/include/hybgen/rt/settings.hpp) is the one definition of every
// run setting. These tests walk each row through both sides: the generator's model-file and
// `--set` path (check.cpp), the run configuration it writes, and the runner's reader, which
// must accept exactly what the generator accepts and read back the same value; and they
// check that the settings page of the docs is the table.

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "hybgen/gen/check.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/parse.hpp"
#include "hybgen/gen/run.hpp"
#include "hybgen/rt/setting_rules.hpp"
#include "hybgen/rt/settings.hpp"

namespace hybgen::gen {
namespace {

const char* const kModel = R"(model box
state x
parameter a = 1
mode m {
  x' = -a*x
}
simulation {
  domain x in [0, 1]
  grid 11
  initial 1
  t_end 2
}
)";

Model model() {
  SourceText src("t.model", kModel);
  return check(parse(src), src);
}

/// Whether `s` holds text (one word, or a '+'-joined list of words).
bool is_text(const rt::SettingSpec& s) {
  return s.type == rt::SettingType::word || s.type == rt::SettingType::words ||
         s.type == rt::SettingType::names;
}

/// A valid value of `s` other than its default, as `--set` text.
std::string other_value(const rt::SettingSpec& s) {
  if (s.type == rt::SettingType::names) return "x";  // kModel's state
  if (is_text(s)) {
    const std::string_view w = s.words.substr(s.words.rfind('|') + 1);  // the last word
    return std::string(w == s.word ? s.words.substr(0, s.words.find('|')) : w);
  }
  double x = s.hi < 1e300 ? s.hi : (s.number > 0 ? 2 * s.number : 3.0);
  if (x == s.number) x = s.lo_open ? (s.lo + s.hi) / 2 : s.lo;
  if (s.type == rt::SettingType::integer) x = std::floor(x);
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", x);
  return b;
}

/// A value `s` refuses, as `--set` text.
std::string bad_value(const rt::SettingSpec& s) {
  if (s.type == rt::SettingType::names) return "x+x";  // both sides: "'x' is given twice"
  if (is_text(s)) return "nosuchword";
  if (s.hi < 1e300) return "1e301";
  return s.lo_open ? std::to_string(s.lo) : "-1e300";
}

TEST(Settings, EveryRowTravelsFromSetToTheRunner) {
  for (const rt::SettingSpec& s : rt::kSettings) {
    const std::string name(s.name), value = other_value(s);
    Model m = model();
    ASSERT_NO_THROW(apply_overrides(m, {name + "=" + value})) << name << "=" << value;
    EXPECT_TRUE(m.sim.settings.given(name)) << name;
    if (s.methods == "derive") continue;  // the symbolic stage's: not in the runner's config
    // What the generator writes (run_config, generator/src/run.cpp) is what the runner reads.
    const nlohmann::json config = run_config(m, "out", "out", true);
    ASSERT_TRUE(config.contains(name)) << name;
    rt::Settings runner;
    ASSERT_NO_THROW(runner = rt::Settings::from_json(config)) << name;
    EXPECT_EQ(runner.to_json(), m.sim.settings.to_json()) << name;
    if (is_text(s))
      EXPECT_EQ(config[name].get<std::string>(), value) << name;
    else
      EXPECT_EQ(config[name].get<double>(), std::stod(value)) << name;
  }
}

TEST(Settings, BothSidesRefuseTheSameValuesWithTheSameReason) {
  for (const rt::SettingSpec& s : rt::kSettings) {
    const std::string name(s.name), value = bad_value(s);
    Model m = model();
    std::string generator_says;
    try {
      apply_overrides(m, {name + "=" + value});
      ADD_FAILURE() << name << "=" << value << " accepted";
    } catch (const UsageError& e) {
      generator_says = e.what();
      EXPECT_EQ(e.exit_code(), ExitCode::UsageError);
    }
    if (s.methods == "derive") continue;
    nlohmann::json config = model().sim.settings.to_json();  // valid: dt resolved
    if (is_text(s))
      config[name] = value;
    else
      config[name] = std::stod(value);
    try {
      (void)rt::Settings::from_json(config);
      ADD_FAILURE() << "the runner accepted " << name << "=" << value;
    } catch (const std::invalid_argument& e) {
      // The reason after the name is the table's, on both sides.
      const std::string runner_says = e.what();
      const std::string reason = runner_says.substr(runner_says.find(' ', 9) + 1);
      EXPECT_NE(generator_says.find(reason), std::string::npos)
          << "generator: " << generator_says << "\nrunner: " << runner_says;
    }
  }
}

TEST(Settings, ModelFileBlockUsesTheSameRules) {
  // A setting in the simulation block goes through the same row as --set.
  const std::string text = std::string(kModel).replace(std::string(kModel).find("  t_end 2"), 9,
                                                       "  t_end 2\n  samples 65");
  SourceText src("t.model", text);
  try {
    (void)check(parse(src), src);
    ADD_FAILURE() << "samples 65 accepted";
  } catch (const ModelError& e) {
    EXPECT_NE(std::string(e.what()).find("must be an integer in [0, 64]"), std::string::npos)
        << e.what();
  }
}

TEST(Settings, AWordListTakesEachWordOnceInAnyOrder) {
  Model m = model();
  ASSERT_NO_THROW(apply_overrides(m, {"outputs=vti+netcdf+npy"}));
  const rt::Settings& s = m.sim.settings;
  EXPECT_TRUE(s.includes<"outputs">("vti"));
  EXPECT_TRUE(s.includes<"outputs">("npy"));
  EXPECT_TRUE(s.includes<"outputs">("netcdf"));
  EXPECT_FALSE(s.includes<"outputs">("png"));
  for (const char* bad : {"outputs=npy+npy", "outputs=npy+", "outputs=+npy", "outputs=npy+mp4"}) {
    Model b = model();
    EXPECT_THROW(apply_overrides(b, {bad}), UsageError) << bad;
  }
  // The model file's block spells the list the same way, spaces around '+' allowed.
  const std::string text = std::string(kModel).replace(std::string(kModel).find("  t_end 2"), 9,
                                                       "  t_end 2\n  outputs npy + png");
  SourceText src("t.model", text);
  const Model f = check(parse(src), src);
  EXPECT_EQ(f.sim.settings.to_json()["outputs"], "npy+png");
  // A list where a number belongs is refused, located.
  const std::string num =
      std::string(kModel).replace(std::string(kModel).find("  t_end 2"), 9, "  t_end npy + png");
  SourceText src2("t.model", num);
  EXPECT_THROW((void)check(parse(src2), src2), ModelError);
}

TEST(Settings, FigureAxesAreStatesOfTheModel) {
  const std::string three = R"(model box3
state x, y, z
mode m {
  x' = 1
  y' = 0
  z' = 0
}
simulation {
  domain x in [0, 1]
  domain y in [0, 1]
  domain z in [0, 1]
  grid 5x5x5
  initial 1
  t_end 1
}
)";
  SourceText src("t.model", three);
  Model m = check(parse(src), src);
  ASSERT_NO_THROW(apply_overrides(m, {"figure_axes=z+x"}));
  EXPECT_EQ(m.sim.settings.names<"figure_axes">(), (std::vector<std::string>{"z", "x"}));
  for (const char* bad :
       {"figure_axes=x+w", "figure_axes=x", "figure_axes=x+x", "figure_axes=2x"}) {
    Model b = check(parse(src), src);
    try {
      apply_overrides(b, {bad});
      ADD_FAILURE() << bad << " accepted";
    } catch (const UsageError& e) {
      if (std::string(bad) == "figure_axes=x+w") {
        EXPECT_NE(std::string(e.what()).find("'w' is not a state variable (the states: x, y, z)"),
                  std::string::npos)
            << e.what();
      }
    }
  }
}

TEST(Settings, DefaultsAndDerivedDefaults) {
  const Model m = model();
  EXPECT_EQ(m.sim.settings.word<"method">(), "characteristics");
  EXPECT_EQ(m.sim.settings.real<"tol">(), 1e-10);
  EXPECT_EQ(m.sim.settings.real<"dt">(), 0.2);  // t_end/10 when not given
  EXPECT_FALSE(m.sim.settings.given("dt"));
  // The derivation limits are read from the table.
  EXPECT_EQ(m.limits.derive_seconds, rt::setting_number("derive_seconds"));
}

// scheme=fv is the generator: its null vector for invariant, stepped in time for transfer
// (runtime/include/hybgen/rt/methods/generator_march.hpp); escape is not built on it, and says
// so before anything runs (setting_rules.hpp, fv_scheme_rule).
TEST(Settings, SchemeFvIsForTransferAndInvariant) {
  for (const std::string method : {"transfer", "invariant", "escape", "characteristics"}) {
    rt::Settings s;
    rt::SettingValue m, f;
    m.word = method;
    f.word = "fv";
    s.assign("method", m);
    s.assign("scheme", f);
    std::string why;
    for (const rt::SettingConflict& c : rt::setting_conflicts(s, rt::RunFacts{}))
      if (c.setting == "scheme") why = c.message;
    EXPECT_EQ(why.empty(), method != "escape") << method << ": " << why;
    if (method == "escape") {
      EXPECT_NE(why.find("method=invariant or transfer"), std::string::npos);
    }
  }
}

// scheme=galerkin is method transfer's, in one process (setting_rules.hpp,
// galerkin_scheme_rule): every other method that reads `scheme` refuses it before anything
// runs, naming the method, and so does a run over two ranks. From the methods table.
TEST(Settings, SchemeGalerkinIsForTransferInOneProcess) {
  rt::RunFacts one, two;
  one.ranks = 1, two.ranks = 2;
  constexpr std::size_t kScheme = rt::setting_index("scheme");
  for (const rt::MethodSpec& method : rt::kMethods) {
    rt::Settings s;
    rt::SettingValue m, g;
    m.word = std::string(method.name);
    g.word = "galerkin";
    s.assign("method", m);
    s.assign("scheme", g);
    const auto why = [&s](const rt::RunFacts& facts) {
      for (const rt::SettingConflict& c : rt::setting_conflicts(s, facts))
        if (c.setting == "scheme") return c.message;
      return std::string();
    };
    const bool reads = rt::method_reads(method, rt::kSettings[kScheme]);
    const bool transfer = method.id == rt::Method::transfer;
    EXPECT_EQ(why(one).empty(), transfer || !reads) << method.name << ": " << why(one);
    if (reads && !transfer) {
      EXPECT_NE(why(one).find("method " + std::string(method.name)), std::string::npos) << why(one);
    }
    if (transfer) {
      EXPECT_NE(why(two).find("one process"), std::string::npos) << why(two);
    }
  }
}

// A method that needs the whole operator in one process (MethodSpec::whole_operator: the
// almost-invariant sets, the coherent pairs) is refused over several ranks before any work
// (setting_rules.hpp, one_process_rule); every other method runs there. From the methods
// table, so that a new method is checked by its row.
TEST(Settings, SeveralRanksAreRefusedExactlyForTheWholeOperatorMethods) {
  rt::RunFacts one, two;
  one.ranks = 1, two.ranks = 2;
  int whole = 0;
  for (const rt::MethodSpec& method : rt::kMethods) {
    rt::Settings s;
    rt::SettingValue v;
    v.word = std::string(method.name);
    s.assign("method", v);
    const auto refused = [&s](const rt::RunFacts& facts) {
      for (const rt::SettingConflict& c : rt::setting_conflicts(s, facts))
        if (c.setting == "ranks" && c.message.find("one process") != std::string::npos) return true;
      return false;
    };
    EXPECT_FALSE(refused(one)) << method.name;
    EXPECT_EQ(refused(two), method.whole_operator) << method.name;
    whole += method.whole_operator ? 1 : 0;
  }
  EXPECT_EQ(whole, 2);  // almost_invariant and coherent
}

// fv_order=4 gives a cycle growing modes (|λ| = 1 + 1.7e-7 on quadratic_cycle.model at 401
// nodes): refused before anything runs (setting_rules.hpp, fv_order_rule); 1–3 and 5 pass.
TEST(Settings, FvOrderFourIsRefused) {
  for (const int order : {1, 2, 3, 4, 5}) {
    rt::Settings s;
    rt::SettingValue v;
    v.number = order;
    v.has_number = true;
    s.assign("fv_order", v);
    std::string why;
    for (const rt::SettingConflict& c : rt::setting_conflicts(s, rt::RunFacts{}))
      if (c.setting == "fv_order") why = c.message;
    EXPECT_EQ(why.empty(), order != 4) << order << ": " << why;
    if (order == 4) {
      EXPECT_NE(why.find("fv_order=5"), std::string::npos) << why;
    }
  }
}

// A tolerance double precision cannot meet used to run and fail at the first step ("ODE step
// size underflow", exit 3); it is refused before anything runs, naming the range.
TEST(Settings, TolBelowDoublePrecisionIsRefused) {
  for (const std::string v : {"1e-300", "1e-15"}) {
    Model m = model();
    try {
      apply_overrides(m, {"tol=" + v});
      ADD_FAILURE() << "tol=" << v << " accepted";
    } catch (const UsageError& e) {
      EXPECT_NE(std::string(e.what()).find("1e-14"), std::string::npos) << e.what();
    }
  }
  Model m = model();
  apply_overrides(m, {"tol=1e-14"});
  EXPECT_EQ(m.sim.settings.real<"tol">(), 1e-14);
}

TEST(Settings, DocsPageIsTheTable) {
  const std::string page = read_file(std::string(HYBGEN_SOURCE_DIR) + "/docs/settings.md");
  EXPECT_NE(page.find(rt::settings_markdown()), std::string::npos)
      << "docs/settings.md is out of date; its table is rt::settings_markdown():\n"
      << rt::settings_markdown();
}

TEST(Settings, TheOutputsPageGivesTheTablesDefaultAndDocumentsConfigJson) {
  // docs/outputs.md gave `outputs`' default as netcdf+png+pdf where the table (and
  // docs/settings.md, --help) said netcdf+png+pdf+gif+html, and left the output folder's
  // config.json undocumented (a81ba15): the page quotes the table's default and says what
  // config.json holds.
  const std::string page = read_file(std::string(HYBGEN_SOURCE_DIR) + "/docs/outputs.md");
  const rt::SettingSpec* outputs = rt::find_setting("outputs");
  ASSERT_NE(outputs, nullptr);
  const std::string quoted = "default `" + std::string(outputs->word) + "`";
  EXPECT_NE(page.find(quoted), std::string::npos) << "docs/outputs.md lacks " << quoted;
  EXPECT_NE(page.find("- `config.json`:"), std::string::npos);
  std::size_t at = 0;
  while ((at = page.find("default `netcdf", at)) != std::string::npos) {
    EXPECT_EQ(page.compare(at, quoted.size(), quoted), 0) << page.substr(at, 60);
    ++at;
  }
}

}  // namespace
}  // namespace hybgen::gen
