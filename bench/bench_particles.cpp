// Benchmarks of the particle method on the paper's bouncing ball (§4.1), elastic (e = 1),
// through the committed generated kernels: the paper's configuration (75×75 on [0, 2] ×
// [−2, 2], Δt = 0.2, t ≤ 9.8) with 1e5 and 1e6 particles. Counters: the relative L1 error
// of the deposited density against the closed-form density (as in bench_characteristics.cpp;
// summed over all output times; the Zeno node (0, 0), where the density has no limit, left
// out), the number of particles, nodes and outputs. The error is Monte-Carlo noise
// (∝ n^(−1/2) per node) plus the cloud-in-cell smoothing (O(h²) where the density is smooth).
//
// Run: build/bench/hybgen_bench_particles

#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "bouncing_ball/bouncing_ball.hpp"
#include "hybgen/rt/methods/particles.hpp"
#include "support/ball_closed_form.hpp"

namespace {

using Model = hybgen_model::bouncing_ball;
namespace rt = hybgen::rt;

void BM_PaperConfigurationParticles(benchmark::State& state) {
  rt::TensorGrid<2> grid;
  grid.axes = {rt::GridAxis{0.0, 2.0, 75}, rt::GridAxis{-2.0, 2.0, 75}};
  std::vector<double> times;
  for (int k = 0; k < 50; ++k) times.push_back(0.2 * k);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  rt::ParticleOptions opt;
  opt.particles = static_cast<std::size_t>(state.range(0));
  opt.seed = 1;
  opt.forward.ode.rtol = 1e-10;
  opt.forward.ode.atol = 1e-12;
  rt::ParticleRun<2> run;
  for (auto _ : state) {
    run = rt::solve_particles<Model>(grid, times, par.data(), opt);
    benchmark::DoNotOptimize(run.solution.u.data());
  }
  if (!run.ok()) state.SkipWithError("a particle trajectory failed");
  state.counters["particles"] = static_cast<double>(opt.particles);
  state.counters["nodes"] = static_cast<double>(grid.size());
  state.counters["outputs"] = static_cast<double>(times.size());
  state.counters["rel_L1"] = hybgen::testing::ball_relative_l1(grid, run.solution, times);
  double worst = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k)
    worst = std::max(worst, std::fabs(run.budget.mass[k] + run.budget.outflow[k] +
                                      run.budget.atom[k] - run.budget.mass0));
  state.counters["budget_residual"] = worst;
}
BENCHMARK(BM_PaperConfigurationParticles)
    ->Arg(100000)
    ->Arg(1000000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
