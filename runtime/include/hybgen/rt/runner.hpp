#pragma once
/// \file runner.hpp
/// The main program of a generated runner: `runner CONFIG.json`. `hybgen run`
/// writes the config (grid, times, parameter values, output directory) and
/// executes the runner, which solves, writes the outputs of docs/design.md's run
/// contract and prints the mass budget.
///
/// Exit codes (exit_codes.hpp): 0 success; 3 numerical failure (what, where,
/// when: a pre-flight failure at t = 0, see preflight.hpp, or a failed
/// characteristic with its backward time); 2 a bad config; 70 anything
/// unexpected, including I/O failures such as a full disk (the message names the
/// file). I/O failures stay 70, not 3: 3 is reserved for the numerics, and the runner writes into
/// the staging directory `hybgen run` gives it, so on any non-zero exit the
/// previous outputs are untouched and `hybgen run` says so.

#include <omp.h>
#include <sys/resource.h>
#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/exit_codes.hpp"
#include "hybgen/rt/io/atomic_file.hpp"
#include "hybgen/rt/io/run_outputs.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "hybgen/rt/methods/preflight.hpp"
#include "hybgen/rt/model.hpp"
#include "hybgen/rt/settings.hpp"

namespace hybgen::rt {

/// A run's settings, read from the config file `hybgen run` writes.
struct RunConfig {
  std::string model;                    ///< Model name.
  std::string out_dir;                  ///< Output directory (exists; hybgen's staging dir).
  std::string final_dir;                ///< Where the outputs end up (messages only).
  std::vector<double> params;           ///< Parameter values, model order.
  std::vector<std::string> axis_names;  ///< State names.
  std::vector<GridAxis> axes;           ///< Grid axes.
  /// Method, times and every method setting (settings.hpp), validated by the table's rules.
  Settings settings;
  bool quiet = false;           ///< No progress output.
  bool preflight_only = false;  ///< Run the pre-flight scan only (`hybgen check --preflight`).
  nlohmann::json seconds;       ///< Timings of the earlier stages.
  /// The model's text, hash and derived equations (generator/src/run.cpp, run_provenance).
  nlohmann::json provenance;

  /// The method.
  const std::string& method() const { return settings.word<"method">(); }
};

/// A configuration error (exit 2).
class ConfigError : public std::runtime_error {
 public:
  /// Construct with a message.
  explicit ConfigError(const std::string& m) : std::runtime_error(m) {}
};

/// Most nodes the pre-flight scan visits (scan_grid).
inline constexpr double kScanNodes = 4194304.0;  // 2^22

/// `grid`, or for a grid of more than kScanNodes nodes the same box with fewer nodes per axis
/// (the same fraction on each, at least 2).
template <std::size_t N>
TensorGrid<N> scan_grid(const TensorGrid<N>& grid) {
  double nodes = 1.0;
  for (const GridAxis& a : grid.axes) nodes *= static_cast<double>(a.n);
  if (nodes <= kScanNodes) return grid;
  const double f = std::pow(kScanNodes / nodes, 1.0 / static_cast<double>(N));
  TensorGrid<N> coarse = grid;
  for (GridAxis& a : coarse.axes)
    a.n = std::max(2, static_cast<int>(std::floor(static_cast<double>(a.n) * f)));
  return coarse;
}

/// The bytes of the densities a run keeps on every node (frames × modes × nodes doubles).
template <std::size_t N>
double density_bytes(const TensorGrid<N>& grid, std::size_t frames, int modes) {
  double nodes = 1.0;
  for (const GridAxis& a : grid.axes) nodes *= static_cast<double>(a.n);
  return nodes * static_cast<double>(frames) * static_cast<double>(modes) * 8.0;
}

/// This machine's memory in bytes (0 if unknown).
inline double physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), size = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && size > 0 ? static_cast<double>(pages) * static_cast<double>(size) : 0.0;
}

/// The peak resident set size of this process so far, in bytes (getrusage).
inline double peak_resident_bytes() {
  rusage u{};
  return ::getrusage(RUSAGE_SELF, &u) == 0 ? 1024.0 * static_cast<double>(u.ru_maxrss) : 0.0;
}

/// Output times 0, dt, 2 dt, ... up to t_end (t_end itself always included).
inline std::vector<double> output_times(double t_end, double dt) {
  std::vector<double> t;
  const auto n = static_cast<long>(std::floor(t_end / dt + 1e-9));
  for (long k = 0; k <= n; ++k) t.push_back(static_cast<double>(k) * dt);
  if (t_end - t.back() > 1e-9 * std::max(1.0, t_end)) t.push_back(t_end);
  t.back() = std::min(t.back(), t_end);
  return t;
}

/// Read and validate a config for model M.
template <HybridModel M>
RunConfig read_config(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError("cannot read the run configuration '" + path + "'");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    throw ConfigError("malformed run configuration '" + path + "': " + e.what());
  }
  RunConfig c;
  try {
    c.model = j.at("model").get<std::string>();
    c.out_dir = j.at("out_dir").get<std::string>();
    c.final_dir = j.value("final_out_dir", c.out_dir);
    c.params = j.at("params").get<std::vector<double>>();
    for (const auto& a : j.at("axes")) {
      c.axis_names.push_back(a.at("name").get<std::string>());
      c.axes.push_back({a.at("min").template get<double>(), a.at("max").template get<double>(),
                        a.at("n").get<int>()});
    }
    // The generator writes every setting (Settings::to_json); method, t_end and dt have no
    // default a runner could assume.
    for (const char* key : {"method", "t_end", "dt"})
      if (!j.contains(key)) throw ConfigError(std::string("missing setting '") + key + "'");
    c.settings = Settings::from_json(j);
    c.quiet = j.value("quiet", false);
    c.preflight_only = j.value("preflight_only", false);
    c.seconds = j.value("seconds", nlohmann::json::object());
    c.provenance = j.value("provenance", nlohmann::json::object());
  } catch (const std::exception& e) {
    throw ConfigError("bad run configuration '" + path + "': " + e.what());
  }
  if (c.params.size() != static_cast<std::size_t>(M::n_param))
    throw ConfigError("the configuration has " + std::to_string(c.params.size()) +
                      " parameters, the model " + std::to_string(M::n_param));
  if (c.axes.size() != static_cast<std::size_t>(M::n_state))
    throw ConfigError("the configuration has " + std::to_string(c.axes.size()) +
                      " axes, the model " + std::to_string(M::n_state) + " states");
  for (std::size_t a = 0; a < c.axes.size(); ++a)
    if (c.axes[a].n < 2 || !(c.axes[a].min < c.axes[a].max))
      throw ConfigError("axis '" + c.axis_names[a] + "' needs min < max and at least 2 nodes");
  for (double p : c.params)
    if (!std::isfinite(p)) throw ConfigError("a parameter value is not finite");
  return c;
}

/// Solve with the configured method, write the outputs and the summary; returns the exit
/// code.
template <HybridModel M>
int run_model(const RunConfig& config, const Backend& backend = serial_backend()) {
  constexpr std::size_t N = state_dim_v<M>;
  using Clock = std::chrono::steady_clock;
  // Rank 0 prints and writes; every rank solves its share (core/backend.hpp).
  RunConfig c = config;
  c.quiet = c.quiet || !backend.root();
  const double* par = c.params.data();
  // Worker threads: the setting when given, else OpenMP's default ($OMP_NUM_THREADS, or one
  // per core, shared by the ranks on this machine). Particles are the same for any count
  // (counter-based streams); sums over threads (the budget's cubatures) may differ in the
  // last digits.
  if (const long long threads = c.settings.integer<"threads">(); threads > 0)
    omp_set_num_threads(static_cast<int>(threads));
  else if (backend.ranks_here() > 1 && std::getenv("OMP_NUM_THREADS") == nullptr)
    omp_set_num_threads(std::max(1, omp_get_num_procs() / backend.ranks_here()));
  TensorGrid<N> grid;
  for (std::size_t a = 0; a < N; ++a) grid.axes[a] = c.axes[a];
  const double dt = c.settings.real<"dt">();
  const std::vector<double> times = output_times(c.settings.real<"t_end">(), dt);
  const std::string& method = c.method();
  MethodSettings ms;
  ms.settings = c.settings;
  ms.quiet = c.quiet;
  const CharacteristicsOptions opt = detail::trace_options(ms);

  // Densities on every node that cannot fit are refused before any work, with the way out.
  const bool marginals = c.settings.word<"density">() == "marginals";
  if (marginals && method != "particles")
    throw ConfigError("density=marginals is what the particles deposit; method " + method +
                      " keeps the density on every node (use method=particles)");
  if (const double need = density_bytes(grid, method == "invariant" ? 1 : times.size(), M::n_mode),
      have = physical_memory_bytes();
      !marginals && have > 0.0 && need > have) {
    char b[400];
    std::snprintf(b, sizeof b,
                  "the densities on the grid need %.3g GB (%.3g nodes x %d mode(s) x %zu "
                  "frame(s)) and this machine has %.3g GB: use a coarser grid, or method=particles "
                  "with density=marginals (the marginal of every pair of axes)",
                  need / 1e9, need / 8.0 / M::n_mode / static_cast<double>(times.size()), M::n_mode,
                  method == "invariant" ? std::size_t{1} : times.size(), have / 1e9);
    throw ConfigError(b);
  }
  // A VTK image is one process's whole grid (or its first three axes): over several ranks
  // run.nc, written by every rank, holds the same arrays (ParaView reads it).
  if (backend.ranks() > 1 && c.settings.includes<"outputs">("vti"))
    throw ConfigError(
        "outputs vti holds a whole grid in one process's file, which a run over several ranks "
        "does not gather: run.nc has the same arrays (ParaView opens it with its NetCDF CF "
        "reader), or run with one rank");
  if (marginals)
    for (const char* o : {"npy", "vti"})
      if (c.settings.includes<"outputs">(o))
        throw ConfigError(std::string("outputs ") + o +
                          " holds the density on every node, which density=marginals does not "
                          "keep (netcdf, png, pdf, svg, gif and html show the marginals)");
  if (!c.quiet && !c.preflight_only) {
    if (method == "invariant")
      std::fprintf(stderr, "hybgen: %s: invariant density on %zu nodes x %d mode(s)...\n",
                   c.model.c_str(), grid.size(), M::n_mode);
    else
      std::fprintf(stderr, "hybgen: %s: %s on %zu nodes x %d mode(s), %zu output times...\n",
                   c.model.c_str(), method.c_str(), grid.size(), M::n_mode, times.size());
  }
  // Pre-flight (t = 0): u0 ≥ 0 and finite on the grid; at every crossing point of every guard
  // in the box, a finite reset landing in the support and the box, not on a guard that fires
  // at once, J finite and ≠ 0, no grazing, a converging numeric inverse, and for the
  // characteristics the seeds that enumerate a reset's several pre-images (preflight.hpp).
  std::vector<std::vector<double>> seeds;
  std::vector<PreflightFailure<N>> notes;
  {
    PreflightOptions popt;
    popt.newton_max_iter = opt.newton_max_iter;
    popt.newton_tol = opt.newton_tol;
    popt.backward = method == "characteristics";  // the one method that inverts Δ
    // A grid too large to visit (a marginals run) is scanned on a coarser grid with the same
    // box: at most kScanNodes nodes, the ends of every axis kept.
    const TensorGrid<N> scan = scan_grid(grid);
    if (scan.size() < grid.size() && !c.quiet)
      std::fprintf(stderr, "hybgen: note: the pre-flight scan visits a coarser grid of %zu nodes\n",
                   scan.size());
    const PreflightFailure<N> pf = preflight<M>(scan, par, popt, &seeds, &notes);
    for (const auto& note : notes)
      if (backend.root())
        std::fprintf(stderr,
                     "hybgen: warning: %s, at an isolated point only (measure zero: no mass is "
                     "there); the scan excludes it, but a grid node exactly there has no finite "
                     "density (choose a grid without a node at that point)\n",
                     describe_preflight<M>(note).c_str());
    if (!pf.ok()) {
      if (backend.root())
        std::fprintf(stderr, "hybgen: numerical failure: %s\n", describe_preflight<M>(pf).c_str());
      return exit_status(ExitCode::Numerical);
    }
    if (c.preflight_only && !backend.root()) return exit_status(ExitCode::Success);
    if (c.preflight_only) {
      std::size_t enumerated = 0;
      for (const auto& sd : seeds) enumerated += sd.empty() ? 0 : 1;
      std::printf("pre-flight scan (t = 0, %s, grid of %zu nodes): ok, %d guard(s)", method.c_str(),
                  grid.size(), M::n_guard);
      if (enumerated > 0)
        std::printf(", %zu with several pre-images (enumerated by the characteristics)",
                    enumerated);
      if (!notes.empty()) std::printf(", %zu isolated re-trigger point(s)", notes.size());
      std::printf("\n");
      return exit_status(ExitCode::Success);
    }
  }
  ms.preimage_seeds = &seeds;
  ms.backend = &backend;
  MethodResult<N> res;
  try {
    res = solve_method<M>(grid, times, dt, par, ms);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());  // e.g. an output time that is not a multiple of the step
  }
  // The largest resident size of any rank (collective: every rank calls it).
  const double peak_bytes = backend.max(peak_resident_bytes());
  // Every rank knows whether the method failed (the failures are agreed across ranks). Each
  // holds its part of the frames and writes it (io/run_outputs.hpp); rank 0 writes the rest.
  if (!res.ok()) {
    if (backend.root())
      std::fprintf(stderr, "hybgen: numerical failure: %s\n", res.failure.c_str());
    return exit_status(ExitCode::Numerical);
  }
  if (backend.root())
    for (const auto& w : res.warnings) std::fprintf(stderr, "hybgen: warning: %s\n", w.c_str());

  // Outputs: the files the setting `outputs` chooses (io/run_outputs.hpp), durable together
  // with summary.json by one sync of the staging directory.
  const auto t2 = Clock::now();
  const Solution<N>& sol = res.solution;
  const std::size_t n_node = grid.size();
  RunRecord rec;
  rec.model = c.model;
  rec.method = method;
  rec.axis_names = c.axis_names;
  rec.axes = c.axes;
  rec.mode_names.assign(M::mode_names.begin(), M::mode_names.end());
  rec.param_names.assign(M::param_names.begin(), M::param_names.end());
  rec.params = c.params;
  rec.times = res.frame_times;
  rec.frame_names = res.frame_names;
  rec.density = std::span<const double>(sol.u.data(), sol.u.size());
  rec.distributed = sol.distributed;
  rec.owned = sol.owned;
  rec.backend = &backend;
  if (!res.marginals.empty()) rec.marginals = &res.marginals;
  for (const std::string& name : c.settings.names<"figure_axes">()) {
    const auto it = std::find(c.axis_names.begin(), c.axis_names.end(), name);
    if (it == c.axis_names.end())
      throw ConfigError("setting 'figure_axes': '" + name + "' is not a state variable");
    rec.figure_axes.push_back(static_cast<std::size_t>(it - c.axis_names.begin()));
  }
  // What the pictures draw besides the density (not for marginals, whose grid is never
  // visited): 2-D, the nodes outside the support (greyed); every guard's surface s = 0 on
  // the planes of the figure pairs, each rank adding its block of the nodes.
  if (rec.marginals == nullptr && N == 2 && backend.root()) {
    rec.outside.assign(n_node, 0);
    bool any_outside = false;
    for (std::size_t i = 0; i < n_node; ++i) {
      const auto y = grid.node(i);
      if (!M::in_support(y.data(), par)) rec.outside[i] = 1, any_outside = true;
    }
    if (!any_outside) rec.outside.clear();
  }
  const auto pairs = figure_pairs(N, rec.figure_axes);
  const Block nodes = backend.block(n_node);
  for (int g = 0; g < M::n_guard && rec.marginals == nullptr; ++g) {
    GuardPlanes planes(rec.axes, pairs);
    std::vector<double> s(nodes.size());
    for (std::size_t i = nodes.begin; i < nodes.end; ++i) {
      const auto y = grid.node(i);
      s[i - nodes.begin] = M::guard_surface(g, y.data(), par);
    }
    planes.add(nodes.begin, s);
    if (backend.ranks() > 1) {
      std::vector<double> v = planes.negated_extremes();
      backend.max(std::span<double>(v));
      planes.set_negated_extremes(v);
    }
    GuardField f{M::guard_names[static_cast<std::size_t>(g)],
                 {},
                 M::guards[static_cast<std::size_t>(g)].from};
    for (std::size_t p = 0; p < pairs.size(); ++p) f.planes.push_back(planes.plane(p));
    rec.guards.push_back(std::move(f));
  }
  rec.budget = res.budget;
  rec.atom_error = res.atom_error;
  rec.provenance = c.provenance;
  rec.summary = nlohmann::json::object();
  rec.summary["settings"] = c.settings.to_json();
  rec.summary["seconds"] = c.seconds.is_object() ? c.seconds : nlohmann::json::object();
  rec.summary["seconds"]["solve"] = res.solve_s;
  rec.summary["seconds"]["budget"] = res.budget_s;
  for (const auto& [key, value] : res.summary.items()) rec.summary[key] = value;
  const DeferredDurability durability(c.out_dir);
  // A distributed run: every rank writes its parts (the writers agree on a failure). Else
  // (one process, or the marginals rank 0 holds): rank 0 alone, and the ranks agree after.
  WrittenOutputs written;
  std::string write_error;
  try {
    if (rec.distributed || backend.root())
      written = write_run_outputs(rec, c.settings, c.out_dir, c.quiet);
  } catch (const std::exception& e) {
    if (rec.distributed || backend.ranks() == 1) throw;
    write_error = e.what();
  }
  if (backend.ranks() > 1 && !rec.distributed && backend.any(!write_error.empty())) {
    if (!write_error.empty()) throw std::runtime_error(write_error);
    return exit_status(ExitCode::Internal);  // rank 0 says why
  }
  // The largest gather any rank received whole from the others (a frame gathered would show).
  const auto gathered =
      static_cast<std::int64_t>(backend.max(static_cast<double>(backend.gathered_values())));
  if (!backend.root()) {
    durability.commit();  // this rank's parts of the files (its machine's file system)
    return exit_status(ExitCode::Success);
  }
  for (const auto& note : written.notes) std::fprintf(stderr, "hybgen: note: %s\n", note.c_str());
  for (const auto& w : written.warnings) std::fprintf(stderr, "hybgen: warning: %s\n", w.c_str());
  const double output_s = std::chrono::duration<double>(Clock::now() - t2).count();

  // summary.json (docs/design.md run contract, extended with the atom, per-mode files and the
  // method's own fields).
  const MassBudget& mb = res.budget;
  nlohmann::json s;
  s["model"] = c.model;
  s["method"] = method;
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t a = 0; a < N; ++a)
    axes.push_back({{"name", c.axis_names[a]},
                    {"min", c.axes[a].min},
                    {"max", c.axes[a].max},
                    {"n", c.axes[a].n}});
  s["grid"] = {{"axes", axes}};
  s["times"] = res.frame_times;
  // `files` and `mode_files`: the .npy frames of a time series (outputs=…+npy), as before
  // `outputs` listed every kind.
  s["files"] = res.frame_times.empty() ? std::vector<std::string>{} : written.npy;
  if (M::n_mode > 1 && !written.mode_npy.empty()) s["mode_files"] = written.mode_npy;
  s["outputs"] = written.to_json();
  if (!written.warnings.empty()) s["output_warnings"] = written.warnings;
  s["settings"] = rec.summary["settings"];
  s["modes"] = std::vector<std::string>(M::mode_names.begin(), M::mode_names.end());
  nlohmann::json params = nlohmann::json::object();
  for (std::size_t j = 0; j < static_cast<std::size_t>(M::n_param); ++j)
    params[M::param_names[j]] = c.params[j];
  s["parameters"] = params;
  s["threads"] = omp_get_max_threads();  // the worker threads this run had (setting `threads`)
  s["backend"] = std::string(backend.name());
  s["ranks"] = backend.ranks();                  // processes (threads each)
  s["peak_memory_bytes_per_rank"] = peak_bytes;  // up to the solve's end, the largest rank
  s["gathered_values_per_rank"] = gathered;      // the largest gather a rank received
  s["initial_mass"] = mb.mass0;
  s["mass"] = mb.mass;
  s["outflow"] = mb.outflow;
  s["atom"] = mb.atom;
  s["atom_error"] = res.atom_error;
  for (const auto& [key, value] : res.summary.items()) s[key] = value;
  nlohmann::json secs = c.seconds.is_object() ? c.seconds : nlohmann::json::object();
  secs["solve"] = res.solve_s;
  secs["budget"] = res.budget_s;
  secs["output"] = output_s;
  s["seconds"] = secs;
  write_file_atomic((std::filesystem::path(c.out_dir) / "summary.json").string(), s.dump(2) + "\n");
  durability.commit();

  if (!c.quiet) {
    // The time hybgen spent before the runner started (derive, build: its config), then ours.
    std::string before;
    for (const char* key : {"derive", "build"})
      if (secs.contains(key) && secs[key].is_number()) {
        char b[48];
        std::snprintf(b, sizeof b, "%s %.3f s, ", key, secs[key].template get<double>());
        before += b;
      }
    // The last line repeats the whole time, build included, so that it is seen last.
    double all_seconds = res.solve_s + res.budget_s + output_s;
    for (const char* key : {"derive", "build"})
      if (secs.contains(key) && secs[key].is_number())
        all_seconds += secs[key].template get<double>();
    char took_buf[96];
    if (secs.contains("build") && secs["build"].is_number())
      std::snprintf(took_buf, sizeof took_buf, " (%.2f s in all, the build %.2f s)", all_seconds,
                    secs["build"].template get<double>());
    else
      std::snprintf(took_buf, sizeof took_buf, " (%.2f s in all)", all_seconds);
    const std::string took = took_buf;
    std::printf("%s: %s on %zu nodes, %zu frame(s): %ssolve %.3f s, budget %.3f s, output %.3f s\n",
                c.model.c_str(), method.c_str(), n_node, res.frame_names.size(), before.c_str(),
                res.solve_s, res.budget_s, output_s);
    if (res.summary.contains("invariant")) {
      const auto& inv = res.summary["invariant"];
      std::printf("leading eigenvalues of the transfer operator (step %g):\n",
                  inv["step"].template get<double>());
      for (const auto& l : inv["eigenvalues"])
        std::printf("  %+.10f %+.10fi   |lambda| = %.10f\n", l["re"].template get<double>(),
                    l["im"].template get<double>(), l["abs"].template get<double>());
      std::printf("spectral gap %.3e, decay rate %.4g per unit time\n",
                  inv["spectral_gap"].template get<double>(),
                  inv["decay_rate"].template get<double>());
      std::printf("outputs in %s: %s, summary.json%s\n", c.final_dir.c_str(),
                  written.describe(res.frame_names).c_str(), took.c_str());
    } else {
      if (mb.mass.empty()) {
        std::printf("mass budget: off\n");
      } else {
        // The last column is what no term accounts for, mass0 − grid − outflow − atom, and
        // the sum of the terms' estimated errors (budget.hpp).
        const std::vector<double> defect = budget_defect(mb), bar = budget_defect_error(mb);
        std::printf("mass budget (initial mass on the grid %.6g):\n", mb.mass0);
        std::printf("  %10s %14s %14s %14s %10s %12s %10s\n", "t", "grid", "outflow", "atom",
                    "+/- atom", "unaccounted", "+/-");
        const std::size_t K = mb.mass.size(), stride = std::max<std::size_t>(1, (K + 9) / 10);
        for (std::size_t k = 0; k < K; ++k)
          if (k % stride == 0 || k + 1 == K)
            std::printf("  %10.4f %14.6e %14.6e %14.6e %10.2e %12.3e %10.2e\n", times[k],
                        mb.mass[k], mb.outflow[k], mb.atom[k],
                        k < res.atom_error.size() ? res.atom_error[k] : 0.0, defect[k], bar[k]);
      }
      std::printf("outputs in %s: %s, summary.json%s\n", c.final_dir.c_str(),
                  written.describe(res.frame_names).c_str(), took.c_str());
    }
  }
  return exit_status(ExitCode::Success);
}

/// Entry point of a generated runner.
/// `backend`: the ranks of the run (core/backend.hpp); a runner built with backend=mpi
/// passes hybgen::mpi's (hybgen/rt/mpi.hpp, mpi_main).
template <HybridModel M>
int runner_main(int argc, char** argv, const Backend& backend = serial_backend()) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CONFIG.json (written by `hybgen run`)\n",
                 argc ? argv[0] : "runner");
    return exit_status(ExitCode::UsageError);
  }
  try {
    const RunConfig c = read_config<M>(argv[1]);
    return run_model<M>(c, backend);
  } catch (const ConfigError& e) {
    // Every rank reads the same config: rank 0 says it once.
    if (backend.root()) std::fprintf(stderr, "hybgen: error: %s\n", e.what());
    return exit_status(ExitCode::UsageError);
  } catch (const std::exception& e) {
    if (backend.ranks() > 1)
      std::fprintf(stderr, "hybgen: error: (rank %d) %s\n", backend.rank(), e.what());
    else
      std::fprintf(stderr, "hybgen: error: %s\n", e.what());
    // Ended without the exit handlers: after a failed write of run.nc (a full disk), HDF5's
    // own handler (H5_term_library) crashes on the file NetCDF could not close. Nothing of
    // this process needs cleaning: hybgen removes its staging directory
    // (tests/e2e/test_failures.cpp, AFullDiskIsAClearErrorAndKeepsThePreviousOutputs).
    std::fflush(nullptr);
    std::_Exit(exit_status(ExitCode::Internal));
  }
}

}  // namespace hybgen::rt
