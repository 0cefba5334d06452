// Tests for the runtime's output writers: atomic files, .npy, PNG pictures, .vti.

#include <gtest/gtest.h>
#include <png.h>
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
#include "hybgen/rt/io/png.hpp"
#include "hybgen/rt/io/vti.hpp"

namespace fs = std::filesystem;
using namespace hybgen::rt;

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

std::string slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

bool same_bits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

/// A decoded RGB image.
struct Image {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;
  Rgb at(int x, int y) const {
    const std::size_t i = (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
                           static_cast<std::size_t>(x)) *
                          3;
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
};

/// Reads a PNG with libpng's simplified API as 8-bit RGB.
Image read_png(const std::string& p) {
  png_image im;
  std::memset(&im, 0, sizeof im);
  im.version = PNG_IMAGE_VERSION;
  if (png_image_begin_read_from_file(&im, p.c_str()) == 0)
    throw std::runtime_error(std::string("cannot read PNG: ") + im.message);
  im.format = PNG_FORMAT_RGB;
  Image out;
  out.width = static_cast<int>(im.width);
  out.height = static_cast<int>(im.height);
  out.rgb.assign(static_cast<std::size_t>(im.width) * im.height * 3, 0);
  if (png_image_finish_read(&im, nullptr, out.rgb.data(), 0, nullptr) == 0)
    throw std::runtime_error(std::string("cannot decode PNG: ") + im.message);
  return out;
}

bool is_dark(Rgb c) {
  return c.r < 100 && c.g < 100 && c.b < 100;
}
bool is_white(Rgb c) {
  return c.r == 255 && c.g == 255 && c.b == 255;
}
/// The bright (yellow) end of viridis.
bool is_viridis_bright(Rgb c) {
  return c.r > 180 && c.g > 180 && c.b < 120;
}
int colour_distance(Rgb a, Rgb b) {
  return std::abs(a.r - b.r) + std::abs(a.g - b.g) + std::abs(a.b - b.b);
}

/// Pixel at the centre of heat-map node (ix, iy) of an nx x ny grid.
std::pair<int, int> node_pixel(const PlotFrame& f, std::size_t ix, std::size_t iy, std::size_t nx,
                               std::size_t ny) {
  const int px =
      static_cast<int>((static_cast<double>(ix) + 0.5) * f.plot_w / static_cast<double>(nx));
  const int row_from_top = static_cast<int>((static_cast<double>(ny - 1 - iy) + 0.5) * f.plot_h /
                                            static_cast<double>(ny));
  return {f.plot_x + px, f.plot_y + row_from_top};
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

  const std::string bytes = slurp(file);
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
  const std::string good = slurp(p);

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
  std::string python;
  for (const char* candidate : {"/usr/bin/python3", "python3"})
    if (std::system((std::string(candidate) + " -c 'import numpy' >/dev/null 2>&1").c_str()) == 0) {
      python = candidate;
      break;
    }
  if (python.empty()) GTEST_SKIP() << "python3 with numpy not available";
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
  EXPECT_EQ(slurp(p), "second");
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
  EXPECT_EQ(slurp(p), "old contents");
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
  EXPECT_EQ(slurp(p), "previous");
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
  EXPECT_EQ(slurp(path("same")), "a");
  EXPECT_EQ(listing(), std::vector<std::string>{"same"});
}

// --------------------------------------------------------------------------- png

TEST_F(OutputTest, HeatmapOfGaussianWithNanAndMask) {
  const std::size_t nx = 75, ny = 60;
  std::vector<double> u(nx * ny);
  std::vector<std::uint8_t> outside(nx * ny, 0);
  for (std::size_t ix = 0; ix < nx; ++ix) {
    for (std::size_t iy = 0; iy < ny; ++iy) {
      const double x = -2.0 + 4.0 * static_cast<double>(ix) / (nx - 1);
      const double y = -1.0 + 2.0 * static_cast<double>(iy) / (ny - 1);
      u[ix * ny + iy] = std::exp(-(x * x + 4.0 * y * y));
      if (ix < 8 && iy < 8) outside[ix * ny + iy] = 1;
    }
  }
  u[60 * ny + 50] = std::numeric_limits<double>::quiet_NaN();
  u[61 * ny + 50] = std::numeric_limits<double>::infinity();
  const std::string p = path("heat.png");
  const PlotFrame f = write_heatmap_png(p, u.data(), nx, ny, "position x", -2.0, 2.0, "velocity v",
                                        -1.0, 1.0, "bouncing_ball  t = 9.800", outside.data());
  const Image im = read_png(p);
  EXPECT_EQ(im.width, f.width);
  EXPECT_EQ(im.height, f.height);
  EXPECT_GE(f.plot_w, 400);
  EXPECT_GE(f.plot_h, 400);
  EXPECT_GT(f.width, f.plot_x + f.plot_w + 60) << "room for the colour bar";
  EXPECT_LE(f.width, 900);
  EXPECT_LE(f.height, 700);

  const Rgb centre = im.at(f.plot_x + f.plot_w / 2, f.plot_y + f.plot_h / 2);
  EXPECT_TRUE(is_viridis_bright(centre))
      << int(centre.r) << "," << int(centre.g) << "," << int(centre.b);
  EXPECT_TRUE(is_white(im.at(0, 0)));
  EXPECT_TRUE(is_white(im.at(im.width - 1, im.height - 1)));

  const auto [nan_x, nan_y] = node_pixel(f, 60, 50, nx, ny);
  EXPECT_EQ(im.at(nan_x, nan_y), png_nonfinite_colour);
  const auto [inf_x, inf_y] = node_pixel(f, 61, 50, nx, ny);
  EXPECT_EQ(im.at(inf_x, inf_y), png_nonfinite_colour);
  const auto [out_x, out_y] = node_pixel(f, 3, 3, nx, ny);
  EXPECT_EQ(im.at(out_x, out_y), png_outside_colour);
  // Just inside the state space, far from the peak: the dark end of viridis.
  const auto [dark_x, dark_y] = node_pixel(f, 0, 30, nx, ny);
  EXPECT_LT(colour_distance(im.at(dark_x, dark_y), viridis(0.0)), 60);

  int dark_title = 0;
  for (int y = 0; y < f.plot_y - 8; ++y)
    for (int x = 0; x < im.width; ++x) dark_title += is_dark(im.at(x, y)) ? 1 : 0;
  EXPECT_GT(dark_title, 100) << "the title must be rendered";
  int dark_below = 0;  // tick labels and axis name
  for (int y = f.plot_y + f.plot_h + 2; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) dark_below += is_dark(im.at(x, y)) ? 1 : 0;
  EXPECT_GT(dark_below, 200);
  int dark_left = 0;  // y tick labels and rotated axis name
  for (int y = f.plot_y; y < f.plot_y + f.plot_h; ++y)
    for (int x = 0; x < f.plot_x - 2; ++x) dark_left += is_dark(im.at(x, y)) ? 1 : 0;
  EXPECT_GT(dark_left, 200);
  // The colour bar holds both ends of viridis.
  bool bar_bright = false, bar_dark = false;
  for (int y = f.plot_y; y < f.plot_y + f.plot_h; ++y)
    for (int x = f.plot_x + f.plot_w + 2; x < im.width; ++x) {
      bar_bright = bar_bright || im.at(x, y) == viridis(1.0);
      bar_dark = bar_dark || im.at(x, y) == viridis(0.0);
    }
  EXPECT_TRUE(bar_bright);
  EXPECT_TRUE(bar_dark);
}

TEST_F(OutputTest, HeatmapOrientationXRightYUp) {
  const std::size_t nx = 5, ny = 3;
  std::vector<double> by_x(nx * ny), by_y(nx * ny);
  for (std::size_t ix = 0; ix < nx; ++ix)
    for (std::size_t iy = 0; iy < ny; ++iy) {
      by_x[ix * ny + iy] = static_cast<double>(ix);
      by_y[ix * ny + iy] = static_cast<double>(iy);
    }
  const PlotFrame f = write_heatmap_png(path("x.png"), by_x.data(), nx, ny, "x", 0, 4, "y", 0, 2,
                                        "increasing in x");
  Image im = read_png(path("x.png"));
  const int mid_y = f.plot_y + f.plot_h / 2, mid_x = f.plot_x + f.plot_w / 2;
  EXPECT_EQ(im.at(f.plot_x + 2, mid_y), viridis(0.0));
  EXPECT_EQ(im.at(f.plot_x + f.plot_w - 3, mid_y), viridis(1.0));
  write_heatmap_png(path("y.png"), by_y.data(), nx, ny, "x", 0, 4, "y", 0, 2, "increasing in y");
  im = read_png(path("y.png"));
  EXPECT_EQ(im.at(mid_x, f.plot_y + f.plot_h - 3), viridis(0.0));
  EXPECT_EQ(im.at(mid_x, f.plot_y + 2), viridis(1.0));
}

TEST_F(OutputTest, HeatmapDegenerateFieldsRender) {
  const std::size_t nx = 4, ny = 4;
  std::vector<double> constant(nx * ny, 0.25), zeros(nx * ny, 0.0),
      nans(nx * ny, std::numeric_limits<double>::quiet_NaN());
  for (const auto* field : {&constant, &zeros, &nans}) {
    const PlotFrame f =
        write_heatmap_png(path("d.png"), field->data(), nx, ny, "a", 0, 1, "b", 0, 1, "degenerate");
    const Image im = read_png(path("d.png"));
    const Rgb c = im.at(f.plot_x + f.plot_w / 2, f.plot_y + f.plot_h / 2);
    EXPECT_EQ(c, field == &nans ? png_nonfinite_colour : viridis(0.5));
  }
  // A single node, a 1 x n grid, a huge range, unicode in labels.
  const double one = 3.0;
  write_heatmap_png(path("one.png"), &one, 1, 1, "a", 2, 2, "b", 0, 0, "single node");
  std::vector<double> row{1e-300, 1e300, -1e300};
  write_heatmap_png(path("row.png"), row.data(), 1, 3, "\xce\xb1 (alpha)", 0, 0, "b", -1e6, 1e6,
                    "t = 1.000e-07  \xe2\x9c\x93");
  EXPECT_EQ(read_png(path("row.png")).width > 0, true);
}

TEST_F(OutputTest, HeatmapRejectsBadArgumentsAndReportsIoErrors) {
  std::vector<double> u(6, 1.0);
  EXPECT_THROW(write_heatmap_png(path("a.png"), u.data(), 0, 6, "x", 0, 1, "y", 0, 1, "t"),
               std::invalid_argument);
  EXPECT_THROW(write_heatmap_png(path("a.png"), u.data(), 2, 3, "x", 1, 0, "y", 0, 1, "t"),
               std::invalid_argument);
  EXPECT_THROW(write_heatmap_png(path("a.png"), u.data(), 2, 3, "x", 0,
                                 std::numeric_limits<double>::quiet_NaN(), "y", 0, 1, "t"),
               std::invalid_argument);
  EXPECT_THROW(write_heatmap_png(path("a.png"), nullptr, 2, 3, "x", 0, 1, "y", 0, 1, "t"),
               std::invalid_argument);
  const std::string missing = path("nope/a.png");
  try {
    write_heatmap_png(missing, u.data(), 2, 3, "x", 0, 1, "y", 0, 1, "t");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
  EXPECT_TRUE(listing().empty());
}

TEST_F(OutputTest, LibpngErrorsBecomeExceptions) {
  const detail::Canvas empty(0, 0, Rgb{255, 255, 255});
  try {
    (void)detail::encode_png(empty, "zero-size");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind("libpng: ", 0), 0u) << msg;
    EXPECT_GT(msg.size(), 8u) << msg;
  }
  // The encoder still works afterwards.
  const detail::Canvas small(3, 2, Rgb{1, 2, 3});
  EXPECT_GT(detail::encode_png(small, "ok").size(), 8u);
}

TEST_F(OutputTest, FontRendersEveryPrintableCharacter) {
  std::string all;
  for (char c = 32; c < 127; ++c) all += c;
  detail::Canvas cv(detail::text_width(all, 1) + 4, 14, detail::white);
  detail::draw_text(cv, 2, 2, all, 1, detail::ink);
  for (std::size_t i = 1; i < all.size(); ++i) {  // every glyph but the space has ink
    int ink = 0;
    const int x0 = 2 + static_cast<int>(i) * detail::font_advance;
    for (int y = 0; y < cv.height(); ++y)
      for (int x = x0; x < x0 + detail::font_cols; ++x) ink += is_dark(cv.get(x, y)) ? 1 : 0;
    EXPECT_GT(ink, 0) << "glyph '" << all[i] << "'";
  }
  EXPECT_EQ(detail::sanitize_text("a\xc3\xa9z\n"), "a?z ");
  EXPECT_EQ(detail::fit_text("abcdefghij", detail::text_width("abcdef", 2), 2), "abc...");
}

TEST_F(OutputTest, TickLabelsUseNiceSteps) {
  const detail::Ticks t = detail::make_ticks(-0.13, 1.02, 0.2);
  EXPECT_EQ(t.labels, (std::vector<std::string>{"0.0", "0.2", "0.4", "0.6", "0.8", "1.0"}));
  const detail::Ticks s = detail::make_ticks(0.0, 1e-4, 2e-5);
  EXPECT_EQ(s.labels, (std::vector<std::string>{"0", "2e-5", "4e-5", "6e-5", "8e-5", "1e-4"}));
  EXPECT_DOUBLE_EQ(detail::nice_step_at_least(0.3), 0.5);
  EXPECT_DOUBLE_EQ(detail::nice_step_at_least(1.5), 2.0);
  EXPECT_DOUBLE_EQ(detail::nice_step_at_least(6.0), 10.0);
  EXPECT_EQ(detail::format_value(0.012345), "0.0123");
  EXPECT_EQ(detail::format_value(1.26e-11), "1.26e-11");
}

TEST_F(OutputTest, LinePlotRenders) {
  std::vector<double> x(101), y(101);
  for (std::size_t i = 0; i < x.size(); ++i) {
    x[i] = -1.0 + 0.02 * static_cast<double>(i);
    y[i] = std::exp(-8.0 * x[i] * x[i]);
  }
  y[30] = std::numeric_limits<double>::quiet_NaN();
  const std::string p = path("line.png");
  const PlotFrame f = write_lineplot_png(p, x, y, "position x", "density u", "diffusion  t = 1.0");
  const Image im = read_png(p);
  EXPECT_EQ(im.width, f.width);
  EXPECT_EQ(im.height, f.height);
  EXPECT_TRUE(is_white(im.at(0, 0)));
  int curve = 0;
  for (int yy = f.plot_y; yy < f.plot_y + f.plot_h; ++yy)
    for (int xx = f.plot_x; xx < f.plot_x + f.plot_w; ++xx)
      curve += colour_distance(im.at(xx, yy), detail::line_ink) < 30 ? 1 : 0;
  EXPECT_GT(curve, f.plot_w) << "the polyline must be drawn";
  // The peak (x = 0, y = 1) is near the top of the plot area, above the centre.
  bool peak = false;
  const int cx = f.plot_x + f.plot_w / 2;
  for (int yy = f.plot_y; yy < f.plot_y + f.plot_h / 6; ++yy)
    peak = peak || colour_distance(im.at(cx, yy), detail::line_ink) < 60;
  EXPECT_TRUE(peak);
  int dark_title = 0;
  for (int yy = 0; yy < f.plot_y - 8; ++yy)
    for (int xx = 0; xx < im.width; ++xx) dark_title += is_dark(im.at(xx, yy)) ? 1 : 0;
  EXPECT_GT(dark_title, 100);

  EXPECT_THROW(write_lineplot_png(p, x, std::vector<double>(3), "x", "y", "t"),
               std::invalid_argument);
  write_lineplot_png(path("empty.png"), {}, {}, "x", "y", "no points");
  const std::vector<double> one{2.0};
  write_lineplot_png(path("one.png"), one, one, "x", "y", "one point");
  EXPECT_GT(read_png(path("one.png")).width, 0);
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

  const std::vector<XmlElement> doc = parse_xml(slurp(p));
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
  EXPECT_NE(slurp(path("c.vti")).find("VTK x/y/z = x- -<&>, v1, v2"), std::string::npos);
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
