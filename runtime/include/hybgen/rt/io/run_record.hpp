#pragma once
/// \file run_record.hpp
/// What a finished run hands its writers: the grid, the modes, the frames and the mass
/// budget, without the model's type. The runner (runner.hpp, a template over the model)
/// fills it; the writers (run_outputs.hpp, netcdf.hpp) are compiled once, in
/// runtime/src/io/, for every dimension.
///
/// Invariant: `density` holds n_frame() × n_mode() × n_node() values, frame-major, then
/// mode, then the node in C order of the grid (last axis fastest): the layout of
/// Solution (core/solution.hpp); or it is empty and `marginals` holds the run's pairs; or
/// the run is `distributed` over the ranks of `backend` and `density` holds, frame-major,
/// this rank's block `owned` of each frame's (mode, node) pairs.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"

namespace hybgen::rt {

/// The part of the marginal of a density on `axes` (C order) that the nodes
/// [first, first + u.size()) contribute: `u` holds those nodes' values; the marginal keeps
/// the axes `keep`, in that order (the first slowest in the result), and integrates the
/// others with the trapezoid rule of their grid axes. `keep` empty: the integral, as the one
/// value. The marginal of a whole density is its part from node 0; a distributed one is the
/// sum of every rank's part.
inline std::vector<double> marginal_part(std::span<const double> u, std::size_t first,
                                         const std::vector<GridAxis>& axes,
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
    std::size_t rem = first + i;  // idx = the multi-index of node first + i (C order)
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

/// The marginal of `u` (C order over `axes`) on the axes `keep`, in that order (the first
/// slowest in the result), integrating the others with the trapezoid rule of their grid
/// axes. `keep` empty: the integral of `u` over the whole grid, as the one value.
inline std::vector<double> marginal(std::span<const double> u, const std::vector<GridAxis>& axes,
                                    const std::vector<std::size_t>& keep) {
  return marginal_part(u, 0, axes, keep);
}

/// The pairs of axes the pictures show, lower axis first: every pair of `figure_axes` (the
/// setting, in the order given), or of every axis when it names fewer than two or the grid
/// has two axes. 2-D: the one pair (0, 1); 1-D: none.
inline std::vector<std::pair<std::size_t, std::size_t>> figure_pairs(
    std::size_t n_axes, const std::vector<std::size_t>& figure_axes) {
  std::vector<std::size_t> axes = figure_axes;
  if (axes.size() < 2 || n_axes == 2) {
    axes.clear();
    for (std::size_t a = 0; a < n_axes; ++a) axes.push_back(a);
  }
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < axes.size(); ++i)
    for (std::size_t j = i + 1; j < axes.size(); ++j) pairs.emplace_back(axes[i], axes[j]);
  return pairs;
}

/// A guard's surface function s (the surface is s = 0) on the planes of the figure pairs,
/// for the pictures' contours. Nodes are added in any pieces (a rank its block, in any
/// order); per plane cell it keeps the least and greatest s of the nodes projecting there.
/// s is drawn on a pair's plane when it does not depend on the other axes: every cell's
/// spread within 1e-9 of s's whole range (2-D: each cell is one node, always drawn).
class GuardPlanes {
 public:
  /// Empty planes of `pairs` on `axes`.
  GuardPlanes(const std::vector<GridAxis>& axes,
              const std::vector<std::pair<std::size_t, std::size_t>>& pairs)
      : axes_(axes), pairs_(pairs) {
    for (const auto& [a, b] : pairs_) {
      const std::size_t n =
          static_cast<std::size_t>(axes_[a].n) * static_cast<std::size_t>(axes_[b].n);
      lo_.emplace_back(n, kNone);
      hi_.emplace_back(n, -kNone);
    }
  }
  /// Add the nodes [first, first + s.size()) with their values of s.
  void add(std::size_t first, std::span<const double> s) {
    const std::size_t N = axes_.size();
    std::vector<std::size_t> idx(N);
    for (std::size_t i = 0; i < s.size(); ++i) {
      std::size_t rem = first + i;
      for (std::size_t a = N; a-- > 0;) {
        idx[a] = rem % static_cast<std::size_t>(axes_[a].n);
        rem /= static_cast<std::size_t>(axes_[a].n);
      }
      for (std::size_t p = 0; p < pairs_.size(); ++p) {
        const auto [a, b] = pairs_[p];
        const std::size_t c = idx[a] * static_cast<std::size_t>(axes_[b].n) + idx[b];
        lo_[p][c] = std::min(lo_[p][c], s[i]);
        hi_[p][c] = std::max(hi_[p][c], s[i]);
      }
    }
  }
  /// Every pair's least values, then the negated greatest: what ranks combine by an
  /// element-wise minimum (as the maximum of the negation; Backend::max).
  [[nodiscard]] std::vector<double> negated_extremes() const {
    std::vector<double> v;
    for (std::size_t p = 0; p < pairs_.size(); ++p) {
      for (const double x : lo_[p]) v.push_back(-x);
      v.insert(v.end(), hi_[p].begin(), hi_[p].end());
    }
    return v;
  }
  /// Replace the extremes by `v` (negated_extremes' layout, after every rank's maximum).
  void set_negated_extremes(std::span<const double> v) {
    std::size_t at = 0;
    for (std::size_t p = 0; p < pairs_.size(); ++p) {
      for (double& x : lo_[p]) x = -v[at++];
      for (double& x : hi_[p]) x = v[at++];
    }
  }
  /// The greatest s on pair p's plane per plane node (over the nodes projecting onto it).
  [[nodiscard]] const std::vector<double>& greatest(std::size_t p) const { return hi_[p]; }
  /// s on pair p's plane, or empty when s depends on the other axes there.
  [[nodiscard]] std::vector<double> plane(std::size_t p) const {
    double lo = kNone, hi = -kNone;
    for (std::size_t q = 0; q < pairs_.size(); ++q)
      for (std::size_t c = 0; c < lo_[q].size(); ++c)
        lo = std::min(lo, lo_[q][c]), hi = std::max(hi, hi_[q][c]);
    const double tol = 1e-9 * std::max(1.0, hi - lo);
    for (std::size_t c = 0; c < lo_[p].size(); ++c)
      if (!(hi_[p][c] - lo_[p][c] <= tol)) return {};
    return lo_[p];
  }

 private:
  static constexpr double kNone = std::numeric_limits<double>::infinity();
  std::vector<GridAxis> axes_;
  std::vector<std::pair<std::size_t, std::size_t>> pairs_;
  std::vector<std::vector<double>> lo_, hi_;
};

/// A guard as the pictures draw it: s on the plane of each figure pair.
struct GuardField {
  std::string name;  ///< Guard name.
  /// s on the plane of each pair of figure_pairs (the run's), in that order, C order with
  /// the pair's first axis slowest; empty for a pair where s depends on the other axes.
  std::vector<std::vector<double>> planes;
  int from = -1;  ///< The mode it fires from (-1: every mode).
  /// A 1-D run's s at every node (the curves' pictures mark where it changes sign); empty in
  /// more dimensions.
  std::vector<double> line = {};
};

/// The GuardField of s given at every node of `axes` (one process).
inline GuardField guard_field(std::string name, int from, std::span<const double> s,
                              const std::vector<GridAxis>& axes,
                              const std::vector<std::pair<std::size_t, std::size_t>>& pairs) {
  GuardPlanes planes(axes, pairs);
  planes.add(0, s);
  GuardField g{std::move(name), {}, from};
  for (std::size_t p = 0; p < pairs.size(); ++p) g.planes.push_back(planes.plane(p));
  if (axes.size() == 1) g.line.assign(s.begin(), s.end());
  return g;
}

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
  /// Whether `density` holds only this rank's pairs `owned` of each frame (several ranks).
  bool distributed = false;
  /// method=almost_invariant: the set (1 … K; 0: none) of every (mode, node), [mode][node];
  /// method=coherent: the pair's set at each frame, [frame][mode][node]; empty otherwise.
  /// run.nc's `set_label`, and the picture sets.png.
  std::span<const std::int32_t> set_label;
  /// What the frames hold, when not the method's own (methods' `frame_what`): the pictures'
  /// titles and colour bars (the sets' picture draws the labels as its frame).
  std::string what;
  /// Whether `density` holds means over each node's dual cell (characteristics with
  /// values=cells, budget/cell_averages.hpp), not values at the nodes.
  bool cell_averages = false;
  Block owned{};  ///< This rank's (mode, node) pairs, flat m·n_node + i, when distributed.
  /// The ranks that write the files together when `distributed` (core/backend.hpp).
  const Backend* backend = nullptr;
  /// Instead of `density` (then empty): the marginals and moments of a run too large for its
  /// grid (core/solution.hpp; particles with density=marginals).
  const Marginals* marginals = nullptr;
  /// Per figure pair (figure_pairs' order): 1 at the plane's nodes onto which no grid node in
  /// the support projects (2-D: the nodes outside the support), C order with the pair's first
  /// axis slowest; an empty mask where there is none. The pictures grey them.
  std::vector<std::vector<std::uint8_t>> outside;
  std::vector<GuardField> guards;  ///< Every guard on the figure pairs' planes.
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
  /// The density of mode m in frame k (not of a distributed run).
  std::span<const double> mode_density(std::size_t k, std::size_t m) const {
    if (distributed) throw std::logic_error("RunRecord::mode_density of a distributed run");
    return density.subspan((k * n_mode() + m) * n_node(), n_node());
  }
  /// This rank's pairs of frame k (the whole frame, [mode][node], in one process).
  std::span<const double> frame_part(std::size_t k) const {
    const std::size_t F = distributed ? owned.size() : n_mode() * n_node();
    return density.subspan(k * F, F);
  }
  /// The first (mode, node) pair of frame_part.
  std::size_t first_pair() const { return distributed ? owned.begin : 0; }
  /// The density summed over the modes in frame k (not of a distributed run).
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
