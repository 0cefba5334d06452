// The run's pictures with Cairo (hybgen/rt/io/figures.hpp states what they show).
//
// Size: about 650 lines; one concept (a figure of a run) in its drawing primitives (ticks,
// axes, heat maps, colour bars, curves), its layouts (frames, budget, spectrum) and its
// surfaces (PNG, PDF, SVG). Splitting the primitives from the layouts would only move
// the Cairo context around.

#include "hybgen/rt/io/figures.hpp"

#include <cairo-pdf.h>
#include <cairo-svg.h>
#include <cairo.h>
#include <fontconfig/fontconfig.h>
#include <omp.h>
#include <png.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/io/animation.hpp"
#include "hybgen/rt/io/colormap.hpp"

namespace hybgen::rt {

namespace {

// ------------------------------------------------------------------ numbers on axes

/// Tick values at a 1-2-5 step over [lo, hi], at most about `max_count`.
std::vector<double> nice_ticks(double lo, double hi, int max_count) {
  const double span = hi - lo;
  if (!(span > 0) || !std::isfinite(span)) return {lo};
  const double raw = span / std::max(max_count, 2);
  const double base = std::pow(10.0, std::floor(std::log10(raw)));
  double step = 10 * base;
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * base >= raw * (1 - 1e-9)) {
      step = m * base;
      break;
    }
  std::vector<double> t;
  for (double k = std::ceil(lo / step - 1e-9); k * step <= hi + step * 1e-9 && t.size() < 40; ++k)
    t.push_back(std::fabs(k * step) < step * 1e-9 ? 0.0 : k * step);
  return t;
}

/// A tick label: short, exact enough for its neighbours (%g with 4 digits, compact
/// exponents).
std::string tick_label(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4g", v);
  std::string s = b;
  const std::size_t e = s.find('e');
  if (e != std::string::npos) {  // 1e-05 -> 1e-5, 2e+03 -> 2e3
    std::string exp = s.substr(e + 1);
    const bool neg = exp[0] == '-';
    if (exp[0] == '-' || exp[0] == '+') exp.erase(0, 1);
    while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
    s = s.substr(0, e) + "e" + (neg ? "-" : "") + exp;
  }
  return s;
}

// ------------------------------------------------------------------ drawing primitives

struct Rect {
  double x, y, w, h;
};

struct Rgb {
  double r, g, b;
};

constexpr Rgb kInk{0.12, 0.12, 0.12};
constexpr Rgb kGrid{0.55, 0.55, 0.55};
constexpr Rgb kOutside{0.85, 0.85, 0.85};
constexpr Rgb kGuard{0.93, 0.33, 0.18};  // orange-red: visible on viridis
/// Curves: the mode curves and the budget's terms (Okabe–Ito colours, colour-blind safe).
constexpr std::array<Rgb, 7> kCurve{{{0.0, 0.45, 0.70},
                                     {0.90, 0.62, 0.0},
                                     {0.0, 0.62, 0.45},
                                     {0.80, 0.40, 0.0},
                                     {0.80, 0.47, 0.65},
                                     {0.34, 0.71, 0.91},
                                     {0.94, 0.89, 0.26}}};

void set_colour(cairo_t* cr, Rgb c, double alpha = 1.0) {
  cairo_set_source_rgba(cr, c.r, c.g, c.b, alpha);
}

void set_font(cairo_t* cr, double size, bool bold = false) {
  cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL,
                         bold ? CAIRO_FONT_WEIGHT_BOLD : CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, size);
}

double text_width(cairo_t* cr, const std::string& s) {
  cairo_text_extents_t e;
  cairo_text_extents(cr, s.c_str(), &e);
  return e.x_advance;
}

/// Text at (x, y) (the baseline), aligned by `align`: 0 left, 0.5 centre, 1 right; shrunk
/// to `max_width` when given and wider.
void text(cairo_t* cr, double x, double y, const std::string& s, double align = 0,
          double max_width = 0) {
  double w = text_width(cr, s);
  cairo_save(cr);
  if (max_width > 0 && w > max_width) {
    cairo_font_extents_t fe;
    cairo_font_extents(cr, &fe);
    cairo_matrix_t m;
    cairo_get_font_matrix(cr, &m);
    cairo_set_font_size(cr, m.xx * max_width / w);
    w = max_width;
  }
  cairo_move_to(cr, x - align * w, y);
  cairo_show_text(cr, s.c_str());
  cairo_restore(cr);
}

/// Text rotated a quarter turn counter-clockwise, centred on (x, y) along its length.
void text_up(cairo_t* cr, double x, double y, const std::string& s) {
  cairo_save(cr);
  cairo_translate(cr, x, y);
  cairo_rotate(cr, -M_PI / 2);
  text(cr, 0, 0, s, 0.5);
  cairo_restore(cr);
}

/// An axis box with ticks and labels: x over [x0, x1] horizontally, y over [y0, y1]
/// upward, inside `r`.
void draw_axes(cairo_t* cr, const Rect& r, double x0, double x1, double y0, double y1,
               const std::string& x_name, const std::string& y_name) {
  set_colour(cr, kInk);
  cairo_set_line_width(cr, 1.0);
  cairo_rectangle(cr, r.x, r.y, r.w, r.h);
  cairo_stroke(cr);
  set_font(cr, 10);
  for (const double v : nice_ticks(x0, x1, std::max(2, static_cast<int>(r.w / 70)))) {
    const double px = r.x + (v - x0) / (x1 - x0) * r.w;
    cairo_move_to(cr, px, r.y + r.h);
    cairo_line_to(cr, px, r.y + r.h + 4);
    cairo_stroke(cr);
    text(cr, px, r.y + r.h + 15, tick_label(v), 0.5);
  }
  double widest = 0;
  for (const double v : nice_ticks(y0, y1, std::max(2, static_cast<int>(r.h / 45)))) {
    const double py = r.y + r.h - (v - y0) / (y1 - y0) * r.h;
    cairo_move_to(cr, r.x - 4, py);
    cairo_line_to(cr, r.x, py);
    cairo_stroke(cr);
    const std::string l = tick_label(v);
    widest = std::max(widest, text_width(cr, l));
    text(cr, r.x - 6, py + 3.5, l, 1);
  }
  set_font(cr, 12);
  text(cr, r.x + r.w / 2, r.y + r.h + 32, x_name, 0.5, r.w);
  text_up(cr, r.x - 14 - widest, r.y + r.h / 2, y_name);
}

/// Colour of the unit value t (viridis).
Rgb colour_at(double t) {
  const auto c = viridis_rgb(t);
  return {c[0] / 255.0, c[1] / 255.0, c[2] / 255.0};
}

/// A vertical colour bar in `r` for `scale`, labelled `label`.
void draw_colour_bar(cairo_t* cr, const Rect& r, const ColourScale& scale,
                     const std::string& label) {
  cairo_pattern_t* g = cairo_pattern_create_linear(0, r.y + r.h, 0, r.y);
  for (int i = 0; i <= 32; ++i) {
    const Rgb c = colour_at(i / 32.0);
    cairo_pattern_add_color_stop_rgb(g, i / 32.0, c.r, c.g, c.b);
  }
  cairo_rectangle(cr, r.x, r.y, r.w, r.h);
  cairo_set_source(cr, g);
  cairo_fill(cr);
  cairo_pattern_destroy(g);
  set_colour(cr, kInk);
  cairo_set_line_width(cr, 1.0);
  cairo_rectangle(cr, r.x, r.y, r.w, r.h);
  cairo_stroke(cr);
  set_font(cr, 10);
  const double a = scale.log ? std::log10(scale.lo) : scale.lo;
  const double b = scale.log ? std::log10(scale.hi) : scale.hi;
  double widest = 0;
  for (const double v : nice_ticks(a, b, 6)) {
    const double py = r.y + r.h - (v - a) / (b - a) * r.h;
    cairo_move_to(cr, r.x + r.w, py);
    cairo_line_to(cr, r.x + r.w + 4, py);
    cairo_stroke(cr);
    const std::string l = scale.log ? "1e" + tick_label(v) : tick_label(v);
    widest = std::max(widest, text_width(cr, l));
    text(cr, r.x + r.w + 6, py + 3.5, l);
  }
  set_font(cr, 11);
  cairo_save(cr);
  cairo_translate(cr, r.x + r.w + 16 + widest, r.y + r.h / 2);
  cairo_rotate(cr, M_PI / 2);
  text(cr, 0, 0, label, 0.5);
  cairo_restore(cr);
}

// ------------------------------------------------------------------ panels of a frame

/// One axis of a panel.
struct PanelAxis {
  std::string name;
  GridAxis grid;
};

/// A heat-map panel: data[ix * ny + iy] at node (ix, iy).
struct HeatPanel {
  std::string title;
  PanelAxis x, y;
  std::vector<double> data;
  std::vector<std::uint8_t> outside;  ///< Same layout; may be empty.
  /// Guard contours, in node-index coordinates, with the guard's name.
  std::vector<std::pair<std::string, std::vector<std::array<double, 4>>>> guards;
  std::size_t scale = 0;  ///< Index of its colour scale (its column).
};

/// The node extent of an axis: half a cell beyond both ends (each node is painted as the
/// cell centred on it).
std::pair<double, double> extent(const GridAxis& a) {
  const double h = (a.max - a.min) / std::max(a.n - 1, 1);
  return {a.min - h / 2, a.max + h / 2};
}

void draw_heat_panel(cairo_t* cr, const Rect& r, const HeatPanel& p, const ColourScale& scale) {
  const auto nx = static_cast<std::size_t>(p.x.grid.n), ny = static_cast<std::size_t>(p.y.grid.n);
  // The cells as an image, one pixel per node, scaled without smoothing.
  cairo_surface_t* img =
      cairo_image_surface_create(CAIRO_FORMAT_RGB24, static_cast<int>(nx), static_cast<int>(ny));
  cairo_surface_flush(img);
  unsigned char* px = cairo_image_surface_get_data(img);
  const int stride = cairo_image_surface_get_stride(img);
  for (std::size_t ix = 0; ix < nx; ++ix)
    for (std::size_t iy = 0; iy < ny; ++iy) {
      const std::size_t i = ix * ny + iy;
      Rgb c;
      if (!p.outside.empty() && p.outside[i])
        c = kOutside;
      else if (!std::isfinite(p.data[i]))
        c = {1.0, 0.0, 1.0};  // magenta: not a number
      else
        c = colour_at(scale.unit(p.data[i]));
      auto* q =
          reinterpret_cast<std::uint32_t*>(px + static_cast<std::size_t>(stride) * (ny - 1 - iy)) +
          ix;
      *q = (static_cast<std::uint32_t>(c.r * 255 + 0.5) << 16) |
           (static_cast<std::uint32_t>(c.g * 255 + 0.5) << 8) |
           static_cast<std::uint32_t>(c.b * 255 + 0.5);
    }
  cairo_surface_mark_dirty(img);
  cairo_save(cr);
  cairo_rectangle(cr, r.x, r.y, r.w, r.h);
  cairo_clip(cr);
  cairo_translate(cr, r.x, r.y);
  cairo_scale(cr, r.w / static_cast<double>(nx), r.h / static_cast<double>(ny));
  cairo_set_source_surface(cr, img, 0, 0);
  cairo_pattern_set_filter(cairo_get_source(cr), CAIRO_FILTER_NEAREST);
  cairo_paint(cr);
  cairo_restore(cr);
  cairo_surface_destroy(img);

  // Guards: node (i, j) is the centre of cell (i, j).
  const auto to_px = [&](double i, double j) {
    return std::pair{r.x + (i + 0.5) / static_cast<double>(nx) * r.w,
                     r.y + r.h - (j + 0.5) / static_cast<double>(ny) * r.h};
  };
  cairo_save(cr);
  cairo_rectangle(cr, r.x, r.y, r.w, r.h);
  cairo_clip(cr);
  set_colour(cr, kGuard);
  cairo_set_line_width(cr, 2.0);
  cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);
  for (const auto& [name, segments] : p.guards)
    for (const auto& s : segments) {
      const auto [ax, ay] = to_px(s[0], s[1]);
      const auto [bx, by] = to_px(s[2], s[3]);
      cairo_move_to(cr, ax, ay);
      cairo_line_to(cr, bx, by);
    }
  cairo_stroke(cr);
  cairo_restore(cr);

  const auto [x0, x1] = extent(p.x.grid);
  const auto [y0, y1] = extent(p.y.grid);
  draw_axes(cr, r, x0, x1, y0, y1, p.x.name, p.y.name);
  set_font(cr, 12, true);
  set_colour(cr, kInk);
  text(cr, r.x + r.w / 2, r.y - 8, p.title, 0.5, r.w);
}

/// A curve of a line plot.
struct Curve {
  std::string label;
  std::vector<double> y;
  Rgb colour;
  double width = 1.6;
  std::vector<double> band;  ///< ± this around y, shaded (may be empty).
  bool dashed = false;
};

/// A plain curve (no band, solid).
Curve curve(std::string label, std::vector<double> y, Rgb colour, double width = 1.6) {
  return Curve{std::move(label), std::move(y), colour, width, {}, false};
}

/// Curves over `x` in `r`, with a legend to the right of `r` (kLegend wide) when several
/// are labelled.
void draw_curves(cairo_t* cr, const Rect& r, const std::vector<double>& x,
                 const std::vector<Curve>& curves, const std::string& x_name,
                 const std::string& y_name, double y_lo_floor = 0) {
  double lo = y_lo_floor, hi = y_lo_floor;
  for (const Curve& c : curves)
    for (std::size_t i = 0; i < c.y.size(); ++i) {
      const double e = c.band.empty() ? 0 : c.band[i];
      if (std::isfinite(c.y[i])) lo = std::min(lo, c.y[i] - e), hi = std::max(hi, c.y[i] + e);
    }
  if (!(hi > lo)) hi = lo + 1;
  const double pad = 0.05 * (hi - lo);
  hi += pad;
  if (lo < y_lo_floor) lo -= pad;
  const double x0 = x.front(), x1 = x.size() > 1 ? x.back() : x.front() + 1;
  const auto X = [&](double v) { return r.x + (v - x0) / (x1 - x0) * r.w; };
  const auto Y = [&](double v) { return r.y + r.h - (v - lo) / (hi - lo) * r.h; };
  cairo_save(cr);
  cairo_rectangle(cr, r.x, r.y, r.w, r.h);
  cairo_clip(cr);
  for (const Curve& c : curves) {
    if (c.width <= 0) continue;  // sets the range only
    cairo_new_path(cr);          // no segment from a text's current point
    if (!c.band.empty()) {
      for (std::size_t i = 0; i < x.size(); ++i) cairo_line_to(cr, X(x[i]), Y(c.y[i] + c.band[i]));
      for (std::size_t i = x.size(); i-- > 0;) cairo_line_to(cr, X(x[i]), Y(c.y[i] - c.band[i]));
      cairo_close_path(cr);
      set_colour(cr, c.colour, 0.22);
      cairo_fill(cr);
    }
    cairo_new_path(cr);
    for (std::size_t i = 0; i < x.size(); ++i) cairo_line_to(cr, X(x[i]), Y(c.y[i]));
    set_colour(cr, c.colour);
    cairo_set_line_width(cr, c.width);
    const double dash[] = {6.0, 4.0};
    cairo_set_dash(cr, dash, c.dashed ? 2 : 0, 0);
    cairo_stroke(cr);
    cairo_set_dash(cr, dash, 0, 0);
  }
  cairo_restore(cr);
  draw_axes(cr, r, x0, x1, lo, hi, x_name, y_name);
  std::vector<const Curve*> legend;
  for (const Curve& c : curves)
    if (!c.label.empty()) legend.push_back(&c);
  if (legend.size() > 1) {
    set_font(cr, 11);
    double w = 0;
    for (const Curve* c : legend) w = std::max(w, text_width(cr, c->label));
    const double lx = r.x + r.w + 16, ly = r.y + 4;  // beside the plot: never over a curve
    for (std::size_t i = 0; i < legend.size(); ++i) {
      const double y = ly + 16.0 * static_cast<double>(i) + 9;
      set_colour(cr, legend[i]->colour);
      cairo_set_line_width(cr, legend[i]->width);
      cairo_move_to(cr, lx, y - 4);
      cairo_line_to(cr, lx + 24, y - 4);
      cairo_stroke(cr);
      set_colour(cr, kInk);
      text(cr, lx + 30, y, legend[i]->label);
    }
  }
}

// ------------------------------------------------------------------ a run's panels

/// Trapezoid weights of an axis.
std::vector<double> weights(const GridAxis& a) {
  return trapezoid_rule(a).weights;
}

/// The marginal of u (C order over `axes`) on the pair (a, b), integrating the others.
std::vector<double> pair_marginal(std::span<const double> u, const std::vector<GridAxis>& axes,
                                  std::size_t a, std::size_t b) {
  const std::size_t N = axes.size();
  std::vector<std::vector<double>> w(N);
  for (std::size_t k = 0; k < N; ++k)
    if (k != a && k != b) w[k] = weights(axes[k]);
  const auto na = static_cast<std::size_t>(axes[a].n), nb = static_cast<std::size_t>(axes[b].n);
  std::vector<double> out(na * nb, 0.0);
  std::vector<std::size_t> idx(N, 0);
  for (std::size_t i = 0; i < u.size(); ++i) {
    std::size_t rem = i;
    for (std::size_t k = N; k-- > 0;) {
      idx[k] = rem % static_cast<std::size_t>(axes[k].n);
      rem /= static_cast<std::size_t>(axes[k].n);
    }
    double weight = 1;
    for (std::size_t k = 0; k < N; ++k)
      if (k != a && k != b) weight *= w[k][idx[k]];
    out[idx[a] * nb + idx[b]] += weight * u[i];
  }
  return out;
}

/// The guard's s on the pair plane (a, b) when it does not depend on the other axes
/// (within 1e-9 of its range), else empty.
std::vector<double> guard_on_pair(const std::vector<double>& s, const std::vector<GridAxis>& axes,
                                  std::size_t a, std::size_t b) {
  const std::size_t N = axes.size();
  const auto na = static_cast<std::size_t>(axes[a].n), nb = static_cast<std::size_t>(axes[b].n);
  std::vector<double> plane(na * nb, std::numeric_limits<double>::quiet_NaN());
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const double v : s) lo = std::min(lo, v), hi = std::max(hi, v);
  const double tol = 1e-9 * std::max(1.0, hi - lo);
  std::vector<std::size_t> idx(N, 0);
  for (std::size_t i = 0; i < s.size(); ++i) {
    std::size_t rem = i;
    for (std::size_t k = N; k-- > 0;) {
      idx[k] = rem % static_cast<std::size_t>(axes[k].n);
      rem /= static_cast<std::size_t>(axes[k].n);
    }
    double& p = plane[idx[a] * nb + idx[b]];
    if (std::isnan(p))
      p = s[i];
    else if (std::fabs(p - s[i]) > tol)
      return {};
  }
  return plane;
}

/// The pairs of axes the panels show: every pair of the chosen axes (figure_axes, in the
/// order given; every axis by default). 2-D: the one pair (x, y).
std::vector<std::pair<std::size_t, std::size_t>> axis_pairs(const RunRecord& run) {
  std::vector<std::size_t> axes = run.figure_axes;
  if (axes.size() < 2 || run.axes.size() == 2) {
    axes.clear();
    for (std::size_t a = 0; a < run.axes.size(); ++a) axes.push_back(a);
  }
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < axes.size(); ++i)
    for (std::size_t j = i + 1; j < axes.size(); ++j) pairs.emplace_back(axes[i], axes[j]);
  return pairs;
}

/// Every heat panel of frame k (2-D and more): per mode in 2-D (the sum with one mode);
/// per pair of axes in 3-D and more, in rows by mode when there are several.
std::vector<HeatPanel> frame_panels(const RunRecord& run, std::size_t k) {
  const std::size_t N = run.axes.size(), M = run.n_mode();
  const std::vector<std::pair<std::size_t, std::size_t>> pairs = axis_pairs(run);
  std::vector<HeatPanel> out;
  const std::vector<double> total = run.total_density(k);
  // Rows: the modes (several), or the sum.
  const std::size_t rows = M > 1 ? M : 1;
  for (std::size_t row = 0; row < rows; ++row) {
    const std::span<const double> u =
        M > 1 ? run.mode_density(k, row) : std::span<const double>(total);
    for (std::size_t c = 0; c < pairs.size(); ++c) {
      const auto [a, b] = pairs[c];
      HeatPanel p;
      p.x = {run.axis_names[a], run.axes[a]};
      p.y = {run.axis_names[b], run.axes[b]};
      p.data = N == 2 ? std::vector<double>(u.begin(), u.end()) : pair_marginal(u, run.axes, a, b);
      if (N == 2) p.outside = run.outside;
      p.title = M > 1 ? "mode " + run.mode_names[row] : std::string();
      if (N > 2)
        p.title += std::string(p.title.empty() ? "" : ": ") + "marginal on (" + run.axis_names[a] +
                   ", " + run.axis_names[b] + ")";
      for (const GuardField& g : run.guards) {
        // With several modes, a guard is drawn in the panels of the mode it fires from.
        if (M > 1 && g.from >= 0 && static_cast<std::size_t>(g.from) != row) continue;
        const std::vector<double> s = N == 2 ? g.values : guard_on_pair(g.values, run.axes, a, b);
        if (!s.empty())
          p.guards.emplace_back(g.name, zero_contour(s, static_cast<std::size_t>(run.axes[a].n),
                                                     static_cast<std::size_t>(run.axes[b].n)));
      }
      p.scale = c;
      out.push_back(std::move(p));
    }
  }
  return out;
}

/// t with three decimals.
std::string fixed3(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f", v);
  return b;
}

/// The figure title of frame k.
std::string frame_title(const RunRecord& run, std::size_t k) {
  return run.model + "  ·  " +
         (run.times.empty() ? std::string("invariant density of the transfer operator")
                            : run.method + "  ·  t = " + fixed3(run.times[k]));
}

// Layout of a frame figure, in points (1 px in PNG).
constexpr double kLegend = 150;
constexpr double kPanel = 250, kGapX = 90, kGapY = 70, kLeft = 70, kTop = 76, kBottom = 50,
                 kBar = 16, kBarSpace = 80;

struct FrameLayout {
  std::size_t cols = 1, rows = 1;
  double width = 0, height = 0, panel = kPanel;
};

FrameLayout frame_layout(std::size_t panels, std::size_t columns) {
  FrameLayout l;
  l.cols = std::max<std::size_t>(1, std::min(panels, columns));
  l.rows = (panels + l.cols - 1) / l.cols;
  if (panels == 1) l.panel = 360;
  l.width = kLeft + static_cast<double>(l.cols) * (l.panel + kGapX + kBarSpace) - kGapX + 20;
  l.height = kTop + static_cast<double>(l.rows) * (l.panel + kGapY) - kGapY + kBottom;
  return l;
}

/// Everything the frames of a run share: their panels' scales and the layout.
struct FramePlan {
  std::vector<std::vector<HeatPanel>> panels;  ///< Per frame (2-D and more).
  std::vector<ColourScale> scales;             ///< Per column.
  std::size_t columns = 1;
  FrameLayout layout;
  double line_max = 0;  ///< 1-D: the largest value over the run.
};

FramePlan plan_frames(const RunRecord& run, const std::string& scale_mode) {
  FramePlan plan;
  const std::size_t N = run.axes.size(), K = run.n_frame();
  if (N == 1) {
    for (double v : run.density)
      if (std::isfinite(v)) plan.line_max = std::max(plan.line_max, v);
    plan.layout.width = 620 + kLegend, plan.layout.height = 440;
    return plan;
  }
  plan.panels.resize(K);
#pragma omp parallel for schedule(dynamic)
  for (std::size_t k = 0; k < K; ++k) plan.panels[k] = frame_panels(run, k);
  const std::size_t pairs = axis_pairs(run).size();
  plan.columns = run.n_mode() > 1 ? pairs : std::min<std::size_t>(pairs, 3);
  if (N == 2 && run.n_mode() > 1) plan.columns = std::min<std::size_t>(run.n_mode(), 3);
  // One scale per pair (column of a row), over every frame and mode.
  plan.scales.resize(pairs);
  for (std::size_t c = 0; c < pairs; ++c) {
    std::vector<double> values;
    for (const auto& frame : plan.panels)
      for (const HeatPanel& p : frame)
        if (p.scale == c) values.insert(values.end(), p.data.begin(), p.data.end());
    plan.scales[c] = choose_colour_scale(values, scale_mode);
  }
  plan.layout = frame_layout(plan.panels.empty() ? 1 : plan.panels.front().size(), plan.columns);
  return plan;
}

void draw_title(cairo_t* cr, double width, const std::string& title) {
  set_colour(cr, kInk);
  set_font(cr, 15, true);
  text(cr, width / 2, 26, title, 0.5, width - 20);
}

/// Panel i's rectangle in a frame figure.
Rect panel_rect(const FrameLayout& l, std::size_t i) {
  const double col = static_cast<double>(i % l.cols), row = static_cast<double>(i / l.cols);
  return {kLeft + col * (l.panel + kGapX + kBarSpace), kTop + row * (l.panel + kGapY), l.panel,
          l.panel};
}

/// Frame k of the run, on a surface of the plan's size.
void draw_frame(cairo_t* cr, const RunRecord& run, const FramePlan& plan, std::size_t k) {
  const FrameLayout& l = plan.layout;
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  draw_title(cr, l.width, frame_title(run, k));
  if (run.axes.size() == 1) {
    std::vector<double> x(static_cast<std::size_t>(run.axes[0].n));
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = axis_node(run.axes[0], static_cast<int>(i));
    std::vector<Curve> curves;
    if (run.n_mode() > 1)
      for (std::size_t m = 0; m < run.n_mode(); ++m) {
        const auto u = run.mode_density(k, m);
        curves.push_back(
            curve("mode " + run.mode_names[m], {u.begin(), u.end()}, kCurve[m % kCurve.size()]));
      }
    curves.push_back(curve(run.n_mode() > 1 ? "sum" : "u", run.total_density(k), kInk, 2.0));
    // An invisible curve at the run's maximum fixes the vertical range: frames compare.
    std::vector<Curve> with_range = curves;
    with_range.insert(with_range.begin(),
                      curve("", std::vector<double>(x.size(), plan.line_max), {1, 1, 1}, 0.0));
    const Rect r{kLeft + 10, kTop, l.width - kLeft - 30 - kLegend, l.height - kTop - kBottom - 10};
    draw_curves(cr, r, x, with_range, run.axis_names[0], "density u");
    return;
  }
  const std::vector<HeatPanel>& panels = plan.panels[k];
  for (std::size_t i = 0; i < panels.size(); ++i) {
    const Rect r = panel_rect(l, i);
    const ColourScale& s = plan.scales[panels[i].scale];
    draw_heat_panel(cr, r, panels[i], s);
    const std::string label = std::string(s.log ? "log scale: " : "") +
                              (run.axes.size() > 2 ? "marginal density" : "density u");
    draw_colour_bar(cr, {r.x + r.w + 12, r.y, kBar, r.h}, s, label);
  }
  // The guards' legend (names), under the title.
  std::vector<std::string> shown;
  for (const HeatPanel& p : panels)
    for (const auto& g : p.guards)
      if (!g.second.empty() && std::find(shown.begin(), shown.end(), g.first) == shown.end())
        shown.push_back(g.first);
  if (!shown.empty()) {
    std::string names;
    for (const auto& n : shown) names += (names.empty() ? "" : ", ") + n;
    set_font(cr, 11);
    set_colour(cr, kGuard);
    cairo_set_line_width(cr, 2.0);
    cairo_move_to(cr, kLeft, 42);
    cairo_line_to(cr, kLeft + 22, 42);
    cairo_stroke(cr);
    set_colour(cr, kInk);
    text(cr, kLeft + 28, 46, "guard" + std::string(shown.size() > 1 ? "s " : " ") + names);
  }
}

/// The mass budget over time.
void draw_budget(cairo_t* cr, const RunRecord& run, double width, double height) {
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  draw_title(cr, width, run.model + "  ·  mass budget (" + run.method + ")");
  const MassBudget& b = run.budget;
  const std::size_t K = run.times.size();
  auto band = [&](const std::vector<double>& e) {
    return e.size() == K ? e : std::vector<double>();
  };
  std::vector<Curve> curves{
      {"mass in the box", b.mass, kCurve[0], 2.0, band(b.mass_error)},
      {"outflow", b.outflow, kCurve[1], 2.0, band(b.outflow_error)},
      {"atom (Zeno)", b.atom, kCurve[2], 2.0,
       band(run.atom_error.size() == K ? run.atom_error : b.atom_error)},
      {"unaccounted", budget_defect(b), kCurve[3], 1.6, band(budget_defect_error(b)), true}};
  draw_curves(cr, {kLeft + 10, kTop, width - kLeft - 30 - kLegend, height - kTop - kBottom - 10},
              run.times, curves, "t", "mass");
}

/// Eigenvalues of the transfer operator in the complex plane, with the unit circle.
void draw_spectrum(cairo_t* cr, const RunRecord& run, double width, double height) {
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  draw_title(cr, width, run.model + "  ·  eigenvalues of the transfer operator");
  const Rect r{kLeft + 10, kTop, height - kTop - kBottom - 10, height - kTop - kBottom - 10};
  const auto X = [&](double v) { return r.x + (v + 1.1) / 2.2 * r.w; };
  const auto Y = [&](double v) { return r.y + r.h - (v + 1.1) / 2.2 * r.h; };
  set_colour(cr, kGrid);
  cairo_set_line_width(cr, 1.0);
  cairo_new_path(cr);  // no segment from the title's current point
  cairo_arc(cr, X(0), Y(0), r.w / 2.2, 0, 2 * M_PI);
  cairo_stroke(cr);
  const nlohmann::json& ev = run.summary["invariant"]["eigenvalues"];
  for (std::size_t i = 0; i < ev.size(); ++i) {
    set_colour(cr, i == 0 ? kGuard : kCurve[0]);
    cairo_new_path(cr);
    cairo_arc(cr, X(ev[i]["re"].get<double>()), Y(ev[i]["im"].get<double>()), i == 0 ? 5 : 4, 0,
              2 * M_PI);
    cairo_fill(cr);
  }
  draw_axes(cr, r, -1.1, 1.1, -1.1, 1.1, "Re λ", "Im λ");
  set_font(cr, 12);
  set_colour(cr, kInk);
  const auto& inv = run.summary["invariant"];
  const double x = r.x + r.w + 30;
  text(cr, x, r.y + 20, "spectral gap " + tick_label(inv.value("spectral_gap", 0.0)));
  text(cr, x, r.y + 40,
       "decay rate " + tick_label(inv.value("decay_rate", 0.0)) + " per unit time");
  for (std::size_t i = 0; i < ev.size() && i < 12; ++i)
    text(cr, x, r.y + 70 + 17.0 * static_cast<double>(i),
         "|λ" + std::to_string(i + 1) + "| = " + tick_label(ev[i]["abs"].get<double>()));
}

// ------------------------------------------------------------------ surfaces

void check_surface(cairo_surface_t* s, const std::string& path) {
  const cairo_status_t st = cairo_surface_status(s);
  if (st != CAIRO_STATUS_SUCCESS)
    throw std::runtime_error("cannot write '" + path + "': " + cairo_status_to_string(st));
}

/// Writes `r` to `path` as an 8-bit RGB PNG, fast: one filter (Up: the heat maps' rows
/// repeat) and zlib level 1. Cairo's own writer (libpng's adaptive filters at level 6) spent
/// 70 % of a run's output time encoding the frames (perf, bench/outputs.sh).
void write_png(const std::string& path, const Raster& r) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("cannot write '" + path + "': " + std::strerror(errno));
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  std::vector<unsigned char> row(static_cast<std::size_t>(r.width) * 3);
  bool ok = png && info;
  if (ok && setjmp(png_jmpbuf(png))) ok = false;  // libpng's errors land here
  if (ok) {
    png_init_io(png, f);
    png_set_IHDR(png, info, static_cast<png_uint_32>(r.width), static_cast<png_uint_32>(r.height),
                 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_UP);
    png_set_compression_level(png, 1);
    png_write_info(png, info);
    for (int y = 0; y < r.height; ++y) {
      for (int x = 0; x < r.width; ++x) {
        const std::uint32_t p =
            r.pixel[static_cast<std::size_t>(y) * static_cast<std::size_t>(r.width) +
                    static_cast<std::size_t>(x)];
        row[3 * static_cast<std::size_t>(x)] = static_cast<unsigned char>((p >> 16) & 255);
        row[3 * static_cast<std::size_t>(x) + 1] = static_cast<unsigned char>((p >> 8) & 255);
        row[3 * static_cast<std::size_t>(x) + 2] = static_cast<unsigned char>(p & 255);
      }
      png_write_row(png, row.data());
    }
    png_write_end(png, nullptr);
  }
  png_destroy_write_struct(png ? &png : nullptr, info ? &info : nullptr);
  const bool closed = std::fclose(f) == 0;
  if (!ok || !closed) {
    const int err = errno;
    std::remove(path.c_str());
    throw std::runtime_error("cannot write '" + path +
                             "': " + (closed ? std::string("libpng failed") : std::strerror(err)));
  }
}

/// Draw with `draw` on a raster of size (w, h), copy its pixels to `raster`, and write it
/// to `path` as PNG when `path` is not empty.
void to_png(const std::string& path, double w, double h, const std::function<void(cairo_t*)>& draw,
            Raster& raster) {
  cairo_surface_t* s = cairo_image_surface_create(
      CAIRO_FORMAT_RGB24, static_cast<int>(std::ceil(w)), static_cast<int>(std::ceil(h)));
  cairo_t* cr = cairo_create(s);
  draw(cr);
  cairo_destroy(cr);
  cairo_surface_flush(s);
  raster.width = cairo_image_surface_get_width(s);
  raster.height = cairo_image_surface_get_height(s);
  const int stride = cairo_image_surface_get_stride(s);
  const unsigned char* d = cairo_image_surface_get_data(s);
  raster.pixel.resize(static_cast<std::size_t>(raster.width) *
                      static_cast<std::size_t>(raster.height));
  for (int y = 0; y < raster.height; ++y)
    std::memcpy(&raster.pixel[static_cast<std::size_t>(y) * static_cast<std::size_t>(raster.width)],
                d + static_cast<std::ptrdiff_t>(y) * stride,
                4 * static_cast<std::size_t>(raster.width));
  const cairo_status_t st = cairo_surface_status(s);
  cairo_surface_destroy(s);
  if (st != CAIRO_STATUS_SUCCESS)
    throw std::runtime_error("cannot draw '" + path + "': " + cairo_status_to_string(st));
  if (!path.empty()) write_png(path, raster);
}

/// Draw `pages` pages with `draw(cr, page)` into a PDF at `path`.
void to_pdf(const std::string& path, double w, double h, std::size_t pages,
            const std::function<void(cairo_t*, std::size_t)>& draw) {
  cairo_surface_t* s = cairo_pdf_surface_create(path.c_str(), w, h);
  check_surface(s, path);
  cairo_pdf_surface_set_metadata(s, CAIRO_PDF_METADATA_CREATOR, "hybgen");
  cairo_t* cr = cairo_create(s);
  for (std::size_t p = 0; p < pages; ++p) {
    draw(cr, p);
    cairo_show_page(cr);
  }
  cairo_destroy(cr);
  cairo_surface_finish(s);
  const cairo_status_t st = cairo_surface_status(s);
  cairo_surface_destroy(s);
  if (st != CAIRO_STATUS_SUCCESS)
    throw std::runtime_error("cannot write '" + path + "': " + cairo_status_to_string(st));
}

}  // namespace

double ColourScale::unit(double v) const {
  if (!(v == v)) return 0;
  if (log) {
    if (!(v > lo)) return 0;
    return std::min(1.0, std::log10(v / lo) / std::log10(hi / lo));
  }
  return std::clamp((v - lo) / (hi - lo), 0.0, 1.0);
}

ColourScale choose_colour_scale(const std::vector<double>& values, const std::string& mode) {
  std::vector<double> positive;
  for (const double v : values)
    if (std::isfinite(v) && v > 0) positive.push_back(v);
  ColourScale s;
  if (positive.empty()) return s;  // all zero: [0, 1]
  const auto p99 = positive.begin() +
                   static_cast<std::ptrdiff_t>(0.99 * static_cast<double>(positive.size() - 1));
  std::nth_element(positive.begin(), p99, positive.end());
  const double q = *p99, top = *std::max_element(positive.begin(), positive.end());
  s.hi = top;
  s.log = mode == "log" || (mode == "auto" && top > 100 * q);
  s.lo = s.log ? top * 1e-4 : 0.0;
  return s;
}

std::vector<std::array<double, 4>> zero_contour(const std::vector<double>& s, std::size_t nx,
                                                std::size_t ny) {
  std::vector<std::array<double, 4>> out;
  if (nx < 2 || ny < 2) return out;
  const auto at = [&](std::size_t i, std::size_t j) { return s[i * ny + j]; };
  // The crossing on the edge from corner a (value va) to b (vb).
  const auto cross = [](double ax, double ay, double va, double bx, double by, double vb) {
    const double t = va / (va - vb);
    return std::array<double, 2>{ax + t * (bx - ax), ay + t * (by - ay)};
  };
  for (std::size_t i = 0; i + 1 < nx; ++i)
    for (std::size_t j = 0; j + 1 < ny; ++j) {
      const double x = static_cast<double>(i), y = static_cast<double>(j);
      const double v00 = at(i, j), v10 = at(i + 1, j), v11 = at(i + 1, j + 1), v01 = at(i, j + 1);
      if (!(std::isfinite(v00) && std::isfinite(v10) && std::isfinite(v11) && std::isfinite(v01)))
        continue;
      // Edges in order: bottom (00-10), right (10-11), top (11-01), left (01-00).
      std::vector<std::array<double, 2>> pts;
      const auto edge = [&](double ax, double ay, double va, double bx, double by, double vb) {
        // s ≤ 0 against s > 0: a surface through nodes (s = 0 exactly, as a guard on the
        // box's face) is drawn through them.
        if ((va <= 0) != (vb <= 0)) pts.push_back(cross(ax, ay, va, bx, by, vb));
      };
      // An edge whose ends are both on the surface (s = 0 exactly, as on a face of the box)
      // is part of it; the rule below sees no crossing there when the rest is s ≤ 0.
      if (v00 == 0 && v10 == 0) out.push_back({x, y, x + 1, y});
      if (v00 == 0 && v01 == 0) out.push_back({x, y, x, y + 1});
      if (i + 2 == nx && v10 == 0 && v11 == 0) out.push_back({x + 1, y, x + 1, y + 1});
      if (j + 2 == ny && v01 == 0 && v11 == 0) out.push_back({x, y + 1, x + 1, y + 1});
      edge(x, y, v00, x + 1, y, v10);
      edge(x + 1, y, v10, x + 1, y + 1, v11);
      edge(x + 1, y + 1, v11, x, y + 1, v01);
      edge(x, y + 1, v01, x, y, v00);
      if (pts.size() == 2) {
        out.push_back({pts[0][0], pts[0][1], pts[1][0], pts[1][1]});
      } else if (pts.size() == 4) {
        // A saddle: pair the crossings so that the centre's side is kept connected.
        const bool centre_neg = (v00 + v10 + v11 + v01) / 4 <= 0;
        const bool a_neg = v00 <= 0;
        if (centre_neg == a_neg) {
          out.push_back({pts[0][0], pts[0][1], pts[1][0], pts[1][1]});
          out.push_back({pts[2][0], pts[2][1], pts[3][0], pts[3][1]});
        } else {
          out.push_back({pts[0][0], pts[0][1], pts[3][0], pts[3][1]});
          out.push_back({pts[1][0], pts[1][1], pts[2][0], pts[2][1]});
        }
      }
    }
  return out;
}

FigureGeometry frame_geometry(const RunRecord& run) {
  const FramePlan plan = plan_frames(run, "linear");
  FigureGeometry g{plan.layout.width, plan.layout.height, {}};
  if (!plan.panels.empty())
    for (std::size_t i = 0; i < plan.panels.front().size(); ++i) {
      const Rect r = panel_rect(plan.layout, i);
      g.panels.push_back({r.x, r.y, r.w, r.h});
    }
  return g;
}

void write_figures(const RunRecord& run, FigureRequest& request, const std::string& dir) {
#if defined(__SANITIZE_ADDRESS__)
  // Under AddressSanitizer (CI's hardening stage), free Cairo's and fontconfig's caches at
  // exit: LeakSanitizer otherwise reports the fonts fontconfig loaded for the text, which
  // Cairo keeps for the life of the process, as leaks of every program that draws.
  static const int registered = std::atexit([] {
    cairo_debug_reset_static_data();
    FcFini();
  });
  (void)registered;
#endif
  const std::filesystem::path out(dir);
  const FramePlan plan = plan_frames(run, request.scale);
  const double W = plan.layout.width, H = plan.layout.height;
  const std::size_t K = run.n_frame();
  // Per-frame files in parallel (each its own surface); the first error wins.
  std::mutex m;
  std::exception_ptr error;
  const auto guarded = [&](const std::function<void()>& f) {
    try {
      f();
    } catch (...) {
      const std::lock_guard<std::mutex> lock(m);
      if (!error) error = std::current_exception();
    }
  };
  // The animation keeps every frame in its palette (a time series only).
  const bool gif = request.gif && K > 1;
  std::vector<IndexedFrame> indexed(gif ? K : 0);
#pragma omp parallel for schedule(dynamic)
  for (std::size_t k = 0; k < K; ++k) {
    const std::string base = run.frame_names[k];
    if (request.png || gif)
      guarded([&] {
        Raster raster;
        to_png(
            request.png ? (out / (base + ".png")).string() : std::string(), W, H,
            [&](cairo_t* cr) { draw_frame(cr, run, plan, k); }, raster);
        if (gif) indexed[k] = quantize(raster);
      });
    if (request.svg)
      guarded([&] {
        const std::string path = (out / (base + ".svg")).string();
        cairo_surface_t* s = cairo_svg_surface_create(path.c_str(), W, H);
        check_surface(s, path);
        cairo_t* cr = cairo_create(s);
        draw_frame(cr, run, plan, k);
        cairo_destroy(cr);
        cairo_surface_finish(s);
        const cairo_status_t st = cairo_surface_status(s);
        cairo_surface_destroy(s);
        if (st != CAIRO_STATUS_SUCCESS)
          throw std::runtime_error("cannot write '" + path + "': " + cairo_status_to_string(st));
      });
  }
  if (error) std::rethrow_exception(error);
  // The animation and the PDF side by side (each is one sequential stream).
  const std::string stem = run.times.empty() ? "invariant" : "density";
#pragma omp parallel sections
  {
#pragma omp section
    if (gif)
      guarded([&] {
        // About six seconds a loop, between 4 and 50 hundredths of a second a frame.
        const int delay = std::clamp(static_cast<int>(600 / K), 4, 50);
        write_gif((out / "animation.gif").string(), indexed, delay);
      });
#pragma omp section
    if (request.pdf)
      guarded([&] {
        to_pdf((out / (stem + ".pdf")).string(), W, H, K,
               [&](cairo_t* cr, std::size_t k) { draw_frame(cr, run, plan, k); });
      });
  }
  if (error) std::rethrow_exception(error);
  if (gif) request.out.push_back("animation.gif");
  for (std::size_t k = 0; k < K; ++k) {
    if (request.png) request.out.push_back(run.frame_names[k] + ".png");
    if (request.svg) request.out.push_back(run.frame_names[k] + ".svg");
  }
  if (request.pdf) request.out.push_back(stem + ".pdf");
  // The budget and the spectrum, in each format asked for.
  const bool budget = !run.times.empty() && run.budget.mass.size() == run.times.size();
  const bool spectrum = run.summary.is_object() && run.summary.contains("invariant");
  for (const auto& [name, wanted] :
       {std::pair{std::string("budget"), budget}, std::pair{std::string("spectrum"), spectrum}}) {
    if (!wanted) continue;
    const double w = 760, h = 480;
    const auto draw = [&](cairo_t* cr) {
      if (name == "budget")
        draw_budget(cr, run, w, h);
      else
        draw_spectrum(cr, run, w, h);
    };
    if (request.png) {
      Raster raster;
      to_png((out / (name + ".png")).string(), w, h, draw, raster);
      request.out.push_back(name + ".png");
    }
    if (request.pdf) {
      to_pdf((out / (name + ".pdf")).string(), w, h, 1,
             [&](cairo_t* cr, std::size_t) { draw(cr); });
      request.out.push_back(name + ".pdf");
    }
  }
}

}  // namespace hybgen::rt
