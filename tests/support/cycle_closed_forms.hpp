#pragma once
/// \file cycle_closed_forms.hpp
/// Closed-form invariant densities of the hybrid cycles in tests/validation/models/ and
/// models/sawtooth.model, derived here (none comes from hybgen), and the relative L1 error of
/// a density on the nodes of a grid against them.
///
/// In one dimension Liouville's equation for a stationary density is (u f)' = 0 between
/// switches, and the mass that crosses a switch per unit time arrives at the reset's image, so
/// the flux q = u|f| is one constant all around a cycle: u = q/|f| on the cycle, 0 elsewhere,
/// q = 1/period for unit mass. A flow that is periodic has its generator's spectrum at
/// 2πik/period (k ∈ ℤ): the transfer operator's λ = e^{μh} lie on the unit circle, none
/// decays, and arg λ₂ = 2πh/period.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <numbers>
#include <ostream>
#include <string>
#include <vector>

#include "hybgen/rt/io/npy.hpp"

namespace hybgen::testing {

/// thermostat_fv.model: heat T' = 4 − T until T = 2, cool T' = −T until T = 1; on [1, 2]
/// u_heat = 1/(ln 3 (4 − T)), u_cool = 1/(ln 3 T); period ln 3. Mode 0 heat, 1 cool.
inline double thermostat_density(int mode, double T) {
  if (T < 1.0 || T > 2.0) return 0.0;
  return 1.0 / (std::log(3.0) * (mode == 0 ? 4.0 - T : T));
}
/// Whether T is on a jump of the thermostat's density (T = 1 or 2): two-valued there.
inline bool on_thermostat_jump(double T) {
  return std::fabs(T - 1.0) < 1e-9 || std::fabs(T - 2.0) < 1e-9;
}

/// models/sawtooth.model: x' = 1 + x on [0, 1], x ↦ 0 at 1; u = 1/(ln 2 (1 + x)), period ln 2.
inline double sawtooth_density(double x) {
  return 1.0 / (std::log(2.0) * (1.0 + x));
}

/// quadratic_cycle.model: x' = 1 + x² on [0, 1], x ↦ 0 at 1; u = (4/π)/(1 + x²), period π/4.
inline double quadratic_density(double x) {
  return 4.0 / std::numbers::pi / (1.0 + x * x);
}

/// halving_cycle.model: up x' = 1 + x to 1, x ↦ x/2, down x' = −(1 + x) to 0; u = q/(1 + x)
/// with q = 1/ln 3 going up on [0, 1] and going down on [0, 1/2]; period ln 3. Mode 0 up.
inline double halving_density(int mode, double x) {
  if (mode == 1 && x > 0.5) return 0.0;
  return 1.0 / (std::log(3.0) * (1.0 + x));
}

/// The node of index i of n on [lo, hi].
inline double grid_node(double lo, double hi, int n, int i) {
  return lo + (hi - lo) * i / (n - 1);
}

/// Trapezoid weight of index i of n (up to the spacing, which cancels in a relative norm).
inline double trapezoid_weight(int n, int i) {
  return i == 0 || i == n - 1 ? 0.5 : 1.0;
}

/// One axis of a grid: n nodes on [lo, hi].
struct Axis {
  double lo = 0.0, hi = 1.0;  ///< The ends.
  int n = 2;                  ///< Nodes.
};

/// Σ w|u − exact| / Σ w|exact| over the nodes of a tensor grid (C order), the nodes where
/// `skip` holds left out (Σ w|u| where the exact density is 0 on every node: a mode not yet
/// reached); NaN if u has the wrong size.
inline double relative_l1(const std::vector<double>& u, const std::vector<Axis>& axes,
                          const std::function<double(const std::vector<double>&)>& exact,
                          const std::function<bool(const std::vector<double>&)>& skip = {}) {
  std::size_t total = 1;
  for (const Axis& a : axes) total *= static_cast<std::size_t>(a.n);
  if (u.size() != total) return std::nan("");
  double num = 0.0, den = 0.0;
  std::vector<double> x(axes.size());
  for (std::size_t k = 0; k < total; ++k) {
    std::size_t rem = k;
    double w = 1.0;
    for (std::size_t a = axes.size(); a-- > 0;) {
      const auto i = static_cast<int>(rem % static_cast<std::size_t>(axes[a].n));
      rem /= static_cast<std::size_t>(axes[a].n);
      x[a] = grid_node(axes[a].lo, axes[a].hi, axes[a].n, i);
      w *= trapezoid_weight(axes[a].n, i);
    }
    if (skip && skip(x)) continue;
    const double e = exact(x);
    num += w * std::fabs(u[k] - e);
    den += w * std::fabs(e);
  }
  return den > 0.0 ? num / den : num;
}

/// A point of the state space.
using Point = std::vector<double>;

/// One closed-form case: a model, its grid, its modes' exact densities and its periods.
struct Case {
  std::string name;                                ///< Test name part.
  std::string model;                               ///< Path from the source directory.
  std::vector<Axis> axes;                          ///< The grid the run uses (--set grid=...).
  std::vector<std::string> modes;                  ///< Mode names ({""}: one mode, invariant.npy).
  std::function<double(int, const Point&)> exact;  ///< Mode m's density at a point.
  std::function<bool(const Point&)> on_jump;       ///< Nodes on a jump, left out.
  /// The periods T_i of the independent cycles: the exact spectrum is exp(2πih Σ k_i/T_i).
  std::vector<double> periods;
};

/// gtest's name for a case in messages.
inline void PrintTo(const Case& c, std::ostream* os) {
  *os << c.name;
}

/// The setting `grid` of the axes ("281", "141x101").
inline std::string grid_setting(const std::vector<Axis>& axes) {
  std::string g;
  for (const Axis& a : axes) {
    if (!g.empty()) g += 'x';
    g += std::to_string(a.n);
  }
  return g;
}

/// Whether a point is on a jump of the thermostat density (its first coordinate).
inline bool thermostat_jump(const Point& x) {
  return on_thermostat_jump(x[0]);
}

/// The five cycles of tests/validation/test_invariant_errors.cpp and
/// bench/bench_invariant.cpp, at the grids they run on.
inline std::vector<Case> cycle_cases() {
  const std::string m = "tests/validation/models/";
  return {
      {"thermostat",
       m + "thermostat_fv.model",
       {{0.8, 2.2, 281}},
       {"heat", "cool"},
       [](int mode, const Point& x) { return thermostat_density(mode, x[0]); },
       thermostat_jump,
       {std::log(3.0)}},
      {"sawtooth",
       "models/sawtooth.model",
       {{0.0, 1.0, 401}},
       {""},
       [](int, const Point& x) { return sawtooth_density(x[0]); },
       {},
       {std::log(2.0)}},
      {"quadratic",
       m + "quadratic_cycle.model",
       {{0.0, 1.0, 401}},
       {""},
       [](int, const Point& x) { return quadratic_density(x[0]); },
       {},
       {std::numbers::pi / 4.0}},
      {"halving",
       m + "halving_cycle.model",
       {{0.0, 1.0, 401}},
       {"up", "down"},
       [](int mode, const Point& x) { return halving_density(mode, x[0]); },
       [](const Point& x) { return std::fabs(x[0] - 0.5) < 1e-9; },
       {std::log(3.0)}},
      {"product",
       m + "thermostat_sawtooth_fv.model",
       {{0.8, 2.2, 141}, {0.0, 1.0, 101}},
       {"heat", "cool"},
       [](int mode, const Point& x) {
         return thermostat_density(mode, x[0]) * sawtooth_density(x[1]);
       },
       thermostat_jump,
       {std::log(3.0), std::log(2.0)}},
  };
}

/// A case's true error: the worst mode's relative L1 error of the invariant density that a
/// run wrote in `dir` (invariant.npy, or invariant_MODE.npy per mode).
inline double cycle_case_error(const Case& c, const std::filesystem::path& dir) {
  double worst = 0.0;
  for (std::size_t m = 0; m < c.modes.size(); ++m) {
    const std::filesystem::path p =
        dir / (c.modes[m].empty() ? "invariant.npy" : "invariant_" + c.modes[m] + ".npy");
    const std::vector<double> u = hybgen::rt::read_npy(p.string()).data;
    const int mode = static_cast<int>(m);
    worst = std::max(worst,
                     relative_l1(
                         u, c.axes, [&](const Point& x) { return c.exact(mode, x); }, c.on_jump));
  }
  return worst;
}
}  // namespace hybgen::testing
