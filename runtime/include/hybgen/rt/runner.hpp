#pragma once
/// \file runner.hpp
/// The main program of a generated runner: `runner CONFIG.json`. `hybgen run`
/// writes the config (grid, times, parameter values, output directory) and
/// executes the runner, which solves, writes the outputs of DESIGN.md's run
/// contract and prints the mass budget.
///
/// Exit codes: 0 success; 3 numerical failure (what, where, when); 2 a bad
/// config; 70 anything unexpected (including I/O failures, which name the file).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "hybgen/rt/atomic_file.hpp"
#include "hybgen/rt/budget.hpp"
#include "hybgen/rt/characteristics.hpp"
#include "hybgen/rt/model.hpp"
#include "hybgen/rt/npy.hpp"
#include "hybgen/rt/png.hpp"
#include "hybgen/rt/vti.hpp"

namespace hybgen::rt {

/// A run's settings, read from the config file `hybgen run` writes.
struct RunConfig {
  std::string model;                    ///< Model name.
  std::string method;                   ///< Solver ("characteristics").
  std::string out_dir;                  ///< Output directory (exists).
  std::vector<double> params;           ///< Parameter values, model order.
  std::vector<std::string> axis_names;  ///< State names.
  std::vector<GridAxis> axes;           ///< Grid axes.
  double t_end = 1.0;                   ///< Final time.
  double dt = 0.1;                      ///< Output interval.
  double tol = 1e-10;                   ///< ODE relative tolerance.
  long max_events = 100000;             ///< Cap on resets per characteristic.
  double budget_tol = 3e-4;             ///< Relative tolerance of the mass budget's cubature.
  bool quiet = false;                   ///< No progress output.
  nlohmann::json seconds;               ///< Timings of the earlier stages.
};

/// A configuration error (exit 2).
class ConfigError : public std::runtime_error {
 public:
  /// Construct with a message.
  explicit ConfigError(const std::string& m) : std::runtime_error(m) {}
};

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
    c.method = j.at("method").get<std::string>();
    c.out_dir = j.at("out_dir").get<std::string>();
    c.params = j.at("params").get<std::vector<double>>();
    for (const auto& a : j.at("axes")) {
      c.axis_names.push_back(a.at("name").get<std::string>());
      c.axes.push_back(
          {a.at("min").get<double>(), a.at("max").get<double>(), a.at("n").get<int>()});
    }
    c.t_end = j.at("t_end").get<double>();
    c.dt = j.at("dt").get<double>();
    c.tol = j.value("tol", 1e-10);
    c.max_events = j.value("max_events", 100000L);
    c.budget_tol = j.value("budget_tol", 3e-4);
    c.quiet = j.value("quiet", false);
    c.seconds = j.value("seconds", nlohmann::json::object());
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
  if (!(c.t_end > 0) || !(c.dt > 0)) throw ConfigError("t_end and dt must be positive");
  if (c.method != "characteristics") throw ConfigError("unknown method '" + c.method + "'");
  return c;
}

namespace detail {

inline std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

inline std::string frame_name(std::size_t k) {
  char b[32];
  std::snprintf(b, sizeof b, "u_%04zu", k);
  return b;
}

}  // namespace detail

/// Solve, write the outputs and the summary; returns the exit code.
template <HybridModel M>
int run_characteristics(const RunConfig& c) {
  constexpr std::size_t N = state_dim_v<M>;
  using Clock = std::chrono::steady_clock;
  const double* par = c.params.data();
  TensorGrid<N> grid;
  for (std::size_t a = 0; a < N; ++a) grid.axes[a] = c.axes[a];
  const std::vector<double> times = output_times(c.t_end, c.dt);
  CharacteristicsOptions opt;
  opt.ode.rtol = c.tol;
  opt.ode.atol = c.tol * 1e-2;
  opt.max_events = static_cast<int>(std::min<long>(c.max_events, 1000000000L));

  if (!c.quiet)
    std::fprintf(stderr, "hybgen: solving %s on %zu nodes x %d mode(s), %zu output times...\n",
                 c.model.c_str(), grid.size(), M::n_mode, times.size());
  const auto t0 = Clock::now();
  const Solution<N> sol = solve_grid<M>(grid, times, par, opt);
  const double solve_s = std::chrono::duration<double>(Clock::now() - t0).count();
  if (!sol.ok()) {
    std::fprintf(stderr, "hybgen: numerical failure: %s\n", describe<M>(sol.failure).c_str());
    return 3;
  }
  const auto t1 = Clock::now();
  // The mass budget integrates u(t) adaptively (characteristics at the
  // cubature nodes): a grid rule cannot integrate the unbounded, striped
  // density near a Zeno point, where the atom forms.
  AdaptiveOptions aopt;
  aopt.rel_tol = c.budget_tol;
  AdaptiveBudgetInfo info;
  const BudgetResult<N> budget = adaptive_mass_budget<M>(grid, times, par, opt, aopt, 3, &info);
  const double budget_s = std::chrono::duration<double>(Clock::now() - t1).count();
  if (!info.volume.converged || !info.surface.converged)
    std::fprintf(stderr,
                 "hybgen: warning: the mass budget's cubature reached its point cap before its "
                 "tolerance %.1e; the atom's error estimate in summary.json says how far it got\n",
                 c.budget_tol);
  if (!budget.ok()) {
    std::fprintf(stderr, "hybgen: numerical failure (mass budget): %s\n",
                 describe<M>(budget.failure).c_str());
    return 3;
  }

  // Outputs: one .npy per output time (sum over modes; per mode too when there
  // are several), a picture and a VTK image.
  const auto t2 = Clock::now();
  const std::filesystem::path out(c.out_dir);
  const std::size_t n_node = grid.size();
  std::vector<std::size_t> shape;
  std::vector<double> origins, spacings;
  for (const auto& a : c.axes) {
    shape.push_back(static_cast<std::size_t>(a.n));
    origins.push_back(a.min);
    spacings.push_back((a.max - a.min) / (a.n - 1));
  }
  std::vector<std::uint8_t> outside(n_node, 0);
  bool any_outside = false;
  for (std::size_t i = 0; i < n_node; ++i) {
    const auto y = grid.node(i);
    if (!M::in_support(y.data(), par)) outside[i] = 1, any_outside = true;
  }
  nlohmann::json files = nlohmann::json::array(), mode_files = nlohmann::json::object();
  std::vector<double> total(n_node);
  for (std::size_t k = 0; k < times.size(); ++k) {
    std::fill(total.begin(), total.end(), 0.0);
    for (std::size_t m = 0; m < sol.n_mode; ++m) {
      auto s = sol.slice(k, m);
      for (std::size_t i = 0; i < n_node; ++i) total[i] += s[i];
    }
    const std::string base = detail::frame_name(k);
    write_npy((out / (base + ".npy")).string(), total, shape);
    files.push_back(base + ".npy");
    if (M::n_mode > 1) {
      for (std::size_t m = 0; m < sol.n_mode; ++m) {
        const std::string name = base + "_" + M::mode_names[m] + ".npy";
        write_npy((out / name).string(), sol.slice(k, m).data(), shape);
        mode_files[M::mode_names[m]].push_back(name);
      }
    }
    std::string title = c.model + "   t = " + detail::fmt("%.3f", times[k]);
    if (M::n_mode > 1) title += "   (sum over modes)";
    const std::string png = (out / (base + ".png")).string();
    if constexpr (N == 1) {
      std::vector<double> xs(n_node);
      for (std::size_t i = 0; i < n_node; ++i) xs[i] = grid.node(i)[0];
      write_lineplot_png(png, xs, total, c.axis_names[0], "u", title);
    } else if constexpr (N == 2) {
      write_heatmap_png(png, total.data(), shape[0], shape[1], c.axis_names[0], c.axes[0].min,
                        c.axes[0].max, c.axis_names[1], c.axes[1].min, c.axes[1].max, title,
                        any_outside ? outside.data() : nullptr);
    } else {
      // Marginal density on the first two axes: integrate the others (trapezoid).
      const std::size_t n0 = shape[0], n1 = shape[1], rest = n_node / (n0 * n1);
      std::vector<std::vector<double>> w(N);
      for (std::size_t a = 2; a < N; ++a) w[a] = trapezoid_rule(c.axes[a]).weights;
      std::vector<double> wrest(rest, 1.0);
      for (std::size_t r = 0; r < rest; ++r) {
        std::size_t rem = r;
        for (std::size_t a = N; a-- > 2;) {
          wrest[r] *= w[a][rem % shape[a]];
          rem /= shape[a];
        }
      }
      std::vector<double> marginal(n0 * n1, 0.0);
      for (std::size_t i = 0; i < n0 * n1; ++i)
        for (std::size_t r = 0; r < rest; ++r) marginal[i] += wrest[r] * total[i * rest + r];
      std::string others;
      for (std::size_t a = 2; a < N; ++a) others += (a > 2 ? ", " : "") + c.axis_names[a];
      write_heatmap_png(png, marginal.data(), n0, n1, c.axis_names[0], c.axes[0].min, c.axes[0].max,
                        c.axis_names[1], c.axes[1].min, c.axes[1].max,
                        title + "   marginal over " + others);
    }
    if constexpr (N <= 3)
      write_vti((out / (base + ".vti")).string(), total.data(), shape, origins, spacings,
                c.axis_names, "u");
  }
  const double output_s = std::chrono::duration<double>(Clock::now() - t2).count();

  // summary.json (DESIGN.md run contract, extended with the atom and per-mode files).
  const MassBudget& mb = budget.budget;
  nlohmann::json s;
  s["model"] = c.model;
  s["method"] = c.method;
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t a = 0; a < N; ++a)
    axes.push_back({{"name", c.axis_names[a]},
                    {"min", c.axes[a].min},
                    {"max", c.axes[a].max},
                    {"n", c.axes[a].n}});
  s["grid"] = {{"axes", axes}};
  s["times"] = times;
  s["files"] = files;
  if (M::n_mode > 1) s["mode_files"] = mode_files;
  s["modes"] = std::vector<std::string>(M::mode_names.begin(), M::mode_names.end());
  nlohmann::json params = nlohmann::json::object();
  for (std::size_t j = 0; j < static_cast<std::size_t>(M::n_param); ++j)
    params[M::param_names[j]] = c.params[j];
  s["parameters"] = params;
  s["initial_mass"] = mb.mass0;
  s["mass"] = mb.mass;
  s["outflow"] = mb.outflow;
  s["atom"] = mb.atom;
  // Estimated |error| of the atom: those of mass(t), mass(0) and the outflow.
  std::vector<double> atom_error(times.size(), 0.0);
  for (std::size_t k = 0; k < times.size(); ++k)
    atom_error[k] = (k < mb.mass_error.size() ? mb.mass_error[k] : 0.0) +
                    (mb.mass_error.empty() ? 0.0 : mb.mass_error[0]) +
                    (k < info.surface.error.size() ? info.surface.error[k] : 0.0);
  s["atom_error"] = atom_error;
  s["budget"] = {{"rel_tol", c.budget_tol},
                 {"volume_points", info.volume.points},
                 {"face_points", info.surface.points},
                 {"converged", info.volume.converged && info.surface.converged}};
  nlohmann::json secs = c.seconds.is_object() ? c.seconds : nlohmann::json::object();
  secs["solve"] = solve_s;
  secs["budget"] = budget_s;
  secs["output"] = output_s;
  s["seconds"] = secs;
  write_file_atomic((out / "summary.json").string(), s.dump(2) + "\n");

  if (!c.quiet) {
    std::printf(
        "%s: characteristics on %zu nodes, %zu output times: solve %.3f s, budget %.3f s, "
        "output %.3f s\n",
        c.model.c_str(), n_node, times.size(), solve_s, budget_s, output_s);
    std::printf("mass budget (initial mass on the grid %.6g):\n", mb.mass0);
    std::printf("  %10s %14s %14s %14s %11s\n", "t", "grid", "outflow", "atom", "+/- atom");
    const std::size_t K = times.size(), stride = std::max<std::size_t>(1, (K + 9) / 10);
    for (std::size_t k = 0; k < K; ++k)
      if (k % stride == 0 || k + 1 == K)
        std::printf("  %10.4f %14.6e %14.6e %14.6e %11.2e\n", times[k], mb.mass[k], mb.outflow[k],
                    mb.atom[k], atom_error[k]);
    std::printf("outputs in %s: u_0000..%s .npy/.png/.vti, summary.json\n", c.out_dir.c_str(),
                detail::frame_name(K - 1).c_str());
  }
  return 0;
}

/// Entry point of a generated runner.
template <HybridModel M>
int runner_main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CONFIG.json (written by `hybgen run`)\n",
                 argc ? argv[0] : "runner");
    return 2;
  }
  try {
    const RunConfig c = read_config<M>(argv[1]);
    return run_characteristics<M>(c);
  } catch (const ConfigError& e) {
    std::fprintf(stderr, "hybgen: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "hybgen: error: %s\n", e.what());
    return 70;
  }
}

}  // namespace hybgen::rt
