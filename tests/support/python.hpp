#pragma once
/// \file python.hpp
/// Debian's python3 as an independent reader (numpy, xarray, netCDF4) for the tests of every
/// directory, and the rule that a reader the README's setup installs must not go missing
/// silently: under CI=true (which .ci/run exports) a missing one fails the test.

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

namespace hybgen::testing {

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
