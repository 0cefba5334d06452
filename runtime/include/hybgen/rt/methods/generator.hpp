#pragma once
/// \file generator.hpp
/// The Liouville generator of a hybrid system as a conservative finite-volume operator on
/// cut cells (`scheme=fv` of the invariant method; docs/methods.md). No time step:
/// the invariant density is its null vector and its eigenvalues μ give the transfer
/// operator's as λ = e^{μh} (generator_solve.hpp).
///
/// Unknowns: per mode m, the cell averages u_c on the cells of `FvAxis` (generator_geometry.hpp)
/// — the dual cells of the node grid cut at the guards leaving m and the reset images entering
/// m — in C order within the mode, modes one after the other. The mass rate is B u:
///
///   d/dt (vol_c u_c) = Σ_faces ± F,   F = area · ⟨X_d u⟩,
///   ⟨X_d u⟩ ≈ ⟨X_d⟩⟨u⟩ + Σ_{a≠d} h_a²/12 · ∂_aX_d · ∂_a⟨u⟩
///
/// on the face of axis d at x_f, ⟨·⟩ the average over the face. ⟨u⟩ is the upwind
/// reconstruction along d from the cell averages of the upwind side's segment (never across a
/// wall), which is the face's average to the order of the stencil: order 1 the upwind cell;
/// 2 the upwind cell and the one behind; 3 the one behind, the upwind cell and the downwind
/// one (the third-order upwind-biased stencil); 5 two behind, the upwind cell and two
/// downwind. Near a wall a stencil is moved inside the segment, except that above order 3 a
/// face whose stencil a wall would push downwind takes the third-order one instead (a
/// fifth-order stencil shifted by two cells gave a cycle's generator eigenvalues with
/// Re μ > 0). Weights from `fv_recon_weights`. At orders 1 and 2, ⟨X_d u⟩ is X_d(x_f)⟨u⟩ (the
/// midpoint rule). From order 3 the product keeps its transverse term: for X_d = X0 + g·s and
/// u = u0 + u1·s + … along a transverse axis (s the offset from the centre, |s| ≤ h/2),
/// ⟨X_d u⟩ − ⟨X_d⟩⟨u⟩ = g·u1·⟨s²⟩ = g u1 h²/12. ⟨X_d⟩ and g = ∂_aX_d come from X_d at the two
/// Gauss points of each transverse axis; ∂_a⟨u⟩ from the quadratic through ⟨u⟩ on the faces
/// of the rows a−1, a, a+1 (moved inside the segment along a). F leaves the upwind cell and
/// enters the downwind one, except
///   * at a face on a plane of a guard g leaving m, where X crosses in g's direction
///     (sign(∂s/∂x_d · X_d) = direction): F enters the cell of mode to(g) holding Δ_g(x_f), on
///     the side of the image plane that X_{to(g)} points to (the downstream side);
///   * at the box's faces: what leaves is lost (outflow), nothing enters.
/// Invariants: every flux leaves one row and enters another (or the box), so 1ᵀB u = −(the
/// rate u's mass leaves the box): the columns sum to 0 except those in the stencils of the
/// box's outflow faces. When an invariant set lies in the box (the cycle; what leaves is
/// transient), B has a null vector supported there: the invariant density. Neither J_g nor
/// div X is used (the fluxes conserve mass, which does the work of 1/|J|). The generator on
/// densities is L = diag(1/vol)·B.
///
/// Accuracy (measured in tests/validation/test_invariant_errors.cpp, test_invariant_fv.cpp and
/// test_transient_closed_forms.cpp): order p in 1-D and for products of 1-D systems (X_d
/// depends on x_d only within a mode: no transverse term) where the stencils are interior;
/// the third-order stencils next to walls bring the observed order of a fifth-order run to
/// about 4 when a wall is inside the box. Without the transverse term the midpoint rule's
/// O(h²) error dominated the ball's annulus at 257² (t = 1: 2.7e-4 against 4.6e-5 with it);
/// the cross terms between two transverse axes are O(h⁴).
///
/// Node values (`fv_node_values`): per axis, the reconstruction of order p centred on the cell
/// holding the node, in its segment; a node on a cut (a wall inside the box) has two one-sided
/// values and gets their mean, and is flagged (`on_jump`), since the density may jump there.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/core/sparse.hpp"
#include "hybgen/rt/methods/generator_geometry.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// The finite-volume generator of a model on a grid (see the file comment).
template <std::size_t N>
struct FvOperator {
  int n_mode = 0;                           ///< Modes.
  int order = 3;                            ///< Reconstruction order p (1, 2 or 3).
  std::vector<std::array<FvAxis, N>> axes;  ///< Per mode, the partition of every axis.
  std::vector<std::size_t> offset;          ///< Per mode, its first unknown; then the total.
  std::vector<double> vol;                  ///< Per unknown, its cell's volume.
  Eigen::SparseMatrix<double> B;            ///< Mass rate: d/dt (vol·u) = B u.
  std::vector<FvGuardPlane> planes;         ///< The guards' planes and images.
  /// A rate of the model: max over modes, axes and faces of |X_d| / (max_d − min_d).
  double rate = 0.0;
  /// Per unknown, the rate at which volume leaves its cell: Σ area·|X·n| over the faces it
  /// is the upwind cell of. out_rate/vol bounds a stable explicit step (generator_march.hpp).
  std::vector<double> out_rate;
  /// Unknowns.
  std::size_t size() const { return offset.empty() ? 0 : offset.back(); }
  /// Cells of mode m along axis a.
  int cells(int m, std::size_t a) const { return axes[static_cast<std::size_t>(m)][a].cells(); }
};

namespace detail {

/// The cuts of mode m on axis a: the planes of the guards leaving m, the images entering m.
inline std::vector<double> fv_cuts(const std::vector<FvGuardPlane>& planes, int m, int a) {
  std::vector<double> out;
  for (const FvGuardPlane& p : planes) {
    if (p.from == m && p.axis == a) out.push_back(p.at);
    if (p.to == m && p.image_axis == a && p.image_in_box) out.push_back(p.image_at);
  }
  return out;
}

/// Upwind reconstruction at face f of `ax` for flow towards +x (side > 0) or −x: the upwind
/// cell, the stencil and its weights; false at a box face the flow enters through.
inline bool fv_face_stencil(const FvAxis& ax, int f, int side, int p, int& up, std::vector<int>& st,
                            std::vector<double>& w) {
  const int K = ax.cells();
  if (side > 0) {
    up = f - 1;
    if (up < 0) return false;
  } else {
    up = f;
    if (up >= K) return false;
  }
  const auto start = [&](int q) { return side > 0 ? up - q / 2 : up - (q - 1) / 2; };
  // Above order 3, a stencil that a wall would push downwind is unstable (a fifth-order one
  // shifted by two cells gives the generator eigenvalues with Re μ > 0): there the third-order
  // stencil (shifted by at most one cell, stable) is used instead.
  if (p > 3 && (start(p) < ax.seg_lo[static_cast<std::size_t>(up)] ||
                start(p) + p - 1 > ax.seg_hi[static_cast<std::size_t>(up)]))
    p = 3;
  st = ax.stencil(start(p), p, up);
  w = fv_recon_weights(ax, st, ax.edge[static_cast<std::size_t>(f)]);
  return true;
}

}  // namespace detail

/// The finite-volume generator of M on `grid` with reconstruction order `order` (1–3), cut at
/// `planes` (fv_guard_planes), a cut within `snap` node spacings of a dual face moving that face
/// (make_fv_axis). Throws std::invalid_argument for another order.
template <HybridModel M>
FvOperator<state_dim_v<M>> assemble_fv_generator(const TensorGrid<state_dim_v<M>>& grid,
                                                 const double* par,
                                                 const std::vector<FvGuardPlane>& planes, int order,
                                                 double snap = kFvSnap) {
  constexpr std::size_t N = state_dim_v<M>;
  if (order < 1 || order > 5) throw std::invalid_argument("scheme=fv: fv_order must be 1 to 5");
  FvOperator<N> op;
  op.n_mode = M::n_mode;
  op.order = order;
  op.planes = planes;
  op.axes.resize(static_cast<std::size_t>(M::n_mode));
  op.offset.assign(1, 0);
  for (int m = 0; m < M::n_mode; ++m) {
    std::size_t cells = 1;
    for (std::size_t a = 0; a < N; ++a) {
      op.axes[static_cast<std::size_t>(m)][a] =
          make_fv_axis(grid.axes[a], detail::fv_cuts(planes, m, static_cast<int>(a)), snap);
      cells *= static_cast<std::size_t>(op.cells(m, a));
    }
    op.offset.push_back(op.offset.back() + cells);
  }
  const std::size_t n = op.size();
  op.vol.assign(n, 1.0);
  op.out_rate.assign(n, 0.0);
  std::vector<Eigen::Triplet<double>> entries;
  std::array<double, N> x{}, X{}, y{};
  std::vector<int> st;
  std::vector<double> w;
  for (int m = 0; m < M::n_mode; ++m) {
    const auto& ax = op.axes[static_cast<std::size_t>(m)];
    std::array<std::size_t, N> dims{}, stride{};
    for (std::size_t a = 0; a < N; ++a) dims[a] = static_cast<std::size_t>(ax[a].cells());
    stride[N - 1] = 1;
    for (std::size_t a = N - 1; a-- > 0;) stride[a] = stride[a + 1] * dims[a + 1];
    const std::size_t base = op.offset[static_cast<std::size_t>(m)];
    // Volumes.
    for (std::size_t c = 0; c < op.offset[static_cast<std::size_t>(m) + 1] - base; ++c) {
      double v = 1.0;
      for (std::size_t a = 0; a < N; ++a)
        v *= ax[a].width(static_cast<int>((c / stride[a]) % dims[a]));
      op.vol[base + c] = v;
    }
    for (std::size_t d = 0; d < N; ++d) {
      const FvAxis& A = ax[d];
      const double width = grid.axes[d].max - grid.axes[d].min;
      // The guard planes of mode m on faces of axis d, per face.
      std::vector<std::vector<const FvGuardPlane*>> on_face(A.edge.size());
      for (const FvGuardPlane& p : planes)
        if (p.from == m && p.axis == static_cast<int>(d))
          on_face[static_cast<std::size_t>(A.nearest_edge(p.at))].push_back(&p);
      // Faces: index d runs over the K_d + 1 edges, the others over the cells.
      std::array<std::size_t, N> fdims = dims;
      fdims[d] = dims[d] + 1;
      std::size_t faces = 1;
      for (std::size_t a = 0; a < N; ++a) faces *= fdims[a];
      std::array<std::size_t, N> idx{};
      for (std::size_t fl = 0; fl < faces; ++fl) {
        std::size_t rem = fl;
        for (std::size_t a = N; a-- > 0;) idx[a] = rem % fdims[a], rem /= fdims[a];
        double area = 1.0;
        for (std::size_t a = 0; a < N; ++a) {
          if (a == d) {
            x[a] = A.edge[idx[a]];
          } else {
            x[a] = ax[a].centre(static_cast<int>(idx[a]));
            area *= ax[a].width(static_cast<int>(idx[a]));
          }
        }
        M::flow(m, x.data(), par, X.data());
        const double v = X[d];
        // Across the face (order ≥ 3): per transverse axis a, X_d at the two Gauss points of
        // the cell's width h_a give the mean ⟨X_d⟩ (to O(h⁴)) and the slope ∂_aX_d.
        double mean = v;
        std::array<double, N> slope{};
        if (order >= 3)
          for (std::size_t a = 0; a < N; ++a) {
            if (a == d) continue;
            const double delta = ax[a].width(static_cast<int>(idx[a])) / (2.0 * std::sqrt(3.0));
            std::array<double, N> xs = x, Xp{}, Xm{};
            xs[a] = x[a] + delta;
            M::flow(m, xs.data(), par, Xp.data());
            xs[a] = x[a] - delta;
            M::flow(m, xs.data(), par, Xm.data());
            mean += 0.5 * (Xp[d] + Xm[d]) - v;
            slope[a] = (Xp[d] - Xm[d]) / (2.0 * delta);
          }
        const bool varies =
            std::any_of(slope.begin(), slope.end(), [](double g) { return g != 0.0; });
        if (!(v != 0.0) && !(mean != 0.0) && !varies) continue;
        op.rate = std::max(op.rate, std::max(std::fabs(v), std::fabs(mean)) / width);
        // Upwind by X_d at the centre; where it vanishes there, by the mean, else either side.
        const int side = v != 0.0 ? (v > 0.0 ? 1 : -1) : (mean < 0.0 ? -1 : 1);
        const int f = static_cast<int>(idx[d]);
        int up = 0;
        if (!detail::fv_face_stencil(A, f, side, order, up, st, w)) continue;  // inflow: none
        const auto cell = [&](int k) {
          std::size_t c = base;
          for (std::size_t a = 0; a < N; ++a)
            c += stride[a] * (a == d ? static_cast<std::size_t>(k) : idx[a]);
          return static_cast<long>(c);
        };
        long dest = -1;  // -1: out of the box
        const FvGuardPlane* sw = nullptr;
        for (const FvGuardPlane* p : on_face[static_cast<std::size_t>(f)])
          if ((p->normal * side > 0.0 ? 1 : -1) ==
              M::guards[static_cast<std::size_t>(p->guard)].direction)
            sw = p;
        if (sw) {
          M::reset(sw->guard, x.data(), par, y.data());
          const auto& tax = op.axes[static_cast<std::size_t>(sw->to)];
          std::array<double, N> Y{};
          M::flow(sw->to, y.data(), par, Y.data());
          std::size_t c = op.offset[static_cast<std::size_t>(sw->to)], s = 1;
          bool inside = sw->image_in_box;
          for (std::size_t a = N; inside && a-- > 0;) {
            const FvAxis& T = tax[a];
            int k;
            if (static_cast<int>(a) == sw->image_axis) {
              const int e = T.nearest_edge(sw->image_at);
              k = std::clamp(Y[a] >= 0.0 ? e : e - 1, 0, T.cells() - 1);
            } else {
              k = T.cell_of(y[a], kFvGeometryTol * (T.edge.back() - T.edge.front()));
            }
            if (k < 0) inside = false;
            c += s * static_cast<std::size_t>(std::max(k, 0));
            s *= static_cast<std::size_t>(T.cells());
          }
          if (inside) dest = static_cast<long>(c);
        } else {
          const int down = side > 0 ? f : f - 1;
          if (down >= 0 && down < A.cells()) dest = cell(down);
        }
        const long src = cell(up);
        // side·F = side·area·(⟨X_d⟩⟨u⟩ + Σ_a h_a²/12 ∂_aX_d ∂_a⟨u⟩) leaves src (see the file
        // comment); ⟨u⟩ on the face of a row is Σ_j w_j u(st_j) in that row.
        const auto deposit = [&](double coef, std::size_t a, int k) {  // coef·⟨u⟩, row k on a
          const long shift =
              a < N ? static_cast<long>(stride[a]) * (k - static_cast<long>(idx[a])) : 0;
          for (std::size_t j = 0; j < st.size(); ++j) {
            const long col = cell(st[j]) + shift;
            entries.emplace_back(src, col, -coef * w[j]);
            if (dest >= 0) entries.emplace_back(dest, col, coef * w[j]);
          }
        };
        for (std::size_t a = 0; a < N; ++a) {
          if (!(slope[a] != 0.0)) continue;
          const FvAxis& T = ax[a];
          const int k = static_cast<int>(idx[a]);
          const double h = T.width(k);
          const std::vector<int> ts = T.stencil(k - 1, 3, k);
          if (ts.size() < 2) continue;
          // ∂_a⟨u⟩ at the centre: the exact derivative of the quadratic (or line) through the
          // rows' face averages, from its values half a width either side.
          const std::vector<double> wp = fv_recon_weights(T, ts, T.centre(k) + 0.5 * h);
          const std::vector<double> wm = fv_recon_weights(T, ts, T.centre(k) - 0.5 * h);
          for (std::size_t t = 0; t < ts.size(); ++t)
            deposit(side * area * h / 12.0 * slope[a] * (wp[t] - wm[t]), a, ts[t]);
        }
        op.out_rate[static_cast<std::size_t>(src)] +=
            area * std::max(std::fabs(v), std::fabs(mean));
        deposit(side * area * mean, N, 0);
      }
    }
  }
  op.B.resize(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  op.B.setFromTriplets(entries.begin(), entries.end());
  op.B.makeCompressed();
  return op;
}

/// Node values from cell averages along one axis: per node, its (cell, weight) pairs, and
/// whether the node lies on a wall inside the box (two one-sided values, averaged).
struct FvNodeRows {
  std::vector<std::vector<std::pair<int, double>>> rows;  ///< Per node.
  std::vector<char> on_jump;                              ///< Per node.
};

/// The node rows of `ax` for the nodes of `a` at order p (see the file comment).
inline FvNodeRows fv_node_rows(const FvAxis& ax, const GridAxis& a, int p) {
  FvNodeRows out;
  const double tol = kFvSnap * (a.max - a.min);
  const auto one_side = [&](int k, double x) {
    std::vector<int> st = ax.stencil(k - (p - 1) / 2, p, k);
    if (p == 2 && x < ax.centre(k)) st = ax.stencil(k - 1, 2, k);
    const std::vector<double> w = fv_recon_weights(ax, st, x);
    std::vector<std::pair<int, double>> r;
    for (std::size_t j = 0; j < st.size(); ++j) r.emplace_back(st[j], w[j]);
    return r;
  };
  for (int i = 0; i < a.n; ++i) {
    const double x = axis_node(a, i);
    const int k = ax.cell_of(x, tol);
    const int e = ax.nearest_edge(x);
    const bool jump = e > 0 && e < ax.cells() && ax.wall[static_cast<std::size_t>(e)] &&
                      std::fabs(ax.edge[static_cast<std::size_t>(e)] - x) <= tol;
    std::vector<std::pair<int, double>> r;
    if (jump) {
      for (auto [c, wt] : one_side(e - 1, x)) r.emplace_back(c, 0.5 * wt);
      for (auto [c, wt] : one_side(e, x)) r.emplace_back(c, 0.5 * wt);
    } else {
      r = one_side(k, x);
    }
    out.rows.push_back(std::move(r));
    out.on_jump.push_back(jump ? 1 : 0);
  }
  return out;
}

/// The node densities [mode][node] of the cell averages `u` of `op` on `grid`, and per
/// (mode, node) whether the node lies on a cut of its mode (`on_jump`, may be null).
template <std::size_t N>
std::vector<double> fv_node_values(const FvOperator<N>& op, const TensorGrid<N>& grid,
                                   const std::vector<double>& u, std::vector<char>* on_jump) {
  const std::size_t nodes = grid.size();
  std::vector<double> out(static_cast<std::size_t>(op.n_mode) * nodes);
  if (on_jump) on_jump->assign(out.size(), 0);
  for (int m = 0; m < op.n_mode; ++m) {
    const auto& ax = op.axes[static_cast<std::size_t>(m)];
    std::array<std::size_t, N> dims{};
    for (std::size_t a = 0; a < N; ++a) dims[a] = static_cast<std::size_t>(ax[a].cells());
    std::vector<double> cur(
        u.begin() + static_cast<std::ptrdiff_t>(op.offset[static_cast<std::size_t>(m)]),
        u.begin() + static_cast<std::ptrdiff_t>(op.offset[static_cast<std::size_t>(m) + 1]));
    std::array<FvNodeRows, N> rows;
    for (std::size_t a = 0; a < N; ++a) {
      rows[a] = fv_node_rows(ax[a], grid.axes[a], op.order);
      // Along axis a: dims[a] cells → n_a nodes.
      std::size_t outer = 1, inner = 1;
      for (std::size_t b = 0; b < a; ++b) outer *= dims[b];
      for (std::size_t b = a + 1; b < N; ++b) inner *= dims[b];
      const auto na = static_cast<std::size_t>(grid.axes[a].n);
      std::vector<double> next(outer * na * inner, 0.0);
      for (std::size_t o = 0; o < outer; ++o)
        for (std::size_t i = 0; i < na; ++i)
          for (const auto& [c, wt] : rows[a].rows[i]) {
            const double* src = cur.data() + (o * dims[a] + static_cast<std::size_t>(c)) * inner;
            double* dst = next.data() + (o * na + i) * inner;
            for (std::size_t r = 0; r < inner; ++r) dst[r] += wt * src[r];
          }
      cur.swap(next);
      dims[a] = na;
    }
    std::copy(cur.begin(), cur.end(),
              out.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(m) * nodes));
    if (on_jump)
      for (std::size_t node = 0; node < nodes; ++node) {
        std::size_t rem = node;
        bool j = false;
        for (std::size_t a = N; a-- > 0;) {
          const auto na = static_cast<std::size_t>(grid.axes[a].n);
          j = j || rows[a].on_jump[rem % na];
          rem /= na;
        }
        (*on_jump)[static_cast<std::size_t>(m) * nodes + node] = j ? 1 : 0;
      }
  }
  return out;
}

}  // namespace hybgen::rt
