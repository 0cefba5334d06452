#pragma once
/// \file generator_geometry.hpp
/// The cut-cell geometry of the finite-volume generator (generator.hpp, `scheme=fv`): where
/// the guards and their reset images lie, and the 1-D partitions of every axis per mode.
///
/// Guards. This increment takes guards whose surface, inside the box, is a union of
/// coordinate hyperplanes x_d = c, and whose reset maps each such plane onto a coordinate
/// hyperplane x_{d'} = c' (every 1-D model; products of 1-D models). `fv_guard_planes` finds
/// them from the kernels alone: the roots of s_g along lines parallel to every axis through a
/// tensor pattern of sample points give points of the guard; ∇s_g there must be parallel to
/// one axis d, the same at every point, and the roots along the lines parallel to d must be
/// the same planes on every line (s constant in the other coordinates); the images Δ_g of
/// sampled points of each plane must have exactly one constant coordinate d' (one
/// hyperplane, not a set of lower dimension). An absorbing guard, and any other, is refused
/// (std::invalid_argument, which the run's chain turns into exit 2), naming the guard.
/// Curved guards (cut cells by quadrature on s_g, local level sets of the images) are not
/// built yet.
///
/// Cells. Per mode m and axis d, `FvAxis` is the partition of [min_d, max_d] into the dual
/// cells of the node grid (faces half-way between nodes, the box ends as faces), cut at the
/// planes of the guards that leave m and the images of the guards that enter m. The cuts and
/// the box ends are walls: a reconstruction stencil never crosses one, so the density may jump
/// there exactly. Invariant: edges strictly increase; every cut in the box is an edge (a cut
/// within kFvSnap·Δx of a dual face moves that face onto the cut instead of making a sliver).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// A cut closer than this fraction of the node spacing to a dual face replaces that face.
inline constexpr double kFvSnap = 1e-8;
/// Relative tolerance of the geometry checks (a plane's position, a gradient's direction).
inline constexpr double kFvGeometryTol = 1e-9;

/// One plane of a guard inside the box, x_axis = at, and its reset image x_image_axis =
/// image_at, as the finite-volume generator uses it.
struct FvGuardPlane {
  int guard = 0;             ///< The guard's index.
  int from = 0;              ///< The mode it leaves.
  int to = 0;                ///< The mode it enters.
  int axis = 0;              ///< d: the plane is x_d = at.
  double at = 0.0;           ///< c.
  double normal = 1.0;       ///< sign of ∂s/∂x_d on the plane: s increases along +x_d when 1.
  int image_axis = 0;        ///< d': the image is x_{d'} = image_at.
  double image_at = 0.0;     ///< c'.
  bool image_in_box = true;  ///< Whether c' lies in [min_{d'}, max_{d'}].
};

namespace detail {

/// The roots of f on [lo, hi]: sign changes on `pieces` equal subintervals refined by
/// bisection, and exact zeros at sample points (each once).
template <class F>
std::vector<double> line_roots(F&& f, double lo, double hi, int pieces) {
  std::vector<double> out;
  double a = lo, fa = f(lo);
  if (fa == 0.0) out.push_back(lo);
  for (int k = 1; k <= pieces; ++k) {
    const double b = k == pieces ? hi : lo + (hi - lo) * k / pieces, fb = f(b);
    if (fb == 0.0) {
      out.push_back(b);
    } else if (fa != 0.0 && (fa < 0.0) != (fb < 0.0)) {
      double x0 = a, x1 = b, f0 = fa;
      for (int it = 0; it < 200 && x1 - x0 > 4e-16 * std::max(1.0, std::fabs(x0)); ++it) {
        const double mid = 0.5 * (x0 + x1), fm = f(mid);
        if (fm == 0.0) {
          x0 = x1 = mid;
          break;
        }
        if ((fm < 0.0) == (f0 < 0.0))
          x0 = mid, f0 = fm;
        else
          x1 = mid;
      }
      out.push_back(0.5 * (x0 + x1));
    }
    a = b, fa = fb;
  }
  return out;
}

/// Sample points per axis for the geometry checks in N dimensions (fewer in high N).
constexpr int geometry_samples(std::size_t N) {
  return N <= 3 ? 5 : N <= 4 ? 4 : 3;
}

/// The tensor pattern of sample coordinates of every axis but `skip` (interior points and
/// both ends), as a list of full points with the `skip` coordinate left at min.
template <std::size_t N>
std::vector<std::array<double, N>> transverse_samples(const TensorGrid<N>& grid, std::size_t skip) {
  const int S = geometry_samples(N);
  std::vector<std::array<double, N>> out(1);
  for (std::size_t a = 0; a < N; ++a) out[0][a] = grid.axes[a].min;
  for (std::size_t a = 0; a < N; ++a) {
    if (a == skip) continue;
    std::vector<std::array<double, N>> next;
    const GridAxis& ax = grid.axes[a];
    for (const auto& p : out)
      for (int k = 0; k < S; ++k) {
        auto q = p;
        // Irrational offsets keep the samples off the nodes and off round numbers.
        const double t = k == 0 ? 0.0 : k == S - 1 ? 1.0 : (k + 0.1234567) / (S - 1);
        q[a] = ax.min + (ax.max - ax.min) * std::min(t, 1.0);
        next.push_back(q);
      }
    out.swap(next);
  }
  return out;
}

/// "guard 'NAME' (from a to b)".
template <HybridModel M>
std::string fv_guard_label(int g) {
  const GuardInfo& gi = M::guards[static_cast<std::size_t>(g)];
  return std::string("guard '") + guard_name<M>(g) + "' (" + mode_name<M>(gi.from) + " -> " +
         mode_name<M>(gi.to) + ")";
}

/// The refusal of a guard the finite-volume scheme cannot cut yet.
template <HybridModel M>
std::invalid_argument fv_refusal(int g, const std::string& why) {
  return std::invalid_argument(
      "scheme=fv: " + fv_guard_label<M>(g) + " " + why +
      "; this version of the finite-volume generator cuts cells only at guards that are "
      "coordinate hyperplanes x_i = c inside the box, with resets mapping them onto coordinate "
      "hyperplanes (docs/methods.md, \"invariant\"): use --set scheme=hat");
}

}  // namespace detail

/// The planes of every guard of M inside the box of `grid` and their reset images (see the
/// file comment); throws std::invalid_argument naming the first guard that is not a
/// coordinate hyperplane or whose image is not one. A guard that does not meet the box has
/// no plane.
template <HybridModel M>
std::vector<FvGuardPlane> fv_guard_planes(const TensorGrid<state_dim_v<M>>& grid,
                                          const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  std::vector<FvGuardPlane> out;
  for (int g = 0; g < M::n_guard; ++g) {
    const GuardInfo& gi = M::guards[static_cast<std::size_t>(g)];
    if (absorbs(gi))
      throw std::invalid_argument(std::string("scheme=fv: guard '") + guard_name<M>(g) +
                                  "' absorbs: the finite-volume generator does not take "
                                  "absorbing guards yet; scheme=hat does");
    // Points of the guard: roots of s along lines parallel to every axis.
    std::vector<std::array<double, N>> on;
    std::vector<std::vector<std::vector<double>>> roots_along(N);  // [axis][line] roots
    for (std::size_t a = 0; a < N; ++a) {
      const GridAxis& ax = grid.axes[a];
      const int pieces = std::max(256, 4 * (ax.n - 1));
      for (const auto& base : detail::transverse_samples(grid, a)) {
        auto p = base;
        const auto s = [&](double t) {
          p[a] = t;
          return M::guard_surface(g, p.data(), par);
        };
        std::vector<double> r = detail::line_roots(s, ax.min, ax.max, pieces);
        for (const double t : r) {
          auto q = base;
          q[a] = t;
          on.push_back(q);
        }
        roots_along[a].push_back(std::move(r));
      }
    }
    if (on.empty()) continue;  // the guard does not meet the box
    // ∇s parallel to one axis d, the same at every point.
    int d = -1;
    for (const auto& x : on) {
      std::array<double, N> grad{};
      M::guard_gradient(g, x.data(), par, grad.data());
      std::size_t big = 0;
      for (std::size_t a = 1; a < N; ++a)
        if (std::fabs(grad[a]) > std::fabs(grad[big])) big = a;
      bool axis_parallel = std::isfinite(grad[big]) && grad[big] != 0.0;
      for (std::size_t a = 0; a < N; ++a)
        if (a != big && !(std::fabs(grad[a]) <= kFvGeometryTol * std::fabs(grad[big])))
          axis_parallel = false;
      if (!axis_parallel || (d >= 0 && static_cast<std::size_t>(d) != big)) {
        std::ostringstream w;
        w.precision(6);
        w << "is not a coordinate hyperplane inside the box: at ";
        write_state<M>(w, x);
        w << " its normal grad s = (";
        for (std::size_t a = 0; a < N; ++a) w << (a ? ", " : "") << grad[a];
        w << ") is not parallel to " << (d >= 0 ? "the same axis as elsewhere" : "an axis");
        throw detail::fv_refusal<M>(g, w.str());
      }
      d = static_cast<int>(big);
    }
    const auto du = static_cast<std::size_t>(d);
    const GridAxis& ax = grid.axes[du];
    const double tol = kFvGeometryTol * std::max(1.0, ax.max - ax.min);
    // The same planes on every line parallel to d: s constant in the other coordinates.
    const std::vector<double>& planes = roots_along[du].front();
    for (const auto& r : roots_along[du]) {
      bool same = r.size() == planes.size();
      for (std::size_t k = 0; same && k < r.size(); ++k) same = std::fabs(r[k] - planes[k]) <= tol;
      if (!same)
        throw detail::fv_refusal<M>(
            g,
            "is not a coordinate hyperplane inside the box: its crossings of lines parallel "
            "to " +
                std::string(M::state_names[du]) + " move with the other coordinates");
    }
    for (const double c : planes) {
      FvGuardPlane pl;
      pl.guard = g, pl.from = gi.from, pl.to = gi.to, pl.axis = d, pl.at = c;
      // The normal's sign and the image: sampled points of the plane.
      std::vector<std::array<double, N>> pts = detail::transverse_samples(grid, du);
      std::vector<std::array<double, N>> img(pts.size());
      for (std::size_t k = 0; k < pts.size(); ++k) {
        pts[k][du] = c;
        std::array<double, N> grad{};
        M::guard_gradient(g, pts[k].data(), par, grad.data());
        if (k == 0) pl.normal = grad[du] >= 0.0 ? 1.0 : -1.0;
        M::reset(g, pts[k].data(), par, img[k].data());
      }
      int constant = 0, which = -1;
      const std::array<double, N> first = img.empty() ? std::array<double, N>{} : img.front();
      for (std::size_t a = 0; a < N; ++a) {
        const double ta = kFvGeometryTol * std::max(1.0, grid.axes[a].max - grid.axes[a].min);
        bool same = std::isfinite(first[a]);
        for (const auto& y : img) same = same && std::fabs(y[a] - first[a]) <= ta;
        if (same) ++constant, which = static_cast<int>(a);
      }
      if (constant != 1) {
        std::ostringstream w;
        w.precision(6);
        w << "has the plane " << M::state_names[du] << " = " << c << ", which its reset maps "
          << (constant == 0 ? "onto a set that is not a coordinate hyperplane"
                            : "onto a set of lower dimension");
        throw detail::fv_refusal<M>(g, w.str());
      }
      pl.image_axis = which;
      pl.image_at = first[static_cast<std::size_t>(which)];
      const GridAxis& ia = grid.axes[static_cast<std::size_t>(which)];
      const double itol = kFvGeometryTol * std::max(1.0, ia.max - ia.min);
      pl.image_in_box = pl.image_at >= ia.min - itol && pl.image_at <= ia.max + itol;
      out.push_back(pl);
    }
  }
  return out;
}

/// The cut-cell partition of one axis in one mode (see the file comment).
struct FvAxis {
  std::vector<double> edge;  ///< K + 1 strictly increasing edges; edge[0] = min, edge[K] = max.
  std::vector<char> wall;    ///< Per edge: a wall (box end or cut) that stencils do not cross.
  std::vector<int> seg_lo;   ///< Per cell: the first cell of its segment (between two walls).
  std::vector<int> seg_hi;   ///< Per cell: the last cell of its segment.

  /// Cells.
  int cells() const { return static_cast<int>(edge.size()) - 1; }
  /// Width of cell k.
  double width(int k) const {
    return edge[static_cast<std::size_t>(k) + 1] - edge[static_cast<std::size_t>(k)];
  }
  /// Centre of cell k.
  double centre(int k) const {
    return 0.5 * (edge[static_cast<std::size_t>(k)] + edge[static_cast<std::size_t>(k) + 1]);
  }
  /// The cell holding x (the right one at an edge; the last at max), or -1 outside [min, max].
  int cell_of(double x, double tol) const {
    if (x < edge.front() - tol || x > edge.back() + tol) return -1;
    const auto it = std::upper_bound(edge.begin(), edge.end(), x);
    return std::clamp(static_cast<int>(it - edge.begin()) - 1, 0, cells() - 1);
  }
  /// The edge nearest x.
  int nearest_edge(double x) const {
    const auto it = std::lower_bound(edge.begin(), edge.end(), x);
    int k = static_cast<int>(it - edge.begin());
    if (k >= static_cast<int>(edge.size())) return static_cast<int>(edge.size()) - 1;
    if (k > 0 && x - edge[static_cast<std::size_t>(k) - 1] < edge[static_cast<std::size_t>(k)] - x)
      --k;
    return k;
  }
  /// The p consecutive cells from `start`, moved inside the segment of `cell` (fewer when the
  /// segment is shorter).
  std::vector<int> stencil(int start, int p, int cell) const {
    const int s0 = seg_lo[static_cast<std::size_t>(cell)],
              s1 = seg_hi[static_cast<std::size_t>(cell)];
    p = std::min(p, s1 - s0 + 1);
    start = std::clamp(start, s0, s1 - p + 1);
    std::vector<int> out(static_cast<std::size_t>(p));
    for (int j = 0; j < p; ++j) out[static_cast<std::size_t>(j)] = start + j;
    return out;
  }
};

/// The partition of `a` into dual cells cut at `cuts` (see the file comment). A cut within
/// kFvSnap node spacings of an edge becomes that edge; one within `snap` spacings (at most 1/4)
/// of an interior edge that is not a wall moves that edge onto the cut instead of making a cell
/// thinner than snap·Δx (the time-stepped generator's step is bounded by its thinnest cell,
/// generator_march.hpp; no node changes cell, since edges move by less than Δx/2).
inline FvAxis make_fv_axis(const GridAxis& a, std::vector<double> cuts, double snap = kFvSnap) {
  FvAxis ax;
  const int n = std::max(a.n, 2);
  ax.edge.push_back(a.min);
  for (int i = 0; i + 1 < n; ++i) ax.edge.push_back(0.5 * (axis_node(a, i) + axis_node(a, i + 1)));
  ax.edge.push_back(a.max);
  ax.wall.assign(ax.edge.size(), 0);
  ax.wall.front() = ax.wall.back() = 1;
  const double h = (a.max - a.min) / (n - 1), tiny = kFvSnap * h,
               near = std::clamp(snap, kFvSnap, 0.25) * h;
  std::sort(cuts.begin(), cuts.end());
  for (const double c : cuts) {
    if (c < a.min - tiny || c > a.max + tiny) continue;
    const auto it = std::lower_bound(ax.edge.begin(), ax.edge.end(), c);
    auto k = static_cast<std::size_t>(it - ax.edge.begin());
    const std::size_t last = ax.edge.size() - 1;
    if (k <= last && ax.edge[k] - c <= tiny) {
      if (k > 0 && k < last) ax.edge[k] = c;
      ax.wall[k] = 1;
      continue;
    }
    if (k > 0 && c - ax.edge[k - 1] <= tiny) {
      if (k - 1 > 0) ax.edge[k - 1] = c;
      ax.wall[k - 1] = 1;
      continue;
    }
    // The nearer movable edge (interior, not a wall) within `near`, else a new edge.
    std::size_t best = 0;
    double best_d = near;
    for (const std::size_t j : {k, k - 1})
      if (j > 0 && j < last && !ax.wall[j] && std::fabs(ax.edge[j] - c) <= best_d)
        best = j, best_d = std::fabs(ax.edge[j] - c);
    if (best > 0) {
      ax.edge[best] = c;
      ax.wall[best] = 1;
    } else {
      ax.edge.insert(ax.edge.begin() + static_cast<std::ptrdiff_t>(k), c);
      ax.wall.insert(ax.wall.begin() + static_cast<std::ptrdiff_t>(k), 1);
    }
  }
  const int K = ax.cells();
  ax.seg_lo.resize(static_cast<std::size_t>(K));
  ax.seg_hi.resize(static_cast<std::size_t>(K));
  int lo = 0;
  for (int k = 0; k < K; ++k) {
    if (ax.wall[static_cast<std::size_t>(k)]) lo = k;
    ax.seg_lo[static_cast<std::size_t>(k)] = lo;
  }
  int hi = K - 1;
  for (int k = K - 1; k >= 0; --k) {
    if (ax.wall[static_cast<std::size_t>(k) + 1]) hi = k;
    ax.seg_hi[static_cast<std::size_t>(k)] = hi;
  }
  return ax;
}

/// Weights w with Σ_j w_j·avg_j(q) = q(x) for every polynomial q of degree < cells.size(),
/// avg_j the average over cell j of `ax`: the reconstruction at x from cell averages (a
/// p × p moment system in the variable (ξ − x)/max width; p ≤ 5 here).
inline std::vector<double> fv_recon_weights(const FvAxis& ax, const std::vector<int>& cells,
                                            double x) {
  constexpr std::size_t kMax = 5;
  const std::size_t p = std::min(cells.size(), kMax);
  double s = 0.0;
  for (std::size_t j = 0; j < p; ++j) s = std::max(s, ax.width(cells[j]));
  // A[q][j] = avg_j(t^q), t = (ξ − x)/s; solve Σ_j A[q][j] w_j = δ_q0 (column p: the right side).
  std::array<std::array<double, kMax + 1>, kMax> A{};
  for (std::size_t j = 0; j < p; ++j) {
    const double a = (ax.edge[static_cast<std::size_t>(cells[j])] - x) / s;
    const double b = (ax.edge[static_cast<std::size_t>(cells[j]) + 1] - x) / s;
    double pa = a, pb = b;
    for (std::size_t q = 0; q < p; ++q) {
      A[q][j] = (pb - pa) / (static_cast<double>(q + 1) * (b - a));
      pa *= a, pb *= b;
    }
  }
  A[0][p] = 1.0;
  // Gauss–Jordan elimination with partial pivoting.
  for (std::size_t c = 0; c < p; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < p; ++r)
      if (std::fabs(A[r][c]) > std::fabs(A[piv][c])) piv = r;
    std::swap(A[c], A[piv]);
    for (std::size_t r = 0; r < p; ++r) {
      if (r == c) continue;
      const double f = A[r][c] / A[c][c];
      for (std::size_t k = c; k <= p; ++k) A[r][k] -= f * A[c][k];
    }
  }
  std::vector<double> w(p);
  for (std::size_t j = 0; j < p; ++j) w[j] = A[j][p] / A[j][j];
  return w;
}

}  // namespace hybgen::rt
