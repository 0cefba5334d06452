// Every numeric setting of the table (runtime/include/hybgen/rt/settings.hpp) at the edges of
// its range, through a whole `hybgen run` of models/sawtooth.model with a method that reads
// it (tests/support/setting_edges.hpp gives the values): an admitted extreme runs or ends
// with a clear error, exit 0, 1 (a derivation limit such as derive_seconds = 0.001 on a loaded
// machine, located at the model), 2 or 3, never an internal error (70) or a signal, within two
// minutes of CPU; a value just outside is refused (exit 2). The overrides alone are walked in
// tests/gen/test_fuzz_regressions.cpp; this runs them. Found on its first run by hand
// (2026-11-30): `--set method=transfer --set step=1e-300` ended in "error: vector::reserve"
// (exit 70), the march asked for 2e300 steps; now a loud cap (setting_rules.hpp's
// steps_rule). The largest particle count (10¹⁰) is left out: it runs for hours by design,
// and says so at once (tests/rt/test_progress.cpp).

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

#include "hybgen/rt/method_table.hpp"
#include "hybgen/rt/settings.hpp"
#include "support/e2e.hpp"
#include "support/setting_edges.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::rt::exit_status;
using hybgen::rt::ExitCode;

const fs::path kWork = hybgen::testing::e2e_dir("setting_edges");
const hybgen::testing::Hybgen hybgen{kWork / "cache"};

/// A method that reads the setting (its first named reader; characteristics for every method
/// and for the derivation's limits).
std::string reader(const hybgen::rt::SettingSpec& spec) {
  for (const hybgen::rt::MethodSpec& m : hybgen::rt::kMethods)
    if (spec.methods.find(m.name) != std::string_view::npos) return std::string(m.name);
  return "characteristics";
}

TEST(SettingEdges, EveryNumberAtTheEdgesOfItsRangeRunsOrIsRefusedCleanly) {
  int runs = 0;
  for (const hybgen::rt::SettingSpec& spec : hybgen::rt::kSettings) {
    for (const hybgen::testing::EdgeValue& c : hybgen::testing::edge_values(spec)) {
      if (spec.name == "particles" && c.inside && c.value > 1e6) continue;  // hours (above)
      char value[64];
      std::snprintf(value, sizeof value, "%.17g", c.value);
      const std::string method = reader(spec);
      const fs::path out = hybgen::testing::own_dir(kWork) / "out";
      fs::remove_all(out);
      const std::string args =
          "run models/sawtooth.model -q --out '" + out.string() +
          "' --set outputs=netcdf --set method=" + method +
          (method == "particles" && spec.name != "particles" ? " --set particles=1000" : "") +
          " --set " + std::string(spec.name) + "=" + value;
      const auto r = hybgen(args, "ulimit -t 120 &&");  // CPU seconds: a runaway is killed
      std::printf("[ edges ] %s=%s (%s, method %s): exit %d\n", std::string(spec.name).c_str(),
                  value, c.inside ? "inside" : "outside", method.c_str(), r.code);
      if (c.inside) {
        EXPECT_TRUE(r.code == exit_status(ExitCode::Success) ||
                    r.code == exit_status(ExitCode::ModelError) ||
                    r.code == exit_status(ExitCode::UsageError) ||
                    r.code == exit_status(ExitCode::Numerical))
            << args << " ended with exit " << r.code << ":\n"
            << r.out;
      } else {
        EXPECT_EQ(r.code, exit_status(ExitCode::UsageError)) << args << ":\n" << r.out;
      }
      ++runs;
    }
  }
  EXPECT_GE(runs, 4 * 15 - 1);  // the table's numbers, not an empty loop
}

}  // namespace
