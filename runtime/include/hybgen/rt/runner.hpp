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
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/exit_codes.hpp"
#include "hybgen/rt/io/atomic_file.hpp"
#include "hybgen/rt/io/json_text.hpp"
#include "hybgen/rt/io/run_outputs.hpp"
#include "hybgen/rt/method_table.hpp"
#include "hybgen/rt/methods/impacts.hpp"
#include "hybgen/rt/methods/methods.hpp"
#include "hybgen/rt/methods/preflight.hpp"
#include "hybgen/rt/model.hpp"
#include "hybgen/rt/setting_rules.hpp"
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
  bool quiet = false;  ///< No progress output.
  /// A sweep point's name (generator/src/sweep.cpp), which its warnings carry; "" for a run.
  std::string label;
  bool preflight_only = false;  ///< Run the pre-flight scan only (`hybgen check --preflight`).
  nlohmann::json seconds;       ///< Timings of the earlier stages.
  /// The model's text, hash and derived equations (generator/src/run.cpp, run_provenance).
  nlohmann::json provenance;

  /// The method.
  const std::string& method() const { return settings.word<"method">(); }
};

/// "hybgen: warning: ", with a sweep point's name ("hybgen: warning: [0_e=0.5] ").
inline std::string warning_prefix(const RunConfig& c) {
  return c.label.empty() ? "hybgen: warning: " : "hybgen: warning: [" + c.label + "] ";
}

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

/// The peak resident set size of this process so far, in bytes (getrusage).
inline double peak_resident_bytes() {
  rusage u{};
  return ::getrusage(RUSAGE_SELF, &u) == 0 ? 1024.0 * static_cast<double>(u.ru_maxrss) : 0.0;
}

/// Output times 0, dt, 2 dt, ... up to t_end (t_end itself always included).
inline std::vector<double> output_times(double t_end, double dt) {
  std::vector<double> t{0.0};
  const auto n = static_cast<long>(std::floor(t_end / dt + 1e-9));
  for (long k = 1; k <= n; ++k) t.push_back(static_cast<double>(k) * dt);
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
    c.label = j.value("label", "");
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

/// A validated run: what every stage after `validate_run` reads.
template <std::size_t N>
struct RunPlan {
  RunConfig config;            ///< The configuration (quiet on every rank but 0).
  const MethodSpec* method{};  ///< The method's row (method_table.hpp).
  TensorGrid<N> grid;          ///< The grid.
  double dt = 0.0;             ///< Output interval.
  std::vector<double> times;   ///< Output times (output_times).
  MethodSettings solve;        ///< What the method reads (seeds and backend set by the chain).
  const Backend* backend{};    ///< The ranks of the run (core/backend.hpp).
  /// The pre-flight's seeds for a reset's several pre-images, per guard (preflight.hpp).
  std::vector<std::vector<double>> seeds;
};

/// Stage 1, validate: the threads, the grid, the output times and the method; then every
/// rule that relates the settings to each other, to the model and to this run
/// (setting_rules.hpp). Throws ConfigError (exit 2) with the first broken rule.
template <HybridModel M>
RunPlan<state_dim_v<M>> validate_run(const RunConfig& config, const Backend& backend) {
  constexpr std::size_t N = state_dim_v<M>;
  RunPlan<N> p;
  p.config = config;
  p.config.quiet = config.quiet || !backend.root();  // rank 0 prints and writes
  p.backend = &backend;
  const Settings& set = p.config.settings;
  // Worker threads: the setting when given, else OpenMP's default ($OMP_NUM_THREADS, or one
  // per core, shared by the ranks on this machine). Particles are the same for any count
  // (counter-based streams); sums over threads (the budget's cubatures) may differ in the
  // last digits.
  if (const long long threads = set.integer<"threads">(); threads > 0)
    omp_set_num_threads(static_cast<int>(threads));
  else if (backend.ranks_here() > 1 && std::getenv("OMP_NUM_THREADS") == nullptr)
    omp_set_num_threads(std::max(1, omp_get_num_procs() / backend.ranks_here()));
  try {
    p.method = &method_named(p.config.method());
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
  RunFacts facts;
  facts.states = p.config.axis_names;
  facts.ranks = backend.ranks();
  for (const GridAxis& a : p.config.axes) facts.grid.push_back(a.n);
  facts.modes = M::n_mode;
  facts.memory_bytes = physical_memory_bytes();
  if (const std::vector<SettingConflict> broken = setting_conflicts(set, facts); !broken.empty())
    throw ConfigError(broken.front().setting == "figure_axes"
                          ? "setting 'figure_axes': " + broken.front().message
                          : broken.front().message);
  for (std::size_t a = 0; a < N; ++a) p.grid.axes[a] = p.config.axes[a];
  p.dt = set.real<"dt">();
  // At most kMaxFrames (the rules); a transport over the interval: its two ends.
  p.times = p.method->ends_only ? std::vector<double>{0.0, set.real<"t_end">()}
                                : output_times(set.real<"t_end">(), p.dt);
  p.solve.settings = set;
  p.solve.quiet = p.config.quiet;
  p.solve.backend = &backend;
  return p;
}

/// The line that says what the run is about to do (stderr; not with --quiet).
template <HybridModel M>
void announce_run(const RunPlan<state_dim_v<M>>& p) {
  if (p.config.quiet || p.config.preflight_only) return;
  const char* model = p.config.model.c_str();
  if (p.method->one_frame)
    std::fprintf(stderr, "hybgen: %s: %s density on %zu nodes x %d mode(s)...\n", model,
                 std::string(p.method->frame).c_str(), p.grid.size(), M::n_mode);
  else if (p.method->ends_only)
    std::fprintf(stderr, "hybgen: %s: %s from t = 0 to %g on %zu nodes x %d mode(s)...\n", model,
                 std::string(p.method->name).c_str(), p.times.back(), p.grid.size(), M::n_mode);
  else
    std::fprintf(stderr, "hybgen: %s: %s on %zu nodes x %d mode(s), %zu output times...\n", model,
                 std::string(p.method->name).c_str(), p.grid.size(), M::n_mode, p.times.size());
}

/// Stage 2, pre-flight (t = 0): u0 ≥ 0 and finite on the grid; at every crossing point of
/// every guard in the box, a finite reset landing in the support (outside the box: a warning,
/// its mass is outflow), not on a guard
/// that fires at once, J finite and ≠ 0, no grazing, a converging numeric inverse, and for a
/// method that inverts the resets the seeds that enumerate a reset's several pre-images
/// (preflight.hpp), kept in `p.seeds`. Returns the exit code when the run ends here (a
/// failure, or `hybgen check --preflight`), else nothing.
template <HybridModel M>
std::optional<int> preflight_run(RunPlan<state_dim_v<M>>& p) {
  constexpr std::size_t N = state_dim_v<M>;
  const Backend& backend = *p.backend;
  const CharacteristicsOptions trace = detail::trace_options(p.solve);
  PreflightOptions popt;
  popt.newton_max_iter = trace.newton_max_iter;
  popt.newton_tol = trace.newton_tol;
  popt.backward = p.method->inverts_resets;
  // A grid too large to visit (a marginals run) is scanned on a coarser grid with the same
  // box: at most kScanNodes nodes, the ends of every axis kept.
  const TensorGrid<N> scan = scan_grid(p.grid);
  if (scan.size() < p.grid.size() && !p.config.quiet)
    std::fprintf(stderr, "hybgen: note: the pre-flight scan visits a coarser grid of %zu nodes\n",
                 scan.size());
  std::vector<PreflightFailure<N>> notes;
  const PreflightFailure<N> pf = preflight<M>(scan, p.config.params.data(), popt, &p.seeds, &notes);
  std::size_t retriggers = 0, outside = 0;
  for (const auto& note : notes) {
    const bool out = note.error == PreflightError::reset_outside_box;
    (out ? outside : retriggers) += 1;
    if (!backend.root()) continue;
    if (out)
      std::fprintf(stderr,
                   "%s%s (the first such point): the mass reset outside the box leaves the "
                   "computed region and is counted as outflow; to follow it, widen the "
                   "domain, or exclude by a `support` line the states no reset reaches\n",
                   warning_prefix(p.config).c_str(), describe_preflight<M>(note).c_str());
    else if (note.error == PreflightError::guards_overlap)
      std::fprintf(stderr,
                   "%s%s, at an isolated point only (a corner where the two surfaces meet: "
                   "measure zero, no mass is there); the run goes on\n",
                   warning_prefix(p.config).c_str(), describe_preflight<M>(note).c_str());
    else
      std::fprintf(stderr,
                   "%s%s, at an isolated point only (measure zero: no mass is there); the scan "
                   "excludes it, but a grid node exactly there has no finite density (choose a "
                   "grid without a node at that point)\n",
                   warning_prefix(p.config).c_str(), describe_preflight<M>(note).c_str());
  }
  if (!pf.ok()) {
    if (backend.root())
      std::fprintf(stderr, "hybgen: numerical failure: %s%s\n", describe_preflight<M>(pf).c_str(),
                   pf.error == PreflightError::guards_overlap
                       ? "; give the guards surfaces that do not overlap, or make them one guard"
                       : "");
    return exit_status(ExitCode::Numerical);
  }
  if (!p.config.preflight_only) return std::nullopt;
  if (backend.root()) {
    std::size_t enumerated = 0;
    for (const auto& sd : p.seeds) enumerated += sd.empty() ? 0 : 1;
    std::printf("pre-flight scan (t = 0, %s, grid of %zu nodes): ok, %d guard(s)",
                std::string(p.method->name).c_str(), p.grid.size(), M::n_guard);
    if (enumerated > 0)
      std::printf(", %zu with several pre-images (enumerated by the characteristics)", enumerated);
    if (retriggers > 0) std::printf(", %zu isolated re-trigger or overlap point(s)", retriggers);
    if (outside > 0) std::printf(", %zu resetting mass out of the box", outside);
    std::printf("\n");
  }
  return exit_status(ExitCode::Success);
}

/// Stage 3, solve: the method of the plan (methods.hpp, `solve_method`). An output time that
/// is not a multiple of the step is a ConfigError (exit 2).
template <HybridModel M>
MethodResult<state_dim_v<M>> solve_run(RunPlan<state_dim_v<M>>& p) {
  p.solve.preimage_seeds = &p.seeds;
  try {
    return solve_method<M>(p.grid, p.times, p.dt, p.config.params.data(), p.solve);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
}

/// The guards on the planes of the figure pairs (each rank adds its block of the nodes), and
/// the plane nodes onto which no node in the support projects: what the pictures draw besides
/// the density. Not for marginals, whose grid is never visited.
template <HybridModel M>
void record_geometry(const RunPlan<state_dim_v<M>>& p, RunRecord& rec) {
  constexpr std::size_t N = state_dim_v<M>;
  const Backend& backend = *p.backend;
  const double* par = p.config.params.data();
  if (rec.marginals != nullptr) return;
  const auto pairs = figure_pairs(N, rec.figure_axes);
  const Block nodes = backend.block(p.grid.size());
  // The planes' greatest value of [node in the support]: 0 where no node projecting onto a
  // plane node is in it (the same combination over ranks as the guards' planes, below).
  auto combine = [&backend](GuardPlanes& planes) {
    if (backend.ranks() == 1) return;
    std::vector<double> v = planes.negated_extremes();
    backend.max(std::span<double>(v));
    planes.set_negated_extremes(v);
  };
  {
    GuardPlanes support(rec.axes, pairs);
    std::vector<double> in(nodes.size());
    for (std::size_t i = nodes.begin; i < nodes.end; ++i)
      in[i - nodes.begin] = M::in_support(p.grid.node(i).data(), par) ? 1.0 : 0.0;
    support.add(nodes.begin, in);
    combine(support);
    rec.outside.assign(pairs.size(), {});
    for (std::size_t q = 0; q < pairs.size(); ++q) {
      const std::vector<double>& any_in = support.greatest(q);
      if (std::all_of(any_in.begin(), any_in.end(), [](double v) { return v > 0.5; })) continue;
      for (const double v : any_in) rec.outside[q].push_back(v > 0.5 ? 0 : 1);
    }
  }
  for (int g = 0; g < M::n_guard; ++g) {
    GuardPlanes planes(rec.axes, pairs);
    std::vector<double> s(nodes.size());
    for (std::size_t i = nodes.begin; i < nodes.end; ++i)
      s[i - nodes.begin] = M::guard_surface(g, p.grid.node(i).data(), par);
    planes.add(nodes.begin, s);
    combine(planes);
    const auto gi = static_cast<std::size_t>(g);
    GuardField f{M::guard_names[gi], {}, M::guards[gi].from};
    for (std::size_t q = 0; q < pairs.size(); ++q) f.planes.push_back(planes.plane(q));
    if constexpr (N == 1)  // a line of nodes: every rank evaluates all of it
      for (std::size_t i = 0; i < p.grid.size(); ++i)
        f.line.push_back(M::guard_surface(g, p.grid.node(i).data(), par));
    rec.guards.push_back(std::move(f));
  }
}

/// summary.json's `impacts` (methods/impacts.hpp, summary_key::impacts): per guard its impacts
/// and their errors by each frame, the mean rates between frames, and where they become
/// infinite; null when the method counted none. Values that are infinite or undefined are null.
template <HybridModel M>
nlohmann::json impacts_summary(const std::vector<double>& times, const MassBudget& mb) {
  if (mb.impacts.empty()) return nullptr;
  const auto series = [](const std::vector<double>& v, std::size_t until) {
    nlohmann::json a = nlohmann::json::array();
    for (std::size_t k = 0; k < v.size(); ++k)
      a.push_back(k < until && std::isfinite(v[k]) ? nlohmann::json(v[k]) : nlohmann::json());
    return a;
  };
  nlohmann::json s = nlohmann::json::object();
  for (std::size_t g = 0; g < mb.impacts.size(); ++g) {
    const std::vector<double>& n = mb.impacts[g];
    if (n.size() != times.size()) continue;
    const std::vector<double> none;
    const std::vector<double>& e = g < mb.impacts_error.size() ? mb.impacts_error[g] : none;
    const std::size_t until =
        g < mb.impacts_infinite_from.size() ? mb.impacts_infinite_from[g] : times.size();
    const ImpactRates r = impact_rates(times, n, e, until);
    s[M::guard_names[g]] = {
        {"values", series(n, until)},
        {"errors", e.size() == n.size() ? series(e, until) : nlohmann::json()},
        {"rate", series(r.rate, until)},
        {"rate_errors", e.size() == n.size() ? series(r.error, until) : nlohmann::json()},
        {"infinite_from", until < times.size() ? nlohmann::json(times[until]) : nlohmann::json()}};
  }
  return s;
}

/// summary.json's `observables` (methods/observables.hpp): per observable its expectation and
/// error per frame, and how the error was estimated; null when the model observes nothing.
/// Collective (a distributed solution's sums).
template <HybridModel M>
nlohmann::json observables_summary(const RunPlan<state_dim_v<M>>& p,
                                   const MethodResult<state_dim_v<M>>& res) {
  if (observable_count<M>() == 0) return nullptr;
  std::vector<ObservableSeries> series;
  if (res.observable_errors == ObservableErrorKind::samples ||
      res.observable_errors == ObservableErrorKind::cells)
    series = res.sampled_observables;
  else if (res.solution.n_time > 0)
    series = observable_expectations<M>(p.grid, res.solution, p.config.params.data(),
                                        res.observable_errors, res.coarse, res.order, *p.backend);
  const char* how = "";
  switch (res.observable_errors) {
    case ObservableErrorKind::quadrature:
      how =
          "twice the Richardson estimate from the trapezoid rule on every second and every "
          "fourth node (the node values are exact)";
      break;
    case ObservableErrorKind::coarse:
      how =
          "twice the Richardson estimate from the same scheme on the halved and quartered "
          "grids";
      break;
    case ObservableErrorKind::samples:
      how = "twice the standard error of the samples' mean";
      break;
    case ObservableErrorKind::cells:
      how =
          "the adaptive cubature's estimates of the integrals of f u and of u over the box, on the "
          "cells of the cell averages (budget/cell_averages.hpp)";
      break;
    case ObservableErrorKind::none:
      how = "none";
      break;
  }
  nlohmann::json j = nlohmann::json::object();
  for (const ObservableSeries& o : series) {
    nlohmann::json values = nlohmann::json::array(), errors = nlohmann::json::array();
    for (std::size_t k = 0; k < o.values.size(); ++k) {
      values.push_back(detail::number_or_null(o.values[k]));
      errors.push_back(detail::number_or_null(o.errors[k]));
    }
    j[o.name] = {
        {"values", values},
        {"errors", errors},
        {"note", std::string("values: the mean of the observable under the density in the box "
                             "(normalised to unit mass; Zeno atoms left out) per frame; errors: ") +
                     how + " (docs/methods.md, \"Observables\")"}};
  }
  return j;
}

/// summary.json as far as the solve knows it (docs/design.md run contract, extended with the
/// atom, the runner's resources and the method's own block, `MethodSpec::summary_key`): built
/// once, here; the writers read it, and `finish_summary` adds what the outputs add.
template <HybridModel M>
nlohmann::json run_summary(const RunPlan<state_dim_v<M>>& p,
                           const MethodResult<state_dim_v<M>>& res, double peak_bytes) {
  namespace k = summary_key;
  const RunConfig& c = p.config;
  const MassBudget& mb = res.budget;
  nlohmann::json s;
  s[k::model] = c.model;
  s[k::method] = std::string(p.method->name);
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t a = 0; a < c.axes.size(); ++a)
    axes.push_back({{"name", c.axis_names[a]},
                    {"min", c.axes[a].min},
                    {"max", c.axes[a].max},
                    {"n", c.axes[a].n}});
  s["grid"] = {{"axes", axes}};
  s[k::times] = res.frame_times;
  s[k::settings] = c.settings.to_json();
  s["modes"] = std::vector<std::string>(M::mode_names.begin(), M::mode_names.end());
  nlohmann::json params = nlohmann::json::object();
  for (std::size_t j = 0; j < static_cast<std::size_t>(M::n_param); ++j)
    params[M::param_names[j]] = c.params[j];
  s["parameters"] = params;
  s["threads"] = omp_get_max_threads();  // the worker threads this run had (setting `threads`)
  s["backend"] = std::string(p.backend->name());
  s["ranks"] = p.backend->ranks();               // processes (threads each)
  s["peak_memory_bytes_per_rank"] = peak_bytes;  // up to the solve's end, the largest rank
  s[k::initial_mass] = mb.mass0;
  s[k::mass] = mb.mass;
  s[k::outflow] = mb.outflow;
  s[k::atom] = mb.atom;
  s[k::atom_error] = res.atom_error;
  for (std::size_t g = 0; g < mb.absorbed.size(); ++g) {
    if (mb.absorbed[g].empty()) continue;
    const bool has_error = g < mb.absorbed_error.size() && !mb.absorbed_error[g].empty();
    s[k::absorbed][M::guard_names[g]] = {
        {"values", mb.absorbed[g]},
        {"errors", has_error ? nlohmann::json(mb.absorbed_error[g]) : nlohmann::json(nullptr)}};
  }
  if (nlohmann::json imp = impacts_summary<M>(res.frame_times, mb); !imp.is_null())
    s[k::impacts] = std::move(imp);
  for (const auto& [key, value] : res.summary.items()) s[key] = value;
  if (nlohmann::json obs = observables_summary<M>(p, res); !obs.is_null())
    s[k::observables] = std::move(obs);
  nlohmann::json secs = c.seconds.is_object() ? c.seconds : nlohmann::json::object();
  secs["solve"] = res.solve_s;
  secs["budget"] = res.budget_s;
  s[k::seconds] = secs;
  return s;
}

/// Stage 4, record: what the writers see of the run (io/run_record.hpp), its summary among it.
/// Collective: every rank calls it.
template <HybridModel M>
RunRecord record_run(const RunPlan<state_dim_v<M>>& p, const MethodResult<state_dim_v<M>>& res) {
  const RunConfig& c = p.config;
  // The largest resident size of any rank, up to the solve's end.
  const double peak_bytes = p.backend->max(peak_resident_bytes());
  RunRecord rec;
  rec.model = c.model;
  rec.method = std::string(p.method->name);
  rec.axis_names = c.axis_names;
  rec.axes = c.axes;
  rec.mode_names.assign(M::mode_names.begin(), M::mode_names.end());
  rec.param_names.assign(M::param_names.begin(), M::param_names.end());
  rec.params = c.params;
  rec.times = res.frame_times;
  rec.frame_names = res.frame_names;
  rec.density = std::span<const double>(res.solution.u.data(), res.solution.u.size());
  rec.distributed = res.solution.distributed;
  rec.cell_averages = res.cell_averages;
  rec.set_label = std::span<const std::int32_t>(res.set_label.data(), res.set_label.size());
  rec.owned = res.solution.owned;
  rec.backend = p.backend;
  if (!res.marginals.empty()) rec.marginals = &res.marginals;
  // The names are states (validate_run's rules).
  for (const std::string& name : c.settings.names<"figure_axes">())
    rec.figure_axes.push_back(static_cast<std::size_t>(
        std::find(c.axis_names.begin(), c.axis_names.end(), name) - c.axis_names.begin()));
  record_geometry<M>(p, rec);
  rec.budget = res.budget;
  rec.atom_error = res.atom_error;
  rec.provenance = c.provenance;
  rec.summary = run_summary<M>(p, res, peak_bytes);
  return rec;
}

/// Stage 5, write: the files the setting `outputs` chooses (io/run_outputs.hpp). A
/// distributed run: every rank writes its parts (the writers agree on a failure). Else (one
/// process, or the marginals rank 0 holds): rank 0 alone, and the ranks agree after. Throws
/// on this rank's failure; nothing on a rank whose failure another rank reports.
template <std::size_t N>
std::optional<WrittenOutputs> write_run(const RunPlan<N>& p, const RunRecord& rec) {
  const Backend& backend = *p.backend;
  WrittenOutputs written;
  std::string write_error;
  try {
    if (rec.distributed || backend.root())
      written = write_run_outputs(rec, p.config.settings, p.config.out_dir, p.config.quiet);
  } catch (const std::exception& e) {
    if (rec.distributed || backend.ranks() == 1) throw;
    write_error = e.what();
  }
  if (backend.ranks() > 1 && !rec.distributed && backend.any(!write_error.empty())) {
    if (!write_error.empty()) throw std::runtime_error(write_error);
    return std::nullopt;  // rank 0 says why
  }
  return written;
}

/// Stage 6, summary: what the outputs add to the record's summary (the files by kind, the
/// .npy frames, the output's warnings and time, the largest gather a rank received).
inline nlohmann::json finish_summary(const RunRecord& rec, const WrittenOutputs& written,
                                     double output_s, std::int64_t gathered) {
  nlohmann::json s = rec.summary;
  // `files` and `mode_files`: the .npy frames of a time series (outputs=…+npy), as before
  // `outputs` listed every kind.
  s["files"] = rec.times.empty() ? std::vector<std::string>{} : written.npy;
  if (rec.n_mode() > 1 && !written.mode_npy.empty()) s["mode_files"] = written.mode_npy;
  s["outputs"] = written.to_json();
  if (!written.warnings.empty()) s[summary_key::output_warnings] = written.warnings;
  s["gathered_values_per_rank"] = gathered;
  s[summary_key::seconds]["output"] = output_s;
  return s;
}

/// Stage 7, report: the terminal's account of the run (stdout; not with --quiet): the time per
/// stage, then the spectrum (invariant), the escape rate (escape) or the mass budget of a time
/// series.
inline void print_run_report(const RunConfig& c, const RunRecord& rec, const nlohmann::json& s,
                             const WrittenOutputs& written) {
  namespace k = summary_key;
  const nlohmann::json& secs = s[k::seconds];
  const auto sec = [&](const char* key) {
    return secs.contains(key) && secs[key].is_number() ? secs[key].get<double>() : -1.0;
  };
  // The time hybgen spent before the runner started (derive, build: its config), then ours;
  // the last line repeats the whole time, build included, so that it is seen last.
  std::string before;
  double all_seconds = sec("solve") + sec("budget") + sec("output");
  for (const char* key : {"derive", "build"})
    if (sec(key) >= 0) {
      char b[48];
      std::snprintf(b, sizeof b, "%s %.3f s, ", key, sec(key));
      before += b, all_seconds += sec(key);
    }
  char took[96];
  if (sec("build") >= 0)
    std::snprintf(took, sizeof took, " (%.2f s in all, the build %.2f s)", all_seconds,
                  sec("build"));
  else
    std::snprintf(took, sizeof took, " (%.2f s in all)", all_seconds);
  std::printf("%s: %s on %zu nodes, %zu frame(s): %ssolve %.3f s, budget %.3f s, output %.3f s\n",
              c.model.c_str(), rec.method.c_str(), rec.n_node(), rec.n_frame(), before.c_str(),
              sec("solve"), sec("budget"), sec("output"));
  // A number of the method's block, or NaN (printed "nan") where it has none.
  const auto num = [](const nlohmann::json& x, const char* key) {
    return x.contains(key) && x[key].is_number() ? x[key].get<double>() : std::nan("");
  };
  if (s.contains(k::invariant)) {
    const auto& inv = s[k::invariant];
    std::printf("leading eigenvalues of the transfer operator (step %g):\n",
                inv["step"].get<double>());
    for (const auto& l : inv["eigenvalues"]) {
      std::printf("  %+.10f %+.10fi   |lambda| = %.10f", l["re"].get<double>(),
                  l["im"].get<double>(), l["abs"].get<double>());
      if (l.contains("error") && l["error"].is_number())
        std::printf("   +/- %.1e", l["error"].get<double>());
      std::printf("\n");
    }
    // The rates with their errors, and the decisions they support (methods/two_grid.hpp).
    const auto err = [&](const char* key) {
      const std::string e = std::string(key) + "_error";
      return inv.contains(e) && inv[e].is_number() ? inv[e].get<double>() : -1.0;
    };
    const auto flag = [&](const char* key) {
      return inv.contains(key) && inv[key].is_boolean() ? std::optional<bool>(inv[key].get<bool>())
                                                        : std::nullopt;
    };
    if (err("spectral_gap") >= 0)
      std::printf(
          "spectral gap %.3e +/- %.1e, decay rate %.4g +/- %.1e per unit time%s\n",
          inv["spectral_gap"].get<double>(), err("spectral_gap"), inv["decay_rate"].get<double>(),
          err("decay_rate"),
          flag("decays") == false ? ": the gap is within its error of 0, no decay is claimed" : "");
    else
      std::printf("spectral gap %.3e, decay rate %.4g per unit time (no error estimate)\n",
                  inv["spectral_gap"].get<double>(), inv["decay_rate"].get<double>());
    if (flag("leaks") == true)
      std::printf(
          "leak rate %.4g +/- %.1e per unit time: mass leaves the box, no density in "
          "it is invariant (method=escape)\n",
          inv["leak_rate"].get<double>(), err("leak_rate"));
    if (inv.contains("error") && inv["error"].is_number())
      std::printf(
          "estimated error of the density %.2e (relative L1), from the grid of %s nodes%s\n",
          inv["error"].get<double>(), inv["coarse_grid"].dump().c_str(),
          flag("error_reliable") == false
              ? "; UNRELIABLE: the observed order of convergence is not the scheme's "
                "(summary.json, invariant.note)"
              : "");
  } else if (s.contains(k::escape)) {
    const auto& e = s[k::escape];
    std::printf("escape rate %.10g +/- %.2g per unit time (lambda1 = %.12f, step %g)\n",
                e["rate"].get<double>(), e["rate_error"].get<double>(), e["lambda1"].get<double>(),
                e["step"].get<double>());
  } else if (s.contains(k::almost_invariant)) {
    const auto& a = s[k::almost_invariant];
    std::printf("almost-invariant sets (step %g; run.nc set_label, sets.png):\n", num(a, "step"));
    for (const auto& set : a["sets"])
      std::printf(
          "  set %d: mass %.6f +/- %.1e, stays with probability %.6f +/- %.1e per "
          "step (exit rate %.4g per unit time)\n",
          set["set"].get<int>(), num(set, "mass"), num(set, "mass_error"), num(set, "ratio"),
          num(set, "ratio_error"), num(set, "exit_rate"));
    std::printf(
        "  sum of the ratios %.6f <= %.6f (the bound from the eigenvalues); mass in no "
        "set %.2e\n",
        num(a, "ratio_sum"), num(a, "bound"), num(a, "unassigned_mass"));
  } else if (s.contains(k::coherent)) {
    const auto& a = s[k::coherent];
    std::printf("coherent pairs from t = 0 to %g (run.nc set_label, sets.png):\n", num(a, "t_end"));
    for (const auto& set : a["sets"])
      std::printf(
          "  pair %d: mass %.6f +/- %.1e at t = 0, %.6f +/- %.1e at t_end; ends in its final "
          "set with probability %.6f +/- %.1e, came from its initial set with %.6f +/- %.1e\n",
          set["set"].get<int>(), num(set, "initial_mass"), num(set, "initial_mass_error"),
          num(set, "final_mass"), num(set, "final_mass_error"), num(set, "forward"),
          num(set, "forward_error"), num(set, "backward"), num(set, "backward_error"));
    std::printf(
        "  sum of sqrt(forward*backward) %.6f <= %.6f (the bound from the singular "
        "values)\n",
        num(a, "coherence_sum"), num(a, "bound"));
  } else if (const MassBudget& mb = rec.budget; mb.mass.empty()) {
    std::printf("mass budget: off\n");
  } else {
    // The last column is what no term accounts for, mass0 − grid − outflow − atom, and the
    // sum of the terms' estimated errors (budget.hpp).
    const std::vector<double> defect = budget_defect(mb), bar = budget_defect_error(mb);
    std::printf("mass budget (initial mass on the grid %.6g):\n", mb.mass0);
    std::printf("  %10s %14s %14s %14s %10s %12s %10s\n", "t", "grid", "outflow", "atom",
                "+/- atom", "unaccounted", "+/-");
    const std::size_t K = mb.mass.size(), stride = std::max<std::size_t>(1, (K + 9) / 10);
    for (std::size_t i = 0; i < K; ++i)
      if (i % stride == 0 || i + 1 == K)
        std::printf("  %10.4f %14.6e %14.6e %14.6e %10.2e %12.3e %10.2e\n", rec.times[i],
                    mb.mass[i], mb.outflow[i], mb.atom[i],
                    i < rec.atom_error.size() ? rec.atom_error[i] : 0.0, defect[i], bar[i]);
  }
  // What each absorbing guard took by the last frame (summary.json `absorbed` has each frame).
  if (s.contains(k::absorbed) && !rec.times.empty())
    for (const auto& [name, a] : s[k::absorbed].items()) {
      const auto& e = a["errors"];
      char bar[48] = "";
      if (e.is_array() && !e.empty() && e.back().is_number())
        std::snprintf(bar, sizeof bar, " +/- %.1e", e.back().get<double>());
      std::printf("absorbed by guard '%s' by t = %g: %.8g%s (of the initial mass %.6g)\n",
                  name.c_str(), rec.times.back(), a["values"].back().get<double>(), bar,
                  rec.budget.mass0);
    }
  // The transfer operator's error per output time (methods.hpp, add_transfer_errors).
  if (s.contains(k::transfer) && s[k::transfer].contains("error") &&
      s[k::transfer]["error"].is_number() && !rec.times.empty()) {
    const auto& t = s[k::transfer];
    std::printf(
        "estimated error of the density at t = %g: %.2e (relative L1), from the grid of %s "
        "nodes%s\n",
        rec.times.back(), t["error"].get<double>(), t["coarse_grid"].dump().c_str(),
        t.value("error_reliable", true) ? ""
                                        : "; UNRELIABLE at some times: the difference does not "
                                          "fall with the grid spacing (summary.json, "
                                          "transfer.errors_reliable)");
  }
  // The observables at the last frame (summary.json has every frame).
  if (s.contains(k::observables) && s[k::observables].is_object())
    for (const auto& [name, o] : s[k::observables].items()) {
      const auto& v = o["values"];
      const auto& e = o["errors"];
      if (v.empty()) continue;
      // A time series: the last time; one frame: its name (invariant, escape).
      std::string at = rec.frame_names.empty() ? "" : "(" + rec.frame_names.front() + ")";
      if (!rec.times.empty()) {
        char b[48];
        std::snprintf(b, sizeof b, "at t = %g", rec.times.back());
        at = b;
      }
      if (v.back().is_number() && e.back().is_number())
        std::printf("E[%s] %s: %.10g +/- %.1e\n", name.c_str(), at.c_str(), v.back().get<double>(),
                    e.back().get<double>());
      else if (v.back().is_number())
        std::printf("E[%s] %s: %.10g (no error estimate)\n", name.c_str(), at.c_str(),
                    v.back().get<double>());
      else
        std::printf("E[%s] %s: undefined (no mass in the box)\n", name.c_str(), at.c_str());
    }
  std::printf("outputs in %s: %s, summary.json%s\n", c.final_dir.c_str(),
              written.describe(rec.frame_names).c_str(), took);
}

/// The run as a chain of stages: validate → pre-flight → solve → record → write → summary →
/// report. Returns the exit code. Every rank calls it; rank 0 prints and writes what is not
/// distributed.
template <HybridModel M>
int run_chain(const RunConfig& config, const Backend& backend = serial_backend()) {
  using Clock = std::chrono::steady_clock;
  RunPlan<state_dim_v<M>> plan = validate_run<M>(config, backend);
  announce_run<M>(plan);
  if (const std::optional<int> ended = preflight_run<M>(plan)) return *ended;
  const MethodResult<state_dim_v<M>> res = solve_run<M>(plan);
  // Every rank knows whether the method failed (the failures are agreed across ranks).
  if (!res.ok()) {
    if (backend.root())
      std::fprintf(stderr, "hybgen: numerical failure: %s\n", res.failure.c_str());
    return exit_status(ExitCode::Numerical);
  }
  if (backend.root())
    for (const auto& w : res.warnings)
      std::fprintf(stderr, "%s%s\n", warning_prefix(config).c_str(), w.c_str());
  const RunRecord rec = record_run<M>(plan, res);
  // The files and summary.json are made durable together, by one sync of the staging
  // directory (io/atomic_file.hpp).
  const auto t0 = Clock::now();
  const DeferredDurability durability(plan.config.out_dir);
  const std::optional<WrittenOutputs> written = write_run(plan, rec);
  if (!written) return exit_status(ExitCode::Internal);
  // The largest gather any rank received whole from the others (a frame gathered would show).
  const auto gathered =
      static_cast<std::int64_t>(backend.max(static_cast<double>(backend.gathered_values())));
  if (!backend.root()) {
    durability.commit();  // this rank's parts of the files (its machine's file system)
    return exit_status(ExitCode::Success);
  }
  for (const auto& note : written->notes) std::fprintf(stderr, "hybgen: note: %s\n", note.c_str());
  for (const auto& w : written->warnings)
    std::fprintf(stderr, "%s%s\n", warning_prefix(plan.config).c_str(), w.c_str());
  const double output_s = std::chrono::duration<double>(Clock::now() - t0).count();
  nlohmann::json summary = finish_summary(rec, *written, output_s, gathered);
  if (!res.warnings.empty()) summary[summary_key::warnings] = res.warnings;
  write_file_atomic((std::filesystem::path(plan.config.out_dir) / "summary.json").string(),
                    json_file_text(summary));
  durability.commit();
  if (!plan.config.quiet) print_run_report(plan.config, rec, summary, *written);
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
    return run_chain<M>(c, backend);
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
