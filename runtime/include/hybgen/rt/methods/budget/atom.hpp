#pragma once
/// \file atom.hpp
/// The two terms of the mass budget that FORWARD flows (forward.hpp) measure, by the adaptive
/// cubature (budget/cubature.hpp) of the initial density, independently of the backward
/// characteristics that give the volume and the outflow through the faces:
///  * the atom: the mass come to rest at Zeno points by each output time;
///  * the reset outflow: the net mass that resets carry across the grid box's boundary (out
///    of the box, minus back into it) by each output time. A reset may land outside the box
///    (a slanted wall throws a corner of a momentum box out of it); that mass has left the
///    computed region as surely as mass crossing a face, and the budget counts it with the
///    outflow (budget.hpp), as the transfer and particle methods do.
///  * the mass each absorbing guard took (model.hpp, `absorbs`) by each output time; what
///    one absorbs inside the box (not on a face, where the faces' integral sees it leave)
///    is reset outflow too.
/// All come from the same flows (`adaptive_atom`), with the outflow's shape
/// (`AdaptiveOutflow`, budget/faces.hpp). The cubature covers the part of the box where the
/// grid's nodes carry initial mass.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/methods/budget/check_points.hpp"
#include "hybgen/rt/methods/budget/cubature.hpp"
#include "hybgen/rt/methods/budget/faces.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/forward.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Largest number of check points of the atom's cubature: each costs a forward flow, so a
/// quarter of the cubature's own point cap (`adaptive_atom`).
inline std::size_t max_atom_checks(const AdaptiveOptions& aopt) {
  return std::max<std::size_t>(aopt.max_points / 4, 1);
}

namespace detail {

/// The forward integrand, V = (2 + G)·K values per point (K output times, G guards): the
/// atom's
///   U[i·V + k]     = Σ_m u0(m, x_i)·[t_Z(m, x_i) ≤ t_k],
/// the initial density of the points whose flow has come to rest at a Zeno accumulation
/// point by t_k (forward.hpp's Zeno signature), the reset outflow's
///   U[i·V + K + k] = Σ_m u0(m, x_i)·(number of resets before or at t_k from a state in the
///                    box [lo, hi] to one outside it, minus those from outside into it, plus
///                    an absorption inside the box; what the faces' integral counts is left
///                    to it: `crossing`),
/// and each guard g's absorbed mass (0 for a guard that does not absorb)
///   U[i·V + (2 + g)·K + k] = Σ_m u0(m, x_i)·[absorbed by g at t ≤ t_k].
/// Only Zeno points in the box are atoms: one outside it is mass that has left.
/// Both are thereby MEASURED where they happen, independently of the backward
/// characteristics that give the mass and the outflow through the faces, so mass0 − mass −
/// outflow − atom is a real check of the budget. A forward flow that hits its event cap
/// without the Zeno signature (chattering) or fails numerically is a failure of the budget
/// (`failure`).
template <HybridModel M>
struct ZenoValues {
  static constexpr std::size_t N = state_dim_v<M>;  ///< State dimension.
  std::span<const double> times;                    ///< Output times.
  const double* par = nullptr;                      ///< Parameters.
  std::array<double, N> lo{};                       ///< The grid box's lower corner.
  std::array<double, N> hi{};                       ///< The grid box's upper corner.
  ForwardOptions fopt{};                            ///< Options of the forward flows.
  const Backend* backend = nullptr;  ///< Ranks sharing the points (null: this process).
  std::string failure;               ///< First failure (describe), or empty.

  /// The inward normals of the faces x lies on (to 1e-10 of the box's width), summed: zero
  /// when x is on none.
  std::array<double, N> face_inward(const std::array<double, N>& x) const {
    std::array<double, N> n{};
    for (std::size_t a = 0; a < N; ++a) {
      const double tol = 1e-10 * (hi[a] - lo[a]);
      if (std::fabs(x[a] - lo[a]) <= tol) n[a] += 1.0;
      if (std::fabs(x[a] - hi[a]) <= tol) n[a] -= 1.0;
    }
    return n;
  }

  /// Whether x lies on a face of the box: a guard on a face (the bouncing ball's ground at
  /// x = 0) resets the mass crossing it there, and the faces' integral already counts what it
  /// resets out of the box, or into it from outside (mass_budget.hpp, face_flux), so the
  /// reset outflow leaves resets FROM a face out.
  bool on_faces(const std::array<double, N>& x) const {
    for (const double v : face_inward(x))
      if (v != 0.0) return true;
    return false;
  }

  /// +1 when a reset of guard g from `before` to `after` carries mass out of the box, −1 into
  /// it, 0 otherwise or when the faces' integral counts it. An image ON a face is inside when
  /// the target mode's flow enters the box there: the faces' integral takes the limit from
  /// inside (characteristics.hpp, spawn_from with a face), so it counts such mass reset from
  /// outside as inflow itself (0 here) and mass reset from inside is an internal transfer;
  /// where the flow leaves at once the image is outside, mass the faces do not see.
  int crossing(int g, const std::array<double, N>& before,
               const std::array<double, N>& after) const {
    if (on_faces(before)) return 0;
    const bool from_in = in_box<N>(before.data(), lo, hi);
    bool to_in = in_box<N>(after.data(), lo, hi);
    if (to_in) {
      const std::array<double, N> inward = face_inward(after);
      if (on_faces(after)) {
        std::array<double, N> X{};
        M::flow(guard_info<M>(static_cast<std::size_t>(g)).to, after.data(), par, X.data());
        if (dot<N>(X.data(), inward.data()) > 0.0) return 0;
        to_in = false;
      }
    }
    return from_in == to_in ? 0 : (from_in ? 1 : -1);
  }

  /// Values per point: V = (2 + G)·K.
  std::size_t values_per_point() const {
    return (2 + static_cast<std::size_t>(M::n_guard)) * times.size();
  }

  /// U[i·V + j] as above, OpenMP over the points.
  bool operator()(std::span<const Cell<N>>, std::span<const std::array<double, N>> pts, std::size_t,
                  std::vector<double>& U) {
    const std::size_t K = times.size(), V = values_per_point();
    const auto P = static_cast<long long>(pts.size());
    const Backend& b = backend ? *backend : serial_backend();
    const Block mine = b.block(pts.size());
    std::atomic<long long> first_fail{P};
    std::string msg;
#pragma omp parallel
    {
      ForwardFlow<M> flow(par, fopt);
#pragma omp for schedule(dynamic, 8)
      for (auto ii = static_cast<long long>(mine.begin); ii < static_cast<long long>(mine.end);
           ++ii) {
        if (ii > first_fail.load(std::memory_order_relaxed)) continue;
        const auto i = static_cast<std::size_t>(ii);
        const std::array<double, N>& x = pts[i];
        if (!M::in_support(x.data(), par)) continue;
        double* atom = U.data() + i * V;
        double* reset_out = atom + K;
        for (int m = 0; m < M::n_mode; ++m) {
          const double u0 = M::initial_density(m, x.data(), par);
          if (u0 == 0.0) continue;  // no mass: its fate does not matter
          // A reset across the box's boundary at time t counts from the first t_k ≥ t on
          // (trajectories are right-continuous: forward.hpp).
          auto on_reset = [&](double t, int g, const std::array<double, N>& before,
                              const std::array<double, N>& after) {
            const int c = crossing(g, before, after);
            if (c == 0) return;
            for (std::size_t k = K; k-- > 0 && times[k] >= t;)
              reset_out[k] += static_cast<double>(c) * u0;
          };
          const ForwardResult<N> r = flow.run(
              m, x, times, [](std::size_t, int, const std::array<double, N>&) {}, on_reset);
          if (r.status == ForwardStatus::event_cap || r.status == ForwardStatus::failed) {
#pragma omp critical(hybgen_rt_budget_zeno_failure)
            {
              if (ii < first_fail.load()) {
                first_fail.store(ii);
                msg = describe<M>(r, m, x);
              }
            }
            break;
          }
          if (r.status == ForwardStatus::absorbed) {
            // Absorbed at r.x: per guard; and out of the box, where the faces' integral does
            // not see it leave (inside the box, off its faces).
            double* taken = atom + (2 + static_cast<std::size_t>(r.guard)) * K;
            const bool inside = in_box<N>(r.x.data(), lo, hi) && !on_faces(r.x);
            for (std::size_t k = K; k-- > 0 && times[k] >= r.t_stop;) {
              taken[k] += u0;
              if (inside) reset_out[k] += u0;
            }
            continue;
          }
          // An atom outside the box is mass that left it through a face or by a reset, which
          // the outflow counts already (as the particles count it: particles.hpp).
          if (r.status != ForwardStatus::zeno || !in_box<N>(r.x.data(), lo, hi)) continue;
          for (std::size_t k = 0; k < K; ++k)
            if (times[k] >= r.t_stop) atom[k] += u0;
        }
      }
    }
    if (b.ranks() > 1) {
      // Point i's V values are U[i·V, (i + 1)·V): the blocks of points tile U in rank order.
      const std::vector<double> all =
          b.all_gather(std::span<const double>(U.data() + mine.begin * V, mine.size() * V));
      std::copy(all.begin(), all.end(), U.begin());
      const std::int64_t first = b.min(std::int64_t{first_fail.load()});
      if (first < P) {
        const std::int64_t owner =
            b.min(first_fail.load() == first ? std::int64_t{b.rank()} : b.ranks());
        msg = b.broadcast(msg, static_cast<int>(owner));
        first_fail.store(first);
      }
    }
    if (first_fail.load() < P) {
      failure = msg;
      return false;
    }
    return true;
  }
};

/// Root cells per axis of the atom's cubature (each cut into 4 per axis by the cubature, with
/// 4 Gauss nodes per axis per cell): 32 nodes per axis up to 2-D, so that a small basin of
/// Zeno points is not missed by the first level of nodes; 16 above.
inline constexpr std::size_t zeno_roots_per_axis(std::size_t n) {
  return n <= 2 ? 2 : 1;
}

}  // namespace detail

/// Adaptive cubature of the Zeno atom and of the reset outflow (see `detail::ZenoValues`):
/// atom[k] = Σ_m ∫_box u0·[t_Z ≤ t_k] is returned, and the net mass that resets carry out of
/// the box by t_k goes to `*reset_out` when given (`outflow` holds each), each guard g's
/// absorbed mass to (*absorbed)[g] when given (sized n_guard; empty for a guard that does not
/// absorb). All times at once,
/// target rel_tol·scale for every value, over the part of the box where the grid's nodes see
/// u0 > 0 (widened by a cell), with the grid's nodes there as check points. Models without
/// guards have neither (0, exactly, without a flow). On a failed forward flow `failure` is
/// set.
template <HybridModel M>
AdaptiveOutflow adaptive_atom(const TensorGrid<state_dim_v<M>>& box, std::span<const double> times,
                              const double* par, const CharacteristicsOptions& opt,
                              const AdaptiveOptions& aopt, double scale, std::string& failure,
                              AdaptiveOutflow* reset_out = nullptr,
                              std::vector<AdaptiveOutflow>* absorbed = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  detail::validate_times(times);
  AdaptiveOutflow res;  // `outflow` holds the atom
  res.outflow.assign(times.size(), 0.0);
  res.error.assign(times.size(), 0.0);
  if (reset_out != nullptr) *reset_out = res;
  if (absorbed != nullptr) {
    absorbed->assign(static_cast<std::size_t>(M::n_guard), AdaptiveOutflow{});
    for (std::size_t g = 0; g < absorbed->size(); ++g)
      if (absorbs(detail::guard_info<M>(g))) (*absorbed)[g] = res;
  }
  // Nothing to integrate: every integral is 0, exactly.
  const auto none = [&] {
    res.converged = true;
    if (reset_out != nullptr) reset_out->converged = true;
    if (absorbed != nullptr)
      for (AdaptiveOutflow& a : *absorbed) a.converged = true;
    return res;
  };
  if (M::n_guard == 0 || times.empty() || times.back() <= 0.0) return none();
  detail::ZenoValues<M> values;
  values.times = times;
  values.par = par;
  for (std::size_t a = 0; a < N; ++a) {
    values.lo[a] = box.axes[a].min;
    values.hi[a] = box.axes[a].max;
  }
  values.backend = opt.backend;
  values.fopt.ode = opt.ode;
  values.fopt.graze_tol = opt.graze_tol;
  // The run's event cap (`max_events`, 100000 by default), not the forward flow's 1000: a
  // model that switches often over a long horizon without Zeno (a spiking neuron) must not
  // fail its budget where its characteristics pass.
  values.fopt.max_events = opt.max_events;
  // The integrand is 0 where u0 is: the cubature covers the box of the grid nodes with
  // u0 > 0, widened by one grid cell (u0 between nodes), clipped to the grid's box. A
  // localized initial density then gets the cubature's whole resolution (a 4-D density on
  // 4 % of the box, tests/validation/test_two_balls.cpp, was otherwise seen by a handful of
  // nodes and its atom underestimated 40-fold under budget=fast's point cap).
  std::array<double, N> slo{}, shi{};
  slo.fill(std::numeric_limits<double>::infinity());
  shi.fill(-std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < box.size(); ++i) {
    const std::array<double, N> y = box.node(i);
    if (!M::in_support(y.data(), par)) continue;
    bool mass = false;
    for (int m = 0; m < M::n_mode && !mass; ++m) mass = M::initial_density(m, y.data(), par) > 0.0;
    if (!mass) continue;
    for (std::size_t a = 0; a < N; ++a) {
      slo[a] = std::min(slo[a], y[a]);
      shi[a] = std::max(shi[a], y[a]);
    }
  }
  if (!(slo[0] <= shi[0])) return none();  // no node carries mass: none reaches a Zeno point
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = box.axes[a];
    const double h = ax.n > 1 ? (ax.max - ax.min) / (ax.n - 1) : 0.0;
    slo[a] = std::max(ax.min, slo[a] - h);
    shi[a] = std::min(ax.max, shi[a] + h);
  }
  const std::size_t R = detail::zeno_roots_per_axis(N);
  std::vector<detail::Cell<N>> roots;
  std::size_t total = 1;
  for (std::size_t a = 0; a < N; ++a) total *= R;
  for (std::size_t flat = 0; flat < total; ++flat) {
    detail::Cell<N> c;
    std::size_t rem = flat;
    for (std::size_t a = 0; a < N; ++a) {
      const std::size_t j = rem % R;
      rem /= R;
      const double lo = slo[a], hi = shi[a];
      c.lo[a] = lo + (hi - lo) * static_cast<double>(j) / static_cast<double>(R);
      c.hi[a] =
          j + 1 == R ? hi : lo + (hi - lo) * static_cast<double>(j + 1) / static_cast<double>(R);
    }
    roots.push_back(c);
  }
  // Check points: the grid's nodes in the cubature's box, with their atom integrand from the
  // same forward flows, so that a Zeno basin the grid resolves is not missed between Gauss
  // nodes (tests/validation/test_two_balls.cpp at budget=fast: 0.103 against 0.129 with an
  // estimate of 4.5e-3 without them, 0.1015 with 1.0e-2 with them — the basin's edge is
  // finer than that test's 9 nodes per axis). A failed flow there leaves the cubature
  // without check points; its own nodes report the failures that matter.
  detail::CheckPoints<N> checks;
  std::vector<double> lattice;  // the check lattice's midpoint sums of every slot (see below)
  {
    detail::check_lattice(box, max_atom_checks(aopt), slo, shi, checks);
    const std::size_t V = values.values_per_point();
    std::vector<double> v(checks.x.size() * V, 0.0);
    if (values(std::span<const detail::Cell<N>>{}, std::span<const std::array<double, N>>(checks.x),
               1, v)) {
      double w = 1.0;
      for (std::size_t a = 0; a < N; ++a) w *= checks.spacing[a];
      lattice.assign(V, 0.0);
      for (std::size_t j = 0; j < checks.x.size(); ++j)
        for (std::size_t q = 0; q < V; ++q) lattice[q] += w * v[j * V + q];
      detail::keep_samples<M>(checks, std::move(v), V, par);
    } else {
      checks = {};
      values.failure.clear();
    }
  }
  const std::size_t V = values.values_per_point();
  detail::AdaptiveCubature<N, detail::ZenoValues<M>> cub(std::move(roots), V, V, aopt, scale,
                                                         values, &checks);
  const bool ok = cub.run();
  if (!ok) failure = values.failure;
  const std::size_t K = times.size();
  detail::collect(cub, ok, 0, K, res.outflow, res);
  if (reset_out != nullptr) detail::collect(cub, ok, K, K, reset_out->outflow, *reset_out);
  // An absorbed mass integrates a step: u0 where the flow reaches the guard by t_k. Its jump
  // can lie in a cell between the cell's last nodes and its edge, seen by neither the Gauss
  // nodes nor the check points; the budget's closure does not see it either where the guard is
  // a face of the box (the faces' integral counts that mass leave). So its estimate is at
  // least twice its distance from the check lattice's own sum of the same values (midpoint
  // weights): at least that if the lattice sum is at least twice as accurate, as it is where
  // the cubature missed what the lattice saw. Measured on x' = 0.7x absorbed at x = 1 (the
  // face) on 201 nodes (tests/validation/test_absorbing.cpp): at t = 2, 0.84375 against
  // 0.84756 with an estimate of 1.2e-11 before; the jump at e^(−1.4) = 0.2466 lay in the cell
  // [0.125, 0.25] above its last node 0.241.
  if (absorbed != nullptr)
    for (std::size_t g = 0; g < absorbed->size(); ++g)
      if (absorbs(detail::guard_info<M>(g))) {
        AdaptiveOutflow& a = (*absorbed)[g];
        detail::collect(cub, ok, (2 + g) * K, K, a.outflow, a);
        if (lattice.size() == V)
          for (std::size_t k = 0; k < K; ++k) {
            a.error[k] =
                std::max(a.error[k], 2.0 * std::fabs(a.outflow[k] - lattice[(2 + g) * K + k]));
            a.error_estimate = std::max(a.error_estimate, a.error[k]);
          }
      }
  return res;
}

}  // namespace hybgen::rt
