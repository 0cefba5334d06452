#pragma once
/// \file source.hpp
/// The text of a .model file, with line lookup for diagnostics.

#include <string>
#include <vector>

#include "hybgen/gen/ast.hpp"
#include "hybgen/gen/errors.hpp"

namespace hybgen::gen {

/// The text of one source file and where its lines start.
class SourceText {
 public:
  /// Wrap `text` read from `path`. Checks nothing.
  SourceText(std::string path, std::string text);
  /// Read a file; throws UsageError if it cannot be read, ModelError if it is
  /// empty (only whitespace/comments is allowed and checked later) or not UTF-8.
  static SourceText load(const std::string& path);
  /// Check that the text is non-empty and valid UTF-8; throws ModelError.
  void validate() const;
  /// The path as given.
  [[nodiscard]] const std::string& path() const { return path_; }
  /// The whole text.
  [[nodiscard]] const std::string& text() const { return text_; }
  /// Line `line` (1-based) without its newline; "" if out of range.
  [[nodiscard]] std::string line(int line) const;
  /// The position of byte offset `offset`.
  [[nodiscard]] SourceLoc loc_of(std::size_t offset) const;
  /// A ModelError at `loc` with the source line and a caret.
  [[nodiscard]] ModelError error(SourceLoc loc, const std::string& message) const;
  /// "FILE:LINE:COL: warning: message" with the source line and a caret ("FILE: warning:
  /// message" when loc has no line).
  [[nodiscard]] std::string warning(SourceLoc loc, const std::string& message) const;
  /// The source line of `loc` and a caret under its column ("" without a line).
  [[nodiscard]] std::string excerpt(SourceLoc loc) const;

 private:
  std::string path_;
  std::string text_;
  std::vector<std::size_t> line_starts_;
};

}  // namespace hybgen::gen
