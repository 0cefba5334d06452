// The pictures (runtime/src/io/figures.cpp), read back as pixels with Cairo's PNG reader:
// orientation (x right, y up), one colour scale for the whole run (a frame at half the
// amplitude is darker, not re-stretched), the automatic log scale at a spike, guards drawn
// where the surface is and only in their mode's panels, nodes outside the support in grey,
// non-finite values in magenta, one panel per pair of axes and mode, a page per frame in
// the PDF; and the contour and scale functions on cases solved by hand.

#include <cairo.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/rt/io/colormap.hpp"
#include "hybgen/rt/io/figures.hpp"
// The drawing primitives are the io library's own (not installed); their axis ticks here.
#include "../../runtime/src/io/drawing.hpp"

namespace {

namespace fs = std::filesystem;
using namespace hybgen::rt;

struct Pixel {
  int r, g, b;
};

/// A PNG's pixels.
class Png {
 public:
  explicit Png(const std::string& path) : s_(cairo_image_surface_create_from_png(path.c_str())) {
    EXPECT_EQ(cairo_surface_status(s_), CAIRO_STATUS_SUCCESS) << path;
  }
  ~Png() { cairo_surface_destroy(s_); }
  Png(const Png&) = delete;
  Png& operator=(const Png&) = delete;
  int width() const { return cairo_image_surface_get_width(s_); }
  int height() const { return cairo_image_surface_get_height(s_); }
  Pixel at(double x, double y) const {
    const unsigned char* d = cairo_image_surface_get_data(s_);
    const int stride = cairo_image_surface_get_stride(s_);
    const auto v = *reinterpret_cast<const std::uint32_t*>(
        d + static_cast<std::ptrdiff_t>(y) * stride + 4 * static_cast<std::ptrdiff_t>(x));
    return {static_cast<int>((v >> 16) & 255), static_cast<int>((v >> 8) & 255),
            static_cast<int>(v & 255)};
  }

 private:
  cairo_surface_t* s_;
};

/// Brightness (viridis grows brighter from 0 to 1).
int brightness(Pixel p) {
  return p.r + p.g + p.b;
}

bool is_guard_colour(Pixel p) {
  return p.r > 180 && p.g < 140 && p.b < 110;
}

class Figures : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("hybgen_figures_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// A 2-D run on [0, 4] x [0, 2] (41 x 21 nodes), one mode, two frames: u = x in frame 0
  /// and x / 2 in frame 1; a guard s = x - 3.
  RunRecord ramp() {
    RunRecord r;
    r.model = "ramp";
    r.method = "characteristics";
    r.axis_names = {"x", "y"};
    r.axes = {{0, 4, 41}, {0, 2, 21}};
    r.mode_names = {"only"};
    r.times = {0, 1};
    r.frame_names = {"u_0000", "u_0001"};
    values_.assign(2 * 41 * 21, 0.0);
    std::vector<double> s(41 * 21);
    for (std::size_t i = 0; i < 41; ++i)
      for (std::size_t j = 0; j < 21; ++j) {
        const double x = 0.1 * static_cast<double>(i);
        values_[i * 21 + j] = x;
        values_[41 * 21 + i * 21 + j] = x / 2;
        s[i * 21 + j] = x - 3;
      }
    r.density = values_;
    r.guards.push_back(guard_field("wall", 0, s, r.axes, figure_pairs(2, {})));
    return r;
  }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
  std::vector<double> values_;
};

TEST_F(Figures, OrientationAndOneScaleForTheRun) {
  RunRecord run = ramp();
  FigureRequest req;
  write_figures(run, req, dir_.string());
  const FigureGeometry g = frame_geometry(run);
  ASSERT_EQ(g.panels.size(), 1u);
  const auto [px, py, pw, ph] = g.panels[0];
  const Png f0(path("u_0000.png")), f1(path("u_0001.png"));
  EXPECT_EQ(f0.width(), static_cast<int>(std::ceil(g.width)));
  // x grows to the right: bright at the right, dark at the left (u = x).
  const double mid_y = py + ph * 0.3;
  EXPECT_GT(brightness(f0.at(px + pw * 0.7, mid_y)), brightness(f0.at(px + pw * 0.1, mid_y)) + 100);
  // The same pixel at half the amplitude is darker: the scale is the run's, not the frame's.
  EXPECT_LT(brightness(f1.at(px + pw * 0.7, mid_y)), brightness(f0.at(px + pw * 0.7, mid_y)) - 60);
  // u = 0 at x = 0 is viridis(0) in both frames.
  const auto low = viridis_rgb(0.0);
  const Pixel left = f1.at(px + 2, mid_y);
  EXPECT_NEAR(left.r, low[0], 3);
  EXPECT_NEAR(left.g, low[1], 3);
  EXPECT_NEAR(left.b, low[2], 3);
}

TEST_F(Figures, TheGuardIsDrawnWhereItsSurfaceIs) {
  RunRecord run = ramp();
  FigureRequest req;
  write_figures(run, req, dir_.string());
  const auto [px, py, pw, ph] = frame_geometry(run).panels[0];
  const Png f(path("u_0000.png"));
  // x = 3 is node 30 of 41: its cell centre at (30.5 / 41) of the panel's width.
  const double gx = px + pw * 30.5 / 41;
  int on = 0, off = 0;
  for (double y = py + 5; y < py + ph - 5; y += 7) {
    on += is_guard_colour(f.at(gx, y)) ? 1 : 0;
    off += is_guard_colour(f.at(px + pw * 0.4, y)) ? 1 : 0;
  }
  EXPECT_GT(on, 25);
  EXPECT_EQ(off, 0);
}

TEST_F(Figures, OutsideIsGreyAndNotANumberIsMagenta) {
  RunRecord run = ramp();
  run.outside.assign(1, std::vector<std::uint8_t>(41 * 21, 0));
  for (std::size_t j = 0; j < 21; ++j) run.outside[0][0 * 21 + j] = run.outside[0][1 * 21 + j] = 1;
  values_[20 * 21 + 10] = std::numeric_limits<double>::quiet_NaN();
  run.guards.clear();
  FigureRequest req;
  write_figures(run, req, dir_.string());
  const auto [px, py, pw, ph] = frame_geometry(run).panels[0];
  const Png f(path("u_0000.png"));
  const Pixel grey = f.at(px + pw * 1.0 / 41, py + ph / 2);
  EXPECT_EQ(grey.r, grey.g);
  EXPECT_GT(grey.r, 200);
  // Node (20, 10): the cell at (20.5/41, 1 - 10.5/21) of the panel.
  const Pixel nan = f.at(px + pw * 20.5 / 41, py + ph * (1 - 10.5 / 21));
  EXPECT_GT(nan.r, 240);
  EXPECT_LT(nan.g, 20);
  EXPECT_GT(nan.b, 240);
}

TEST_F(Figures, PairsOfAxesAndModesAndAPagePerFrame) {
  // 4-D, two modes: 6 pairs x 2 modes = 12 panels; the PDF has one page per frame.
  RunRecord run;
  run.model = "four";
  run.method = "transfer";
  run.axis_names = {"a", "b", "c", "d"};
  run.axes = {{0, 1, 5}, {0, 1, 4}, {0, 1, 3}, {0, 1, 6}};
  run.mode_names = {"on", "off"};
  run.times = {0, 0.5, 1};
  run.frame_names = {"u_0000", "u_0001", "u_0002"};
  values_.assign(3 * 2 * 5 * 4 * 3 * 6, 1.0);
  run.density = values_;
  EXPECT_EQ(frame_geometry(run).panels.size(), 12u);
  run.figure_axes = {3, 0, 1};  // figure_axes=d+a+b: 3 pairs x 2 modes
  EXPECT_EQ(frame_geometry(run).panels.size(), 6u);
  run.figure_axes.clear();
  FigureRequest req;
  req.pdf = true;
  req.svg = true;
  write_figures(run, req, dir_.string());
  for (const char* f : {"u_0002.png", "u_0002.svg", "density.pdf"})
    EXPECT_TRUE(fs::exists(dir_ / f)) << f;
  std::ifstream in(dir_ / "density.pdf", std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string pdf = ss.str();
  EXPECT_EQ(pdf.rfind("%PDF", 0), 0u);
  std::size_t pages = 0;
  for (auto p = pdf.find("/Type /Page"); p != std::string::npos; p = pdf.find("/Type /Page", p + 1))
    pages += pdf.compare(p, 12, "/Type /Pages") == 0 ? 0 : 1;
  EXPECT_EQ(pages, 3u);
}

TEST_F(Figures, AMarginalGreysWhatNoNodeOfTheSupportProjectsOnto) {
  // 3-D: the marginal on (a, b) is masked where its first row of a is (the runner marks a plane
  // node when no grid node in the support projects onto it: runner.hpp, record_geometry); the
  // other pairs have no mask.
  RunRecord run;
  run.model = "three";
  run.method = "characteristics";
  run.axis_names = {"a", "b", "c"};
  run.axes = {{0, 1, 11}, {0, 1, 11}, {0, 1, 11}};
  run.mode_names = {"only"};
  run.times = {0};
  run.frame_names = {"u_0000"};
  values_.assign(11 * 11 * 11, 1.0);
  run.density = values_;
  run.outside.assign(3, {});
  run.outside[0].assign(11 * 11, 0);
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 11; ++j) run.outside[0][i * 11 + j] = 1;  // a ≤ 0.2
  FigureRequest req;
  write_figures(run, req, dir_.string());
  const FigureGeometry g = frame_geometry(run);
  ASSERT_EQ(g.panels.size(), 3u);
  const Png f(path("u_0000.png"));
  auto is_grey = [](Pixel p) { return p.r == p.g && p.g == p.b && p.r > 200; };
  // Panel (a, b): grey at a = 0.1, coloured at a = 0.7; panel (a, c): coloured at a = 0.1.
  const auto [px, py, pw, ph] = g.panels[0];
  EXPECT_TRUE(is_grey(f.at(px + pw * 1.5 / 11, py + ph / 2)));
  EXPECT_FALSE(is_grey(f.at(px + pw * 7.5 / 11, py + ph / 2)));
  const auto [qx, qy, qw, qh] = g.panels[1];
  EXPECT_FALSE(is_grey(f.at(qx + qw * 1.5 / 11, qy + qh / 2)));
}

TEST(Ticks, EveryAxisGetsAtLeastTwo) {
  using hybgen::rt::drawing::nice_ticks;
  // A narrow panel asks for two ticks; on [−1.5, 1.5] the step 2 left only 0 (the 4-D
  // marginals' y axis), so the next finer step, 1, is taken.
  EXPECT_EQ(nice_ticks(-1.5, 1.5, 2), (std::vector<double>{-1, 0, 1}));
  EXPECT_EQ(nice_ticks(0, 2, 2), (std::vector<double>{0, 1, 2}));
  EXPECT_EQ(nice_ticks(-2, 2, 3), (std::vector<double>{-2, 0, 2}));
  for (const double w : {0.3, 0.7, 1.5, 3.0, 7.0, 30.0})
    for (int n = 2; n <= 8; ++n) {
      const std::vector<double> t = nice_ticks(-w / 2, w / 2 + 0.01 * w, n);
      EXPECT_GE(t.size(), 2u) << w << " " << n;
      EXPECT_LE(t.size(), static_cast<std::size_t>(2 * n + 2)) << w << " " << n;
    }
}

/// Whether p is within `tol` of the colour (r, g, b) in every channel.
bool near_colour(Pixel p, int r, int g, int b, int tol = 40) {
  return std::abs(p.r - r) <= tol && std::abs(p.g - g) <= tol && std::abs(p.b - b) <= tol;
}

/// In the right quarter of `png` (the legend), the most pixels of colour (r, g, b) in one row,
/// and how many separate runs of that colour the row has (a dashed sample has several).
std::pair<int, int> legend_sample(const Png& png, int r, int g, int b) {
  int best = 0, runs = 0;
  for (int y = 0; y < png.height(); ++y) {
    int count = 0, row_runs = 0;
    bool in = false;
    for (int x = 3 * png.width() / 4; x < png.width(); ++x) {
      const bool hit = near_colour(png.at(x, y), r, g, b);
      count += hit ? 1 : 0;
      row_runs += hit && !in ? 1 : 0;
      in = hit;
    }
    if (count > best) best = count, runs = row_runs;
  }
  return {best, runs};
}

TEST_F(Figures, TheBudgetsLegendShowsEachLineAsDrawn) {
  // budget.png: the outflow (orange, solid) and what is unaccounted (a reddish purple, dashed)
  // are told apart in the legend by colour and by the dash, as on the plot.
  RunRecord run;
  run.model = "leak";
  run.method = "characteristics";
  run.axis_names = {"x"};
  run.axes = {{0, 1, 11}};
  run.mode_names = {"only"};
  run.times = {0, 1, 2};
  run.frame_names = {"u_0000", "u_0001", "u_0002"};
  values_.assign(3 * 11, 1.0);
  run.density = values_;
  run.budget.times = run.times;
  run.budget.mass0 = 1.0;
  run.budget.mass = {1.0, 0.8, 0.6};
  run.budget.outflow = {0.0, 0.2, 0.35};
  run.budget.atom = {0.0, 0.0, 0.0};
  FigureRequest req;
  write_figures(run, req, dir_.string());
  const Png png(path("budget.png"));
  const auto [outflow_px, outflow_runs] = legend_sample(png, 230, 158, 0);  // kCurve[1]
  const auto [defect_px, defect_runs] = legend_sample(png, 204, 120, 166);  // kCurve[4]
  EXPECT_GE(outflow_px, 15);
  EXPECT_EQ(outflow_runs, 1);  // solid
  EXPECT_GE(defect_px, 8);
  EXPECT_GE(defect_runs, 2);  // dashed
}

TEST_F(Figures, AOneDimensionalFrameMarksItsGuards) {
  // u on [0, 2] (41 nodes), a guard s = x − 1.3: a dashed vertical line in the guards'
  // colour where s changes sign, none elsewhere (the columns at x = 0.5 and 1.7 have none).
  RunRecord run;
  run.model = "line";
  run.method = "characteristics";
  run.axis_names = {"x"};
  run.axes = {{0, 2, 41}};
  run.mode_names = {"only"};
  run.times = {0};
  run.frame_names = {"u_0000"};
  values_.assign(41, 1.0);
  run.density = values_;
  std::vector<double> s(41);
  for (std::size_t i = 0; i < s.size(); ++i) s[i] = 0.05 * static_cast<double>(i) - 1.3;
  run.guards.push_back(guard_field("switch", 0, s, run.axes, figure_pairs(1, {})));
  FigureRequest req;
  write_figures(run, req, dir_.string());
  const Png png(path("u_0000.png"));
  // Columns by their guard-coloured pixels: the line is the column with the most, and it sits
  // 1.3/2 of the way along the plot's frame.
  int best_x = -1, best = 0, first = png.width(), last = -1;
  for (int x = 0; x < png.width(); ++x) {
    int count = 0;
    for (int y = 0; y < png.height(); ++y) count += is_guard_colour(png.at(x, y)) ? 1 : 0;
    if (count > best) best = count, best_x = x;
  }
  // The plot's frame: the row with the most dark pixels is an edge of it, spanning x's range.
  int edge_row = 0, edge_count = 0;
  for (int y = 0; y < png.height(); ++y) {
    int count = 0;
    for (int x = 0; x < png.width(); ++x) count += brightness(png.at(x, y)) < 200 ? 1 : 0;
    if (count > edge_count) edge_count = count, edge_row = y;
  }
  for (int x = 0; x < png.width(); ++x)
    if (brightness(png.at(x, edge_row)) < 200) first = std::min(first, x), last = std::max(last, x);
  ASSERT_GT(best, 40);  // dashed: most of a plot's height
  ASSERT_LT(first, last);
  EXPECT_NEAR(best_x, first + 0.65 * (last - first), 6);
}

TEST(ColourScale, LinearFromZeroAndLogAtASpike) {
  std::vector<double> v(1000, 1.0);
  v[3] = 2.0;
  const ColourScale lin = choose_colour_scale(v, "auto");
  EXPECT_FALSE(lin.log);
  EXPECT_EQ(lin.lo, 0.0);
  EXPECT_EQ(lin.hi, 2.0);
  EXPECT_DOUBLE_EQ(lin.unit(1.0), 0.5);
  EXPECT_EQ(lin.unit(-1.0), 0.0);
  EXPECT_EQ(lin.unit(std::numeric_limits<double>::quiet_NaN()), 0.0);
  v[7] = 341.0;  // one node at a Zeno point
  const ColourScale log = choose_colour_scale(v, "auto");
  EXPECT_TRUE(log.log);
  EXPECT_EQ(log.hi, 341.0);
  EXPECT_DOUBLE_EQ(log.lo, 341.0 * 1e-4);
  EXPECT_NEAR(log.unit(341.0 * 1e-2), 0.5, 1e-12);  // two of four decades
  EXPECT_FALSE(choose_colour_scale(v, "linear").log);
  EXPECT_TRUE(choose_colour_scale(std::vector<double>(10, 1.0), "log").log);
}

TEST(ZeroContour, ALineACircleAndAFace) {
  // s = i - 1.5 on 4 x 3 nodes: the vertical line i = 1.5, length 2.
  std::vector<double> s(4 * 3);
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t j = 0; j < 3; ++j) s[i * 3 + j] = static_cast<double>(i) - 1.5;
  double length = 0;
  for (const auto& e : zero_contour(s, 4, 3)) {
    EXPECT_DOUBLE_EQ(e[0], 1.5);
    EXPECT_DOUBLE_EQ(e[2], 1.5);
    length += std::hypot(e[2] - e[0], e[3] - e[1]);
  }
  EXPECT_DOUBLE_EQ(length, 2.0);
  // A circle of radius 3 about (5, 5): every end within 0.1 of the circle.
  std::vector<double> c(11 * 11);
  for (std::size_t i = 0; i < 11; ++i)
    for (std::size_t j = 0; j < 11; ++j)
      c[i * 11 + j] = std::hypot(static_cast<double>(i) - 5, static_cast<double>(j) - 5) - 3;
  const auto ring = zero_contour(c, 11, 11);
  EXPECT_GE(ring.size(), 16u);
  for (const auto& e : ring) {
    EXPECT_NEAR(std::hypot(e[0] - 5, e[1] - 5), 3, 0.1);
    EXPECT_NEAR(std::hypot(e[2] - 5, e[3] - 5), 3, 0.1);
  }
  // s = j - 2 on 3 x 3 nodes: zero on the top row and negative below: the face j = 2.
  std::vector<double> f(9);
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j) f[i * 3 + j] = static_cast<double>(j) - 2;
  double top = 0;
  for (const auto& e : zero_contour(f, 3, 3)) {
    EXPECT_EQ(e[1], 2.0);
    EXPECT_EQ(e[3], 2.0);
    top += std::fabs(e[2] - e[0]);
  }
  EXPECT_DOUBLE_EQ(top, 2.0);
}

}  // namespace
