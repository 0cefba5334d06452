#pragma once
// The figures' drawing primitives with Cairo (internal to runtime/src/io/): numbers on axes,
// text, axes with ticks, colour bars, heat-map panels and curves. figures.cpp lays them out
// into a run's figures.

#include <cairo.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/io/animation.hpp"
#include "hybgen/rt/io/figures.hpp"

namespace hybgen::rt::drawing {

/// A rectangle in the figure's units (points; pixels in PNG), y downward.
struct Rect {
  double x, y, w, h;  ///< Corner and size.
};

/// A colour, channels in [0, 1].
struct Rgb {
  double r, g, b;  ///< Red, green, blue.
};

/// One axis of a panel.
struct PanelAxis {
  std::string name;  ///< The state's name.
  GridAxis grid;     ///< Its nodes.
};

/// A heat-map panel: data[ix * ny + iy] at node (ix, iy).
struct HeatPanel {
  std::string title;                  ///< Above the panel.
  PanelAxis x, y;                     ///< Horizontal and vertical axes.
  std::vector<double> data;           ///< The values, C order (nx, ny).
  std::vector<std::uint8_t> outside;  ///< Same layout; may be empty.
  /// Guard contours, in node-index coordinates, with the guard's name.
  std::vector<std::pair<std::string, std::vector<std::array<double, 4>>>> guards;
  std::size_t scale = 0;  ///< Index of its colour scale (its column).
};

/// A curve of a line plot.
struct Curve {
  std::string label;         ///< In the legend (empty: none).
  std::vector<double> y;     ///< One value per x.
  Rgb colour;                ///< Line colour.
  double width = 1.6;        ///< Line width (0: not drawn; sets the range only).
  std::vector<double> band;  ///< ± this around y, shaded (may be empty).
  bool dashed = false;       ///< Dashed line.
};

/// Text and axes.
inline constexpr Rgb kInk{0.12, 0.12, 0.12};
/// Grid lines and the unit circle.
inline constexpr Rgb kGrid{0.55, 0.55, 0.55};
/// Nodes outside the support.
inline constexpr Rgb kOutside{0.85, 0.85, 0.85};
/// Guards: orange-red, visible on viridis.
inline constexpr Rgb kGuard{0.93, 0.33, 0.18};
/// Curves: the mode curves and the budget's terms (Okabe–Ito colours, colour-blind safe).
inline constexpr std::array<Rgb, 7> kCurve{{{0.0, 0.45, 0.70},
                                            {0.90, 0.62, 0.0},
                                            {0.0, 0.62, 0.45},
                                            {0.80, 0.40, 0.0},
                                            {0.80, 0.47, 0.65},
                                            {0.34, 0.71, 0.91},
                                            {0.94, 0.89, 0.26}}};

/// Tick values at a 1-2-5 step over [lo, hi], at most about `max_count` and at least two
/// (one, lo, for an empty or non-finite span).
std::vector<double> nice_ticks(double lo, double hi, int max_count);
/// A tick label: %.4g with compact exponents (1e-5, 2e3).
std::string tick_label(double v);
/// Set the source colour.
void set_colour(cairo_t* cr, Rgb c, double alpha = 1.0);
/// Set the font: DejaVu Sans at `size`.
void set_font(cairo_t* cr, double size, bool bold = false);
/// The advance of `s` in the current font.
double text_width(cairo_t* cr, const std::string& s);
/// Text at (x, y) (the baseline), aligned by `align` (0 left, 0.5 centre, 1 right), shrunk
/// to `max_width` when given and wider.
void text(cairo_t* cr, double x, double y, const std::string& s, double align = 0,
          double max_width = 0);
/// Text turned a quarter counter-clockwise, centred on (x, y) along its length.
void text_up(cairo_t* cr, double x, double y, const std::string& s);
/// An axis box in `r` with ticks and labels: x over [x0, x1], y over [y0, y1] upward.
void draw_axes(cairo_t* cr, const Rect& r, double x0, double x1, double y0, double y1,
               const std::string& x_name, const std::string& y_name);
/// Viridis at t in [0, 1].
Rgb colour_at(double t);
/// Colour of label v of a categorical scale (ColourScale::categories): 0 pale, k the k-th
/// curve colour.
Rgb category_colour(double v);
/// A vertical colour bar in `r` for `scale`, labelled `label`.
void draw_colour_bar(cairo_t* cr, const Rect& r, const ColourScale& scale,
                     const std::string& label);
/// The extent of an axis's cells: half a cell beyond its first and last node.
std::pair<double, double> extent(const GridAxis& a);
/// A heat map of `p` in `r` on `scale`, its guards, axes and title.
void draw_heat_panel(cairo_t* cr, const Rect& r, const HeatPanel& p, const ColourScale& scale);
/// A plain curve (no band, solid).
Curve curve(std::string label, std::vector<double> y, Rgb colour, double width = 1.6);
/// Curves over `x` in `r`, a legend to the right of `r` when several are labelled; the
/// vertical range starts at `y_lo_floor` or below.
void draw_curves(cairo_t* cr, const Rect& r, const std::vector<double>& x,
                 const std::vector<Curve>& curves, const std::string& x_name,
                 const std::string& y_name, double y_lo_floor = 0);

/// Throws "cannot write 'PATH': Cairo's message" when `s` is in error.
void check_surface(cairo_surface_t* s, const std::string& path);
/// Writes `r` to `path` as an 8-bit RGB PNG, fast: one filter (Up: the heat maps' rows
/// repeat) and zlib level 1. Cairo's own writer (libpng's adaptive filters at level 6) spent
/// 70 % of a run's output time encoding the frames (perf, bench/outputs.sh).
void write_png(const std::string& path, const Raster& r);
/// Draw with `draw` on a raster of size (w, h), copy its pixels to `raster`, and write it
/// to `path` as PNG when `path` is not empty.
void to_png(const std::string& path, double w, double h, const std::function<void(cairo_t*)>& draw,
            Raster& raster);
/// Draw `pages` pages with `draw(cr, page)` into a PDF at `path`.
void to_pdf(const std::string& path, double w, double h, std::size_t pages,
            const std::function<void(cairo_t*, std::size_t)>& draw);
/// Draw with `draw` into an SVG at `path`.
void to_svg(const std::string& path, double w, double h, const std::function<void(cairo_t*)>& draw);

}  // namespace hybgen::rt::drawing
