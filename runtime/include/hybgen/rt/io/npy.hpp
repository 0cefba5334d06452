#pragma once
/// \file npy.hpp
/// NumPy .npy files (format version 1.0, dtype '<f8', C order).
///
/// Layout written by `write_npy` (numpy/lib/format.py):
///   "\x93NUMPY" 0x01 0x00 <uint16 LE header_len>
///   "{'descr': '<f8', 'fortran_order': False, 'shape': (n0, n1), }" + ' '* + '\n'
///   little-endian float64 data, C order (last axis fastest)
/// The header is padded with spaces so that 10 + header_len (the data offset) is a
/// multiple of 64. `read_npy` accepts versions 1.0-3.0, '<f8' and '>f8', C order.

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "hybgen/rt/io/atomic_file.hpp"

namespace hybgen::rt {

/// An array read back from a .npy file: `data` in C order, `data.size()` = Π shape.
struct NpyArray {
  std::vector<std::size_t> shape;  ///< Extent per axis; empty for a 0-d array.
  std::vector<double> data;        ///< Values, last axis fastest.
};

namespace detail {

/// Magic string that opens every .npy file.
inline constexpr std::string_view npy_magic{"\x93NUMPY", 6};

/// Π shape, throwing std::length_error when it overflows size_t (or its byte size does).
inline std::size_t npy_element_count(const std::vector<std::size_t>& shape) {
  std::size_t n = 1;
  for (std::size_t e : shape) {
    if (e != 0 && n > std::numeric_limits<std::size_t>::max() / e)
      throw std::length_error("npy: shape too large");
    n *= e;
  }
  if (n > std::numeric_limits<std::size_t>::max() / sizeof(double))
    throw std::length_error("npy: shape too large");
  return n;
}

/// Python repr of a shape tuple: "()", "(3,)", "(3, 4)".
inline std::string npy_shape_repr(const std::vector<std::size_t>& shape) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) s += ", ";
    s += std::to_string(shape[i]);
  }
  if (shape.size() == 1) s += ',';
  s += ')';
  return s;
}

/// The complete version-1.0 preamble (magic, version, length, padded dict, '\n').
inline std::string npy_header(const std::vector<std::size_t>& shape) {
  std::string dict =
      "{'descr': '<f8', 'fortran_order': False, 'shape': " + npy_shape_repr(shape) + ", }";
  const std::size_t unpadded = npy_magic.size() + 2 + 2 + dict.size() + 1;  // + '\n'
  const std::size_t total = (unpadded + 63) / 64 * 64;
  dict.append(total - unpadded, ' ');
  dict += '\n';
  const std::size_t header_len = dict.size();
  if (header_len > 0xFFFF) throw std::length_error("npy: header too long for format 1.0");
  std::string out(npy_magic);
  out += '\x01';
  out += '\x00';
  out += static_cast<char>(header_len & 0xFFu);
  out += static_cast<char>((header_len >> 8) & 0xFFu);
  out += dict;
  return out;
}

/// Reverses the bytes of each 8-byte word in `bytes` (length a multiple of 8).
inline void npy_swap8(char* bytes, std::size_t words) {
  for (std::size_t w = 0; w < words; ++w) {
    char* p = bytes + 8 * w;
    for (int i = 0; i < 4; ++i) std::swap(p[i], p[7 - i]);
  }
}

/// Minimal parser for the Python-literal header dict of a .npy file.
class NpyHeaderParser {
 public:
  /// Parses `text` (the dict, without the trailing newline); `path` is for messages.
  NpyHeaderParser(std::string_view text, const std::string& path) : s_(text), path_(path) {}

  /// Parses the dict; sets descr, fortran_order and shape. Throws on malformed input.
  void parse() {
    skip_ws();
    expect('{');
    bool have_descr = false, have_order = false, have_shape = false;
    for (;;) {
      skip_ws();
      if (peek() == '}') {
        ++pos_;
        break;
      }
      const std::string key = parse_string();
      skip_ws();
      expect(':');
      skip_ws();
      if (key == "descr") {
        descr_ = parse_string();
        have_descr = true;
      } else if (key == "fortran_order") {
        fortran_order_ = parse_bool();
        have_order = true;
      } else if (key == "shape") {
        shape_ = parse_shape();
        have_shape = true;
      } else {
        fail("unexpected key '" + key + "'");
      }
      skip_ws();
      if (peek() == ',') {
        ++pos_;
      } else if (peek() != '}') {
        fail("expected ',' or '}'");
      }
    }
    skip_ws();
    if (pos_ != s_.size()) fail("trailing characters after header dict");
    if (!have_descr || !have_order || !have_shape) fail("header dict lacks a required key");
  }

  /// The 'descr' value, e.g. "<f8".
  const std::string& descr() const { return descr_; }
  /// The 'fortran_order' value.
  bool fortran_order() const { return fortran_order_; }
  /// The 'shape' value.
  const std::vector<std::size_t>& shape() const { return shape_; }

 private:
  [[noreturn]] void fail(const std::string& why) const {
    throw std::runtime_error("read_npy: malformed header in '" + path_ + "': " + why);
  }
  char peek() const { return pos_ < s_.size() ? s_[pos_] : '\0'; }
  void skip_ws() {
    while (pos_ < s_.size() && (s_[pos_] == ' ' || s_[pos_] == '\t')) ++pos_;
  }
  void expect(char c) {
    if (peek() != c) fail(std::string("expected '") + c + "'");
    ++pos_;
  }
  std::string parse_string() {
    const char q = peek();
    if (q != '\'' && q != '"') fail("expected a quoted string");
    ++pos_;
    const std::size_t end = s_.find(q, pos_);
    if (end == std::string_view::npos) fail("unterminated string");
    std::string out(s_.substr(pos_, end - pos_));
    pos_ = end + 1;
    return out;
  }
  bool parse_bool() {
    if (s_.substr(pos_, 4) == "True") {
      pos_ += 4;
      return true;
    }
    if (s_.substr(pos_, 5) == "False") {
      pos_ += 5;
      return false;
    }
    fail("expected True or False");
  }
  std::vector<std::size_t> parse_shape() {
    expect('(');
    std::vector<std::size_t> shape;
    for (;;) {
      skip_ws();
      if (peek() == ')') {
        ++pos_;
        break;
      }
      if (peek() < '0' || peek() > '9') fail("expected a non-negative integer in shape");
      std::size_t v = 0;
      while (peek() >= '0' && peek() <= '9') {
        const auto digit = static_cast<std::size_t>(peek() - '0');
        if (v > (std::numeric_limits<std::size_t>::max() - digit) / 10) fail("shape overflow");
        v = v * 10 + digit;
        ++pos_;
      }
      if (peek() == 'L') ++pos_;  // Python 2 long suffix
      shape.push_back(v);
      skip_ws();
      if (peek() == ',') {
        ++pos_;
      } else if (peek() != ')') {
        fail("expected ',' or ')' in shape");
      }
    }
    return shape;
  }

  std::string_view s_;
  const std::string& path_;
  std::size_t pos_ = 0;
  std::string descr_;
  bool fortran_order_ = false;
  std::vector<std::size_t> shape_;
};

}  // namespace detail

/// Writes a float64 array of `shape` (C order, last axis fastest) read from `data` to
/// `path` as .npy version 1.0, '<f8', atomically. A 0-d shape `{}` writes one value.
/// Throws std::runtime_error on I/O failure (message names `path`).
inline void write_npy(const std::string& path, const double* data,
                      const std::vector<std::size_t>& shape) {
  const std::size_t n = detail::npy_element_count(shape);
  if (n > 0 && data == nullptr) throw std::invalid_argument("write_npy: null data for " + path);
  const std::string header = detail::npy_header(shape);
  AtomicFile file(path);
  file.write(header);
  if constexpr (std::endian::native == std::endian::little) {
    if (n > 0) file.write(data, n * sizeof(double));
  } else {
    constexpr std::size_t chunk = 4096;
    std::vector<char> buf(chunk * 8);
    for (std::size_t i = 0; i < n; i += chunk) {
      const std::size_t m = std::min(chunk, n - i);
      std::memcpy(buf.data(), data + i, m * 8);
      detail::npy_swap8(buf.data(), m);
      file.write(buf.data(), m * 8);
    }
  }
  file.commit();
}

/// Creates `path` as a .npy file of `shape` (version 1.0, '<f8') whose values are written
/// later, in pieces, by `write_npy_part`: its header, and its full size (zeros). For the ranks
/// of a distributed run, each writing its own block (io/run_outputs.hpp). Throws
/// std::runtime_error naming `path`.
inline void create_npy(const std::string& path, const std::vector<std::size_t>& shape) {
  const std::string header = detail::npy_header(shape);
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error(detail::io_error_message(path, "create", errno));
  const auto bytes = static_cast<off_t>(header.size() + 8 * detail::npy_element_count(shape));
  const bool ok =
      ::pwrite(fd, header.data(), header.size(), 0) == static_cast<ssize_t>(header.size()) &&
      ::ftruncate(fd, bytes) == 0;
  const int err = errno;
  ::close(fd);
  if (!ok) throw std::runtime_error(detail::io_error_message(path, "write", err));
}

/// Writes the values [first, first + n) (flat C order) of the .npy file `path` of `shape`
/// that `create_npy` made; any process, in any order. Throws std::runtime_error naming it.
inline void write_npy_part(const std::string& path, const std::vector<std::size_t>& shape,
                           std::size_t first, const double* data, std::size_t n) {
  if (first + n > detail::npy_element_count(shape))
    throw std::invalid_argument("write_npy_part: past the end of " + path);
  const std::size_t header = detail::npy_header(shape).size();
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(detail::io_error_message(path, "open", errno));
  constexpr std::size_t chunk = std::size_t{1} << 16;
  std::vector<char> buf(chunk * 8);
  bool ok = true;
  for (std::size_t i = 0; i < n && ok; i += chunk) {
    const std::size_t m = std::min(chunk, n - i);
    std::memcpy(buf.data(), data + i, m * 8);
    if constexpr (std::endian::native != std::endian::little) detail::npy_swap8(buf.data(), m);
    const auto at = static_cast<off_t>(header + 8 * (first + i));
    std::size_t done = 0;
    while (done < m * 8 && ok) {
      const ssize_t w =
          ::pwrite(fd, buf.data() + done, m * 8 - done, at + static_cast<off_t>(done));
      if (w < 0 && errno == EINTR) continue;
      ok = w > 0;
      if (ok) done += static_cast<std::size_t>(w);
    }
  }
  const int err = errno;
  ::close(fd);
  if (!ok) throw std::runtime_error(detail::io_error_message(path, "write", err));
}

/// Convenience overload: checks `data.size()` against Π `shape`.
inline void write_npy(const std::string& path, const std::vector<double>& data,
                      const std::vector<std::size_t>& shape) {
  if (data.size() != detail::npy_element_count(shape))
    throw std::invalid_argument("write_npy: data size does not match shape for " + path);
  write_npy(path, data.data(), shape);
}

/// Reads a .npy file of float64 values in C order. Validates the magic, version, header
/// dict (descr '<f8' or '>f8', fortran_order False, shape) and that the file holds
/// exactly Π shape values; throws std::runtime_error otherwise (e.g. when truncated).
inline NpyArray read_npy(const std::string& path) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) {
    throw std::runtime_error("cannot read '" + path +
                             "': " + std::generic_category().message(errno));
  }
  std::string bytes;
  char buf[65536];
  for (;;) {
    const std::size_t got = std::fread(buf, 1, sizeof buf, f.get());
    bytes.append(buf, got);
    if (got < sizeof buf) break;
  }
  if (std::ferror(f.get())) throw std::runtime_error("cannot read '" + path + "': I/O error");

  const auto bad = [&](const std::string& why) {
    return std::runtime_error("read_npy: '" + path + "' " + why);
  };
  if (bytes.size() < 10 || std::string_view(bytes).substr(0, 6) != detail::npy_magic)
    throw bad("is not a .npy file (bad magic)");
  const auto byte = [&](std::size_t i) {
    return static_cast<std::size_t>(static_cast<unsigned char>(bytes[i]));
  };
  const std::size_t major = byte(6);
  std::size_t header_len = 0, prefix = 0;
  if (major == 1) {
    header_len = byte(8) | (byte(9) << 8);
    prefix = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) throw bad("is truncated (header)");
    header_len = byte(8) | (byte(9) << 8) | (byte(10) << 16) | (byte(11) << 24);
    prefix = 12;
  } else {
    throw bad("has unsupported format version " + std::to_string(major));
  }
  if (bytes.size() < prefix + header_len) throw bad("is truncated (header)");
  if (header_len == 0 || bytes[prefix + header_len - 1] != '\n')
    throw bad("has a header not terminated by a newline");
  std::string_view dict(bytes.data() + prefix, header_len - 1);
  while (!dict.empty() && (dict.back() == ' ' || dict.back() == '\0')) dict.remove_suffix(1);
  detail::NpyHeaderParser parser(dict, path);
  parser.parse();
  bool swap = false;
  if (parser.descr() == "<f8") {
    swap = std::endian::native != std::endian::little;
  } else if (parser.descr() == ">f8") {
    swap = std::endian::native != std::endian::big;
  } else {
    throw bad("has unsupported dtype '" + parser.descr() + "' (expected '<f8')");
  }
  if (parser.fortran_order()) throw bad("is in Fortran order (unsupported)");

  NpyArray out;
  out.shape = parser.shape();
  const std::size_t n = detail::npy_element_count(out.shape);
  const std::size_t data_bytes = bytes.size() - prefix - header_len;
  if (data_bytes < n * sizeof(double)) {
    throw bad("is truncated: expected " + std::to_string(n * sizeof(double)) +
              " data bytes, found " + std::to_string(data_bytes));
  }
  if (data_bytes > n * sizeof(double)) throw bad("has trailing bytes after the data");
  out.data.resize(n);
  if (n > 0) {
    std::memcpy(out.data.data(), bytes.data() + prefix + header_len, n * sizeof(double));
    if (swap) detail::npy_swap8(reinterpret_cast<char*>(out.data.data()), n);
  }
  return out;
}

}  // namespace hybgen::rt
