#pragma once
/// \file solution.hpp
/// What every method returns: densities at points for each mode and output time (Solution),
/// the failure that stopped a trajectory (TraceError, TraceStatus, TraceFailure, describe),
/// and the mass budget (MassBudget: mass in the box, outflow, atom, and their error bars).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <iomanip>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/core/geometry.hpp"
#include "hybgen/rt/core/names.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// What went wrong on a characteristic.
enum class TraceError {
  none,                ///< Nothing.
  non_finite_flow,     ///< X or div X not finite (ODE could not continue).
  non_finite_reset,    ///< Δ⁻¹(y*) not finite at a reset image.
  zero_jacobian,       ///< |J| = 0 or J not finite at a pre-image.
  inverse_failed,      ///< Newton for Δ⁻¹ did not converge.
  event_cap,           ///< More than `max_events` resets on one characteristic.
  branch_cap,          ///< Too many pending reversed-reset branches.
  step_limit,          ///< ODE `max_steps` exceeded.
  step_underflow,      ///< ODE step size underflow (singular or stiff flow).
  non_finite_density,  ///< u0 · weight · exp(−∫div) not finite at a foot point.
  grazing,             ///< The flow is tangent to the guard where the orbit crosses it.
};

/// Human-readable name of a `TraceError`.
inline const char* trace_error_name(TraceError e) {
  switch (e) {
    case TraceError::none:
      return "no error";
    case TraceError::non_finite_flow:
      return "non-finite vector field or divergence";
    case TraceError::non_finite_reset:
      return "non-finite inverse reset";
    case TraceError::zero_jacobian:
      return "zero or non-finite hybrid Jacobian";
    case TraceError::inverse_failed:
      return "Newton iteration for the inverse reset did not converge";
    case TraceError::event_cap:
      return "too many resets on one characteristic (max_events)";
    case TraceError::branch_cap:
      return "too many pending reset branches";
    case TraceError::step_limit:
      return "ODE step limit exceeded";
    case TraceError::step_underflow:
      return "ODE step size underflow";
    case TraceError::non_finite_density:
      return "non-finite density value";
    case TraceError::grazing:
      return "grazing: the flow is tangent to the guard at a crossing";
  }
  return "?";
}

/// Outcome of one characteristic: where (mode, guard, backward time τ, state) it failed.
template <std::size_t N>
struct TraceStatus {
  TraceError error = TraceError::none;  ///< What happened.
  int mode = -1;                        ///< Mode at the failure.
  int guard = -1;                       ///< Guard involved, or −1.
  double tau = 0.0;                     ///< Backward time τ of the failure.
  std::array<double, N> state{};        ///< State at the failure.
  int events = 0;                       ///< Resets crossed so far.
  double value = 0.0;                   ///< grazing: |∇s·X|/(|∇s||X|) at `state`; else 0.
  /// Whether nothing failed.
  bool ok() const { return error == TraceError::none; }
};

/// A failed characteristic together with its starting point.
template <std::size_t N>
struct TraceFailure {
  TraceStatus<N> status{};        ///< What failed, where (status.ok() if nothing failed).
  int start_mode = -1;            ///< Mode of the starting point.
  std::size_t start_index = 0;    ///< Index of the starting point (grid node / point).
  std::array<double, N> start{};  ///< Coordinates of the starting point.
  /// Whether nothing failed.
  bool ok() const { return status.ok(); }
};

/// Densities at points for all modes and output times: u[(k·n_mode + m)·n_point + i].
///
/// A run over several ranks (core/backend.hpp) keeps each frame where it was computed:
/// then `distributed` is set and u holds, per frame, only the (mode, point) pairs of
/// `owned` (flat indices m·n_point + i), u[k·owned.size() + (m·n_point + i − owned.begin)].
/// No rank holds a whole frame; the writers write every rank's part (io/run_outputs.hpp).
template <std::size_t N>
struct Solution {
  std::size_t n_time = 0;     ///< Number of output times.
  std::size_t n_mode = 0;     ///< Number of modes.
  std::size_t n_point = 0;    ///< Number of points (grid nodes, C order).
  std::vector<double> u;      ///< Values, layout [time][mode][point] (or [time][owned]).
  TraceFailure<N> failure{};  ///< The failure with the smallest (mode, point) index, if any.
  bool distributed = false;   ///< Whether u holds only the pairs of `owned`.
  Block owned{};              ///< The (mode, point) pairs held when `distributed`.

  /// Whether every characteristic succeeded.
  bool ok() const { return failure.ok(); }
  /// Values held per frame: n_mode·n_point, or owned.size() when distributed.
  std::size_t frame_size() const { return distributed ? owned.size() : n_mode * n_point; }
  /// Flat index of (time k, mode m, point i), a pair this process holds.
  std::size_t index(std::size_t k, std::size_t m, std::size_t i) const {
    return k * frame_size() + m * n_point + i - (distributed ? owned.begin : 0);
  }
  /// u(t_k, mode m, point i).
  double at(std::size_t k, std::size_t m, std::size_t i) const { return u[index(k, m, i)]; }
  /// All points of mode m at time k (a C-order grid-shaped array for grid solutions); not
  /// for a distributed solution, which holds no whole mode.
  std::span<const double> slice(std::size_t k, std::size_t m) const {
    if (distributed) throw std::logic_error("Solution::slice of a distributed solution");
    return {u.data() + index(k, m, 0), n_point};
  }
  /// Keep only the pairs of `own` of a whole solution (each rank its block), frame by frame.
  void keep_only(Block own) {
    if (distributed) throw std::logic_error("Solution::keep_only of a distributed solution");
    const std::size_t F = n_mode * n_point;
    std::vector<double> part(n_time * own.size());
    for (std::size_t k = 0; k < n_time; ++k)
      std::copy(u.begin() + static_cast<std::ptrdiff_t>(k * F + own.begin),
                u.begin() + static_cast<std::ptrdiff_t>(k * F + own.end),
                part.begin() + static_cast<std::ptrdiff_t>(k * own.size()));
    u = std::move(part);
    owned = own;
    distributed = true;
  }
};

/// One-line description of a failed characteristic for an error message (exit code 3).
template <HybridModel M>
std::string describe(const TraceFailure<state_dim_v<M>>& f) {
  constexpr std::size_t N = state_dim_v<M>;
  std::ostringstream os;
  os << std::setprecision(17);
  auto point = [&os](const std::array<double, N>& x) { write_state<M>(os, x); };
  const TraceStatus<N>& s = f.status;
  os << "characteristic from ";
  point(f.start);
  os << " in mode '" << mode_name<M>(f.start_mode) << "' failed: " << trace_error_name(s.error);
  if (s.guard >= 0 && s.guard < M::n_guard) os << " at guard '" << guard_name<M>(s.guard) << "'";
  os << " at backward time tau = " << s.tau << ", state ";
  point(s.state);
  os << ", mode '" << mode_name<M>(s.mode) << "', after " << s.events << " resets";
  if (s.error == TraceError::grazing) detail::describe_grazing(os, s.value);
  return os.str();
}

/// The mass budget over a box: for each output time t_k,
///   mass[k] = Σ_modes ∫_box u(t_k),  outflow[k] = ∫₀^{t_k} Σ_modes ∮_∂box u X·n_out (plus,
///   where measured, what resets carried out of the box), and atom[k], the mass come to rest
///   at Zeno points in the box: measured (`adaptive_mass_budget`), or for the fixed-rule
///   budgets of mass_budget.hpp the remainder mass0 − mass[k] − outflow[k], which there also
///   holds the mass resets carried out of the box.
struct MassBudget {
  std::vector<double> times;  ///< Output times.
  double mass0 = 0.0;         ///< Σ_modes ∫_box u0.
  std::vector<double> mass;   ///< Mass in the box at each output time.
  /// Net outflow from the box during [0, t_k]: through its faces, and by resets that land
  /// outside it (minus those that land back in it).
  std::vector<double> outflow;
  /// The part of `outflow` that resets carried across the box's boundary (the adaptive budget
  /// of characteristics measures it on its own, budget/atom.hpp; empty elsewhere).
  std::vector<double> reset_outflow;
  /// Mass at atoms: measured at Zeno points in the box by `adaptive_mass_budget` (budget.hpp);
  /// for the fixed-rule budgets of mass_budget.hpp, the remainder mass0 − mass − outflow.
  std::vector<double> atom;
  /// Estimated |error| of mass[k] (`adaptive_mass_budget`, budget.hpp); empty for fixed rules.
  std::vector<double> mass_error;
  double mass0_error = 0.0;  ///< Estimated |error| of mass0 (adaptive only).
  /// Estimated |error| of mass0 − mass[k], measured as one integral (adaptive only,
  /// budget/volume.hpp); empty: mass0_error + mass_error[k].
  std::vector<double> drop_error;
  /// Estimated |error| of the defect as the budget measured it, before its terms' bars were
  /// widened by it (methods.hpp); empty: `budget_defect_error` sums the terms' bars.
  std::vector<double> defect_error;
  std::vector<double> outflow_error;  ///< Estimated |error| of outflow[k] (adaptive only).
  std::vector<double> atom_error;     ///< Estimated |error| of atom[k] (adaptive only).
  /// Per guard g: the mass that g absorbed (`reset absorb`, model.hpp) by each output time —
  /// part of `outflow`, the mass that left the box — or empty where g does not absorb or the
  /// method does not count it.
  std::vector<std::vector<double>> absorbed;
  /// Estimated |error| of absorbed[g][k] (as `absorbed`; empty without an estimate).
  std::vector<std::vector<double>> absorbed_error;
  /// Per guard g: the impacts on g in (0, t_k], Σ_m ∫ u0·(number of times g fires on the flow
  /// from (m, x) by t_k) — each firing weighted by the mass it carries, so impacts[g][k] −
  /// impacts[g][k − 1] over t_k − t_{k−1} is the mean rate at which mass crosses g
  /// (methods/impacts.hpp); empty where the method does not count impacts.
  std::vector<std::vector<double>> impacts;
  /// Estimated |error| of impacts[g][k] (empty without an estimate).
  std::vector<std::vector<double>> impacts_error;
  /// Per guard g: the first frame from which impacts[g] is infinite — mass has come to rest at
  /// a Zeno point whose impacts accumulate on g — or the number of frames (as `impacts`).
  std::vector<std::size_t> impacts_infinite_from;
};

/// mass0 − mass[k] − outflow[k] − atom[k]: what no term of the budget accounts for.
inline std::vector<double> budget_defect(const MassBudget& b) {
  std::vector<double> d(b.mass.size(), 0.0);
  for (std::size_t k = 0; k < d.size() && k < b.outflow.size() && k < b.atom.size(); ++k)
    d[k] = b.mass0 - b.mass[k] - b.outflow[k] - b.atom[k];
  return d;
}

/// Estimated |error| of budget_defect(b)[k]: `defect_error` where the budget kept it, else the
/// sum of its terms' estimates, mass0 − mass[k]
/// taken as one term where the budget measured it so (`drop_error`: the two masses' errors
/// come from the same cubature cells, and at t = 0 the drop is exactly 0).
inline std::vector<double> budget_defect_error(const MassBudget& b) {
  if (!b.defect_error.empty()) return b.defect_error;
  std::vector<double> e(b.mass.size(), 0.0);
  auto at = [](const std::vector<double>& v, std::size_t k) { return k < v.size() ? v[k] : 0.0; };
  for (std::size_t k = 0; k < e.size(); ++k) {
    const double drop =
        k < b.drop_error.size() ? b.drop_error[k] : at(b.mass_error, k) + b.mass0_error;
    e[k] = drop + at(b.outflow_error, k) + at(b.atom_error, k);
  }
  return e;
}

/// The frame at which node values under-resolve the density worst, or `node_sums.size()` when
/// none does: where the trapezoid sum of the node values (`node_sums[k]`) differs from the
/// adaptive budget's mass by more than 5 % of the initial mass and 10 times the mass's error
/// bar. Node samples of a density narrower than the grid's spacing are speckle, not its shape
/// (docs/outputs.md); characteristics then report cell averages (`values=auto`), and the
/// outputs warn when what they hold still fails the test (io/run_outputs.hpp).
inline std::size_t under_resolved_frame(const MassBudget& b, std::span<const double> node_sums) {
  const std::size_t K = node_sums.size();
  if (b.mass.size() != K || b.mass_error.size() != K || !(b.mass0 > 0)) return K;
  double worst = 0;
  std::size_t worst_k = K;
  for (std::size_t k = 0; k < K; ++k) {
    const double gap = std::fabs(node_sums[k] - b.mass[k]);
    if (gap > 0.05 * b.mass0 && gap > 10 * b.mass_error[k] && gap > worst) worst = gap, worst_k = k;
  }
  return worst_k;
}

/// What a run whose grid is too large to hold keeps of the density (the particles with
/// `density=marginals`): the 2-D marginal of every pair of axes on the pair's grid nodes,
/// and the first two moments of the mass in the box.
///
/// Invariants: `pairs` lists every (a, b), a < b, in the order (0,1), (0,2), …, (1,2), …;
/// pair p's values in one (frame, mode) block start at offset[p] and hold n_a × n_b
/// densities, a slowest; a block holds `block` values; `values` holds n_frame × n_mode
/// blocks, frame-major. The trapezoid integral of a pair's marginal is the mass of that mode
/// in the box. mass, mean and covariance are per frame over every mode: mean [frame][axis],
/// covariance [frame][axis][axis] (of the state, weighted by the mass in the box).
struct Marginals {
  std::vector<std::array<std::size_t, 2>> pairs;  ///< The pairs of axes (a, b), a < b.
  std::vector<std::size_t> offset;                ///< Start of each pair in a block.
  std::size_t block = 0;                          ///< Values per (frame, mode).
  std::vector<double> values;                     ///< The marginal densities.
  std::vector<double> mass;                       ///< Mass in the box per frame.
  std::vector<double> mean;                       ///< Mean state per frame.
  std::vector<double> covariance;                 ///< Covariance per frame.
  /// Whether there are none (a run that kept the full density).
  [[nodiscard]] bool empty() const { return pairs.empty(); }
  /// Pair p's n_a × n_b values in frame k, mode m (of n_mode).
  [[nodiscard]] std::span<const double> pair(std::size_t k, std::size_t m, std::size_t n_mode,
                                             std::size_t p) const {
    const std::size_t size = (p + 1 < offset.size() ? offset[p + 1] : block) - offset[p];
    return std::span<const double>(values).subspan((k * n_mode + m) * block + offset[p], size);
  }
  /// The index of pair (a, b), a < b, in `pairs` (pairs.size() when absent).
  [[nodiscard]] std::size_t index(std::size_t a, std::size_t b) const {
    for (std::size_t p = 0; p < pairs.size(); ++p)
      if (pairs[p][0] == a && pairs[p][1] == b) return p;
    return pairs.size();
  }
};

}  // namespace hybgen::rt
