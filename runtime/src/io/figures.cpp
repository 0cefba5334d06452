// The run's pictures with Cairo (hybgen/rt/io/figures.hpp states what they show).
//
// The primitives (axes, colour bars, heat maps, curves) are in drawing.cpp; here: a run's
// panels, the layouts of its figures (frames, budget, spectrum) and the surfaces (PNG, PDF,
// SVG, the animation's frames).

#include "hybgen/rt/io/figures.hpp"

#include <cairo.h>
#include <fontconfig/fontconfig.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "drawing.hpp"
#include "hybgen/rt/io/animation.hpp"
#include "hybgen/rt/method_table.hpp"

namespace hybgen::rt {

namespace {

using namespace drawing;

// ------------------------------------------------------------------ a run's panels

/// The pairs of axes the panels show (run_record.hpp, figure_pairs).
std::vector<std::pair<std::size_t, std::size_t>> axis_pairs(const RunRecord& run) {
  return figure_pairs(run.axes.size(), run.figure_axes);
}

/// The deposited marginal of frame k on (a, b), a slowest: mode m, or every mode summed
/// when m is n_mode (transposed when a > b: the run keeps each pair once, lower axis first).
std::vector<double> pair_marginal(const Marginals& mg, const RunRecord& run, std::size_t k,
                                  std::size_t m, std::size_t a, std::size_t b) {
  const std::size_t lo = std::min(a, b), hi = std::max(a, b), M = run.n_mode();
  const std::size_t p = mg.index(lo, hi);
  const auto nl = static_cast<std::size_t>(run.axes[lo].n);
  const auto nh = static_cast<std::size_t>(run.axes[hi].n);
  std::vector<double> sum(nl * nh, 0.0);
  if (p == mg.pairs.size()) return sum;
  for (std::size_t mode = 0; mode < M; ++mode) {
    if (m < M && mode != m) continue;
    const std::span<const double> u = mg.pair(k, mode, M, p);
    for (std::size_t i = 0; i < sum.size(); ++i) sum[i] += u[i];
  }
  if (a < b) return sum;
  std::vector<double> t(sum.size());
  for (std::size_t i = 0; i < nl; ++i)
    for (std::size_t j = 0; j < nh; ++j) t[j * nl + i] = sum[i * nh + j];
  return t;
}

/// Every heat panel of frame k (2-D and more): per mode in 2-D (the sum with one mode);
/// per pair of axes in 3-D and more, in rows by mode when there are several.
std::vector<HeatPanel> frame_panels(const RunRecord& run, std::size_t k) {
  const std::size_t N = run.axes.size(), M = run.n_mode();
  const std::vector<std::pair<std::size_t, std::size_t>> pairs = axis_pairs(run);
  std::vector<HeatPanel> out;
  const Marginals* mg = run.marginals;
  const std::vector<double> total = mg ? std::vector<double>() : run.total_density(k);
  // Rows: the modes (several), or the sum.
  const std::size_t rows = M > 1 ? M : 1;
  for (std::size_t row = 0; row < rows; ++row) {
    const std::span<const double> u =
        mg ? std::span<const double>()
           : (M > 1 ? run.mode_density(k, row) : std::span<const double>(total));
    for (std::size_t c = 0; c < pairs.size(); ++c) {
      const auto [a, b] = pairs[c];
      HeatPanel p;
      p.x = {run.axis_names[a], run.axes[a]};
      p.y = {run.axis_names[b], run.axes[b]};
      if (mg)
        p.data = pair_marginal(*mg, run, k, M > 1 ? row : M, a, b);
      else
        p.data = N == 2 ? std::vector<double>(u.begin(), u.end()) : marginal(u, run.axes, {a, b});
      if (c < run.outside.size()) p.outside = run.outside[c];
      p.title = M > 1 ? "mode " + run.mode_names[row] : std::string();
      if (N > 2)
        p.title += std::string(p.title.empty() ? "" : ": ") + "marginal on (" + run.axis_names[a] +
                   ", " + run.axis_names[b] + ")";
      for (const GuardField& g : run.guards) {
        // With several modes, a guard is drawn in the panels of the mode it fires from.
        if (M > 1 && g.from >= 0 && static_cast<std::size_t>(g.from) != row) continue;
        if (c < g.planes.size() && !g.planes[c].empty())
          p.guards.emplace_back(g.name,
                                zero_contour(g.planes[c], static_cast<std::size_t>(run.axes[a].n),
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
  // A one-frame method's frame says what it is (method_table.hpp, frame_what).
  const MethodSpec* method = find_method(run.method);
  if (!run.what.empty()) return run.model + "  ·  " + run.what;
  return run.model + "  ·  " +
         (run.times.empty()
              ? (method != nullptr ? std::string(method->frame_what) : std::string("density"))
              : run.method + (run.cell_averages ? ", cell averages" : "") +
                    "  ·  t = " + fixed3(run.times[k]));
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
  /// What a frame of labels names (its colour bars' label: write_sets_figure); empty for
  /// densities.
  std::string labels;
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

/// The points of a 1-D run where each guard's s changes sign (linear between nodes), as
/// dashed vertical lines in the guards' colour across `r` (the plot of the curves over `x`),
/// each named at its top; a guard met at several points is named once.
void draw_guard_marks(cairo_t* cr, const Rect& r, const std::vector<double>& x,
                      const std::vector<GuardField>& guards) {
  if (x.size() < 2) return;
  const auto X = [&](double v) { return r.x + (v - x.front()) / (x.back() - x.front()) * r.w; };
  const double dash[] = {4.0, 3.0};
  set_font(cr, 11);
  double label_y = r.y + 13;
  for (const GuardField& g : guards) {
    if (g.line.size() != x.size()) continue;
    std::vector<double> at;
    for (std::size_t i = 0; i + 1 < x.size(); ++i) {
      const double a = g.line[i], b = g.line[i + 1];
      if (a == 0.0 && (i == 0 || g.line[i - 1] != 0.0)) at.push_back(x[i]);
      if (a != 0.0 && b != 0.0 && (a < 0.0) != (b < 0.0))
        at.push_back(x[i] + a / (a - b) * (x[i + 1] - x[i]));
    }
    if (!at.empty() && g.line.back() == 0.0) at.push_back(x.back());
    for (std::size_t j = 0; j < at.size(); ++j) {
      set_colour(cr, kGuard);
      cairo_set_line_width(cr, 1.4);
      cairo_set_dash(cr, dash, 2, 0);
      cairo_new_path(cr);
      cairo_move_to(cr, X(at[j]), r.y);
      cairo_line_to(cr, X(at[j]), r.y + r.h);
      cairo_stroke(cr);
      cairo_set_dash(cr, dash, 0, 0);
      if (j == 0) {
        const double w = text_width(cr, g.name);
        text(cr, std::min(X(at[j]) + 4, r.x + r.w - w - 2), label_y, g.name);
      }
    }
    if (!at.empty()) label_y += 14;
  }
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
    // With several modes the sum is drawn first, thin and dashed, so that a mode holding all
    // the mass (where the sum equals it) stays visible on top of it.
    // (Not for frames that hold labels, `what`: their sum over the modes means nothing.)
    std::vector<Curve> curves;
    Curve sum = curve(run.n_mode() > 1 ? "sum" : "u", run.total_density(k), kInk,
                      run.n_mode() > 1 ? 1.2 : 2.0);
    sum.dashed = run.n_mode() > 1;
    if (run.n_mode() == 1 || run.what.empty()) curves.push_back(std::move(sum));
    if (run.n_mode() > 1)
      for (std::size_t m = 0; m < run.n_mode(); ++m) {
        const auto u = run.mode_density(k, m);
        curves.push_back(curve("mode " + run.mode_names[m], {u.begin(), u.end()},
                               kCurve[m % kCurve.size()], 2.0));
      }
    // An invisible curve at the run's maximum fixes the vertical range: frames compare.
    std::vector<Curve> with_range = curves;
    with_range.insert(with_range.begin(),
                      curve("", std::vector<double>(x.size(), plan.line_max), {1, 1, 1}, 0.0));
    const Rect r{kLeft + 10, kTop, l.width - kLeft - 30 - kLegend, l.height - kTop - kBottom - 10};
    draw_curves(cr, r, x, with_range, run.axis_names[0], run.what.empty() ? "density u" : "set");
    draw_guard_marks(cr, r, x, run.guards);
    return;
  }
  const std::vector<HeatPanel>& panels = plan.panels[k];
  for (std::size_t i = 0; i < panels.size(); ++i) {
    const Rect r = panel_rect(l, i);
    const ColourScale& s = plan.scales[panels[i].scale];
    draw_heat_panel(cr, r, panels[i], s);
    const std::string label = !plan.labels.empty()
                                  ? plan.labels
                                  : std::string(s.log ? "log scale: " : "") +
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

/// A summary.json series of K frames into `curve`: `values` (NaN where not a number: a gap) and
/// `errors` as its band (0 where not a number; no band unless K of them). False when `values`
/// does not hold K frames (the curve is not drawn).
bool fill_series(Curve& curve, const nlohmann::json& values, const nlohmann::json& errors,
                 std::size_t K) {
  if (values.is_array())
    for (const auto& v : values) curve.y.push_back(v.is_number() ? v.get<double>() : std::nan(""));
  if (errors.is_array())
    for (const auto& e : errors) curve.band.push_back(e.is_number() ? e.get<double>() : 0.0);
  if (curve.y.size() != K) return false;
  if (curve.band.size() != K) curve.band.clear();
  return true;
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
      // Not an orange beside the outflow's: a reddish purple, dashed (legend too).
      {"unaccounted", budget_defect(b), kCurve[4], 1.6, band(budget_defect_error(b)), true}};
  // Each trap's part of the outflow (`reset absorb`), dashed in the colours after those.
  if (run.summary.is_object() && run.summary.contains(summary_key::absorbed)) {
    std::size_t c = 5;
    for (const auto& [guard, a] : run.summary[summary_key::absorbed].items()) {
      Curve curve{"absorbed by " + guard, {}, kCurve[c++ % std::size(kCurve)], 1.6, {}, true};
      if (fill_series(curve, a["values"], a["errors"], K)) curves.push_back(std::move(curve));
    }
  }
  draw_curves(cr, {kLeft + 10, kTop, width - kLeft - 30 - kLegend, height - kTop - kBottom - 10},
              run.times, curves, "t", "mass");
}

/// The observables' means over time (methods/observables.hpp), each with its error as a band.
void draw_observables(cairo_t* cr, const RunRecord& run, double width, double height) {
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  draw_title(cr, width,
             run.model + "  ·  observables, mean under the density (" + run.method + ")");
  std::vector<Curve> curves;
  std::size_t c = 0;
  for (const auto& [name, o] : run.summary[summary_key::observables].items()) {
    Curve curve{"E[" + name + "]", {}, kCurve[c++ % std::size(kCurve)], 2.0, {}};
    if (fill_series(curve, o["values"], o["errors"], run.times.size()))
      curves.push_back(std::move(curve));
  }
  draw_curves(cr, {kLeft + 10, kTop, width - kLeft - 30 - kLegend, height - kTop - kBottom - 10},
              run.times, curves, "t", curves.size() == 1 ? curves.front().label : "mean");
}

/// The mean impact rate on each guard over time (methods/impacts.hpp), each with its error as a
/// band; a gap where it is undefined (the first frame) or infinite (Zeno).
void draw_impacts(cairo_t* cr, const RunRecord& run, double width, double height) {
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  draw_title(cr, width,
             run.model + "  ·  impacts on the guards per unit time (" + run.method + ")");
  std::vector<Curve> curves;
  std::size_t c = 0;
  for (const auto& [guard, a] : run.summary[summary_key::impacts].items()) {
    Curve curve{"rate on " + guard, {}, kCurve[c++ % std::size(kCurve)], 2.0, {}};
    if (fill_series(curve, a["rate"], a["rate_errors"], run.times.size()))
      curves.push_back(std::move(curve));
  }
  const Rect plot{kLeft + 10, kTop, width - kLeft - 30 - kLegend, height - kTop - kBottom - 10};
  draw_curves(
      cr, plot, run.times, curves, "t",
      curves.size() == 1 ? curves.front().label + " (mass per unit time)" : "mass per unit time");
  // Where the impacts are infinite the curve stops; say why, inside the plot.
  set_font(cr, 12);
  set_colour(cr, kInk);
  double y = plot.y + 22;
  for (const auto& [guard, a] : run.summary[summary_key::impacts].items())
    if (a["infinite_from"].is_number()) {
      text(cr, plot.x + 12, y,
           "on " + guard + ": infinite from t = " + tick_label(a["infinite_from"].get<double>()) +
               " (mass at a Zeno point)");
      y += 18;
    }
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
  const nlohmann::json& ev = run.summary[summary_key::invariant]["eigenvalues"];
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
  const auto& inv = run.summary[summary_key::invariant];
  const double x = r.x + r.w + 30;
  text(cr, x, r.y + 20, "spectral gap " + tick_label(inv.value("spectral_gap", 0.0)));
  text(cr, x, r.y + 40,
       "decay rate " + tick_label(inv.value("decay_rate", 0.0)) + " per unit time");
  for (std::size_t i = 0; i < ev.size() && i < 12; ++i)
    text(cr, x, r.y + 70 + 17.0 * static_cast<double>(i),
         "|λ" + std::to_string(i + 1) + "| = " + tick_label(ev[i]["abs"].get<double>()));
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

namespace {

/// sets.png (and .pdf, .svg as asked): the sets' labels drawn as a frame, a panel per mode (a
/// marginal's panels in 3-D and more show the labels' sums: the picture is for 1-D and 2-D).
/// Labels at two times (method=coherent, [frame][mode][node]): the two frames side by side,
/// the pairs' initial sets on the left and their final sets on the right, in the same colours.
void write_sets_figure(const RunRecord& run, FigureRequest& request,
                       const std::filesystem::path& out) {
  const std::vector<double> labels(run.set_label.begin(), run.set_label.end());
  const std::size_t per_frame = run.n_mode() * run.n_node();
  const bool two_times =
      !run.times.empty() && labels.size() == run.n_frame() * per_frame && run.n_frame() == 2;
  RunRecord sets = run;
  sets.density = labels;
  sets.marginals = nullptr;
  if (!two_times) {
    sets.times.clear();
    sets.frame_names = {"sets"};
  }
  const auto what = [&](std::size_t k) {
    return two_times ? "coherent pairs at t = " + fixed3(run.times[k]) +
                           (k == 0 ? ": initial sets" : ": final sets") + " (run.nc set_label)"
                     : std::string("almost-invariant sets (run.nc set_label)");
  };
  FramePlan plan = plan_frames(sets, "linear");
  plan.labels = two_times ? "coherent pair" : "almost-invariant set";
  int K = 0;
  for (const std::int32_t l : run.set_label) K = std::max(K, static_cast<int>(l));
  for (ColourScale& scale : plan.scales) scale.categories = std::max(K, 1);
  const std::size_t frames = two_times ? 2 : 1;
  const double W = plan.layout.width, H = plan.layout.height,
               total_w = W * static_cast<double>(frames);
  const auto draw = [&](cairo_t* cr) {
    for (std::size_t k = 0; k < frames; ++k) {
      sets.what = what(k);
      cairo_save(cr);
      const double x = W * static_cast<double>(k);
      cairo_rectangle(cr, x, 0, W, H);
      cairo_clip(cr);
      cairo_translate(cr, x, 0);
      draw_frame(cr, sets, plan, k);
      cairo_restore(cr);
    }
  };
  if (request.png) {
    Raster raster;
    to_png((out / "sets.png").string(), total_w, H, draw, raster);
    request.out.push_back("sets.png");
  }
  if (request.svg) {
    to_svg((out / "sets.svg").string(), total_w, H, draw);
    request.out.push_back("sets.svg");
  }
  if (request.pdf) {
    to_pdf((out / "sets.pdf").string(), total_w, H, 1, [&](cairo_t* cr, std::size_t) { draw(cr); });
    request.out.push_back("sets.pdf");
  }
}

}  // namespace

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
        to_svg((out / (base + ".svg")).string(), W, H,
               [&](cairo_t* cr) { draw_frame(cr, run, plan, k); });
      });
  }
  if (error) std::rethrow_exception(error);
  // The animation and the PDF side by side (each is one sequential stream).
  // One frame (a stationary answer): its name; a time series: density.pdf.
  const std::string stem = run.times.empty() ? run.frame_names.front() : "density";
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
  if (!run.set_label.empty() && !run.distributed) write_sets_figure(run, request, out);
  // The budget and the spectrum, in each format asked for.
  const bool budget = !run.times.empty() && run.budget.mass.size() == run.times.size();
  const bool spectrum = run.summary.is_object() && run.summary.contains(summary_key::invariant);
  // The observables over time (a time series of two frames or more).
  const bool observables = run.times.size() > 1 && run.summary.is_object() &&
                           run.summary.contains(summary_key::observables);
  // The impact rates over time (methods/impacts.hpp).
  const bool impacts = run.times.size() > 1 && run.summary.is_object() &&
                       run.summary.contains(summary_key::impacts) &&
                       !run.summary[summary_key::impacts].empty();
  for (const auto& [name, wanted] :
       {std::pair{std::string("budget"), budget}, std::pair{std::string("spectrum"), spectrum},
        std::pair{std::string("observables"), observables},
        std::pair{std::string("impacts"), impacts}}) {
    if (!wanted) continue;
    const double w = 760, h = 480;
    const auto draw = [&](cairo_t* cr) {
      if (name == "budget")
        draw_budget(cr, run, w, h);
      else if (name == "spectrum")
        draw_spectrum(cr, run, w, h);
      else if (name == "impacts")
        draw_impacts(cr, run, w, h);
      else
        draw_observables(cr, run, w, h);
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
