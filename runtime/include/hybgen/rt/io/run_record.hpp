#pragma once
/// \file run_record.hpp
/// What a finished run hands its writers: the grid, the modes, the frames and the mass
/// budget, without the model's type. The runner (runner.hpp, a template over the model)
/// fills it; the writers (run_outputs.hpp, netcdf.hpp) are compiled once, in
/// runtime/src/io/, for every dimension.
///
/// Invariant: `density` holds n_frame() × n_mode() × n_node() values, frame-major, then
/// mode, then the node in C order of the grid (last axis fastest): the layout of
/// Solution (core/solution.hpp); or it is empty and `marginals` holds the run's pairs.

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"

namespace hybgen::rt {

/// The marginal of `u` (C order over `axes`) on the axes `keep`, in that order (the first
/// slowest in the result), integrating the others with the trapezoid rule of their grid
/// axes. `keep` empty: the integral of `u` over the whole grid, as the one value.
inline std::vector<double> marginal(std::span<const double> u, const std::vector<GridAxis>& axes,
                                    const std::vector<std::size_t>& keep) {
  const std::size_t N = axes.size();
  std::vector<std::vector<double>> w(N);
  std::vector<bool> kept(N, false);
  for (const std::size_t a : keep) kept[a] = true;
  for (std::size_t a = 0; a < N; ++a)
    if (!kept[a]) w[a] = trapezoid_rule(axes[a]).weights;
  std::size_t n_out = 1;
  for (const std::size_t a : keep) n_out *= static_cast<std::size_t>(axes[a].n);
  std::vector<double> out(n_out, 0.0);
  std::vector<std::size_t> idx(N, 0);
  for (std::size_t i = 0; i < u.size(); ++i) {
    std::size_t rem = i;  // idx = the multi-index of node i (C order)
    for (std::size_t a = N; a-- > 0;) {
      idx[a] = rem % static_cast<std::size_t>(axes[a].n);
      rem /= static_cast<std::size_t>(axes[a].n);
    }
    double weight = 1.0;
    for (std::size_t a = 0; a < N; ++a)
      if (!kept[a]) weight *= w[a][idx[a]];
    std::size_t o = 0;
    for (const std::size_t a : keep) o = o * static_cast<std::size_t>(axes[a].n) + idx[a];
    out[o] += weight * u[i];
  }
  return out;
}

/// A guard's surface function s sampled at the grid's nodes (the surface is s = 0): the
/// pictures draw its zero contour.
struct GuardField {
  std::string name;            ///< Guard name.
  std::vector<double> values;  ///< s at every node, C order.
  int from = -1;               ///< The mode it fires from (-1: every mode).
};

/// A finished run, as its writers see it.
struct RunRecord {
  std::string model;                     ///< Model name.
  std::string method;                    ///< The method that solved it.
  std::vector<std::string> axis_names;   ///< State names, one per grid axis.
  std::vector<GridAxis> axes;            ///< Grid axes (nodes at both ends).
  std::vector<std::string> mode_names;   ///< Mode names, model order.
  std::vector<std::string> param_names;  ///< Parameter names, model order.
  std::vector<double> params;            ///< Parameter values, model order.
  /// Frame times; empty for a stationary result (the invariant density: one frame).
  std::vector<double> times;
  std::vector<std::string> frame_names;  ///< File stem per frame (u_0000, …, or invariant).
  std::span<const double> density;       ///< [frame][mode][node] (see the invariant above).
  /// Instead of `density` (then empty): the marginals and moments of a run too large for its
  /// grid (core/solution.hpp; particles with density=marginals).
  const Marginals* marginals = nullptr;
  std::vector<std::uint8_t> outside;  ///< 1 at nodes outside the support (empty: none).
  std::vector<GuardField> guards;     ///< Every guard's s at the nodes.
  /// The axes whose pairs the pictures show (setting figure_axes; empty: every axis).
  std::vector<std::size_t> figure_axes;
  MassBudget budget;               ///< Per frame time (empty: no budget).
  std::vector<double> atom_error;  ///< Estimated |error| of budget.atom (may be empty).
  nlohmann::json summary;          ///< summary.json as written (method blocks, timings).
  /// From the configuration: model_text, model_path, model_sha256, equations (text),
  /// equations_latex,
  /// hybgen_version (generator/src/run.cpp, run_provenance); may be empty.
  nlohmann::json provenance;

  /// Nodes per frame and mode.
  std::size_t n_node() const {
    std::size_t n = 1;
    for (const GridAxis& a : axes) n *= static_cast<std::size_t>(a.n);
    return n;
  }
  /// Modes.
  std::size_t n_mode() const { return mode_names.size(); }
  /// Frames.
  std::size_t n_frame() const { return frame_names.size(); }
  /// The density of mode m in frame k.
  std::span<const double> mode_density(std::size_t k, std::size_t m) const {
    return density.subspan((k * n_mode() + m) * n_node(), n_node());
  }
  /// The density summed over the modes in frame k.
  std::vector<double> total_density(std::size_t k) const {
    std::vector<double> t(n_node(), 0.0);
    for (std::size_t m = 0; m < n_mode(); ++m) {
      const std::span<const double> u = mode_density(k, m);
      for (std::size_t i = 0; i < t.size(); ++i) t[i] += u[i];
    }
    return t;
  }
};

}  // namespace hybgen::rt
