#pragma once
/// \file json_text.hpp
/// The JSON files a run writes (summary.json, config.json, sweep.json) as people read them:
/// nlohmann::json's `dump(2)` layout, except that an array whose elements are all scalars
/// (numbers, strings, booleans, null) stays on one line. A time series of 51 output times is
/// one line, not 53; summary.json of the shipped ball is about 100 lines instead of 700.
/// Every scalar is printed by `dump()` itself, so the text parses back to the same value
/// (doubles round-trip; NaN and ±Inf are written null, as by `dump`). The key order is the
/// value's own: an `ordered_json` (sweep.json) keeps its insertion order.

#include <nlohmann/json.hpp>
#include <string>

namespace hybgen::rt {

namespace detail {

/// Append j at nesting `depth` (2 spaces per level) to `out`.
template <class Json>
void append_json_text(std::string& out, const Json& j, int depth) {
  const auto pad = [&out](int d) { out.append(static_cast<std::size_t>(2 * d), ' '); };
  if (j.is_object()) {
    if (j.empty()) {
      out += "{}";
      return;
    }
    out += "{\n";
    bool first = true;
    for (auto it = j.begin(); it != j.end(); ++it) {
      if (!first) out += ",\n";
      first = false;
      pad(depth + 1);
      out += Json(it.key()).dump() + ": ";
      append_json_text(out, it.value(), depth + 1);
    }
    out += "\n";
    pad(depth);
    out += "}";
    return;
  }
  if (j.is_array()) {
    bool flat = true;
    for (const auto& e : j) flat = flat && !e.is_structured();
    if (j.empty() || flat) {
      out += "[";
      for (std::size_t i = 0; i < j.size(); ++i) out += (i ? ", " : "") + j[i].dump();
      out += "]";
      return;
    }
    out += "[\n";
    for (std::size_t i = 0; i < j.size(); ++i) {
      if (i) out += ",\n";
      pad(depth + 1);
      append_json_text(out, j[i], depth + 1);
    }
    out += "\n";
    pad(depth);
    out += "]";
    return;
  }
  out += j.dump();
}

}  // namespace detail

/// `j` (nlohmann::json or nlohmann::ordered_json) as the text of a JSON file (see the file
/// comment), ending in a newline.
template <class Json>
std::string json_file_text(const Json& j) {
  std::string out;
  detail::append_json_text(out, j, 0);
  return out + "\n";
}

}  // namespace hybgen::rt
