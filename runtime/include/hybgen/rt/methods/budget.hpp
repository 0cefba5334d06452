#pragma once
/// \file budget.hpp
/// Accurate mass budgets by adaptive cubature: the box mass Σ_modes ∫_box u(t_k), the
/// cumulative outflow through the box faces and the mass at Zeno points, for all output
/// times at once, with u evaluated exactly (to ODE tolerance) by backward characteristics at
/// the cubature nodes. The one include for callers; the concepts live in budget/:
///  * budget/cubature_rule.hpp, budget/cubature.hpp: the adaptive cubature (cells, the rule
///    on a cell, refinement, the error model, its work bound);
///  * budget/check_points.hpp: the points where the integrand is already known;
///  * budget/volume.hpp: the mass on the grid's box (`adaptive_mass`);
///  * budget/faces.hpp: the outflow through the box faces (`adaptive_outflow`);
///  * budget/atom.hpp: the mass at Zeno points and the mass resets carry out of the box
///    (`adaptive_atom`);
///  * here: the three together and their closure (`adaptive_mass_budget`).
///
/// Why adaptive. Near a Zeno point the density is unbounded and striped (bouncing ball,
/// e < 1: u ~ 1/(p² + 2x) near (0, 0), with jumps by 1/e² across curves winding into the
/// origin); elsewhere it jumps across the images of the reset surface. Fixed rules
/// (trapezoid on the grid nodes, uniform Gauss) miss O(1) of the mass near the Zeno point,
/// and the face fluxes jump at fixed places (e.g. where the reset image of a box edge meets a
/// face), which uniform face rules integrate with an O(h) error that accumulates over time.
/// The runtime does not know where any of this is, so the cubature finds it.
///
/// The terms are measured independently, so mass0 − mass − outflow − atom (the defect) tests
/// them: within the sum of their estimates it says the budget is closed; beyond, it is mass
/// no term measures (mass from outside the box that a reset carries into it, or an error the
/// estimates missed). The three share the cubature's refinement machinery and its
/// bound on work (budget/cubature.hpp).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/rt/core/grid.hpp"
#include "hybgen/rt/core/solution.hpp"
#include "hybgen/rt/methods/budget/atom.hpp"
#include "hybgen/rt/methods/budget/check_points.hpp"
#include "hybgen/rt/methods/budget/cubature.hpp"
#include "hybgen/rt/methods/budget/cubature_rule.hpp"
#include "hybgen/rt/methods/budget/faces.hpp"
#include "hybgen/rt/methods/budget/volume.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/mass_budget.hpp"
#include "hybgen/rt/model.hpp"

namespace hybgen::rt {

/// Diagnostics of `adaptive_mass_budget`.
struct AdaptiveBudgetInfo {
  AdaptiveMass volume;            ///< The volume integral (masses).
  AdaptiveOutflow surface;        ///< The face integral (outflow).
  AdaptiveOutflow atom;           ///< The atom's integral (`outflow` holds the atom).
  AdaptiveOutflow reset;          ///< The reset outflow's integral (part of the budget's outflow).
  std::size_t impact_points = 0;  ///< Points of the impacts' cubature (`adaptive_impacts`).
  double impact_seconds = 0.0;    ///< Its wall time.
};

/// The mass budget by adaptive cubature, every term measured on its own:
///  * mass and mass0: `adaptive_mass` (backward characteristics in the box);
///  * outflow: `adaptive_outflow` (backward characteristics on the faces, integrated in time
///    along each to rel_tol/10), target rel_tol·max(mass0, max_k mass_k), plus the net mass
///    that resets carry out of the box (forward flows from the box, `adaptive_atom`);
///  * atom: `adaptive_atom` (forward flows from the box to their Zeno points), same target;
///  * absorbed: the same flows, the mass each absorbing guard took (part of the outflow);
///  * impacts: forward flows too, the firings of every guard (`adaptive_impacts`; not a term
///    of the budget, methods/impacts.hpp).
/// Each has its estimated error (mass_error, outflow_error, atom_error, and drop_error for
/// mass0 − mass: `adaptive_mass`); the DEFECT
/// mass0 − mass − outflow − atom (`budget_defect`) checks them against each other: it is what
/// no term accounts for (mass that started outside the box and is reset into it, or an error
/// the estimates missed). `grid` gives the box and the
/// volume cubature's check points (`nodes`: the run's solution at its nodes, or null).
/// A failed characteristic is reported in `failure` (volume first), a failed forward flow in
/// `message`.
template <HybridModel M>
BudgetResult<state_dim_v<M>> adaptive_mass_budget(const TensorGrid<state_dim_v<M>>& grid,
                                                  std::span<const double> times, const double* par,
                                                  const CharacteristicsOptions& opt,
                                                  const AdaptiveOptions& aopt = {},
                                                  AdaptiveBudgetInfo* info = nullptr,
                                                  const Solution<state_dim_v<M>>* nodes = nullptr) {
  constexpr std::size_t N = state_dim_v<M>;
  BudgetResult<N> res;
  MassBudget& mb = res.budget;
  mb.times.assign(times.begin(), times.end());
  AdaptiveMass am = adaptive_mass<M>(grid, times, par, opt, aopt, res.failure, nodes);
  double scale = std::fabs(am.mass0);
  for (const double m : am.mass) scale = std::max(scale, std::fabs(m));
  TraceFailure<N> flux_failure;
  const double time_tol = 0.1 * aopt.rel_tol;
  AdaptiveOutflow ao =
      adaptive_outflow<M>(grid, times, par, opt, aopt, scale, time_tol, flux_failure);
  if (res.failure.ok()) res.failure = flux_failure;
  AdaptiveOutflow reset;
  std::vector<AdaptiveOutflow> absorbed;
  std::vector<double> zeno_time;
  AdaptiveOutflow az = adaptive_atom<M>(grid, times, par, opt, aopt, scale, res.message, &reset,
                                        &absorbed, &zeno_time);
  // The impacts on every guard, in their own cubature; infinite from the earliest Zeno time
  // the atom's flows saw on each guard (methods/impacts.hpp).
  mb.impacts_infinite_from = impacts_infinite_from(times, zeno_time);
  std::vector<AdaptiveOutflow> impacts;
  const auto t_impacts = std::chrono::steady_clock::now();
  if (res.message.empty())
    impacts = adaptive_impacts<M>(grid, times, par, opt, aopt, scale, mb.impacts_infinite_from,
                                  res.message);
  if (info != nullptr) {
    info->impact_points = impacts.empty() ? 0 : impacts.front().points;
    info->impact_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_impacts).count();
  }
  mb.impacts.assign(impacts.size(), {});
  mb.impacts_error.assign(impacts.size(), {});
  for (std::size_t g = 0; g < impacts.size(); ++g) {
    mb.impacts[g] = std::move(impacts[g].outflow);
    mb.impacts_error[g] = std::move(impacts[g].error);
  }
  mb.absorbed.assign(absorbed.size(), {});
  mb.absorbed_error.assign(absorbed.size(), {});
  for (std::size_t g = 0; g < absorbed.size(); ++g) {
    mb.absorbed[g] = std::move(absorbed[g].outflow);
    mb.absorbed_error[g] = std::move(absorbed[g].error);
  }
  mb.mass0 = am.mass0;
  mb.mass = am.mass;
  mb.mass_error = am.error;
  mb.mass0_error = am.mass0_error;
  mb.drop_error = am.drop_error;
  mb.outflow = ao.outflow;
  mb.reset_outflow = reset.outflow;
  for (std::size_t k = 0; k < times.size(); ++k) mb.outflow[k] += reset.outflow[k];
  mb.atom = az.outflow;
  mb.outflow_error.resize(times.size());
  mb.atom_error = az.error;
  // The time integral's tolerance is relative to max|u| along each face characteristic:
  // ≤ time_tol·scale over the run (scale ≥ the mass that can cross).
  // The time integrals' own share beyond that: what their work cap left unresolved and the
  // most their floor can change (budget/faces.hpp).
  for (std::size_t k = 0; k < times.size(); ++k)
    mb.outflow_error[k] = ao.error[k] + time_tol * scale + ao.time_error[k] + reset.error[k];
  if (info != nullptr) {
    info->volume = std::move(am);
    info->surface = std::move(ao);
    info->atom = std::move(az);
    info->reset = std::move(reset);
  }
  return res;
}

/// The bounds that stopped `adaptive_mass_budget` short of its tolerance, in words for the
/// run's warning ("" if none did): a cubature's point cap (budget/cubature.hpp), the work cap
/// of the faces' time integrals (budget/faces.hpp). Either way the error estimates are
/// widened by what was left (`error`, `outflow_error`), not the run prolonged.
inline std::string budget_bounds_reached(const AdaptiveBudgetInfo& info) {
  std::string s;
  if (info.volume.capped || info.surface.capped || info.atom.capped || info.reset.capped)
    s = "its point cap";
  if (info.surface.time_capped > 0) {
    if (!s.empty()) s += " and ";
    s += "the work cap of the time integral on " + std::to_string(info.surface.time_capped) +
         " face characteristics (their unresolved part is in outflow_error)";
  }
  return s;
}

}  // namespace hybgen::rt
