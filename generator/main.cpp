// hybgen: .model text --parse--> AST --check--> Model --derive--> IR --emit-->
// generated sources --build--> runner --run--> densities.
//
// Every failure is a hybgen::gen::Error mapped to the exit codes of DESIGN.md;
// anything else that escapes is a bug (exit 70).

#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "hybgen/gen/build.hpp"
#include "hybgen/gen/check.hpp"
#include "hybgen/gen/derive.hpp"
#include "hybgen/gen/emit.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/parse.hpp"

namespace {

using namespace hybgen::gen;
using Clock = std::chrono::steady_clock;

/// The front half of the pipeline, shared by every subcommand.
struct Frontend {
  SourceText src;
  Model model;
  HybridSystem sys;
  double seconds = 0;

  Frontend(const std::string& path, const std::vector<std::string>& sets)
      : src(SourceText::load(path)) {
    const auto t0 = Clock::now();
    ModelAst ast = parse(src);     // stage 1: text -> AST
    model = check(ast, src);       // stage 2: AST -> Model
    apply_overrides(model, sets);  //          --set KEY=VALUE
    {
      // A single GiNaC operation cannot be interrupted: past the derivation's
      // own budget (checked between operations) the watchdog ends the process
      // with a located error naming the object being derived.
      const Watchdog watchdog(src.path(), model.limits.derive_seconds * 1.5 + 5);
      sys = derive(model, src);  // stage 3: Model -> IR
    }
    sys.model = &model;
    seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  }
  Frontend(const Frontend&) = delete;
  Frontend& operator=(const Frontend&) = delete;

  void print_warnings() const {
    for (const auto& w : sys.warnings) std::cerr << src.path() << ": warning: " << w << "\n";
  }
};

/// Run `exe config` and return its exit code.
int run_process(const std::string& exe, const std::string& config) {
  std::fflush(stdout);
  std::fflush(stderr);
  pid_t pid = ::fork();
  if (pid < 0) throw InternalError("fork failed");
  if (pid == 0) {
    ::execl(exe.c_str(), exe.c_str(), config.c_str(), static_cast<char*>(nullptr));
    std::perror("hybgen: cannot execute the runner");
    ::_exit(70);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) throw InternalError("waitpid failed");
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  std::cerr << "hybgen: the runner was killed by signal " << WTERMSIG(status) << "\n";
  return 70;
}

int cmd_check(const std::string& path, const std::vector<std::string>& sets) {
  Frontend fe(path, sets);
  fe.print_warnings();
  std::cout << fe.src.path() << ": ok: model '" << fe.model.name << "', " << fe.model.state.size()
            << " states, " << fe.sys.modes.size() << " modes, " << fe.sys.guards.size()
            << " guards\n";
  return 0;
}

int cmd_derive(const std::string& path, const std::vector<std::string>& sets,
               const std::string& format) {
  Frontend fe(path, sets);
  if (format == "json") {
    std::cout << derive_json(fe.sys).dump(2) << "\n";
  } else if (format == "latex") {
    std::cout << derive_latex(fe.sys);
  } else {
    std::cout << derive_text(fe.sys);
  }
  if (format == "latex") fe.print_warnings();  // text lists them itself; json carries them
  return 0;
}

int cmd_generate(const std::string& path, const std::vector<std::string>& sets, std::string dir) {
  Frontend fe(path, sets);
  fe.print_warnings();
  GeneratedFiles files = emit(fe.sys);  // stage 4: IR -> sources
  if (dir.empty()) dir = "generated/" + fe.model.name;
  try {
    write_generated(files, dir);
  } catch (const std::filesystem::filesystem_error& e) {
    throw UsageError(std::string("cannot write to '") + dir + "': " + e.what());
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());
  }
  std::cout << "wrote " << dir << "/" << files.header_name << " and " << dir << "/"
            << files.report_name << "\n";
  return 0;
}

BuildResult do_build(Frontend& fe, const std::string& cache, bool verbose, bool quiet) {
  GeneratedFiles files = emit(fe.sys);  // stage 4: IR -> sources
  BuildOptions opt;
  opt.cache_dir = cache;
  opt.verbose = verbose;
  if (!quiet) std::cerr << "hybgen: building the runner of '" << fe.model.name << "'...\n";
  BuildResult b = build_runner(files, fe.model.name, opt);  // stage 5: sources -> runner
  if (!quiet)
    std::cerr << "hybgen: runner " << (b.cached ? "(cached) " : "") << b.executable << "\n";
  return b;
}

int cmd_build(const std::string& path, const std::vector<std::string>& sets,
              const std::string& cache, bool verbose) {
  Frontend fe(path, sets);
  fe.print_warnings();
  BuildResult b = do_build(fe, cache, verbose, false);
  std::cout << b.executable << "\n";
  return 0;
}

int cmd_run(const std::string& path, const std::vector<std::string>& sets, std::string out,
            const std::string& cache, bool quiet) {
  Frontend fe(path, sets);
  fe.print_warnings();
  const Model& m = fe.model;
  if (!m.sim.present)
    throw ModelError(m.path, {1, 1},
                     "the model has no simulation block, so there is nothing to run");
  BuildResult b = do_build(fe, cache, false, quiet);
  if (out.empty()) out = "out/" + m.name;
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec) throw UsageError("cannot create the output directory '" + out + "': " + ec.message());
  nlohmann::json cfg;
  cfg["model"] = m.name;
  cfg["method"] = m.sim.method;
  cfg["out_dir"] = out;
  std::vector<double> params;
  for (const auto& p : m.params) params.push_back(p.value_d);
  cfg["params"] = params;
  nlohmann::json axes = nlohmann::json::array();
  for (std::size_t i = 0; i < m.state.size(); ++i)
    axes.push_back(
        {{"name", m.state[i]}, {"min", m.sim.lo[i]}, {"max", m.sim.hi[i]}, {"n", m.sim.grid[i]}});
  cfg["axes"] = axes;
  cfg["t_end"] = m.sim.t_end;
  cfg["dt"] = m.sim.dt;
  cfg["tol"] = m.sim.tol;
  cfg["max_events"] = m.sim.max_events;
  cfg["particles"] = m.sim.particles;
  cfg["seed"] = m.sim.seed;
  cfg["step"] = m.sim.step > 0 ? m.sim.step : m.sim.dt;
  cfg["scheme"] = m.sim.scheme;
  cfg["eigenvalues"] = m.sim.eigenvalues;
  cfg["quiet"] = quiet;
  cfg["seconds"] = {{"derive", fe.seconds}, {"build", b.seconds}};
  const std::string config = out + "/config.json";
  try {
    write_file_atomic(config, cfg.dump(2) + "\n");
  } catch (const std::runtime_error& e) {
    throw UsageError(e.what());
  }
  return run_process(b.executable, config);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "hybgen: symbolic-to-numeric code generator for hybrid dynamical systems.\n"
      "Derives the hybrid Frobenius-Perron PDE of a .model file, emits specialised C++\n"
      "kernels, builds them against the runtime and evolves densities.",
      "hybgen"};
  app.set_version_flag("--version", std::string("hybgen ") + generator_version());
  app.require_subcommand(1);
  std::string model, format = "text", out, cache;
  std::vector<std::string> sets;
  bool verbose = false, quiet = false;
  auto add_model = [&](CLI::App* sub) {
    sub->add_option("MODEL", model, "the .model file")->required();
    sub->add_option("--set", sets, "override a parameter or setting: KEY=VALUE (repeatable)")
        ->type_name("KEY=VALUE");
  };
  auto* check = app.add_subcommand("check", "parse the model and verify its hypotheses");
  add_model(check);
  auto* derive = app.add_subcommand("derive", "print the derived equations");
  add_model(derive);
  derive->add_option("--format", format, "text, latex or json")
      ->check(CLI::IsMember({"text", "latex", "json"}));
  auto* generate = app.add_subcommand("generate", "write the kernel header and derivation report");
  add_model(generate);
  generate->add_option("-o,--output", out, "output directory (default: generated/<model>)");
  auto* build = app.add_subcommand("build", "generate and compile the runner (cached)");
  add_model(build);
  build->add_option("--cache", cache,
                    "build cache directory (default: $HYBGEN_CACHE or ~/.cache/hybgen)");
  build->add_flag("-v,--verbose", verbose, "print the compiler command");
  auto* run = app.add_subcommand("run", "derive, build and run: evolve the initial density");
  add_model(run);
  run->add_option("--out", out, "output directory (default: out/<model>)");
  run->add_option("--cache", cache, "build cache directory");
  run->add_flag("-q,--quiet", quiet, "no progress output");

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return static_cast<int>(ExitCode::UsageError);
  }
  try {
    if (*check) return cmd_check(model, sets);
    if (*derive) return cmd_derive(model, sets, format);
    if (*generate) return cmd_generate(model, sets, out);
    if (*build) return cmd_build(model, sets, cache, verbose);
    if (*run) return cmd_run(model, sets, out, cache, quiet);
  } catch (const ModelError& e) {
    std::cerr << e.what() << "\n";
    return static_cast<int>(e.exit_code());
  } catch (const Error& e) {
    std::cerr << "hybgen: error: " << e.what() << "\n";
    return static_cast<int>(e.exit_code());
  } catch (const std::exception& e) {
    std::cerr << "hybgen: internal error: " << e.what() << "\n";
    return static_cast<int>(ExitCode::Internal);
  }
  return static_cast<int>(ExitCode::Internal);
}
