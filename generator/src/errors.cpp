#include "hybgen/gen/errors.hpp"

#include <cstdio>
#include <fstream>
#include <sstream>

#include "hybgen/gen/source.hpp"

namespace hybgen::gen {

namespace {
std::string format_model_error(const std::string& file, SourceLoc loc, const std::string& message,
                               const std::string& excerpt, const char* severity = "error") {
  std::ostringstream os;
  os << file << ':' << (loc.line > 0 ? loc.line : 1) << ':' << (loc.col > 0 ? loc.col : 1) << ": "
     << severity << ": " << message;
  if (!excerpt.empty()) os << '\n' << excerpt;
  return os.str();
}
}  // namespace

ModelError::ModelError(const std::string& file, SourceLoc loc, const std::string& message,
                       const std::string& excerpt)
    : Error(format_model_error(file, loc, message, excerpt), ExitCode::ModelError),
      bare_(message),
      loc_(loc) {}

SourceText::SourceText(std::string path, std::string text)
    : path_(std::move(path)), text_(std::move(text)) {
  line_starts_.push_back(0);
  for (std::size_t i = 0; i < text_.size(); ++i)
    if (text_[i] == '\n') line_starts_.push_back(i + 1);
}

SourceText SourceText::load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw UsageError("cannot open model file '" + path + "'");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw UsageError("cannot read model file '" + path + "'");
  SourceText src(path, ss.str());
  src.validate();
  return src;
}

void SourceText::validate() const {
  // UTF-8 validation (RFC 3629): reject overlongs, surrogates, > U+10FFFF.
  const auto* s = reinterpret_cast<const unsigned char*>(text_.data());
  const std::size_t n = text_.size();
  std::size_t i = 0;
  while (i < n) {
    unsigned c = s[i];
    std::size_t len = 0;
    unsigned lo = 0x80, hi = 0xBF;
    if (c < 0x80) {
      if (c == 0) throw error(loc_of(i), "NUL byte in model file");
      ++i;
      continue;
    } else if (c >= 0xC2 && c <= 0xDF) {
      len = 1;
    } else if (c >= 0xE0 && c <= 0xEF) {
      len = 2;
      if (c == 0xE0) lo = 0xA0;
      if (c == 0xED) hi = 0x9F;
    } else if (c >= 0xF0 && c <= 0xF4) {
      len = 3;
      if (c == 0xF0) lo = 0x90;
      if (c == 0xF4) hi = 0x8F;
    } else {
      throw error(
          loc_of(i), "the model file is not valid UTF-8 (byte 0x" + [&] {
            char b[3];
            std::snprintf(b, sizeof b, "%02X", c);
            return std::string(b);
          }() + ")");
    }
    if (i + len >= n) {
      throw error(loc_of(i), "the model file is not valid UTF-8 (truncated sequence)");
    }
    for (std::size_t k = 1; k <= len; ++k) {
      unsigned cc = s[i + k];
      unsigned l = (k == 1) ? lo : 0x80, h = (k == 1) ? hi : 0xBF;
      if (cc < l || cc > h)
        throw error(loc_of(i), "the model file is not valid UTF-8 (bad continuation byte)");
    }
    i += len + 1;
  }
  bool blank = true;
  for (char ch : text_)
    if (!(ch == ' ' || ch == '\t' || ch == '\n' || ch == '\r')) blank = false;
  if (blank) throw error({1, 1}, "the model file is empty");
}

std::string SourceText::line(int line) const {
  if (line < 1 || static_cast<std::size_t>(line) > line_starts_.size()) return {};
  std::size_t b = line_starts_[static_cast<std::size_t>(line - 1)];
  std::size_t e = text_.find('\n', b);
  if (e == std::string::npos) e = text_.size();
  std::string l = text_.substr(b, e - b);
  if (!l.empty() && l.back() == '\r') l.pop_back();
  return l;
}

SourceLoc SourceText::loc_of(std::size_t offset) const {
  std::size_t lo = 0, hi = line_starts_.size();
  while (hi - lo > 1) {
    std::size_t mid = (lo + hi) / 2;
    if (line_starts_[mid] <= offset)
      lo = mid;
    else
      hi = mid;
  }
  return {static_cast<int>(lo + 1), static_cast<int>(offset - line_starts_[lo] + 1)};
}

std::string SourceText::excerpt(SourceLoc loc) const {
  std::string l = line(loc.line);
  if (loc.line <= 0 || (l.empty() && loc.col > 1)) return {};
  // Tabs in the excerpt are kept so that the caret lines up in terminals.
  std::string caret;
  for (int k = 1; k < loc.col && static_cast<std::size_t>(k - 1) < l.size(); ++k)
    caret += (l[static_cast<std::size_t>(k - 1)] == '\t') ? '\t' : ' ';
  return "  " + l + "\n  " + caret + "^";
}

ModelError SourceText::error(SourceLoc loc, const std::string& message) const {
  return ModelError(path_, loc, message, excerpt(loc));
}

std::string SourceText::warning(SourceLoc loc, const std::string& message) const {
  if (loc.line <= 0) return path_ + ": warning: " + message;
  return format_model_error(path_, loc, message, excerpt(loc), "warning");
}

}  // namespace hybgen::gen
