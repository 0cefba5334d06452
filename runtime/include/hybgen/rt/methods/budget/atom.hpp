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
///  * the impacts on every guard (methods/impacts.hpp) by each output time: the same
///    integrand's shape, counting firings, in a cubature of their own (`adaptive_impacts`),
///    refined for them.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
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
#include "hybgen/rt/methods/budget/step_lines.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/forward.hpp"
#include "hybgen/rt/methods/impacts.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Largest number of check points of the atom's cubature: each costs a forward flow, so a
/// quarter of the cubature's own point cap (`adaptive_atom`).
inline std::size_t max_atom_checks(const AdaptiveOptions& aopt) {
  return std::max<std::size_t>(aopt.max_points / 4, 1);
}

/// Most points of a check lattice finer than the grid's nodes: budget=full's check points
/// (max_atom_checks of the default options), which the runner's budgets never exceed. A caller
/// that raises the cubature's point cap far beyond it (a test asking 4·10⁶ for a tight
/// tolerance) raises what the adaptive cubature may spend where its integrand needs it, but
/// the lattice is spent in full on every run: under that cap alone a 41² grid's lattice is 24
/// points per spacing, about 9·10⁵ forward flows (tests/validation/test_shear_reset.cpp ran
/// 176 s), where budget=full's is 7, about 8·10⁴.
inline std::size_t max_fine_lattice_points() {
  return max_atom_checks(AdaptiveOptions{});
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
/// With `impacts` set the integrand is instead V = G·K impact counts (`adaptive_impacts`):
///   U[i·V + g·K + k] = Σ_m u0(m, x_i)·(number of firings of g at t ≤ t_k), for k <
///   count_until[g], and 0 beyond (frames where the impacts are infinite: Zeno).
/// Either way `zeno_time[g]` records the earliest time t_Z > 0 at which a flow with u0 > 0 came
/// to rest at a Zeno point whose impacts accumulate on g (its last guard; methods/impacts.hpp).
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
  bool impacts = false;              ///< Count impacts instead (see above).
  /// Also the counts: V more values per point, each slot's with 1 in place of u0 (summed over
  /// the modes with u0 > 0), for locating the steps' jumps (budget/step_lines.hpp). Set for
  /// the check lattice alone, whose values it doubles; not for the cubature's own points.
  bool with_counts = false;
  std::vector<std::size_t> count_until;  ///< With `impacts`: per guard, the frames counted.
  /// Per guard, the earliest Zeno time of a flow ending on it (+∞: none); all ranks agree.
  std::vector<double> zeno_time =
      std::vector<double>(static_cast<std::size_t>(M::n_guard), HUGE_VAL);

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

  /// The integrand's values per point: V = (2 + G)·K, or G·K with `impacts`.
  std::size_t slots() const {
    const auto G = static_cast<std::size_t>(M::n_guard);
    return (impacts ? G : 2 + G) * times.size();
  }

  /// Values per point: `slots()`, twice that `with_counts`.
  std::size_t values_per_point() const { return (with_counts ? 2 : 1) * slots(); }

  /// U[i·V + j] as above, OpenMP over the points.
  bool operator()(std::span<const Cell<N>>, std::span<const std::array<double, N>> pts, std::size_t,
                  std::vector<double>& U) {
    const std::size_t K = times.size(), S = slots(), V = values_per_point();
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
        double* row = U.data() + i * V;
        double* counts = with_counts ? row + S : nullptr;
        for (int m = 0; m < M::n_mode; ++m) {
          const double u0 = M::initial_density(m, x.data(), par);
          if (u0 == 0.0) continue;  // no mass: its fate does not matter
          // Slot j gains u0·c (and its count c).
          auto add = [&](std::size_t j, double c) {
            row[j] += c * u0;
            if (counts != nullptr) counts[j] += c;
          };
          // Guard g's impact count from the first frame at or after t (`impacts`).
          auto count = [&](int g, double t) {
            const auto G = static_cast<std::size_t>(g);
            for (std::size_t k = std::min(K, count_until[G]); k-- > 0 && times[k] >= t;)
              add(G * K + k, 1.0);
          };
          // A reset across the box's boundary at time t counts from the first t_k ≥ t on
          // (trajectories are right-continuous: forward.hpp).
          auto on_reset = [&](double t, int g, const std::array<double, N>& before,
                              const std::array<double, N>& after) {
            if (impacts) return count(g, t);
            const int c = crossing(g, before, after);
            if (c == 0) return;
            for (std::size_t k = K; k-- > 0 && times[k] >= t;) add(K + k, static_cast<double>(c));
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
          if (r.status == ForwardStatus::zeno && r.guard >= 0 && r.t_stop > 0.0) {
#pragma omp critical(hybgen_rt_budget_zeno_time)
            {
              double& z = zeno_time[static_cast<std::size_t>(r.guard)];
              z = std::min(z, r.t_stop);
            }
          }
          if (impacts) {
            if (r.status == ForwardStatus::absorbed) count(r.guard, r.t_stop);
            continue;
          }
          if (r.status == ForwardStatus::absorbed) {
            // Absorbed at r.x: per guard; and out of the box, where the faces' integral does
            // not see it leave (inside the box, off its faces).
            const std::size_t taken = (2 + static_cast<std::size_t>(r.guard)) * K;
            const bool inside = in_box<N>(r.x.data(), lo, hi) && !on_faces(r.x);
            for (std::size_t k = K; k-- > 0 && times[k] >= r.t_stop;) {
              add(taken + k, 1.0);
              if (inside) add(K + k, 1.0);
            }
            continue;
          }
          // An atom outside the box is mass that left it through a face or by a reset, which
          // the outflow counts already (as the particles count it: particles.hpp).
          if (r.status != ForwardStatus::zeno || !in_box<N>(r.x.data(), lo, hi)) continue;
          for (std::size_t k = 0; k < K; ++k)
            if (times[k] >= r.t_stop) add(k, 1.0);
        }
      }
    }
    if (b.ranks() > 1) {
      // The earliest Zeno time of every rank: min = −max(−t).
      for (double& z : zeno_time) z = -z;
      b.max(std::span<double>(zeno_time));
      for (double& z : zeno_time) z = -z;
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

/// The forward flows' cubature (`adaptive_atom`, `adaptive_impacts`): `values` integrated
/// over the part of the box where the grid's nodes see u0 > 0 (widened by a cell, clipped to
/// the box), all slots targeted at rel_tol·scale, with a lattice through the grid's nodes
/// there as check points (`fine_lattice`). `lattice` gets the check lattice's trapezoid sums of
/// every slot, their jumps located along its lines (`locate_steps`; empty without check
/// points). Returns no cubature when no node carries mass (every
/// integral is 0), else the finished one; `ok` is false on a failed forward flow (values.failure).
template <HybridModel M>
struct ForwardCubature {
  std::unique_ptr<CheckPoints<state_dim_v<M>>> checks;  ///< Outlives `cub`, which reads it.
  std::unique_ptr<AdaptiveCubature<state_dim_v<M>, ZenoValues<M>>> cub;  ///< Null: nothing.
};

/// See `ForwardCubature`.
template <HybridModel M>
ForwardCubature<M> forward_cubature(const TensorGrid<state_dim_v<M>>& box, const double* par,
                                    const AdaptiveOptions& aopt, double scale,
                                    ZenoValues<M>& values, std::vector<double>& lattice, bool& ok) {
  constexpr std::size_t N = state_dim_v<M>;
  using Cubature = AdaptiveCubature<N, ZenoValues<M>>;
  ok = true;
  lattice.clear();
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
  ForwardCubature<M> res;
  if (!(slo[0] <= shi[0])) return res;  // no node carries mass
  for (std::size_t a = 0; a < N; ++a) {
    const GridAxis& ax = box.axes[a];
    const double h = ax.n > 1 ? (ax.max - ax.min) / (ax.n - 1) : 0.0;
    slo[a] = std::max(ax.min, slo[a] - h);
    shi[a] = std::min(ax.max, shi[a] + h);
  }
  const std::size_t R = zeno_roots_per_axis(N);
  std::vector<Cell<N>> roots;
  std::size_t total = 1;
  for (std::size_t a = 0; a < N; ++a) total *= R;
  for (std::size_t flat = 0; flat < total; ++flat) {
    Cell<N> c;
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
  // Check points: a lattice through the grid's nodes in the cubature's box, as fine as a
  // quarter of the cubature's points allow (`fine_lattice`), with their integrand from the
  // same forward flows, so that a Zeno basin the lattice resolves is not missed between Gauss
  // nodes (tests/validation/test_two_balls.cpp at budget=fast: 0.103 against 0.129 with an
  // estimate of 4.5e-3 without them, 0.1015 with 1.0e-2 with them — the basin's edge is
  // finer than that test's 9 nodes per axis), nor a step's jump (`collect_step`). A failed
  // flow there leaves the cubature without check points; its own nodes report the failures
  // that matter.
  res.checks = std::make_unique<CheckPoints<N>>();
  CheckPoints<N>* checks = res.checks.get();
  {
    std::vector<double> weight;
    std::array<std::size_t, N> shape{};
    fine_lattice(box, max_atom_checks(aopt), max_fine_lattice_points(), slo, shi, *checks, weight,
                 shape);
    // The integrand and its counts (ZenoValues::with_counts): W = 2V values per point.
    values.with_counts = true;
    const std::size_t V = values.slots(), W = values.values_per_point();
    const std::span<const std::array<double, N>> pts(checks->x);
    std::vector<double> v(pts.size() * W, 0.0);
    if (values(std::span<const Cell<N>>{}, pts, 1, v)) {
      lattice.assign(V, 0.0);
      for (std::size_t j = 0; j < pts.size(); ++j)
        for (std::size_t q = 0; q < V; ++q) lattice[q] += weight[j] * v[j * W + q];
      // The steps' jumps located along the lattice's lines (budget/step_lines.hpp) until the
      // segments left could be off by at most the cubature's target (their signs vary: far
      // less), for at most twice the lattice's flows (and the cubature's own cap). On the
      // elastic ball at budget=full, dt = 0.125 (tests/validation/test_calibration.cpp):
      // six halvings, 1.5·10⁵ flows beside the lattice's 8.4·10⁴ and the cubature's 1.3·10⁵.
      // On the paper's ball at budget=fast (a Zeno point, where the counts' jumps accumulate
      // and no halving ends them), the cap: one halving, 1315 flows beside the lattice's 1444.
      auto eval = [&](std::span<const std::array<double, N>> p, std::vector<double>& out) {
        return values(std::span<const Cell<N>>{}, p, 1, out);
      };
      locate_steps<N>(pts, shape, checks->spacing, slo, shi, v, V, eval, aopt.rel_tol * scale,
                      std::min(aopt.max_points, 2 * pts.size()), lattice);
      values.failure.clear();  // a failed flow there: the sums keep what was located before
      // The integrand's values alone, as check points.
      for (std::size_t j = 0; j < pts.size(); ++j)
        std::copy_n(v.begin() + static_cast<std::ptrdiff_t>(j * W), V,
                    v.begin() + static_cast<std::ptrdiff_t>(j * V));
      v.resize(pts.size() * V);
      keep_samples<M>(*checks, std::move(v), V, par);
    } else {
      *checks = {};
      values.failure.clear();
    }
    values.with_counts = false;
  }
  const std::size_t V = values.values_per_point();
  res.cub = std::make_unique<Cubature>(std::move(roots), V, V, aopt, scale, values, checks);
  ok = res.cub->run();
  return res;
}

/// Slots first..first + K − 1 of a forward cubature into `a`, each estimate at least twice
/// its distance from the check lattice's own sum of the same values (trapezoid weights). The
/// slot integrates a step — u0 where the flow has done something by t_k — whose jump can lie
/// in a cell between the cell's last nodes and its edge, seen by neither the Gauss nodes nor
/// the check points; the budget's closure does not see it either where the guard is a face of
/// the box (the faces' integral counts that mass leave). The estimate is at least that if the
/// lattice sum is at least twice as accurate, as it is where the cubature missed what the
/// lattice saw. Measured on x' = 0.7x absorbed at x = 1 (the face) on 201 nodes
/// (tests/validation/test_absorbing.cpp): at t = 2, 0.84375 against 0.84756 with an estimate
/// of 1.2e-11 before; the jump at e^(−1.4) = 0.2466 lay in the cell [0.125, 0.25] above its
/// last node 0.241. Where the cubature is right, the floor is the lattice's own error. Of the
/// trapezoid rule on the lattice's points, that is about the jump times its cells' width, so
/// the lattice is as fine as the cap allows (`fine_lattice`, up to 64 points per grid
/// spacing), not the grid's nodes (the shuttle's impacts at t = 0.5,
/// tests/validation/test_impacts.cpp: a bar of 2.8e-3 on the nodes for an error of 3.4e-6,
/// 5.3e-5 on the finer lattice), and its jumps are located along its lines
/// (budget/step_lines.hpp): in two dimensions the rule's error, one per line a jump crosses,
/// had kept the elastic ball's impact bars 14–60× their errors on 10 of its 48 frames
/// (tests/validation/test_calibration.cpp). The same lattice as check points finds the face's
/// jump above: 5.6e-4 off at t = 2 with a bar of 4.0e-3.
template <class Cubature>
void collect_step(const Cubature& cub, bool ok, std::size_t first, std::size_t K,
                  const std::vector<double>& lattice, AdaptiveOutflow& a) {
  collect(cub, ok, first, K, a.outflow, a);
  if (lattice.size() < first + K) return;
  for (std::size_t k = 0; k < K; ++k) {
    a.error[k] = std::max(a.error[k], 2.0 * std::fabs(a.outflow[k] - lattice[first + k]));
    a.error_estimate = std::max(a.error_estimate, a.error[k]);
  }
}

/// The forward flows' integrand for the box `box` at `times` (see ZenoValues).
template <HybridModel M>
ZenoValues<M> forward_values(const TensorGrid<state_dim_v<M>>& box, std::span<const double> times,
                             const double* par, const CharacteristicsOptions& opt) {
  ZenoValues<M> values;
  values.times = times;
  values.par = par;
  for (std::size_t a = 0; a < state_dim_v<M>; ++a) {
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
  return values;
}

}  // namespace detail

/// Adaptive cubature of the Zeno atom and of the reset outflow (see `detail::ZenoValues`):
/// atom[k] = Σ_m ∫_box u0·[t_Z ≤ t_k] is returned, and the net mass that resets carry out of
/// the box by t_k goes to `*reset_out` when given (`outflow` holds each), each guard g's
/// absorbed mass to (*absorbed)[g] when given (sized n_guard; empty for a guard that does not
/// absorb), and each guard's earliest Zeno time (+∞: none) to `*zeno_time` when given. All
/// times at once, target rel_tol·scale for every value, over the part of the box where the
/// grid's nodes see u0 > 0 (widened by a cell), with a lattice through the grid's nodes there
/// as check points (`detail::forward_cubature`). Models without guards have neither (0, exactly,
/// without a flow). On a failed forward flow `failure` is set.
template <HybridModel M>
AdaptiveOutflow adaptive_atom(const TensorGrid<state_dim_v<M>>& box, std::span<const double> times,
                              const double* par, const CharacteristicsOptions& opt,
                              const AdaptiveOptions& aopt, double scale, std::string& failure,
                              AdaptiveOutflow* reset_out = nullptr,
                              std::vector<AdaptiveOutflow>* absorbed = nullptr,
                              std::vector<double>* zeno_time = nullptr) {
  detail::validate_times(times);
  AdaptiveOutflow res;  // `outflow` holds the atom
  res.outflow.assign(times.size(), 0.0);
  res.error.assign(times.size(), 0.0);
  res.converged = true;
  if (reset_out != nullptr) *reset_out = res;
  if (absorbed != nullptr) {
    absorbed->assign(static_cast<std::size_t>(M::n_guard), AdaptiveOutflow{});
    for (std::size_t g = 0; g < absorbed->size(); ++g)
      if (absorbs(detail::guard_info<M>(g))) (*absorbed)[g] = res;
  }
  if (zeno_time != nullptr) zeno_time->assign(static_cast<std::size_t>(M::n_guard), HUGE_VAL);
  // Nothing to integrate: every integral is 0, exactly.
  if (M::n_guard == 0 || times.empty() || times.back() <= 0.0) return res;
  detail::ZenoValues<M> values = detail::forward_values<M>(box, times, par, opt);
  std::vector<double> lattice;
  bool ok = true;
  const detail::ForwardCubature<M> fc =
      detail::forward_cubature<M>(box, par, aopt, scale, values, lattice, ok);
  if (!fc.cub) return res;  // no node carries mass: none reaches a Zeno point
  const auto& cub = fc.cub;
  if (!ok) failure = values.failure;
  if (zeno_time != nullptr) *zeno_time = values.zeno_time;
  const std::size_t K = times.size();
  detail::collect(*cub, ok, 0, K, res.outflow, res);
  if (reset_out != nullptr) detail::collect(*cub, ok, K, K, reset_out->outflow, *reset_out);
  if (absorbed != nullptr)
    for (std::size_t g = 0; g < absorbed->size(); ++g)
      if (absorbs(detail::guard_info<M>(g)))
        detail::collect_step(*cub, ok, (2 + g) * K, K, lattice, (*absorbed)[g]);
  return res;
}

/// Adaptive cubature of the impacts on every guard (methods/impacts.hpp): impacts[g][k] =
/// Σ_m ∫_box u0·(number of firings of g by t_k) in `outflow`, over the part of the box where
/// the grid's nodes see u0 > 0, as `adaptive_atom`, in a cubature of its own refined for them
/// (the atom's is refined for its own slots, all 0 on an elastic ball). Frames from
/// infinite_from[g] on are not integrated (0 there): their impacts are infinite, a Zeno
/// accumulation on g (`impacts_infinite_from`). Each estimate is at least twice its distance
/// from the check lattice's sum (`detail::collect_step`): the counts are steps too. On a
/// failed forward flow `failure` is set.
template <HybridModel M>
std::vector<AdaptiveOutflow> adaptive_impacts(const TensorGrid<state_dim_v<M>>& box,
                                              std::span<const double> times, const double* par,
                                              const CharacteristicsOptions& opt,
                                              const AdaptiveOptions& aopt, double scale,
                                              const std::vector<std::size_t>& infinite_from,
                                              std::string& failure) {
  detail::validate_times(times);
  const auto G = static_cast<std::size_t>(M::n_guard);
  const std::size_t K = times.size();
  AdaptiveOutflow zero;
  zero.outflow.assign(K, 0.0);
  zero.error.assign(K, 0.0);
  zero.converged = true;
  std::vector<AdaptiveOutflow> res(G, zero);
  if (G == 0 || times.empty() || times.back() <= 0.0) return res;
  detail::ZenoValues<M> values = detail::forward_values<M>(box, times, par, opt);
  values.impacts = true;
  values.count_until.assign(G, K);
  for (std::size_t g = 0; g < G && g < infinite_from.size(); ++g)
    values.count_until[g] = std::min(infinite_from[g], K);
  std::vector<double> lattice;
  bool ok = true;
  const detail::ForwardCubature<M> fc =
      detail::forward_cubature<M>(box, par, aopt, scale, values, lattice, ok);
  if (!fc.cub) return res;
  const auto& cub = fc.cub;
  if (!ok) failure = values.failure;
  for (std::size_t g = 0; g < G; ++g) detail::collect_step(*cub, ok, g * K, K, lattice, res[g]);
  return res;
}

}  // namespace hybgen::rt
