#pragma once
/// \file e2e.hpp
/// What the end-to-end tests share: running the built `hybgen` from the source directory
/// with a private cache (its exit codes: hybgen/rt/exit_codes.hpp, included), writing a
/// model they made up, reading JSON, and finding Debian's python3 with the modules an
/// independent reader needs.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hybgen/gen/fs.hpp"
#include "hybgen/rt/exit_codes.hpp"
#include "support/python.hpp"
#include "support/shell.hpp"

namespace hybgen::testing {

/// Whether this test is compiled under AddressSanitizer (CI's hardening stage,
/// scripts/ci-hardening.sh, where a runner compiled at -Og under ASan + UBSan takes 10-20× its
/// Release time): such a test may keep every code path and leave out a repeat of it.
inline constexpr bool kSanitized =
#ifdef __SANITIZE_ADDRESS__
    true;
#else
    false;
#endif

/// The test's work directory under the build tree (created).
inline std::filesystem::path e2e_dir(const std::string& name) {
  const std::filesystem::path d = std::filesystem::path(HYBGEN_BINARY_DIR) / name;
  std::filesystem::create_directories(d);
  return d;
}

/// `base`/SUITE.TEST for the running test (created; `base`/outside_tests outside one): where a
/// test writes its runs. ctest runs each test in a process of its own, several at once, so two
/// tests that run the same case (one model by two methods, say) must never share an output
/// directory: hybgen refuses the second writer (the output lock) and a shared directory can
/// hand one test the other's files.
inline std::filesystem::path own_dir(const std::filesystem::path& base) {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path d =
      base / (info == nullptr ? std::string("outside_tests")
                              : std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::create_directories(d);
  return d;
}

/// Where run_hybgen sends hybgen's standard error.
enum class Stderr {
  Merged,     ///< Into the captured output, after standard output.
  Discarded,  ///< To /dev/null: the output is standard output alone (e.g. JSON to parse).
};

/// The environment variable `name`, or `fallback` where it is unset or empty.
inline std::string env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return std::string(v != nullptr && *v != '\0' ? v : fallback);
}

/// The hybgen under test: this build's, or the executable named by the environment variable
/// HYBGEN_UNDER_TEST (to list the tests an older hybgen fails: docs/hardening.md, "Against an
/// older hybgen").
inline std::string hybgen_exe() {
  return env_or("HYBGEN_UNDER_TEST", HYBGEN_EXE);
}

/// The directory hybgen runs from (its relative paths, models/…, are read there): the source
/// tree, or the one named by HYBGEN_UNDER_TEST_SOURCE (an older hybgen's own tree, whose
/// shipped models it can read).
inline std::string hybgen_source_dir() {
  return env_or("HYBGEN_UNDER_TEST_SOURCE", HYBGEN_SOURCE_DIR);
}

/// Run hybgen with `args` from the source directory with the cache `cache`; all output (or
/// standard output alone: `err`). `prefix` goes before the command in the shell: environment
/// assignments, or set-up ending in "&&" (`cd DIR &&`, `ulimit -f 40 &&`).
inline ShellResult run_hybgen(const std::string& args, const std::filesystem::path& cache,
                              const std::string& prefix = "", Stderr err = Stderr::Merged) {
  return run_shell("cd '" + hybgen_source_dir() + "' && " + prefix + (prefix.empty() ? "" : " ") +
                   "HYBGEN_CACHE='" + cache.string() + "' '" + hybgen_exe() + "' " + args +
                   (err == Stderr::Merged ? " 2>&1" : " 2>/dev/null"));
}

/// run_hybgen's prefix for runs on MPI ranks (`--ranks N`): as root (CI), and more ranks than
/// cores allowed (a 1-core machine still tests 2). Under the sanitizers (an environment variable
/// that an unsanitized program ignores) without LeakSanitizer: Open MPI's plugins, which it loads
/// and unloads itself, leave allocations that no suppression can name (their module is gone by
/// the leak check: "<unknown module>"; a 10-line MPI_Init/MPI_Finalize program reports 8 of
/// them). The serial runs check the runtime's leaks; ASan's other checks and UBSan stay on.
inline constexpr const char* kMpiEnv =
    "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 "
    "HYBGEN_MPIEXEC='mpiexec --oversubscribe' ASAN_OPTIONS=detect_leaks=0";

/// A test's `hybgen`: run_hybgen with the test's own cache, called like the executable.
struct Hybgen {
  std::filesystem::path cache;  ///< HYBGEN_CACHE of every run.
  /// Run with `args` after `prefix` (as run_hybgen's); all output.
  ShellResult operator()(const std::string& args, const std::string& prefix = "") const {
    return run_hybgen(args, cache, prefix);
  }
  /// Run with `args`; standard output alone (standard error discarded).
  ShellResult stdout_only(const std::string& args) const {
    return run_hybgen(args, cache, "", Stderr::Discarded);
  }
};

/// Write `text` to `dir`/models/`name`; returns the path.
inline std::string write_model_file(const std::filesystem::path& dir, const std::string& name,
                                    const std::string& text) {
  std::filesystem::create_directories(dir / "models");
  const std::string path = (dir / "models" / name).string();
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

/// A JSON file.
inline nlohmann::json read_json_file(const std::filesystem::path& p) {
  return nlohmann::json::parse(hybgen::gen::read_file(p.string()));
}

/// `hybgen run 'MODEL' --quiet --out 'DIR' SETS` into a fresh `dir`, with the cache `cache`:
/// its summary.json, or null when the run failed (a test failure with hybgen's output).
inline nlohmann::json run_summary(const std::string& model, const std::filesystem::path& dir,
                                  const std::string& sets, const std::filesystem::path& cache) {
  std::filesystem::remove_all(dir);
  const ShellResult res =
      run_hybgen("run '" + model + "' --quiet --out '" + dir.string() + "' " + sets, cache);
  EXPECT_EQ(res.code, 0) << res.out;
  if (res.code != 0) return nullptr;
  return read_json_file(dir / "summary.json");
}

/// How wide a bar of the budget's cubatures may be whatever its error: `margin` (twice by
/// default) times the tolerance the run asked for, summary.json's budget rel_tol
/// (`fallback_tol` without one) times its initial mass. The cubature stops near that
/// tolerance, each estimate a little above or below it, however much smaller its error is by
/// luck (docs/hardening.md, "Calibrated bars").
inline double asked_width(const nlohmann::json& s, double fallback_tol = 0.0, double margin = 2.0) {
  const bool tol = s.contains("budget") && s["budget"].contains("rel_tol");
  return margin * (tol ? s["budget"]["rel_tol"].get<double>() : fallback_tol) *
         s["initial_mass"].get<double>();
}

}  // namespace hybgen::testing
