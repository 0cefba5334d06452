#pragma once
/// \file mass_budget.hpp
/// Mass budgets over the grid box with fixed tensor rules (tests and their references): the
/// mass in the box by tensor cubature of the exact density, the cumulative outflow through its
/// faces by the time integral of the flux along characteristics, and the atom as what remains
/// (which then also holds what resets carried out of the box). The runs' budgets (budget=fast
/// and full) are budget.hpp's adaptive ones, every term measured and its error bounded.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// A mass budget and the first failed characteristic, if any.
template <std::size_t N>
struct BudgetResult {
  MassBudget budget;          ///< The budget (partial if a trace failed).
  TraceFailure<N> failure{};  ///< First failed characteristic.
  std::string message;        ///< Another failure (a forward flow of the atom), or empty.
  /// Whether every characteristic and flow succeeded.
  bool ok() const { return failure.ok() && message.empty(); }
};

namespace detail {

/// The outward normal flux density X_m·n_out of mode m at a point y of the face of the box
/// [lo, hi] normal to `axis` (n_out = `sign` e_axis), or 0 where the mass crossing there is
/// not gained or lost by the box: at a point of a guard surface S_h where h fires, the mass is
/// reset to Δ_h(y); it leaves the box iff it crosses outwards and Δ_h(y) is outside, and it
/// enters iff it arrives from outside and Δ_h(y) is inside. `diam` scales the surface test.
template <HybridModel M>
double face_flux(int m, const double* y, std::size_t axis, double sign,
                 const std::array<double, state_dim_v<M>>& lo,
                 const std::array<double, state_dim_v<M>>& hi, double diam, const double* par) {
  constexpr std::size_t N = state_dim_v<M>;
  std::array<double, N> X{};
  M::flow(m, y, par, X.data());
  const double xn = sign * X[axis];
  bool fires = false, image_in_box = false;
  for (std::size_t g = 0; g < static_cast<std::size_t>(M::n_guard) && !fires; ++g) {
    const GuardInfo gi = guard_info<M>(g);
    if (gi.from != m) continue;
    std::array<double, N> grad{}, img{};
    M::guard_gradient(static_cast<int>(g), y, par, grad.data());
    const double gn = std::sqrt(dot<N>(grad.data(), grad.data()));
    if (!(std::fabs(M::guard_surface(static_cast<int>(g), y, par)) <= 1e-12 * gn * diam)) continue;
    if (sign_of(dot<N>(grad.data(), X.data())) != gi.direction) continue;
    M::reset(static_cast<int>(g), y, par, img.data());
    fires = true;
    image_in_box = in_box<N>(img.data(), lo, hi);
  }
  const bool counts = !fires || (xn > 0.0 ? !image_in_box : image_in_box);
  return counts ? xn : 0.0;
}

/// Default relative tolerance of the time integral of the boundary flux
/// (CharacteristicsOptions::cumulative_tol) when the caller sets none.
inline constexpr double kFluxTimeTol = 1e-8;

/// `opt` with the time integral of the flux switched on (its own tolerance, or kFluxTimeTol).
inline CharacteristicsOptions cumulative_options(const CharacteristicsOptions& opt) {
  CharacteristicsOptions o = opt;
  if (!(o.cumulative_tol > 0.0)) o.cumulative_tol = kFluxTimeTol;
  return o;
}

/// Cumulative net outflow through the faces of `box` at the output times, with the tensor
/// rules `face` (rule of axis b used along b on every face normal to another axis); in time,
/// ∫₀^{t_k} u dt at each face point adaptively along its characteristic (`cumulative_tol`).
/// Resets on the faces are accounted for: at a face point on a guard surface S_h where h fires,
/// the crossing mass counts as outflow only if Δ_h(y) lies outside the box (and as inflow,
/// when it arrives from outside, only if Δ_h(y) lies inside); on a reset image the part of
/// the density reset from inside the box is no inflow (see `FaceContext`). For the bouncing
/// ball the ground face therefore carries no net flux, exactly, instead of two log-divergent
/// fluxes near a Zeno point whose quadratures do not cancel.
template <HybridModel M>
std::vector<double> outflow(const TensorGrid<state_dim_v<M>>& box,
                            const std::array<AxisRule, state_dim_v<M>>& face,
                            std::span<const double> times, const double* par,
                            const CharacteristicsOptions& opt,
                            TraceFailure<state_dim_v<M>>& failure) {
  constexpr std::size_t N = state_dim_v<M>;
  const std::size_t K = times.size();
  std::vector<double> result(K, 0.0);
  if (K == 0 || times.back() <= 0.0) return result;
  // Face points.
  std::array<double, N> lo{}, hi{};
  double diam = 0.0;
  for (std::size_t a = 0; a < N; ++a) {
    lo[a] = box.axes[a].min;
    hi[a] = box.axes[a].max;
    diam = std::max(diam, hi[a] - lo[a]);
  }
  std::vector<std::array<double, N>> pts;
  std::vector<FaceContext<N>> ctx;
  std::vector<double> wts;
  std::vector<std::size_t> axis_of;
  std::vector<double> sign_of_face;
  for (std::size_t a = 0; a < N; ++a) {
    for (int side = -1; side <= 1; side += 2) {
      if (side == 1 && hi[a] == lo[a]) continue;
      std::size_t total = 1;
      for (std::size_t b = 0; b < N; ++b)
        if (b != a) total *= face[b].nodes.size();
      for (std::size_t flat = 0; flat < total; ++flat) {
        std::array<double, N> y{};
        double w = 1.0;
        std::size_t rem = flat;
        for (std::size_t b = N; b-- > 0;) {
          if (b == a) continue;
          const std::size_t n = face[b].nodes.size();
          y[b] = face[b].nodes[rem % n];
          w *= face[b].weights[rem % n];
          rem /= n;
        }
        y[a] = side < 0 ? lo[a] : hi[a];
        FaceContext<N> c{};
        c.inward[a] = side < 0 ? 1.0 : -1.0;
        c.lo = lo;
        c.hi = hi;
        pts.push_back(y);
        ctx.push_back(c);
        wts.push_back(w);
        axis_of.push_back(a);
        sign_of_face.push_back(static_cast<double>(side));
      }
    }
  }
  const Solution<N> sol =
      evaluate<M>(std::span<const std::array<double, N>>(pts), times, par, cumulative_options(opt),
                  std::span<const FaceContext<N>>(ctx));
  if (!sol.ok()) {
    failure = sol.failure;
    return result;
  }
  // Flux weights w·(X_m·n_out) per (mode, point), 0 where the mass is reset into the box.
  const std::size_t nm = static_cast<std::size_t>(M::n_mode);
  std::vector<double> fw(nm * pts.size(), 0.0);
  for (std::size_t m = 0; m < nm; ++m) {
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const double* y = pts[i].data();
      if (!M::in_support(y, par)) continue;
      fw[m * pts.size() + i] = wts[i] * face_flux<M>(static_cast<int>(m), y, axis_of[i],
                                                     sign_of_face[i], lo, hi, diam, par);
    }
  }
  for (std::size_t k = 0; k < K; ++k)
    for (std::size_t m = 0; m < nm; ++m)
      for (std::size_t i = 0; i < pts.size(); ++i)
        result[k] += fw[m * pts.size() + i] * sol.at(k, m, i);
  return result;
}

template <HybridModel M>
double initial_mass(const std::array<const AxisRule*, state_dim_v<M>>& rules, const double* par) {
  double s = 0.0;
  for (int m = 0; m < M::n_mode; ++m) {
    s += tensor_sum<state_dim_v<M>>(rules, [&](std::size_t flat) {
      const auto y = tensor_node<state_dim_v<M>>(rules, flat);
      return M::in_support(y.data(), par) ? M::initial_density(m, y.data(), par) : 0.0;
    });
  }
  return s;
}

}  // namespace detail

/// Mass budget of a grid solution (the runner's default): masses by the tensor trapezoid rule
/// on the grid nodes (from `sol`), outflow through the faces of the grid box by the trapezoid
/// rule on the face nodes and adaptively in time (`detail::outflow`).
template <HybridModel M>
BudgetResult<state_dim_v<M>> mass_budget(const TensorGrid<state_dim_v<M>>& grid,
                                         const Solution<state_dim_v<M>>& sol,
                                         std::span<const double> times, const double* par,
                                         const CharacteristicsOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  BudgetResult<N> res;
  std::array<AxisRule, N> rules;
  std::array<const AxisRule*, N> rp{};
  for (std::size_t a = 0; a < N; ++a) {
    rules[a] = trapezoid_rule(grid.axes[a]);
    rp[a] = &rules[a];
  }
  MassBudget& mb = res.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = detail::initial_mass<M>(rp, par);
  mb.mass.assign(times.size(), 0.0);
  for (std::size_t k = 0; k < times.size() && k < sol.n_time; ++k)
    for (std::size_t m = 0; m < sol.n_mode; ++m)
      mb.mass[k] += detail::tensor_sum<N>(rp, [&](std::size_t i) { return sol.at(k, m, i); });
  mb.outflow = detail::outflow<M>(grid, rules, times, par, opt, res.failure);
  mb.atom.resize(times.size());
  for (std::size_t k = 0; k < times.size(); ++k) mb.atom[k] = mb.mass0 - mb.mass[k] - mb.outflow[k];
  return res;
}

/// Mass budget with explicit tensor quadrature rules: `volume` (one rule per axis, spanning
/// the box of `box`) for the masses, `face` for the faces; the density is evaluated by
/// characteristics at the quadrature nodes (use graded Gauss–Legendre near singularities).
template <HybridModel M>
BudgetResult<state_dim_v<M>> mass_budget(const TensorGrid<state_dim_v<M>>& box,
                                         const std::array<AxisRule, state_dim_v<M>>& volume,
                                         const std::array<AxisRule, state_dim_v<M>>& face,
                                         std::span<const double> times, const double* par,
                                         const CharacteristicsOptions& opt) {
  constexpr std::size_t N = state_dim_v<M>;
  BudgetResult<N> res;
  std::array<const AxisRule*, N> rp{};
  std::size_t total = 1;
  for (std::size_t a = 0; a < N; ++a) {
    rp[a] = &volume[a];
    total *= volume[a].nodes.size();
  }
  MassBudget& mb = res.budget;
  mb.times.assign(times.begin(), times.end());
  mb.mass0 = detail::initial_mass<M>(rp, par);
  const Solution<N> sol = detail::solve_points<M>(
      total, [&rp](std::size_t i) { return detail::tensor_node<N>(rp, i); },
      [](std::size_t) -> const FaceContext<N>* { return nullptr; }, times, par, opt);
  mb.mass.assign(times.size(), 0.0);
  if (!sol.ok()) res.failure = sol.failure;
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t m = 0; m < sol.n_mode; ++m)
      mb.mass[k] += detail::tensor_sum<N>(rp, [&](std::size_t i) { return sol.at(k, m, i); });
  TraceFailure<N> flux_failure;
  mb.outflow = detail::outflow<M>(box, face, times, par, opt, flux_failure);
  if (res.failure.ok()) res.failure = flux_failure;
  mb.atom.resize(times.size());
  for (std::size_t k = 0; k < times.size(); ++k) mb.atom[k] = mb.mass0 - mb.mass[k] - mb.outflow[k];
  return res;
}

}  // namespace hybgen::rt
