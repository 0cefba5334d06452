// The figures' drawing primitives (drawing.hpp).

#include "drawing.hpp"

#include <cairo-pdf.h>
#include <cairo-svg.h>
#include <png.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <stdexcept>

#include "hybgen/rt/io/colormap.hpp"

namespace hybgen::rt::drawing {

// ------------------------------------------------------------------ numbers on axes

/// See drawing.hpp. A step that leaves one tick in the span (2 on [−1.5, 1.5]) gives way to
/// the next finer one.
std::vector<double> nice_ticks(double lo, double hi, int max_count) {
  const double span = hi - lo;
  if (!(span > 0) || !std::isfinite(span)) return {lo};
  const double raw = span / std::max(max_count, 2);
  const double base = std::pow(10.0, std::floor(std::log10(raw)));
  // The 1-2-5 steps from base/10 up; the first at least `raw` is taken.
  const std::array<double, 5> steps{0.5 * base, base, 2 * base, 5 * base, 10 * base};
  std::size_t pick = 1;
  while (pick + 1 < 5 && steps[pick] < raw * (1 - 1e-9)) ++pick;
  auto ticks = [lo, hi](double step) {
    std::vector<double> t;
    for (double k = std::ceil(lo / step - 1e-9); k * step <= hi + step * 1e-9 && t.size() < 40; ++k)
      t.push_back(std::fabs(k * step) < step * 1e-9 ? 0.0 : k * step);
    return t;
  };
  std::vector<double> t = ticks(steps[pick]);
  for (; t.size() < 2 && pick > 0; t = ticks(steps[--pick])) {
  }
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

void set_colour(cairo_t* cr, Rgb c, double alpha) {
  cairo_set_source_rgba(cr, c.r, c.g, c.b, alpha);
}

void set_font(cairo_t* cr, double size, bool bold) {
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
void text(cairo_t* cr, double x, double y, const std::string& s, double align, double max_width) {
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

/// Colour of label v of a categorical scale: 0 pale, k the k-th curve colour (cycling).
Rgb category_colour(double v) {
  const long k = std::isfinite(v) ? std::lround(v) : 0;
  if (k <= 0) return {0.97, 0.97, 0.97};
  return kCurve[static_cast<std::size_t>(k - 1) % kCurve.size()];
}

namespace {

/// A categorical bar in `r`: one box per label, 0 at the bottom ("none"), each named at its
/// side. Returns the widest name.
double draw_category_boxes(cairo_t* cr, const Rect& r, const ColourScale& scale) {
  const int n = scale.categories + 1;
  const double h = r.h / n;
  set_font(cr, 10);
  double widest = 0;
  for (int k = 0; k < n; ++k) {
    const double y = r.y + r.h - (k + 1) * h;
    const Rgb c = category_colour(k);
    cairo_set_source_rgb(cr, c.r, c.g, c.b);
    cairo_rectangle(cr, r.x, y, r.w, h);
    cairo_fill(cr);
    set_colour(cr, kInk);
    cairo_set_line_width(cr, 1.0);
    cairo_rectangle(cr, r.x, y, r.w, h);
    cairo_stroke(cr);
    const std::string l = k == 0 ? "none" : std::to_string(k);
    widest = std::max(widest, text_width(cr, l));
    text(cr, r.x + r.w + 6, y + h / 2 + 3.5, l);
  }
  return widest;
}

/// The viridis ramp in `r` with its ticks (linear or log10). Returns the widest tick label.
double draw_ramp(cairo_t* cr, const Rect& r, const ColourScale& scale) {
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
  return widest;
}

}  // namespace

/// A vertical colour bar in `r` for `scale`, labelled `label`.
void draw_colour_bar(cairo_t* cr, const Rect& r, const ColourScale& scale,
                     const std::string& label) {
  const double widest =
      scale.categories > 0 ? draw_category_boxes(cr, r, scale) : draw_ramp(cr, r, scale);
  set_font(cr, 11);
  cairo_save(cr);
  cairo_translate(cr, r.x + r.w + 16 + widest, r.y + r.h / 2);
  cairo_rotate(cr, M_PI / 2);
  text(cr, 0, 0, label, 0.5);
  cairo_restore(cr);
}

// ------------------------------------------------------------------ panels

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
      else if (scale.categories > 0)
        c = category_colour(p.data[i]);
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

/// A plain curve (no band, solid).
Curve curve(std::string label, std::vector<double> y, Rgb colour, double width) {
  return Curve{std::move(label), std::move(y), colour, width, {}, false};
}

/// Curves over `x` in `r`, with a legend to the right of `r` (kLegend wide) when several
/// are labelled.
void draw_curves(cairo_t* cr, const Rect& r, const std::vector<double>& x,
                 const std::vector<Curve>& curves, const std::string& x_name,
                 const std::string& y_name, double y_lo_floor) {
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
    // A value that is not finite (NaN: undefined, infinite, none) is a gap in the line and
    // its band: each run of finite values is drawn on its own.
    const auto finite = [&](std::size_t i) {
      return i < c.y.size() && std::isfinite(c.y[i]) &&
             (c.band.empty() || std::isfinite(c.band[i]));
    };
    if (!c.band.empty()) {
      for (std::size_t b = 0; b < x.size();) {
        if (!finite(b)) {
          ++b;
          continue;
        }
        std::size_t e = b;
        while (e < x.size() && finite(e)) ++e;
        cairo_new_sub_path(cr);
        for (std::size_t i = b; i < e; ++i) cairo_line_to(cr, X(x[i]), Y(c.y[i] + c.band[i]));
        for (std::size_t i = e; i-- > b;) cairo_line_to(cr, X(x[i]), Y(c.y[i] - c.band[i]));
        cairo_close_path(cr);
        b = e;
      }
      set_colour(cr, c.colour, 0.22);
      cairo_fill(cr);
    }
    cairo_new_path(cr);
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (!(i < c.y.size() && std::isfinite(c.y[i]))) {
        cairo_new_sub_path(cr);  // pen up
        continue;
      }
      cairo_line_to(cr, X(x[i]), Y(c.y[i]));
    }
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
      // The sample shows the line as drawn: dashed curves get the same dash.
      const double dash[] = {6.0, 4.0};
      cairo_set_dash(cr, dash, legend[i]->dashed ? 2 : 0, 0);
      cairo_move_to(cr, lx, y - 4);
      cairo_line_to(cr, lx + 24, y - 4);
      cairo_stroke(cr);
      cairo_set_dash(cr, dash, 0, 0);
      set_colour(cr, kInk);
      text(cr, lx + 30, y, legend[i]->label);
    }
  }
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

namespace {

/// Draw `pages` pages on the vector surface `s` (PDF or SVG) of `path`, finish it and report
/// its status.
void to_vector(cairo_surface_t* s, const std::string& path, std::size_t pages,
               const std::function<void(cairo_t*, std::size_t)>& draw) {
  check_surface(s, path);
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

void to_pdf(const std::string& path, double w, double h, std::size_t pages,
            const std::function<void(cairo_t*, std::size_t)>& draw) {
  cairo_surface_t* s = cairo_pdf_surface_create(path.c_str(), w, h);
  if (cairo_surface_status(s) == CAIRO_STATUS_SUCCESS)
    cairo_pdf_surface_set_metadata(s, CAIRO_PDF_METADATA_CREATOR, "hybgen");
  to_vector(s, path, pages, draw);
}

void to_svg(const std::string& path, double w, double h,
            const std::function<void(cairo_t*)>& draw) {
  to_vector(cairo_svg_surface_create(path.c_str(), w, h), path, 1,
            [&](cairo_t* cr, std::size_t) { draw(cr); });
}

}  // namespace hybgen::rt::drawing
