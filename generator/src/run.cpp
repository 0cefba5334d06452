// Building and running a derived model (run.hpp).

#include "hybgen/gen/run.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "hybgen/gen/emit.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/hash.hpp"
#include "hybgen/gen/outputs.hpp"
#include "hybgen/gen/process.hpp"
#include "hybgen/gen/render.hpp"
#include "hybgen/rt/io/json_text.hpp"
#include "hybgen/rt/setting_rules.hpp"

namespace hybgen::gen {

namespace fs = std::filesystem;

std::vector<std::string> runner_command(const rt::Settings& settings, const std::string& runner,
                                        const std::string& config) {
  if (settings.word<"backend">() != "mpi") return {runner, config};
  std::vector<std::string> command;
  const char* launcher = std::getenv("HYBGEN_MPIEXEC");
  std::istringstream words(launcher && *launcher ? launcher : "mpiexec");
  for (std::string w; words >> w;) command.push_back(w);
  const std::string path = find_program(command.front());
  if (path.empty())
    throw UsageError("backend=mpi: the MPI launcher '" + command.front() +
                     "' is not on PATH (install openmpi-bin: bash scripts/setup.sh --mpi; or set "
                     "HYBGEN_MPIEXEC to the launcher's command)");
  command.front() = path;
  command.insert(command.end(),
                 {"-n", std::to_string(settings.integer<"ranks">()), runner, config});
  return command;
}

void check_runnable(const Frontend& fe) {
  const Model& m = fe.model;
  if (!m.sim.present)
    throw ModelError(m.path, {1, 1},
                     "the model has no simulation block, so there is nothing to run");
  // The rules that relate the settings to each other, to the method and to the model, as the
  // runner applies them (runtime/include/hybgen/rt/setting_rules.hpp), before anything is
  // built; a reset the method cannot invert is located at the reset.
  const std::vector<std::pair<std::size_t, std::string>> no_inverse = guards_without_inverse(fe);
  rt::RunFacts facts;
  facts.states = m.state;
  facts.guards_without_inverse = &no_inverse;
  facts.grid = m.sim.grid;
  facts.modes = static_cast<int>(m.modes.size());
  facts.memory_bytes = rt::physical_memory_bytes();
  for (const rt::SettingConflict& c : rt::setting_conflicts(m.sim.settings, facts)) {
    if (c.guard >= 0)
      throw fe.src.error(m.guards[static_cast<std::size_t>(c.guard)].reset_loc, c.message);
    throw UsageError(c.setting == "figure_axes" ? "setting 'figure_axes': " + c.message
                                                : c.message);
  }
}

std::vector<std::pair<std::size_t, std::string>> guards_without_inverse(const Frontend& fe) {
  std::vector<std::pair<std::size_t, std::string>> out;
  for (std::size_t gi = 0; gi < fe.sys.guards.size(); ++gi)
    if (fe.sys.guards[gi].inverse_on_guard_only && fe.sys.guards[gi].image_axis < 0)
      out.emplace_back(gi, fe.sys.guards[gi].name);
  return out;
}

nlohmann::json run_config(const Model& m, const std::string& out_dir,
                          const std::string& final_out_dir, bool quiet) {
  nlohmann::json cfg;
  cfg["model"] = m.name;
  cfg["out_dir"] = out_dir;
  cfg["final_out_dir"] = final_out_dir;
  std::vector<double> params;
  for (const auto& p : m.params) params.push_back(p.value_d);
  cfg["params"] = params;
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t i = 0; i < m.state.size(); ++i)
    axes.push_back(
        {{"name", m.state[i]}, {"min", m.sim.lo[i]}, {"max", m.sim.hi[i]}, {"n", m.sim.grid[i]}});
  cfg["axes"] = axes;
  cfg.update(m.sim.settings.to_json());  // method, times, every method setting (settings.hpp)
  cfg["quiet"] = quiet;
  return cfg;
}

nlohmann::json run_provenance(const Frontend& fe) {
  // What derive checked: the reduction's hypotheses (Lie-group models), each guard's kind of
  // inverse reset, and derive's warnings (docs/design.md: derive --format json).
  const nlohmann::ordered_json d = derive_json(fe.sys);
  nlohmann::json checks = {{"warnings", d.value("warnings", nlohmann::ordered_json::array())}};
  if (d.contains("reduction") && d["reduction"].is_object() &&
      d["reduction"].contains("hypotheses"))
    checks["hypotheses"] = d["reduction"]["hypotheses"];
  nlohmann::json guards = nlohmann::json::array();
  for (const auto& g : d["guards"])
    guards.push_back(
        {{"name", g.value("name", "")}, {"reset_inverse_kind", g.value("reset_inverse_kind", "")}});
  checks["guards"] = guards;
  return {{"checks", checks},
          {"model_path", fe.src.path()},
          {"sets", fe.sets},
          {"model_text", fe.src.text()},
          {"model_sha256", sha256_hex(fe.src.text())},
          {"equations", derive_text(fe.sys)},
          {"equations_latex", derive_latex(fe.sys)},
          {"hybgen_version", generator_version()}};
}

void stop_if_interrupted(OutputTransaction& tx) {
  const int sig = interrupt_signal();
  if (!sig) return;
  tx.abort();
  if (::isatty(STDERR_FILENO)) std::cerr << '\n';  // end a progress bar's line
  std::cerr << "hybgen: interrupted by signal " << sig << " (" << ::strsignal(sig) << "); "
            << tx.unchanged() << "\n";
  die_by_signal(sig);  // so that a calling shell or script stops too
}

std::string default_out_dir(const Frontend& fe, const std::string& suffix) {
  // The file's name, not `model NAME`: two files that share a model name (a copy being
  // edited) must not replace each other's outputs.
  const std::string stem = fs::path(fe.src.path()).stem().string();
  return "out/" + (stem.empty() || stem == "-" ? fe.model.name : stem) + suffix;
}

int run_to_outputs(const Frontend& fe, const RunOptions& options) {
  check_runnable(fe);
  const Model& m = fe.model;
  const std::string out = options.out.empty() ? default_out_dir(fe) : options.out;
  OutputTransaction tx(out, OutputKind::Run);
  const BuildResult b = build_model_runner(fe, options.build, options.quiet);
  // From here on an interrupt removes the staging directory instead of leaving it.
  const InterruptGuard interrupt_guard;
  const fs::path staging = tx.stage();

  nlohmann::json cfg = run_config(m, staging.string(), out, options.quiet);
  cfg["provenance"] = run_provenance(fe);
  cfg["seconds"] = {{"derive", fe.seconds}, {"build", b.seconds}};
  const std::string config = (staging / "config.json").string();
  try {
    write_file_atomic(config, hybgen::rt::json_file_text(cfg));
  } catch (const std::runtime_error& e) {
    throw UsageError(std::string(e.what()) + "; " + tx.unchanged());
  }
  // An interrupt is what interrupt_signal() says, not a runner's exit status above 128 (which
  // is a failure like any other).
  const int rc = run_process(runner_command(m.sim.settings, b.executable, config), interrupt_guard);
  stop_if_interrupted(tx);
  if (rc != 0) {
    tx.abort();
    std::cerr << "hybgen: the run failed (exit " << rc << "); " << tx.unchanged() << "\n";
    return rc;
  }
  // The config as it applies to OUT (the runner has finished with the staging path).
  cfg["out_dir"] = out;
  try {
    write_file_atomic(config, hybgen::rt::json_file_text(cfg));
  } catch (const std::runtime_error& e) {
    throw InternalError(std::string(e.what()) + "; " + tx.unchanged());
  }
  stop_if_interrupted(tx);
  tx.commit();
  return 0;
}

int run_preflight(const Frontend& fe, const BuildOptions& build, bool quiet) {
  const Model& m = fe.model;
  if (!m.sim.present)
    throw ModelError(m.path, {1, 1},
                     "the model has no simulation block, so there is no grid "
                     "for the pre-flight scan");
  const BuildResult b = build_model_runner(fe, build, quiet);
  const InterruptGuard interrupt_guard;
  std::string tmpl = (fs::temp_directory_path() / "hybgen-preflight-XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr)
    throw UsageError(std::string("cannot create a temporary directory: ") + std::strerror(errno));
  const fs::path dir = tmpl;
  nlohmann::json cfg = run_config(m, dir.string(), dir.string(), quiet);
  cfg["preflight_only"] = true;
  const std::string config = (dir / "config.json").string();
  int rc = 70;
  std::error_code ec;
  try {
    write_file_atomic(config, hybgen::rt::json_file_text(cfg));
    rc = run_process(runner_command(m.sim.settings, b.executable, config), interrupt_guard);
  } catch (...) {
    fs::remove_all(dir, ec);
    throw;
  }
  fs::remove_all(dir, ec);
  if (rc > 128) die_by_signal(rc - 128);
  return rc;
}

}  // namespace hybgen::gen
