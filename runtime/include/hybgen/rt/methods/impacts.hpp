#pragma once
/// \file impacts.hpp
/// Impacts on a guard: how much mass crosses it, and how often, by each output time.
///
/// Definition. For guard g and output time t_k,
///   N_g(t_k) = Σ_m ∫ u0(m, x)·n_g(m, x; t_k) dx,
/// n_g the number of times g fires on the hybrid flow from (m, x) in (0, t_k] (a firing at an
/// absorbing guard counts once, and ends the flow). Each firing counts with the mass it
/// carries, so N_g is the mass that has crossed g by t_k, counted once per crossing, and
///   r_g(t_k) = (N_g(t_k) − N_g(t_{k−1}))/(t_k − t_{k−1})   (t_{−1} = 0, N_g(0) = 0)
/// is the mean rate at which mass crosses g over (t_{k−1}, t_k]: impacts per unit time, summed
/// over the modes; as dt → 0, the flux of u through g. With one unit of initial mass, N_g is
/// the expected number of impacts by t_k. For an absorbing guard N_g is its absorbed mass (the
/// same number as summary.json's `absorbed`), N_g/mass0 the probability of reaching g by t_k,
/// and r_g/mass0 the mean density of the first-passage time over the interval.
///
/// Zeno. A flow that comes to rest at a Zeno point fires its last guard infinitely often
/// before t_Z, so N_g(t_k) is infinite once any mass has reached such a point through g. The
/// methods report it from the first frame at or after the earliest Zeno time they saw on g
/// (`impacts_infinite_from`; values, errors and rates null there), over the flows that come
/// to rest at a time t_Z > 0: the points that reach a Zeno point by bouncing fill a set of
/// positive measure, while one already at rest at t = 0 (the ball's (0, 0) as a grid node) is
/// a single point, no mass. Before that
/// the count is finite and measured; the mass that reaches a Zeno point only later is counted
/// with the firings it has made by t_k.
///
/// Who measures it (MassBudget::impacts): characteristics by forward flows from the box in an
/// adaptive cubature of the initial density (budget/atom.hpp, `adaptive_impacts`, with the
/// budget; its estimated error); particles by counting each particle's firings (2σ̂ by
/// collapsed strata, particles.hpp); transfer by the fraction of every cell's samples that
/// fire g within one step, applied to the marched density (transfer.hpp; the mass of the box
/// only: what has left it fires nothing, and no error estimate). The cubature and the
/// particles follow a flow that leaves the box and comes back; transfer does not.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <vector>

namespace hybgen::rt {

/// The mean impact rates of one guard over the intervals between frames (file comment), and
/// their errors: NaN where the interval is empty (a first frame at t = 0) or the impacts are
/// infinite (k ≥ infinite_from) or not measured.
struct ImpactRates {
  std::vector<double> rate;   ///< r_g(t_k).
  std::vector<double> error;  ///< (e_k + e_{k−1})/(t_k − t_{k−1}); NaN without errors.
};

/// `ImpactRates` of the impacts `n` (errors `e`, may be empty) at `times`.
inline ImpactRates impact_rates(std::span<const double> times, const std::vector<double>& n,
                                const std::vector<double>& e, std::size_t infinite_from) {
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  const std::size_t K = std::min(times.size(), n.size());
  ImpactRates r{std::vector<double>(K, nan), std::vector<double>(K, nan)};
  for (std::size_t k = 0; k < K && k < infinite_from; ++k) {
    const double t0 = k > 0 ? times[k - 1] : 0.0, n0 = k > 0 ? n[k - 1] : 0.0;
    const double dt = times[k] - t0;
    if (!(dt > 0.0)) continue;
    r.rate[k] = (n[k] - n0) / dt;
    if (e.size() >= K) r.error[k] = (e[k] + (k > 0 ? e[k - 1] : 0.0)) / dt;
  }
  return r;
}

/// The first frame k with times[k] ≥ zeno_time[g], per guard (times.size() if none): from
/// there the impacts on g are infinite (file comment).
inline std::vector<std::size_t> impacts_infinite_from(std::span<const double> times,
                                                      const std::vector<double>& zeno_time) {
  std::vector<std::size_t> from(zeno_time.size(), times.size());
  for (std::size_t g = 0; g < zeno_time.size(); ++g)
    from[g] = static_cast<std::size_t>(std::lower_bound(times.begin(), times.end(), zeno_time[g]) -
                                       times.begin());
  return from;
}

}  // namespace hybgen::rt
