// Benchmarks of the transfer-operator method (runtime/transfer.hpp) on the paper's bouncing
// ball (§4.1), with the committed generated kernels:
//  (a) BM_TransferPaper: the paper's configuration, 75×75, h = Δt = 0.2, to t = 9.8:
//      time (assembly + march) and relative L1 errors against the closed-form density;
//  (b) BM_TransferGrid / BM_TransferGridH16: grids 65² … 1025² to t = 10 (outputs every
//      0.5) at h = 0.05 and at h = 1/16: time including assembly, relative L1 error at t = 10
//      and the observed order against the previous grid (the test BallConvergesAtSecondOrder
//      asserts the h = 1/16 orders; at h = 0.05 the momentum shift per step is a fractional
//      number of cells that alternates between grids, so the order oscillates around the
//      trend by ±log₂1.5);
//  (c) BM_TransferStep*: one CSR mat-vec against the memory-traffic floor, bytes moved /
//      bandwidth of a STREAM triad measured in the same process.
//
// Run: build/bench/hybgen_bench_transfer   (see README).

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <tuple>
#include <vector>

#include "bouncing_ball/bouncing_ball.hpp"
#include "hybgen/rt/methods/invariant.hpp"
#include "hybgen/rt/methods/transfer.hpp"
#include "support/ball_closed_form.hpp"

namespace {

using Model = hybgen_model::bouncing_ball;
namespace rt = hybgen::rt;

/// Elastic ball, m = g = 1: u(t, x, p) = u0(φ₋ₜ(x, p)) (tests/support/ball_closed_form.hpp).
template <class U0>
double exact_elastic(double x, double p, double t, U0&& u0) {
  if (0.5 * p * p + x <= 0.0) return std::nan("");  // the Zeno point: no limit
  return hybgen::testing::ball_pullback_elastic(x, p, t, u0);
}

double gauss_u0(double x, double p) {
  return x >= 0.0 ? std::exp(-(x - 1.0) * (x - 1.0) - p * p) : 0.0;
}

/// Smooth cut-off in the energy: 1 for E ≤ 1, 0 for E ≥ 1.8 (quintic smoothstep).
double chi(double E) {
  const double s = std::clamp((1.8 - E) / 0.8, 0.0, 1.0);
  return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
}

double compact_u0(double x, double p) {
  return gauss_u0(x, p) * chi(0.5 * p * p + x);
}

/// The generated ball with an initial density supported in {E ≤ 1.8}, an invariant set
/// inside the box: no mass meets the faces, so the error is the discretisation error alone
/// (a box-limited operator has no inflow, and ~9 % of the Gaussian's mass starts at x > 2).
struct CompactBall : Model {
  /// u0 = Gaussian · χ(E).
  static double initial_density(int, const double* x, const double*) {
    return compact_u0(x[0], x[1]);
  }
};

rt::TensorGrid<2> ball_grid(int n) {
  rt::TensorGrid<2> g;
  g.axes = {rt::GridAxis{0.0, 2.0, n}, rt::GridAxis{-2.0, 2.0, n}};
  return g;
}

rt::TransferOptions options(double h) {
  rt::TransferOptions o;
  o.step = h;
  o.forward.ode.rtol = 1e-10;
  o.forward.ode.atol = 1e-12;
  return o;
}

std::vector<double> output_times(double t_end, double dt) {
  std::vector<double> t;
  for (int k = 0; k * dt <= t_end + 1e-9; ++k) t.push_back(k * dt);
  return t;
}

/// Σ|u − u_exact| / Σ|u_exact| over the output times `ks` and the nodes with `keep(x, p)`
/// (plain sums as in bench_characteristics.cpp; the Zeno node excluded).
template <class U0, class Keep>
double relative_l1(const rt::TensorGrid<2>& grid, const rt::Solution<2>& sol,
                   const std::vector<double>& times, const std::vector<std::size_t>& ks, U0&& u0,
                   Keep&& keep) {
  double err = 0.0, norm = 0.0;
  for (const std::size_t k : ks)
    for (std::size_t i = 0; i < grid.size(); ++i) {
      const auto y = grid.node(i);
      const double ue = exact_elastic(y[0], y[1], times[k], u0);
      if (std::isnan(ue) || !keep(y[0], y[1])) continue;
      err += std::fabs(sol.at(k, 0, i) - ue);
      norm += std::fabs(ue);
    }
  return err / norm;
}

// ---------------------------------------------------------------------------------------
// (a) The paper's configuration.

/// rel_L1: against the exact density on the whole box, all 50 outputs (like the
/// characteristics benchmark) — dominated by the inflow a box-limited method cannot know;
/// rel_L1_E2: on the nodes with E ≤ 2, the largest invariant set inside the box, whose exact
/// density no inflow reaches.
void paper_run(benchmark::State& state, rt::TransferScheme scheme) {
  const auto grid = ball_grid(75);
  const auto times = output_times(9.8, 0.2);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  auto opt = options(0.2);
  opt.scheme = scheme;
  opt.forward.ode.rtol = 1e-10;
  opt.forward.ode.atol = 1e-12;
  rt::TransferRun<2> run;
  double assembly = 0.0;
  for (auto _ : state) {
    const auto op = rt::assemble_transfer<Model>(grid, par.data(), opt);
    if (!op.ok()) {
      state.SkipWithError("a trace failed");
      return;
    }
    run = rt::march(op, rt::initial_vector<Model>(grid, par.data()), times);
    assembly = op.seconds;
    benchmark::DoNotOptimize(run.solution.u.data());
  }
  std::vector<std::size_t> all(times.size());
  for (std::size_t k = 0; k < all.size(); ++k) all[k] = k;
  state.counters["assembly_s"] = assembly;
  state.counters["rel_L1"] =
      relative_l1(grid, run.solution, times, all, gauss_u0, [](double, double) { return true; });
  state.counters["rel_L1_E2"] =
      relative_l1(grid, run.solution, times, all, gauss_u0,
                  [](double x, double p) { return 0.5 * p * p + x <= 2.0; });
  state.counters["mass_loss"] = run.budget.mass0 - run.budget.mass.back();
  double closure = 0.0;
  for (std::size_t k = 0; k < times.size(); ++k)
    closure = std::max(closure, std::fabs(run.budget.mass[k] + run.budget.outflow[k] +
                                          run.budget.atom[k] - run.budget.mass0));
  state.counters["budget_err"] = closure;
}

/// The `hat` scheme (default), 4×4 samples per cell.
void BM_TransferPaper(benchmark::State& state) {
  paper_run(state, rt::TransferScheme::hat);
}
BENCHMARK(BM_TransferPaper)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);

/// The `galerkin` scheme (transfer.hpp: the hat expansion moved exactly and projected back),
/// its default 8×8 samples per cell.
void BM_TransferPaperGalerkin(benchmark::State& state) {
  paper_run(state, rt::TransferScheme::galerkin);
}
BENCHMARK(BM_TransferPaperGalerkin)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);

// ---------------------------------------------------------------------------------------
// (b) Work–precision.

std::map<std::tuple<double, int, int>, double>& errors() {
  static std::map<std::tuple<double, int, int>, double> e;
  return e;
}

void grid_run(benchmark::State& state, double h,
              rt::TransferScheme scheme = rt::TransferScheme::hat) {
  const int n = static_cast<int>(state.range(0));
  const auto grid = ball_grid(n);
  const auto times = output_times(10.0, 0.5);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  rt::TransferRun<2> run;
  double assembly = 0.0, step_s = 0.0;
  long nnz = 0;
  for (auto _ : state) {
    rt::TransferOptions o = options(h);
    o.scheme = scheme;
    const auto op = rt::assemble_transfer<CompactBall>(grid, par.data(), o);
    if (!op.ok()) {
      state.SkipWithError("a trace failed");
      return;
    }
    run = rt::march(op, rt::initial_vector<CompactBall>(grid, par.data()), times);
    assembly = op.seconds;
    step_s = run.seconds / static_cast<double>(run.n_steps);
    nnz = static_cast<long>(op.P.nonZeros());
    benchmark::DoNotOptimize(run.solution.u.data());
  }
  // Trapezoid-weighted relative L1 error at t = 10, as in test_transfer.cpp.
  const auto w = rt::detail::trapezoid_weights(grid, 1);
  double num = 0.0, den = 0.0;
  const std::size_t k = times.size() - 1;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    const auto y = grid.node(i);
    const double ue = exact_elastic(y[0], y[1], times[k], compact_u0);
    if (std::isnan(ue)) continue;
    num += w[i] * std::fabs(run.solution.at(k, 0, i) - ue);
    den += w[i] * std::fabs(ue);
  }
  const double err = num / den;
  const int key = static_cast<int>(scheme);
  errors()[{h, n, key}] = err;
  state.counters["nodes"] = static_cast<double>(grid.size());
  state.counters["nnz"] = static_cast<double>(nnz);
  state.counters["assembly_s"] = assembly;
  state.counters["step_s"] = step_s;
  state.counters["rel_L1_t10"] = err;
  if (const auto it = errors().find({h, (n - 1) / 2 + 1, key}); it != errors().end())
    state.counters["order"] = std::log2(it->second / err);
}

/// h = 0.05 (the target configuration at 1025²).
void BM_TransferGrid(benchmark::State& state) {
  grid_run(state, 0.05);
}
BENCHMARK(BM_TransferGrid)
    ->Arg(65)
    ->Arg(129)
    ->Arg(257)
    ->Arg(513)
    ->Arg(1025)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

/// h = 0.05 by `galerkin`: second order, and no growth of the error with the steps.
void BM_TransferGridGalerkin(benchmark::State& state) {
  grid_run(state, 0.05, rt::TransferScheme::galerkin);
}
BENCHMARK(BM_TransferGridGalerkin)
    ->Arg(65)
    ->Arg(129)
    ->Arg(257)
    ->Arg(513)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

/// h = 1/16: whole-cell momentum shifts on every grid (the test's configuration).
void BM_TransferGridH16(benchmark::State& state) {
  grid_run(state, 1.0 / 16.0);
}
BENCHMARK(BM_TransferGridH16)
    ->Arg(65)
    ->Arg(129)
    ->Arg(257)
    ->Arg(513)
    ->Arg(1025)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

// ---------------------------------------------------------------------------------------
// (c) Step time against the memory-traffic floor.

/// Bandwidth (bytes/s) of a STREAM triad a = b + s·c over three arrays of 2²⁴ doubles
/// (3 × 128 MiB ≫ the 32 MiB L3), OpenMP static schedule, first-touch initialised with the
/// same schedule; STREAM's count of 24 bytes per element (write-allocate traffic not
/// counted, as for the mat-vec floor); best of 10. Measured afresh for every benchmark, right
/// before its steps: on a shared machine the available bandwidth drifts with the load.
double triad_bandwidth() {
  const double bw = [] {
    const std::int64_t n = std::int64_t{1} << 24;
    double* a = new double[static_cast<std::size_t>(n)];
    double* b = new double[static_cast<std::size_t>(n)];
    double* c = new double[static_cast<std::size_t>(n)];
#pragma omp parallel for schedule(static)
    for (std::int64_t i = 0; i < n; ++i) {
      a[i] = 0.0;
      b[i] = 1.0;
      c[i] = 2.0;
    }
    double best = 1e300;
    for (int rep = 0; rep < 10; ++rep) {
      const auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static)
      for (std::int64_t i = 0; i < n; ++i) a[i] = b[i] + 3.0 * c[i];
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      benchmark::DoNotOptimize(a[rep]);
      best = std::min(best, s);
    }
    delete[] a;
    delete[] b;
    delete[] c;
    return 24.0 * static_cast<double>(n) / best;
  }();
  return bw;
}

enum class StepKind { own, own_mass, eigen };

void step_run(benchmark::State& state, StepKind kind) {
  const int n = static_cast<int>(state.range(0));
  const auto grid = ball_grid(n);
  const std::array<double, 3> par{1.0, 1.0, 1.0};
  const auto op = rt::assemble_transfer<Model>(grid, par.data(), options(0.05));
  const auto R = static_cast<Eigen::Index>(op.size());
  Eigen::VectorXd x =
      Eigen::Map<const Eigen::VectorXd>(rt::initial_vector<Model>(grid, par.data()).data(), R);
  Eigen::VectorXd y = Eigen::VectorXd::Zero(R);
  const double bw = triad_bandwidth();
  double best = 1e300;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    switch (kind) {
      case StepKind::own:
        rt::detail::csr_matvec(op.P, x.data(), y.data());
        break;
      case StepKind::own_mass:
        benchmark::DoNotOptimize(
            rt::detail::csr_step(op.P, x.data(), y.data(), op.outflow.data(), op.atom.data()));
        break;
      case StepKind::eigen:
        y.noalias() = op.P * x;
        break;
    }
    x.swap(y);
    benchmark::ClobberMemory();
    best = std::min(best,
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  const double nnz = static_cast<double>(op.P.nonZeros()), rows = static_cast<double>(R);
  double bytes = 12.0 * nnz + 4.0 * (rows + 1.0) + 16.0 * rows;
  if (kind == StepKind::own_mass) bytes += 8.0 * rows;  // the trapezoid weights
  state.counters["nnz"] = nnz;
  state.counters["bytes"] = bytes;
  state.counters["bw_GBps"] = bw * 1e-9;
  state.counters["floor_s"] = bytes / bw;
  state.counters["step_s"] = benchmark::Counter(
      1.0, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  // Fastest single step and its ratio to the floor (less sensitive to other processes).
  state.counters["step_min_s"] = best;
  state.counters["ratio_min"] = best / (bytes / bw);
  // (mean seconds per step) / floor_s.
  state.counters["ratio"] = benchmark::Counter(
      bytes / bw, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

/// Own OpenMP CSR loop (static schedule), plain y = P x.
void BM_TransferStep(benchmark::State& state) {
  step_run(state, StepKind::own);
}
/// The step `march` takes: y = P x fused with the discrete mass Σ w y.
void BM_TransferStepMass(benchmark::State& state) {
  step_run(state, StepKind::own_mass);
}
/// Eigen's y.noalias() = P x (OpenMP inside Eigen, dynamic schedule).
void BM_TransferStepEigen(benchmark::State& state) {
  step_run(state, StepKind::eigen);
}
BENCHMARK(BM_TransferStep)->Arg(257)->Arg(1025)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_TransferStepMass)->Arg(257)->Arg(1025)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_TransferStepEigen)->Arg(257)->Arg(1025)->UseRealTime()->MinTime(1.0);

}  // namespace

BENCHMARK_MAIN();
