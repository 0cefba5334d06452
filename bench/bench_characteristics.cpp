// Benchmarks of the characteristics method on the paper's bouncing ball (§4.1):
// the paper's MATLAB script took 252 s for a 75×75 grid and 50 steps with
// nearest-grid-point interpolation. Each benchmark reports the solve time and
// the relative L1 error against the closed-form density of the elastic ball
// (tests/support/ball_closed_form.hpp).
//
// Run: build/bench/hybgen_bench   (see README).

#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "bouncing_ball/bouncing_ball.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "support/ball_closed_form.hpp"

namespace {

using Model = hybgen_model::bouncing_ball;
namespace rt = hybgen::rt;

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
  state.counters["rel_L1"] = hybgen::testing::ball_relative_l1(grid, sol, times);
}

/// The paper's configuration: 75×75, Δt = 0.2, to t = 9.8 (50 steps).
void BM_PaperConfiguration(benchmark::State& state) {
  solve(state, 75, 9.8, 0.2);
}
BENCHMARK(BM_PaperConfiguration)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

/// Growing grids to t = 10 with outputs every 0.5.
void BM_Grid(benchmark::State& state) {
  solve(state, static_cast<int>(state.range(0)), 10.0, 0.5);
}
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
