#pragma once
/// \file e2e.hpp
/// What the end-to-end tests share: running the built `hybgen` from the source directory
/// with a private cache, writing a model they made up, reading JSON, and finding Debian's
/// python3 with the modules an independent reader needs.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "hybgen/gen/fs.hpp"
#include "support/shell.hpp"

namespace hybgen::testing {

/// The test's work directory under the build tree (created).
inline std::filesystem::path e2e_dir(const std::string& name) {
  const std::filesystem::path d = std::filesystem::path(HYBGEN_BINARY_DIR) / name;
  std::filesystem::create_directories(d);
  return d;
}

/// Run hybgen with `args` from the source directory with the cache `cache`; all output.
inline ShellResult run_hybgen(const std::string& args, const std::filesystem::path& cache) {
  return run_shell("cd '" + std::string(HYBGEN_SOURCE_DIR) + "' && HYBGEN_CACHE='" +
                   cache.string() + "' '" + std::string(HYBGEN_EXE) + "' " + args + " 2>&1");
}

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

/// Debian's python3 when it imports every module of `modules` ("" when none does). The
/// Debian interpreter comes first: a python3 earlier on PATH may lack Debian's packages.
inline std::string python_with(const std::string& modules) {
  for (const char* candidate : {"/usr/bin/python3", "python3"})
    if (std::system(
            (std::string(candidate) + " -c 'import " + modules + "' >/dev/null 2>&1").c_str()) == 0)
      return candidate;
  return "";
}

}  // namespace hybgen::testing

/// Skip the test, saying why, when `python` is empty; in CI (CI=true), where
/// scripts/setup.sh installs the readers, fail instead: a reader must not go missing
/// silently.
#define HYBGEN_REQUIRE_PYTHON(python, modules)                                         \
  do {                                                                                 \
    if ((python).empty()) {                                                            \
      const char* ci_ = std::getenv("CI");                                             \
      if (ci_ && std::string(ci_) == "true")                                           \
        FAIL() << "CI has no python3 with " << (modules) << " (scripts/setup.sh)";     \
      GTEST_SKIP() << "no python3 with " << (modules) << ": install Debian's python3 " \
                   << "packages (scripts/setup.sh --tests)";                           \
    }                                                                                  \
  } while (0)
