#pragma once
/// \file rt_setup.hpp
/// Set-up shared by the runtime tests (tests/rt/): output times, ODE tolerances, the paper's
/// grid of the bouncing ball and a wall clock.

#include <chrono>
#include <vector>

#include "hybgen/rt/methods/characteristics.hpp"

namespace hybgen::testing {

/// n output times 0, dt, …, (n − 1)·dt.
inline std::vector<double> output_times(int n, double dt) {
  std::vector<double> t;
  for (int k = 0; k < n; ++k) t.push_back(dt * k);
  return t;
}

/// Characteristics options with the ODE tolerances rtol and atol (the rest default).
inline rt::CharacteristicsOptions tolerances(double rtol, double atol) {
  rt::CharacteristicsOptions o;
  o.ode.rtol = rtol;
  o.ode.atol = atol;
  return o;
}

/// The paper's grid of the bouncing ball (§4.1): 75×75 nodes on [0, 2] × [−2, 2].
inline rt::TensorGrid<2> paper_grid() {
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{0.0, 2.0, 75}, rt::GridAxis{-2.0, 2.0, 75}};
  return grid;
}

/// Seconds of wall-clock time since t0.
inline double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace hybgen::testing
