// Benchmarks of the density solvers on higher-dimensional systems (docs/benchmarks.md):
// time and memory against grid size for
//  - the reduced Chaplygin sleigh, 3-D (models/chaplygin.model: state (v, omega, theta) on
//    [−1.5, 1.5]² × [−1, 1], t_end = 2, dt = 0.5), grids n³ for n = 17, 33, 65, 129;
//  - the S, I, R model with intervention, 3-D (models/sir_3d.model: [0.05, 1]³, t_end = 4,
//    dt = 0.5), grids n³ for n = 17, 33, 65, 129;
//  - the reduced GL₂ system, 5-D (models/gl2.model: ζ ∈ [−1, 1]⁴, q ∈ [0, 1], t_end = 1,
//    dt = 0.5), grids n⁵ for n = 5, 9, 13, 17;
// each with the committed generated kernels (generated/<model>/<model>.hpp), the model
// file's parameters, domain, t_end and dt (outputs every dt), ODE tolerances rtol = 1e-10,
// atol = 1e-12 (the runner's default tol = 1e-10).
//
//  BM_Characteristics_<model>/n: `solve_grid` (densities only; the adaptive mass budget
//    the runner adds is not timed). Counters: nodes, outputs, solve_s, us_per_node
//    (solve time / nodes: one backward characteristic per node serves all outputs),
//    sol_MB (bytes of the solution array: outputs × nodes × 8) and rss_MB.
//  BM_Transfer_<model>/n: `assemble_transfer` (interpolating scheme, step h = dt) and
//    `march` to t_end. Counters: nodes, assembly_s, march_s, step_s, us_per_node
//    (assembly time / nodes), nnz, nnz_per_row, csr_MB (values 8 B + column indices 4 B per
//    nonzero, row pointers 4 B per row), sol_MB (march output) and rss_MB.
//
// rss_MB is the growth of the process's peak resident set during the run: Linux's VmHWM
// after resetting it (`echo 5 > /proc/self/clear_refs`) right before the run, minus VmRSS
// at that moment (after malloc_trim(0), so that freed heap memory of earlier runs is not reused
// unseen) — everything the run touched (arrays, CSR, assembly buffers, per-thread workspaces),
// not an estimate. −1 if /proc is unavailable.
//
// Limits (so a run of the whole executable stays within minutes on a shared 2-core
// machine): a grid is skipped, with the reason as the benchmark's error message, when the
// previous grid's time scaled by the node ratio predicts more than HYBGEN_BENCH_CAP_S
// seconds (default 30), or, for the transfer operator, when its memory predicted from the
// previous grid's nonzeros per row (2^N per row before that) exceeds HYBGEN_BENCH_CAP_MB
// (default 4096) megabytes.
//
// Run: build/bench/hybgen_bench_dims   (see README; --benchmark_filter=GL2 for one model).

#include <benchmark/benchmark.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "chaplygin/chaplygin.hpp"
#include "gl2/gl2.hpp"
#include "hybgen/rt/methods/characteristics.hpp"
#include "hybgen/rt/methods/transfer.hpp"
#include "sir_3d/sir_3d.hpp"

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace {

namespace rt = hybgen::rt;

// ---------------------------------------------------------------------------------------
// Memory and limits.

/// A field of /proc/self/status in kB ("VmHWM", "VmRSS"), or −1.
long status_kb(const char* key) {
  std::ifstream f("/proc/self/status");
  std::string line;
  const std::string k = std::string(key) + ":";
  while (std::getline(f, line))
    if (line.rfind(k, 0) == 0) return std::strtol(line.c_str() + k.size(), nullptr, 10);
  return -1;
}

/// Returns freed heap memory to the kernel (glibc keeps freed chunks below its dynamic mmap
/// threshold, up to 32 MiB each, resident; a later run reusing them would not raise the peak),
/// then resets the peak RSS (VmHWM) to the current RSS; returns the current RSS in kB (or −1).
long reset_peak_rss() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
  {
    std::ofstream c("/proc/self/clear_refs");
    c << "5";
  }
  return status_kb("VmRSS");
}

/// Growth of the peak RSS since `reset_peak_rss` returned `base`, in MB (or −1).
double peak_growth_mb(long base) {
  const long hwm = status_kb("VmHWM");
  return base < 0 || hwm < 0 ? -1.0 : static_cast<double>(hwm - base) / 1024.0;
}

/// The environment variable `name` as a number, or `fallback` if it is not set.
double env_or(const char* name, double fallback) {
  const char* s = std::getenv(name);
  return s != nullptr ? std::strtod(s, nullptr) : fallback;
}

/// Predicted-time cap in seconds.
double time_cap() {
  return env_or("HYBGEN_BENCH_CAP_S", 30.0);
}

/// Predicted-memory cap in MB.
double memory_cap() {
  return env_or("HYBGEN_BENCH_CAP_MB", 4096.0);
}

/// The previous grid of a (model, method) pair: nodes, seconds, nonzeros per row.
struct Previous {
  double nodes = 0.0;    ///< Nodes of the previous grid.
  double seconds = 0.0;  ///< Its time (solve, or assembly + march).
  double nnz_row = 0.0;  ///< Transfer: its nonzeros per row.
};

/// The previous grid per "method_model" key (benchmarks run in registration order).
std::map<std::string, Previous>& previous() {
  static std::map<std::string, Previous> p;
  return p;
}

// ---------------------------------------------------------------------------------------
// The models' configurations (their .model files' simulation blocks).

/// A model's box, horizon and output interval.
template <std::size_t N>
struct Config {
  const char* key;                           ///< Name for the limits' bookkeeping.
  std::array<std::array<double, 2>, N> box;  ///< Domain per state variable.
  double t_end;                              ///< Horizon.
  double dt;                                 ///< Output interval (and transfer step).
};

const Config<3> kChaplygin{"chaplygin", {{{-1.5, 1.5}, {-1.5, 1.5}, {-1.0, 1.0}}}, 2.0, 0.5};
const Config<3> kSir3d{"sir_3d", {{{0.05, 1.0}, {0.05, 1.0}, {0.05, 1.0}}}, 4.0, 0.5};
const Config<5> kGl2{
    "gl2", {{{-1.0, 1.0}, {-1.0, 1.0}, {-1.0, 1.0}, {-1.0, 1.0}, {0.0, 1.0}}}, 1.0, 0.5};

/// The grid with n nodes on every axis of the model's box.
template <std::size_t N>
rt::TensorGrid<N> make_grid(const Config<N>& c, int n) {
  rt::TensorGrid<N> g;
  for (std::size_t a = 0; a < N; ++a) g.axes[a] = rt::GridAxis{c.box[a][0], c.box[a][1], n};
  return g;
}

/// 0, dt, 2 dt, …, t_end.
std::vector<double> output_times(double t_end, double dt) {
  std::vector<double> t;
  for (int k = 0; k * dt <= t_end + 1e-9; ++k) t.push_back(k * dt);
  return t;
}

/// rtol = 1e-10, atol = 1e-12 (the runner's default tol = 1e-10).
rt::CharacteristicsOptions trace_options() {
  rt::CharacteristicsOptions o;
  o.ode.rtol = 1e-10;
  o.ode.atol = 1e-12;
  return o;
}

/// Skip message if the run predicted from the previous grid exceeds a cap, else "".
std::string over_cap(const Previous& prev, double nodes, double predicted_mb) {
  char b[200];
  if (prev.nodes > 0.0) {
    const double t = prev.seconds * nodes / prev.nodes;
    if (t > time_cap()) {
      std::snprintf(b, sizeof b, "skipped: predicted %.0f s > HYBGEN_BENCH_CAP_S = %.0f s", t,
                    time_cap());
      return b;
    }
  }
  if (predicted_mb > memory_cap()) {
    std::snprintf(b, sizeof b, "skipped: predicted %.0f MB > HYBGEN_BENCH_CAP_MB = %.0f MB",
                  predicted_mb, memory_cap());
    return b;
  }
  return "";
}

// ---------------------------------------------------------------------------------------
// The runs.

/// Characteristics on the n-node-per-axis grid (n = state.range(0)) of configuration c.
template <class M>
void characteristics_run(benchmark::State& state, const Config<rt::state_dim_v<M>>& c) {
  constexpr std::size_t N = rt::state_dim_v<M>;
  const int n = static_cast<int>(state.range(0));
  const auto grid = make_grid(c, n);
  const auto times = output_times(c.t_end, c.dt);
  const double nodes = static_cast<double>(grid.size() * static_cast<std::size_t>(M::n_mode));
  const double sol_mb = nodes * static_cast<double>(times.size()) * 8.0 / 1048576.0;
  Previous& prev = previous()[std::string("char_") + c.key];
  if (const std::string why = over_cap(prev, nodes, sol_mb); !why.empty()) {
    state.SkipWithError(why.c_str());
    return;
  }
  const auto opt = trace_options();
  const auto par = M::param_defaults;
  rt::Solution<N> sol;
  double rss = -1.0, seconds = 0.0;
  for (auto _ : state) {
    const long base = reset_peak_rss();
    const auto t0 = std::chrono::steady_clock::now();
    sol = rt::solve_grid<M>(grid, times, par.data(), opt);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rss = peak_growth_mb(base);
    benchmark::DoNotOptimize(sol.u.data());
  }
  if (!sol.ok()) {
    state.SkipWithError(("a characteristic failed: " + rt::describe<M>(sol.failure)).c_str());
    return;
  }
  prev = Previous{nodes, seconds, 0.0};
  state.counters["nodes"] = nodes;
  state.counters["outputs"] = static_cast<double>(times.size());
  state.counters["solve_s"] = seconds;
  state.counters["us_per_node"] = 1e6 * seconds / nodes;
  state.counters["sol_MB"] = sol_mb;
  state.counters["rss_MB"] = rss;
}

/// Interpolating transfer operator (h = dt), assembled and marched to t_end, on the n-node-per-axis
/// grid of configuration c.
template <class M>
void transfer_run(benchmark::State& state, const Config<rt::state_dim_v<M>>& c) {
  constexpr std::size_t N = rt::state_dim_v<M>;
  const int n = static_cast<int>(state.range(0));
  const auto grid = make_grid(c, n);
  const auto times = output_times(c.t_end, c.dt);
  const double rows = static_cast<double>(grid.size() * static_cast<std::size_t>(M::n_mode));
  Previous& prev = previous()[std::string("transfer_") + c.key];
  // Assembly holds (column, value) pairs (16 B) per entry while the CSR (12 B per nonzero) is
  // built; then the march's solution array and two work vectors.
  const double nnz_row = prev.nnz_row > 0.0 ? prev.nnz_row : static_cast<double>(1u << N);
  const double predicted_mb =
      (rows * nnz_row * 28.0 + rows * (static_cast<double>(times.size()) + 3.0) * 8.0) / 1048576.0;
  if (const std::string why = over_cap(prev, rows, predicted_mb); !why.empty()) {
    state.SkipWithError(why.c_str());
    return;
  }
  rt::TransferOptions o;
  o.step = c.dt;
  o.forward.ode = trace_options().ode;
  const auto par = M::param_defaults;
  rt::TransferRun<N> run;
  double rss = -1.0, assembly = 0.0, nnz = 0.0;
  for (auto _ : state) {
    const long base = reset_peak_rss();
    const auto op = rt::assemble_transfer<M>(grid, par.data(), o);
    if (!op.ok()) {
      state.SkipWithError(("the assembly failed: " + op.failure_message).c_str());
      return;
    }
    run = rt::march(op, rt::initial_vector<M>(grid, par.data()), times);
    rss = peak_growth_mb(base);
    assembly = op.seconds;
    nnz = static_cast<double>(op.P.nonZeros());
    benchmark::DoNotOptimize(run.solution.u.data());
  }
  prev = Previous{rows, assembly + run.seconds, nnz / rows};
  state.counters["nodes"] = rows;
  state.counters["assembly_s"] = assembly;
  state.counters["march_s"] = run.seconds;
  state.counters["step_s"] = run.n_steps > 0 ? run.seconds / static_cast<double>(run.n_steps) : 0.0;
  state.counters["us_per_node"] = 1e6 * assembly / rows;
  state.counters["nnz"] = nnz;
  state.counters["nnz_per_row"] = nnz / rows;
  state.counters["csr_MB"] = (12.0 * nnz + 4.0 * (rows + 1.0)) / 1048576.0;
  state.counters["sol_MB"] = static_cast<double>(run.solution.u.size()) * 8.0 / 1048576.0;
  state.counters["rss_MB"] = rss;
}

// ---------------------------------------------------------------------------------------

/// Chaplygin sleigh, characteristics, n³.
void BM_Characteristics_Chaplygin(benchmark::State& state) {
  characteristics_run<hybgen_model::chaplygin>(state, kChaplygin);
}
/// Chaplygin sleigh, transfer operator, n³.
void BM_Transfer_Chaplygin(benchmark::State& state) {
  transfer_run<hybgen_model::chaplygin>(state, kChaplygin);
}
/// SIR 3-D, characteristics, n³.
void BM_Characteristics_Sir3d(benchmark::State& state) {
  characteristics_run<hybgen_model::sir_3d>(state, kSir3d);
}
/// SIR 3-D, transfer operator, n³.
void BM_Transfer_Sir3d(benchmark::State& state) {
  transfer_run<hybgen_model::sir_3d>(state, kSir3d);
}
/// GL₂, characteristics, n⁵.
void BM_Characteristics_GL2(benchmark::State& state) {
  characteristics_run<hybgen_model::gl2>(state, kGl2);
}
/// GL₂, transfer operator, n⁵.
void BM_Transfer_GL2(benchmark::State& state) {
  transfer_run<hybgen_model::gl2>(state, kGl2);
}

/// n³ grids, n = 17, 33, 65, 129; one iteration each (a run takes seconds).
void grids_3d(benchmark::internal::Benchmark* b) {
  for (const int n : {17, 33, 65, 129}) b->Arg(n);
  b->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
}

/// n⁵ grids, n = 5, 9, 13, 17; one iteration each.
void grids_5d(benchmark::internal::Benchmark* b) {
  for (const int n : {5, 9, 13, 17}) b->Arg(n);
  b->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
}

BENCHMARK(BM_Characteristics_Chaplygin)->Apply(grids_3d);
BENCHMARK(BM_Transfer_Chaplygin)->Apply(grids_3d);
BENCHMARK(BM_Characteristics_Sir3d)->Apply(grids_3d);
BENCHMARK(BM_Transfer_Sir3d)->Apply(grids_3d);
BENCHMARK(BM_Characteristics_GL2)->Apply(grids_5d);
BENCHMARK(BM_Transfer_GL2)->Apply(grids_5d);

}  // namespace

BENCHMARK_MAIN();
