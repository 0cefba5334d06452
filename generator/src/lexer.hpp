#pragma once
/// \file lexer.hpp
/// Stage 1's lexer (parse.cpp's parser pulls tokens from it one at a time, so that errors are
/// reported in source order). Internal to the generator library: not a public header.

#include <cstddef>
#include <string>
#include <string_view>

#include "hybgen/gen/source.hpp"

namespace hybgen::gen::lexing {

/// Whether c is a decimal digit.
inline bool is_digit(char c) {
  return c >= '0' && c <= '9';
}
/// Whether c may start an identifier.
inline bool is_ident_start(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_';
}
/// Whether c may continue an identifier.
inline bool is_ident_char(char c) {
  return is_ident_start(c) || is_digit(c);
}

/// "3:12".
inline std::string loc_str(SourceLoc loc) {
  return std::to_string(loc.line) + ":" + std::to_string(loc.col);
}

/// `value` as `digits` upper-case hexadecimal digits.
inline std::string hex(unsigned long value, int digits) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string s(static_cast<std::size_t>(digits), '0');
  for (int i = digits - 1; i >= 0; --i) {
    s[static_cast<std::size_t>(i)] = kHex[value & 15U];
    value >>= 4U;
  }
  return s;
}

/// `text` shortened for a message.
inline std::string shorten(const std::string& text) {
  constexpr std::size_t kMax = 40;
  return text.size() <= kMax ? text : text.substr(0, kMax) + "...";
}

// ---------------------------------------------------------------------------
// Lexer
// ---------------------------------------------------------------------------

/// Token kinds.
enum class Tok {
  End,     ///< End of the text.
  Error,   ///< A lexical error; `text` is the message.
  Ident,   ///< [A-Za-z_][A-Za-z0-9_]*
  Number,  ///< 12, 0.25, .5, 1e-3, 2.5E+2
  Grid,    ///< 75x75, 33x33x33
  Punct,   ///< An operator or punctuation; `text` is its spelling.
};

/// One token with the position of its first character.
struct Token {
  Tok kind = Tok::End;  ///< Kind.
  std::string text;     ///< Spelling (the message for Tok::Error).
  SourceLoc loc;        ///< Position of the first character.
};

/// Splits the text into tokens, one at a time. Never reads out of bounds.
class Lexer {
 public:
  explicit Lexer(std::string_view text) : text_(text) {}

  /// The next token; Tok::End forever after the end or after an error.
  Token next() {
    if (failed_) return {Tok::End, "", loc_at(pos_)};
    skip_space_and_comments();
    const std::size_t start = pos_;
    if (start >= text_.size()) return {Tok::End, "", loc_at(start)};
    const char c = text_[start];
    if (is_ident_start(c)) {
      std::size_t p = start;
      while (p < text_.size() && is_ident_char(text_[p])) ++p;
      return make(Tok::Ident, start, p);
    }
    if (is_digit(c) || (c == '.' && start + 1 < text_.size() && is_digit(text_[start + 1])))
      return lex_number(start);
    const char d = start + 1 < text_.size() ? text_[start + 1] : '\0';
    if ((c == '*' && d == '*') || (c == '<' && d == '=') || (c == '>' && d == '='))
      return make(Tok::Punct, start, start + 2);
    if (std::string_view("+-*/^()[]{},;:'=<>").find(c) != std::string_view::npos)
      return make(Tok::Punct, start, start + 1);
    return bad_character(start);
  }

 private:
  SourceLoc loc_at(std::size_t pos) const {
    return {line_, static_cast<int>(pos - line_start_ + 1)};
  }

  Token make(Tok kind, std::size_t begin, std::size_t end) {
    pos_ = end;
    return {kind, std::string(text_.substr(begin, end - begin)), loc_at(begin)};
  }

  Token error(std::size_t pos, std::string message) {
    failed_ = true;
    return {Tok::Error, std::move(message), loc_at(pos)};
  }

  // Whitespace is ' ', \t, \r, \n, \f, \v; comments run from '#' or '//' to
  // the end of the line.
  void skip_space_and_comments() {
    while (pos_ < text_.size()) {
      const char c = text_[pos_];
      if (c == '\n') {
        ++pos_;
        ++line_;
        line_start_ = pos_;
      } else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
        ++pos_;
      } else if (c == '#' || (c == '/' && pos_ + 1 < text_.size() && text_[pos_ + 1] == '/')) {
        while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
      } else {
        return;
      }
    }
  }

  // NUMBER := ( digits [ '.' digits* ] | '.' digits ) [ ('e'|'E') ['+'|'-'] digits ]
  // GRID   := digits 'x' digits { 'x' digits }
  Token lex_number(std::size_t start) {
    const std::size_t n = text_.size();
    std::size_t p = start;
    bool integer = true;
    while (p < n && is_digit(text_[p])) ++p;
    if (p < n && text_[p] == '.') {
      integer = false;
      ++p;
      while (p < n && is_digit(text_[p])) ++p;
    }
    if (p < n && (text_[p] == 'e' || text_[p] == 'E')) {
      std::size_t q = p + 1;
      if (q < n && (text_[q] == '+' || text_[q] == '-')) ++q;
      if (q < n && is_digit(text_[q])) {
        integer = false;
        p = q;
        while (p < n && is_digit(text_[p])) ++p;
      } else if (q > p + 1) {
        return error(start, "malformed number '" + std::string(text_.substr(start, q - start)) +
                                "': the exponent needs digits");
      }
      // Otherwise the 'e' is a letter after the number: reported below.
    }
    if (integer && p + 1 < n && text_[p] == 'x' && is_digit(text_[p + 1])) {
      while (p + 1 < n && text_[p] == 'x' && is_digit(text_[p + 1])) {
        ++p;
        while (p < n && is_digit(text_[p])) ++p;
      }
      if (p < n && (is_ident_char(text_[p]) || text_[p] == '.')) {
        std::size_t q = p;
        while (q < n && (is_ident_char(text_[q]) || text_[q] == '.')) ++q;
        return error(start, "malformed grid literal '" +
                                shorten(std::string(text_.substr(start, q - start))) +
                                "' (expected e.g. 75x75)");
      }
      return make(Tok::Grid, start, p);
    }
    if (p < n && is_ident_start(text_[p])) {
      std::size_t q = p;
      while (q < n && is_ident_char(text_[q])) ++q;
      const std::string number(text_.substr(start, p - start));
      const std::string letters(text_.substr(p, q - p));
      return error(start, "a number is followed by letters: '" + shorten(number + letters) +
                              "' (write " + shorten(number + "*" + letters) + ")");
    }
    if (p < n && (text_[p] == '.' || is_digit(text_[p]))) {
      std::size_t q = p;
      while (q < n && (text_[q] == '.' || is_ident_char(text_[q]))) ++q;
      return error(
          start, "malformed number '" + shorten(std::string(text_.substr(start, q - start))) + "'");
    }
    return make(Tok::Number, start, p);
  }

  // Any other byte: say which character it is.
  Token bad_character(std::size_t start) {
    const auto u = static_cast<unsigned char>(text_[start]);
    if (u < 0x20 || u == 0x7F) return error(start, "unexpected control character 0x" + hex(u, 2));
    if (u < 0x80) return error(start, std::string("unexpected character '") + text_[start] + "'");
    // Non-ASCII: show the whole UTF-8 sequence and its code point.
    std::size_t len = u >= 0xF8 ? 1 : u >= 0xF0 ? 4 : u >= 0xE0 ? 3 : u >= 0xC0 ? 2 : 1;
    bool ok = len > 1 && start + len <= text_.size();
    unsigned long cp = u & (len == 2 ? 0x1FU : len == 3 ? 0x0FU : 0x07U);
    for (std::size_t k = 1; ok && k < len; ++k) {
      const auto b = static_cast<unsigned char>(text_[start + k]);
      if ((b & 0xC0U) != 0x80U) ok = false;
      cp = (cp << 6U) | (b & 0x3FU);
    }
    if (!ok)
      return error(start,
                   "unexpected byte 0x" + hex(u, 2) + " (only ASCII is allowed outside comments)");
    return error(start, "unexpected character '" + std::string(text_.substr(start, len)) + "' (U+" +
                            hex(cp, cp > 0xFFFF ? 6 : 4) +
                            "; only ASCII is allowed outside comments)");
  }

  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_start_ = 0;
  int line_ = 1;
  bool failed_ = false;
};

}  // namespace hybgen::gen::lexing
