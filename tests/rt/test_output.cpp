// Tests for the runtime's output writers: atomic files, .npy, .vti (pictures:
// test_figures.cpp).

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/io/atomic_file.hpp"
#include "hybgen/rt/io/npy.hpp"
#include "hybgen/rt/io/vti.hpp"
#include "support/files.hpp"
#include "support/python.hpp"

namespace fs = std::filesystem;
using namespace hybgen::rt;
using hybgen::testing::read_text;

namespace {

/// A fresh directory per test, removed afterwards.
class OutputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("hybgen_rt_output_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::vector<std::string> listing() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename());
    std::sort(names.begin(), names.end());
    return names;
  }

  fs::path dir_;
};

bool same_bits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

// ----------------------------------------------------------------------------- npy

void expect_npy_round_trip(const std::string& file, const std::vector<std::size_t>& shape,
                           const std::string& shape_repr) {
  std::size_t n = 1;
  for (auto e : shape) n *= e;
  std::vector<double> data(n);
  for (std::size_t i = 0; i < n; ++i) data[i] = std::sin(static_cast<double>(i) * 0.37) * 1e3;
  if (n > 2) data[1] = std::numeric_limits<double>::quiet_NaN();
  write_npy(file, data.data(), shape);

  const std::string bytes = read_text(file);
  ASSERT_GE(bytes.size(), 10u);
  EXPECT_EQ(bytes.substr(0, 6), std::string("\x93NUMPY", 6));
  EXPECT_EQ(bytes[6], '\x01');
  EXPECT_EQ(bytes[7], '\x00');
  const std::size_t header_len =
      static_cast<unsigned char>(bytes[8]) |
      (static_cast<std::size_t>(static_cast<unsigned char>(bytes[9])) << 8);
  EXPECT_EQ((10 + header_len) % 64, 0u) << "data must start at a multiple of 64";
  const std::string dict =
      "{'descr': '<f8', 'fortran_order': False, 'shape': " + shape_repr + ", }";
  const std::string header = bytes.substr(10, header_len);
  EXPECT_EQ(header.substr(0, dict.size()), dict);
  EXPECT_EQ(header.back(), '\n');
  EXPECT_EQ(header.find_first_not_of(' ', dict.size()), header_len - 1) << "padding is spaces";
  EXPECT_EQ(bytes.size(), 10 + header_len + 8 * n);
  if (n > 0) {  // raw little-endian float64 right after the header
    double first = 0.0;
    std::memcpy(&first, bytes.data() + 10 + header_len, sizeof first);
    EXPECT_TRUE(same_bits(first, data[0]));
  }

  const NpyArray back = read_npy(file);
  EXPECT_EQ(back.shape, shape);
  ASSERT_EQ(back.data.size(), n);
  for (std::size_t i = 0; i < n; ++i) EXPECT_TRUE(same_bits(back.data[i], data[i])) << i;
}

}  // namespace

TEST_F(OutputTest, NpyRoundTrip1D) {
  expect_npy_round_trip(path("a.npy"), {7}, "(7,)");
}
TEST_F(OutputTest, NpyRoundTrip2D) {
  expect_npy_round_trip(path("b.npy"), {3, 4}, "(3, 4)");
}
TEST_F(OutputTest, NpyRoundTrip3D) {
  expect_npy_round_trip(path("c.npy"), {2, 3, 5}, "(2, 3, 5)");
}
TEST_F(OutputTest, NpyRoundTripScalarAndEmpty) {
  expect_npy_round_trip(path("d.npy"), {}, "()");
  expect_npy_round_trip(path("e.npy"), {0, 3}, "(0, 3)");
}

TEST_F(OutputTest, NpyVectorOverloadChecksSize) {
  EXPECT_THROW(write_npy(path("x.npy"), std::vector<double>(5), {2, 3}), std::invalid_argument);
  write_npy(path("x.npy"), std::vector<double>(6, 1.5), {2, 3});
  EXPECT_EQ(read_npy(path("x.npy")).data, std::vector<double>(6, 1.5));
}

TEST_F(OutputTest, NpyReaderRejectsTruncatedAndMalformedFiles) {
  const std::string p = path("t.npy");
  std::vector<double> data(100, 2.0);
  write_npy(p, data.data(), {10, 10});
  const std::string good = read_text(p);

  fs::resize_file(p, good.size() - 3);  // truncated data
  EXPECT_THROW(
      {
        try {
          read_npy(p);
        } catch (const std::runtime_error& e) {
          EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
          throw;
        }
      },
      std::runtime_error);
  fs::resize_file(p, 40);  // truncated header
  EXPECT_THROW(read_npy(p), std::runtime_error);
  fs::resize_file(p, 5);  // not even the magic
  EXPECT_THROW(read_npy(p), std::runtime_error);

  const auto write_raw = [&](const std::string& s) {
    std::ofstream(p, std::ios::binary | std::ios::trunc) << s;
  };
  std::string bad = good;
  bad[1] = 'X';  // magic
  write_raw(bad);
  EXPECT_THROW(read_npy(p), std::runtime_error);
  bad = good;
  bad.replace(bad.find("<f8"), 3, "<f4");  // dtype
  write_raw(bad);
  EXPECT_THROW(read_npy(p), std::runtime_error);
  bad = good;
  bad.replace(bad.find("False"), 5, "True ");  // Fortran order
  write_raw(bad);
  EXPECT_THROW(read_npy(p), std::runtime_error);
  bad = good;
  bad.replace(bad.find("(10, 10)"), 8, "(10, 1x)");  // shape syntax
  write_raw(bad);
  EXPECT_THROW(read_npy(p), std::runtime_error);
  write_raw(good + "extra");  // trailing bytes
  EXPECT_THROW(read_npy(p), std::runtime_error);
  EXPECT_THROW(read_npy(path("missing.npy")), std::runtime_error);
  write_raw(good);
  EXPECT_EQ(read_npy(p).data, data);
}

// numpy is an independent reader of the format. scripts/setup.sh installs Debian's
// python3-numpy for /usr/bin/python3 (a python3 earlier on PATH may lack it).
TEST_F(OutputTest, NpyLoadsInNumpyIfAvailable) {
  const std::string python = hybgen::testing::python_with("numpy");
  HYBGEN_REQUIRE_PYTHON(python, "numpy");
  const std::string p = path("np.npy");
  std::vector<double> data(24);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<double>(i) * 0.5;
  write_npy(p, data.data(), {2, 3, 4});
  const std::string cmd = python + " -c \"import numpy as np; a = np.load('" + p +
                          "'); assert a.shape == (2, 3, 4) and a.dtype == np.float64; "
                          "assert a[1, 2, 3] == 11.5 and a.flags.c_contiguous\"";
  EXPECT_EQ(std::system(cmd.c_str()), 0);
}

// ------------------------------------------------------------------------ atomic

TEST_F(OutputTest, AtomicWriteReplacesFileAndLeavesNoTemporaries) {
  const std::string p = path("f.txt");
  write_file_atomic(p, "first");
  write_file_atomic(p, std::string_view("second"));
  EXPECT_EQ(read_text(p), "second");
  EXPECT_EQ(listing(), std::vector<std::string>{"f.txt"});
}

TEST_F(OutputTest, AtomicWriteIntoMissingDirectoryNamesThePath) {
  const std::string p = path("no_such_dir/u_0001.npy");
  try {
    const double v = 1.0;
    write_npy(p, &v, {1});
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("'" + p + "'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("No such file or directory"), std::string::npos) << msg;
  }
}

TEST_F(OutputTest, AbandonedAtomicFileKeepsPreviousContents) {
  const std::string p = path("keep.txt");
  write_file_atomic(p, "old contents");
  {
    AtomicFile f(p);
    f.write("new but never committed");
    EXPECT_TRUE(fs::exists(f.temp_path()));
    EXPECT_NE(f.temp_path().find(p + ".tmp." + std::to_string(::getpid()) + "."),
              std::string::npos);
  }
  EXPECT_EQ(read_text(p), "old contents");
  EXPECT_EQ(listing(), std::vector<std::string>{"keep.txt"});
}

TEST_F(OutputTest, FailedWriteThrowsAndKeepsPreviousFile) {
  // Simulate a full disk with a file-size limit: write() fails with EFBIG.
  const std::string p = path("u_0001.npy");
  write_file_atomic(p, "previous");
  rlimit old_limit{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  rlimit small = old_limit;
  small.rlim_cur = 4096;
  if (old_limit.rlim_max != RLIM_INFINITY && old_limit.rlim_max < small.rlim_cur)
    GTEST_SKIP() << "hard file-size limit too low";
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  std::string message;
  try {
    std::vector<double> big(8192, 3.0);
    write_npy(p, big.data(), {big.size()});
  } catch (const std::runtime_error& e) {
    message = e.what();
  }
  ::setrlimit(RLIMIT_FSIZE, &old_limit);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_NE(message.find("cannot write '" + p + "'"), std::string::npos) << message;
  EXPECT_NE(message.find("File too large"), std::string::npos) << message;
  EXPECT_EQ(read_text(p), "previous");
  EXPECT_EQ(listing(), std::vector<std::string>{"u_0001.npy"});
}

TEST_F(OutputTest, FailedRenameThrowsAndRemovesTemporary) {
  const std::string p = path("occupied");
  fs::create_directories(p + "/child");  // rename(file, non-empty dir) fails
  try {
    write_file_atomic(p, "data");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("'" + p + "'"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_directory(p + "/child"));
  EXPECT_EQ(listing(), std::vector<std::string>{"occupied"});
}

TEST_F(OutputTest, AtomicTemporariesAreUnique) {
  AtomicFile a(path("same"));
  AtomicFile b(path("same"));
  EXPECT_NE(a.temp_path(), b.temp_path());
  b.write("b");
  b.commit();
  a.write("a");
  a.commit();
  EXPECT_EQ(read_text(path("same")), "a");
  EXPECT_EQ(listing(), std::vector<std::string>{"same"});
}

// --------------------------------------------------------------------------- vti

namespace {

/// One element of a parsed XML document.
struct XmlElement {
  std::string name;
  std::map<std::string, std::string> attrs;
  std::string text;
  int depth = 0;
};

/// A strict little XML parser: throws unless the document is well-formed (one root,
/// matched tags, quoted unique attributes, no stray '<' or '&').
std::vector<XmlElement> parse_xml(const std::string& s) {
  std::vector<XmlElement> out;
  std::vector<std::size_t> open;
  std::size_t i = 0;
  int roots = 0;
  const auto fail = [&](const std::string& why) {
    throw std::runtime_error("XML: " + why + " at " + std::to_string(i));
  };
  const auto name_char = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == ':' ||
           c == '.';
  };
  const auto check_text = [&](const std::string& t) {
    if (t.find('<') != std::string::npos) fail("'<' in text");
    for (std::size_t a = t.find('&'); a != std::string::npos; a = t.find('&', a + 1)) {
      const std::size_t semi = t.find(';', a);
      const std::string ent = semi == std::string::npos ? "" : t.substr(a, semi - a + 1);
      if (ent != "&amp;" && ent != "&lt;" && ent != "&gt;" && ent != "&quot;" && ent != "&apos;")
        fail("bad entity");
    }
  };
  while (i < s.size()) {
    if (s[i] != '<') {
      const std::size_t next = s.find('<', i);
      const std::string text =
          s.substr(i, next == std::string::npos ? std::string::npos : next - i);
      check_text(text);
      if (open.empty() && text.find_first_not_of(" \t\r\n") != std::string::npos)
        fail("text outside the root");
      if (!open.empty()) out[open.back()].text += text;
      i = next == std::string::npos ? s.size() : next;
      continue;
    }
    if (s.compare(i, 5, "<?xml") == 0) {
      if (i != 0) fail("misplaced declaration");
      i = s.find("?>", i);
      if (i == std::string::npos) fail("unterminated declaration");
      i += 2;
    } else if (s.compare(i, 4, "<!--") == 0) {
      const std::size_t end = s.find("-->", i + 4);
      if (end == std::string::npos) fail("unterminated comment");
      if (s.substr(i + 4, end - i - 4).find("--") != std::string::npos) fail("'--' in comment");
      i = end + 3;
    } else if (s.compare(i, 2, "</") == 0) {
      std::size_t j = i + 2;
      while (j < s.size() && name_char(s[j])) ++j;
      const std::string name = s.substr(i + 2, j - i - 2);
      while (j < s.size() && std::isspace(static_cast<unsigned char>(s[j]))) ++j;
      if (j >= s.size() || s[j] != '>') fail("bad end tag");
      if (open.empty() || out[open.back()].name != name) fail("mismatched </" + name + ">");
      open.pop_back();
      i = j + 1;
    } else {
      std::size_t j = i + 1;
      while (j < s.size() && name_char(s[j])) ++j;
      XmlElement e;
      e.name = s.substr(i + 1, j - i - 1);
      if (e.name.empty()) fail("empty tag name");
      e.depth = static_cast<int>(open.size());
      bool self_closing = false;
      for (;;) {
        while (j < s.size() && std::isspace(static_cast<unsigned char>(s[j]))) ++j;
        if (j >= s.size()) fail("unterminated tag");
        if (s[j] == '>') {
          ++j;
          break;
        }
        if (s.compare(j, 2, "/>") == 0) {
          self_closing = true;
          j += 2;
          break;
        }
        std::size_t k = j;
        while (k < s.size() && name_char(s[k])) ++k;
        const std::string an = s.substr(j, k - j);
        if (an.empty() || k >= s.size() || s[k] != '=' || k + 1 >= s.size() || s[k + 1] != '"')
          fail("bad attribute");
        const std::size_t close = s.find('"', k + 2);
        if (close == std::string::npos) fail("unterminated attribute");
        const std::string value = s.substr(k + 2, close - k - 2);
        check_text(value);
        if (!e.attrs.emplace(an, value).second) fail("duplicate attribute");
        j = close + 1;
      }
      if (open.empty() && ++roots > 1) fail("several roots");
      out.push_back(e);
      if (!self_closing) open.push_back(out.size() - 1);
      i = j;
    }
  }
  if (!open.empty()) fail("unclosed <" + out[open.back()].name + ">");
  if (roots != 1) fail("no root element");
  return out;
}

const XmlElement& find_element(const std::vector<XmlElement>& doc, const std::string& name) {
  for (const auto& e : doc)
    if (e.name == name) return e;
  throw std::runtime_error("no element " + name);
}

std::vector<unsigned char> base64_decode(const std::string& in) {
  static const std::string alphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::vector<unsigned char> out;
  unsigned buffer = 0;
  int bits = 0;
  for (const char c : in) {
    if (std::isspace(static_cast<unsigned char>(c)) || c == '=') continue;
    const std::size_t v = alphabet.find(c);
    if (v == std::string::npos) throw std::runtime_error("bad base64");
    buffer = (buffer << 6) | static_cast<unsigned>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<unsigned char>((buffer >> bits) & 0xFFu));
    }
  }
  return out;
}

std::uint64_t le64(const unsigned char* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

/// Writes a vti of C-order index values and checks extents and VTK point order.
void check_vti(const std::string& p, const std::vector<std::size_t>& dims,
               const std::string& extent) {
  std::size_t n = 1;
  for (auto d : dims) n *= d;
  std::vector<double> data(n);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<double>(i);
  std::vector<double> origins, spacings;
  std::vector<std::string> names;
  for (std::size_t k = 0; k < dims.size(); ++k) {
    origins.push_back(-1.5 * static_cast<double>(k + 1));
    spacings.push_back(0.25 * static_cast<double>(k + 1));
    names.push_back(k == 0 ? "x--<&>" : "v" + std::to_string(k));
  }
  write_vti(p, data.data(), dims, origins, spacings, names, "density u&\"1\"");

  const std::vector<XmlElement> doc = parse_xml(read_text(p));
  const XmlElement& root = find_element(doc, "VTKFile");
  EXPECT_EQ(root.depth, 0);
  EXPECT_EQ(root.attrs.at("type"), "ImageData");
  EXPECT_EQ(root.attrs.at("byte_order"), "LittleEndian");
  EXPECT_EQ(root.attrs.at("header_type"), "UInt64");
  const XmlElement& image = find_element(doc, "ImageData");
  EXPECT_EQ(image.attrs.at("WholeExtent"), extent);
  EXPECT_EQ(find_element(doc, "Piece").attrs.at("Extent"), extent);
  std::string origin = "-1.5", spacing = "0.25";
  if (dims.size() >= 2) origin += " -3", spacing += " 0.5";
  if (dims.size() >= 3) origin += " -4.5", spacing += " 0.75";
  for (std::size_t k = dims.size(); k < 3; ++k) origin += " 0", spacing += " 1";
  EXPECT_EQ(image.attrs.at("Origin"), origin);
  EXPECT_EQ(image.attrs.at("Spacing"), spacing);
  const XmlElement& array = find_element(doc, "DataArray");
  EXPECT_EQ(array.attrs.at("type"), "Float64");
  EXPECT_EQ(array.attrs.at("Name"), "density u&amp;&quot;1&quot;");
  EXPECT_EQ(array.attrs.at("format"), "binary");
  EXPECT_EQ(find_element(doc, "PointData").attrs.at("Scalars"), array.attrs.at("Name"));

  const std::vector<unsigned char> raw = base64_decode(array.text);
  ASSERT_EQ(raw.size(), 8 + 8 * n);
  EXPECT_EQ(le64(raw.data()), 8 * n);
  std::size_t d[3] = {1, 1, 1};
  for (std::size_t k = 0; k < dims.size(); ++k) d[k] = dims[k];
  std::size_t pos = 0;
  for (std::size_t k = 0; k < d[2]; ++k)
    for (std::size_t j = 0; j < d[1]; ++j)
      for (std::size_t i = 0; i < d[0]; ++i, ++pos) {
        const double v = std::bit_cast<double>(le64(raw.data() + 8 + 8 * pos));
        EXPECT_EQ(v, static_cast<double>((i * d[1] + j) * d[2] + k)) << i << "," << j << "," << k;
      }
}

}  // namespace

TEST_F(OutputTest, VtiIsWellFormedWithExtentsAndTransposedValues) {
  check_vti(path("a.vti"), {5}, "0 4 0 0 0 0");
  check_vti(path("b.vti"), {3, 2}, "0 2 0 1 0 0");
  check_vti(path("c.vti"), {2, 3, 4}, "0 1 0 2 0 3");
  EXPECT_NE(read_text(path("c.vti")).find("VTK x/y/z = x- -<&>, v1, v2"), std::string::npos);
}

TEST_F(OutputTest, VtiRejectsBadArguments) {
  std::vector<double> u(16, 1.0);
  EXPECT_THROW(
      write_vti(path("a.vti"), u.data(), {2, 2, 2, 2}, {0, 0, 0, 0}, {1, 1, 1, 1}, {}, "u"),
      std::invalid_argument);
  EXPECT_THROW(write_vti(path("a.vti"), u.data(), {4, 4}, {0, 0}, {1, 0}, {}, "u"),
               std::invalid_argument);
  EXPECT_THROW(write_vti(path("a.vti"), u.data(), {4, 4}, {0}, {1, 1}, {}, "u"),
               std::invalid_argument);
  EXPECT_THROW(write_vti(path("a.vti"), u.data(), {4, 4}, {0, 0}, {1, 1}, {"x"}, "u"),
               std::invalid_argument);
  EXPECT_TRUE(listing().empty());
}
