#pragma once
/// \file exit_codes.hpp
/// The process exit codes of `hybgen` and of the runners it builds, defined once: the
/// generator's error classes map to them (generator/include/hybgen/gen/errors.hpp) and the
/// runner returns them (runner.hpp), and `hybgen run` passes a runner's code through.
/// Documented in README.md ("Exit codes") and docs/design.md ("Exit codes").

namespace hybgen::rt {

/// A process exit code.
enum class ExitCode : int {
  Success = 0,      ///< Everything worked.
  ModelError = 1,   ///< The model is wrong (syntax, unknown symbol, hypothesis).
  UsageError = 2,   ///< Bad command line, or a bad run configuration given to a runner.
  Numerical = 3,    ///< Numerical failure at run time (what, where, when).
  BuildFailed = 4,  ///< Compiling generated code failed.
  Internal = 70,    ///< A bug in hybgen, or an I/O failure (the message names the file).
};

/// As the int a process returns.
constexpr int exit_status(ExitCode c) {
  return static_cast<int>(c);
}

}  // namespace hybgen::rt
