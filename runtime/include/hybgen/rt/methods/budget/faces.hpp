#pragma once
/// \file faces.hpp
/// The outflow term of the mass budget: the cumulative net outflow through the faces of the
/// grid box at every output time, by the adaptive cubature (budget/cubature.hpp) over the
/// faces of a time integral along each face point's backward characteristic.
///
/// Faces: one cubature over all 2N faces together (cells tagged with their face), of the
/// cumulative outflow density at each output time (see `detail::FaceValues`); in time the
/// integral ∫₀^{t_k} u dt is taken along each face point's characteristic by adaptive
/// Gauss–Legendre on the ODE's dense output (CharacteristicsOptions::cumulative_tol), so a
/// flux that starts or stops inside an output interval costs a few more panels, not accuracy.
/// A face point costs one characteristic for all times, so the faces are cheap.
///
/// Bounded work in time too: each face characteristic's time integral halves at most a fixed
/// number of panels per branch (Tracer::accumulate, characteristics.hpp), and below the
/// density c_ref = kFluxFloorFraction·scale/|box| it accepts any panel, so an integrand that
/// is rounding noise where u0 is 0 in exact arithmetic (a compactly supported u0 written with
/// abs or max, expanded into cancelling terms) costs no more than one that is 0. What a
/// capped time integral leaves unresolved, and the most the floor can change, are
/// integrated over the faces on the same cells as the outflow (passive slots of the
/// cubature) into `AdaptiveOutflow::time_error`; the points capped are counted, and a
/// capped outflow is not `converged`.

#include <algorithm>
#include <array>
#include <cstddef>
#include <span>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/methods/budget/cubature.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/mass_budget.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Result of `adaptive_outflow`: cumulative net outflow through the box faces
/// (`error[k]`: the space part of outflow[k]'s error; points are face points).
struct AdaptiveOutflow : CubatureStats {
  std::vector<double> outflow;  ///< ∫₀^{t_k} Σ_modes ∮_∂box u X·n_out, per output time.
  /// The time integrals' share of outflow[k]'s error beyond their tolerance: what their work
  /// cap left unresolved plus the most their floor can change (empty for the atom).
  std::vector<double> time_error;
  std::size_t time_capped = 0;  ///< Face (point, mode) pairs whose time integral was capped.
};

/// The time integrals of the faces accept any panel below c_ref = kFluxFloorFraction times
/// the box's mean density at the budget's scale (`adaptive_outflow`): far above the rounding
/// noise of a u0 that is 0 by cancellation, far below the densities whose flux the budget
/// measures (its share of the outflow's error is ≤ time_tol·kFluxFloorFraction·scale·t_k·
/// (flux through the faces per unit density)/|box|, and is added to the error).
inline constexpr double kFluxFloorFraction = 1e-3;

namespace detail {

/// Face integrand: the cumulative net outflow density at a face point,
///   g_k(y) = Σ_m fw_m(y) ∫₀^{t_k} u(t, m, y) dt,
/// the time integral taken along the characteristic from y to the tolerance `time_tol`
/// (CharacteristicsOptions::cumulative_tol: adaptive in time, so a flux that starts or stops
/// inside an output interval is integrated as accurately as one that does not), u the limit
/// from inside the box (FaceContext) and the flux weight fw_m = X_m·n_out, except at a point
/// of a guard surface S_h where h fires: the mass crossing there is reset to Δ_h(y) and
/// counts only if it leaves the box (outwards, Δ_h(y) outside) or enters it (inwards, Δ_h(y)
/// inside) — the rule of `detail::outflow`. Face f = 2a + side is normal to axis a at lo[a]
/// (side 0) or hi[a] (side 1); its D = N − 1 coordinates are the other axes in order; a
/// cell's tag indexes `face`.
template <HybridModel M>
struct FaceValues {
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  static constexpr std::size_t D = N - 1;           ///< Face dimension.
  std::span<const double> times;                    ///< Output times.
  std::array<double, N> lo{}, hi{};                 ///< The box.
  double diam = 0.0;                                ///< Largest box side.
  const double* par = nullptr;                      ///< Parameters.
  CharacteristicsOptions opt{};                     ///< Options, cumulative_tol > 0.
  TraceFailure<N> failure{};                        ///< First failure.
  std::vector<std::size_t> face;                    ///< Face 2a + side of each root box.
  std::size_t capped = 0;  ///< (point, mode) pairs whose time integral reached its work cap.
  std::vector<std::array<double, N>> y;  ///< Work: the points in ℝᴺ.
  std::vector<FaceContext<N>> ctx;       ///< Work: their faces.

  /// U[i·2K + k] = g_k(point i) for the face of each point's cell, and in the passive slots
  /// U[i·2K + K + k] = Σ_m |fw_m|·(the time integral's unresolved error + tol·c_ref·t_k), the
  /// most its error exceeds the relative tolerance by (opt.cumulative_errors is set).
  bool operator()(std::span<const Cell<D>> cells, std::span<const std::array<double, D>> pts,
                  std::size_t per_cell, std::vector<double>& U) {
    const std::size_t P = pts.size(), K = times.size(), KS = 2 * K;
    y.resize(P);
    ctx.resize(P);
    for (std::size_t i = 0; i < P; ++i) {
      const std::size_t f = face[cells[i / per_cell].tag], a = f / 2;
      if constexpr (D > 0) {
        for (std::size_t b = 0, j = 0; b < N; ++b)
          if (b != a) y[i][b] = pts[i][j++];
      }
      y[i][a] = f % 2 == 0 ? lo[a] : hi[a];
      ctx[i] = FaceContext<N>{};
      ctx[i].inward[a] = f % 2 == 0 ? 1.0 : -1.0;
      ctx[i].lo = lo;
      ctx[i].hi = hi;
    }
    const Solution<N> sol = evaluate<M>(std::span<const std::array<double, N>>(y), times, par, opt,
                                        std::span<const FaceContext<N>>(ctx));
    if (!sol.ok()) {
      failure = sol.failure;
      return false;
    }
    for (std::size_t i = 0; i < P; ++i) {
      const std::size_t a = face[cells[i / per_cell].tag] / 2;
      const double sign = ctx[i].inward[a] > 0.0 ? -1.0 : 1.0;  // n_out along a
      const double* yi = y[i].data();
      if (!M::in_support(yi, par)) continue;
      for (std::size_t m = 0; m < sol.n_mode; ++m) {
        const double xn = face_flux<M>(static_cast<int>(m), yi, a, sign, lo, hi, diam, par);
        if (xn == 0.0) continue;
        if (sol.at(KS - 1, m, i) > 0.0) ++capped;  // cumulative: t_K's error is the largest
        for (std::size_t k = 0; k < K; ++k) {
          U[i * KS + k] += xn * sol.at(k, m, i);
          const double floor = opt.cumulative_tol * opt.cumulative_floor * times[k];
          U[i * KS + K + k] += std::fabs(xn) * (sol.at(K + k, m, i) + floor);
        }
      }
    }
    return true;
  }
};

}  // namespace detail

/// Adaptive cubature of the cumulative net outflow through the faces of `box` (the rule of
/// `detail::outflow`, see `detail::FaceValues`), all faces in one cubature; in time the
/// integral along each face point's characteristic to the relative tolerance `time_tol`,
/// with the floor c_ref = kFluxFloorFraction·scale/|box| (none if scale ≤ 0) and its work
/// cap (file comment; `time_error`, `time_capped`). The target is rel_tol·scale per output
/// time (scale: e.g. the box mass; ≤ 0: the largest |outflow|).
template <HybridModel M>
AdaptiveOutflow adaptive_outflow(const TensorGrid<state_dim_v<M>>& box,
                                 std::span<const double> times, const double* par,
                                 const CharacteristicsOptions& opt, const AdaptiveOptions& aopt,
                                 double scale, double time_tol,
                                 TraceFailure<state_dim_v<M>>& failure) {
  constexpr std::size_t N = state_dim_v<M>;
  constexpr std::size_t D = N - 1;
  detail::validate_times(times);
  AdaptiveOutflow res;
  res.outflow.assign(times.size(), 0.0);
  res.error.assign(times.size(), 0.0);
  detail::FaceValues<M> values;
  values.times = times;
  values.par = par;
  values.opt = opt;
  values.opt.cumulative_tol = time_tol > 0.0 ? time_tol : detail::kFluxTimeTol;
  values.opt.cumulative_errors = true;
  res.time_error.assign(times.size(), 0.0);
  if (times.empty() || times.back() <= 0.0) {
    res.converged = true;
    return res;
  }
  std::vector<detail::Cell<D>> faces;
  double volume = 1.0;  // |box| over its axes of positive width
  for (std::size_t a = 0; a < N; ++a) {
    values.lo[a] = box.axes[a].min;
    values.hi[a] = box.axes[a].max;
    values.diam = std::max(values.diam, values.hi[a] - values.lo[a]);
    if (values.hi[a] > values.lo[a]) volume *= values.hi[a] - values.lo[a];
  }
  values.opt.cumulative_floor = scale > 0.0 ? kFluxFloorFraction * scale / volume : 0.0;
  for (std::size_t a = 0; a < N; ++a) {
    for (std::size_t side = 0; side < 2; ++side) {
      if (side == 1 && values.hi[a] == values.lo[a]) continue;
      detail::Cell<D> f;
      for (std::size_t b = 0, j = 0; b < N; ++b) {
        if (b == a) continue;
        f.lo[j] = values.lo[b];
        f.hi[j] = values.hi[b];
        ++j;
      }
      f.tag = faces.size();
      faces.push_back(f);
      values.face.push_back(2 * a + side);
    }
  }
  // Slots: the outflow at the K times (targeted), then their time errors (passive).
  const std::size_t K = times.size();
  const std::size_t per_point = 2 * K * (1 + static_cast<std::size_t>(M::n_mode));
  detail::AdaptiveCubature<D, detail::FaceValues<M>> cub(faces, 2 * K, per_point, aopt, scale,
                                                         values, nullptr, K);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  detail::collect(cub, ok, 0, K, res.outflow, res);
  for (std::size_t k = 0; k < K; ++k) res.time_error[k] = std::max(cub.integral(K + k), 0.0);
  res.time_capped = values.capped;
  if (res.time_capped > 0) res.converged = false;  // stopped by a bound: say so
  return res;
}

}  // namespace hybgen::rt
