// The invariant method's schemes on five closed-form cycles (tests/support/cycle_closed_forms.hpp:
// a thermostat in a box wider than its cycle, the sawtooth, x' = 1 + x², a two-mode cycle with
// the reset x ↦ x/2, and thermostat × sawtooth in 2-D), through `hybgen run` as a user runs it:
// per case and scheme (fv, the default where it applies; hat, the former default; cell, Ulam)
// the wall time of the run (the runner already built), the solve's own time from summary.json,
// the true relative L1 error of the density against the closed form, and the error the run
// estimated. docs/benchmarks.md has a table of its counters.
//
//   build/bench/hybgen_bench_invariant --benchmark_counters_tabular=true

#include <benchmark/benchmark.h>

#include <chrono>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "support/cycle_closed_forms.hpp"
#include "support/e2e.hpp"

namespace {

namespace fs = std::filesystem;
using hybgen::testing::Case;

const fs::path kWork = hybgen::testing::e2e_dir("bench_invariant");
const hybgen::testing::Hybgen hybgen_cli{kWork / "cache"};

void invariant_scheme(benchmark::State& state, const Case& c, const std::string& scheme) {
  const fs::path dir = kWork / (c.name + "_" + scheme);
  const std::string args = "run '" + c.model + "' --quiet --out '" + dir.string() +
                           "' --set method=invariant --set scheme=" + scheme +
                           " --set outputs=npy --set grid=" + hybgen::testing::grid_setting(c.axes);
  if (hybgen_cli(args).code != 0) {  // builds the runner, untimed
    state.SkipWithError("hybgen run failed");
    return;
  }
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto r = hybgen_cli(args);
    state.SetIterationTime(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (r.code != 0) {
      state.SkipWithError(r.out.c_str());
      return;
    }
  }
  const nlohmann::json s = hybgen::testing::read_json_file(dir / "summary.json");
  const nlohmann::json& inv = s["invariant"];
  state.counters["error"] = hybgen::testing::cycle_case_error(c, dir);
  state.counters["estimate"] = inv["error"].is_number() ? inv["error"].get<double>() : -1.0;
  state.counters["solve_s"] = s["seconds"]["solve"].get<double>();
  state.counters["unknowns"] = static_cast<double>(inv["rows"].get<std::size_t>());
}

const bool registered = [] {
  for (const Case& c : hybgen::testing::cycle_cases())
    for (const char* scheme : {"fv", "hat"})
      benchmark::RegisterBenchmark(
          ("invariant/" + c.name + "/" + scheme).c_str(),
          [c, s = std::string(scheme)](benchmark::State& st) { invariant_scheme(st, c, s); })
          ->UseManualTime()
          ->Iterations(3)
          ->Unit(benchmark::kMillisecond);
  return true;
}();

}  // namespace

BENCHMARK_MAIN();
