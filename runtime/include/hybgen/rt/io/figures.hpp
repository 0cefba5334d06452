#pragma once
/// \file figures.hpp
/// The run's pictures, drawn with Cairo (anti-aliased text and lines; one drawing gives
/// PNG, PDF and SVG):
///  - a figure per frame: a 1-D line plot (one curve per mode and their sum); a 2-D heat
///    map (one panel per mode when there are several); in 3-D and more, the marginal
///    density on every pair of axes, one panel each (rows: modes);
///  - one colour scale per panel column for the whole run, so that frames compare: linear
///    from 0 to the run's maximum, or logarithmic over four decades below it (setting
///    `figure_scale`: auto picks log when the maximum is over 100 times the 99th percentile,
///    as at a Zeno point), with a labelled colour bar;
///  - each guard's surface drawn where it is a curve in the panel's plane (in 2-D always;
///    in a pair panel when the guard does not depend on the other axes), and the nodes
///    outside the support in grey;
///  - `budget`: the mass budget over time with its error bands; `spectrum`: the invariant
///    density's eigenvalues in the complex plane.
///  - `animation.gif`: every frame of a time series, looping (animation.hpp).
/// Docs: docs/outputs.md, "Pictures".

#include <array>
#include <string>
#include <vector>

#include "hybgen/rt/io/run_record.hpp"

namespace hybgen::rt {

/// Which files of pictures to write, and how to scale them.
struct FigureRequest {
  bool png = true;               ///< u_0000.png … (one per frame), budget.png, spectrum.png.
  bool pdf = false;              ///< density.pdf (one page per frame), budget.pdf, spectrum.pdf.
  bool svg = false;              ///< u_0000.svg … , budget.svg, spectrum.svg.
  bool gif = false;              ///< animation.gif: every frame, looping (animation.hpp).
  std::string scale = "auto";    ///< linear, log or auto (figure_scale).
  std::vector<std::string> out;  ///< Filled: the files written, relative to the directory.
};

/// The colour scale of a run: linear [0, hi] or log10 over [lo, hi].
struct ColourScale {
  bool log = false;  ///< Logarithmic.
  double lo = 0.0;   ///< Lowest value shown (log: hi / 1e4).
  double hi = 1.0;   ///< Highest value shown: the run's maximum.
  /// More than 0: the values are labels 0 … categories (sets.png), drawn in distinct colours
  /// (0 pale), not on the ramp.
  int categories = 0;
  /// Where v falls on the bar, in [0, 1] (clamped; NaN: 0).
  double unit(double v) const;
};

/// The scale for `values` (every value the panels of a column show, over the whole run):
/// `mode` linear, log or auto.
ColourScale choose_colour_scale(const std::vector<double>& values, const std::string& mode);

/// Draws `run`'s figures into `dir`; throws std::runtime_error naming the file on failure.
/// Frames are drawn in parallel. Returns the warnings the pictures give (a scale chosen
/// automatically is reported in `request.out`'s order of files, not here).
void write_figures(const RunRecord& run, FigureRequest& request, const std::string& dir);

/// Where a frame figure's heat panels are, in pixels of its PNG (tests, and the report's
/// overlays): the figure's size and each panel's rectangle (x, y, width, height), in the
/// order mode-major, then pairs of axes (a, b), a < b. 1-D figures have no panels.
struct FigureGeometry {
  double width = 0;                           ///< Figure width.
  double height = 0;                          ///< Figure height.
  std::vector<std::array<double, 4>> panels;  ///< Heat panels.
};

/// The geometry of `run`'s frame figures (every frame has the same).
FigureGeometry frame_geometry(const RunRecord& run);

/// Line segments (x0, y0, x1, y1) in grid coordinates of the zero contour of `s`, a C-order
/// (nx, ny) array of node values (marching squares; a saddle cell is split by the sign of
/// its centre's mean). Node (i, j) is the point (i, j).
std::vector<std::array<double, 4>> zero_contour(const std::vector<double>& s, std::size_t nx,
                                                std::size_t ny);

}  // namespace hybgen::rt
