// Benchmarks of the characteristics method on the paper's bouncing ball (§4.1):
// the paper's MATLAB script took 252 s for a 75×75 grid and 50 steps with
// nearest-grid-point interpolation. Each benchmark reports the solve time and
// the relative L1 error against the closed-form density (elastic ball,
// m = g = 1): u(t, x, p) = u0(R φ_t(R(x, p))), R(x, p) = (x, −p).
//
// Run: build/bench/hybgen_bench   (see README).

#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "bouncing_ball/bouncing_ball.hpp"
#include "hybgen/rt/characteristics.hpp"

namespace {

using Model = hybgen_model::bouncing_ball;
namespace rt = hybgen::rt;

double exact_elastic(double t, double x, double p) {
  const double p0 = -p, v0 = std::sqrt(p0 * p0 + 2 * x);
  if (v0 == 0.0) return std::nan("");  // the Zeno point: no limit
  const double tau = std::fmod(v0 - p0 + t, 2 * v0);
  const double xf = v0 * tau - tau * tau / 2, pf = -(v0 - tau);
  return std::exp(-(xf - 1) * (xf - 1) - pf * pf);
}

/// Relative L1 error over all output times and nodes (the Zeno node excluded).
double relative_l1(const rt::TensorGrid<2>& grid, const rt::Solution<2>& sol,
                   const std::vector<double>& times) {
  double err = 0, norm = 0;
  for (std::size_t k = 0; k < times.size(); ++k)
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const auto y = grid.node(i);
      const double ue = exact_elastic(times[k], y[0], y[1]);
      if (std::isnan(ue)) continue;
      err += std::fabs(sol.at(k, 0, i) - ue);
      norm += std::fabs(ue);
    }
  return err / norm;
}

void solve(benchmark::State& state, int n, double t_end, double dt) {
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{0.0, 2.0, n}, rt::GridAxis{-2.0, 2.0, n}};
  std::vector<double> times;
  for (int k = 0; k * dt <= t_end + 1e-9; ++k) times.push_back(k * dt);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  rt::CharacteristicsOptions opt;
  opt.ode.rtol = 1e-10;
  opt.ode.atol = 1e-12;
  rt::Solution<2> sol;
  for (auto _ : state) {
    sol = rt::solve_grid<Model>(grid, times, par.data(), opt);
    benchmark::DoNotOptimize(sol.u.data());
  }
  if (!sol.ok()) state.SkipWithError("a characteristic failed");
  state.counters["nodes"] = static_cast<double>(grid.size());
  state.counters["outputs"] = static_cast<double>(times.size());
  state.counters["rel_L1"] = relative_l1(grid, sol, times);
}

/// The paper's configuration: 75×75, Δt = 0.2, to t = 9.8 (50 steps).
void BM_PaperConfiguration(benchmark::State& state) {
  solve(state, 75, 9.8, 0.2);
}
BENCHMARK(BM_PaperConfiguration)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

/// Growing grids to t = 10 with outputs every 0.5.
void BM_Grid(benchmark::State& state) { solve(state, static_cast<int>(state.range(0)), 10.0, 0.5); }
BENCHMARK(BM_Grid)
    ->Arg(65)
    ->Arg(129)
    ->Arg(257)
    ->Arg(513)
    ->Arg(1025)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
