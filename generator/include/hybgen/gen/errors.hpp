#pragma once
/// \file errors.hpp
/// hybgen's errors: a small class hierarchy, one class per exit code of
/// docs/design.md. Every failure the user can cause is one of these; anything else
/// that escapes is a bug and exits 70.

#include <stdexcept>
#include <string>

#include "hybgen/gen/ast.hpp"

#include "hybgen/rt/exit_codes.hpp"

namespace hybgen::gen {

/// Process exit codes, shared with the runners (runtime/include/hybgen/rt/exit_codes.hpp).
using ExitCode = rt::ExitCode;

/// Base of all hybgen errors: a message and the exit code it maps to.
class Error : public std::runtime_error {
 public:
  /// Construct with the full, already formatted message.
  Error(std::string message, ExitCode code) : std::runtime_error(std::move(message)), code_(code) {}
  /// The process exit code this error maps to.
  [[nodiscard]] ExitCode exit_code() const { return code_; }

 private:
  ExitCode code_;
};

/// The model is wrong: formatted as `FILE:LINE:COL: error: MESSAGE`, followed
/// by the source line and a caret under the column when the text is known.
class ModelError : public Error {
 public:
  /// A located error; `excerpt` is the source line + caret (may be empty).
  ModelError(const std::string& file, SourceLoc loc, const std::string& message,
             const std::string& excerpt = {});
  /// The message without location or excerpt.
  [[nodiscard]] const std::string& bare_message() const { return bare_; }
  /// Where the error is.
  [[nodiscard]] SourceLoc loc() const { return loc_; }

 private:
  std::string bare_;
  SourceLoc loc_;
};

/// Bad command line (unknown option, malformed --set, missing file): exit 2.
class UsageError : public Error {
 public:
  /// Construct from a message.
  explicit UsageError(const std::string& message) : Error(message, ExitCode::UsageError) {}
};

/// A numerical failure at run time (NaN, event cap, ...): exit 3.
class NumericalError : public Error {
 public:
  /// Construct from a message that says what and where.
  explicit NumericalError(const std::string& message) : Error(message, ExitCode::Numerical) {}
};

/// Compiling generated code failed: exit 4; the message names the log file.
class BuildError : public Error {
 public:
  /// Construct from a message naming the compiler log.
  explicit BuildError(const std::string& message) : Error(message, ExitCode::BuildFailed) {}
};

/// A bug in hybgen: exit 70.
class InternalError : public Error {
 public:
  /// Construct from a message.
  explicit InternalError(const std::string& message) : Error(message, ExitCode::Internal) {}
};

}  // namespace hybgen::gen
