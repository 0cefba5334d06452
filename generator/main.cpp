// hybgen's command line: the subcommands and their options, mapped onto the library
// (frontend.hpp, emit.hpp, render.hpp, build.hpp, run.hpp, sweep.hpp). Every failure is a
// hybgen::gen::Error mapped to the exit codes of docs/design.md; anything else that
// escapes is a bug (exit 70).

#include <CLI/CLI.hpp>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "hybgen/gen/build.hpp"
#include "hybgen/gen/emit.hpp"
#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/frontend.hpp"
#include "hybgen/gen/process.hpp"
#include "hybgen/gen/render.hpp"
#include "hybgen/gen/run.hpp"
#include "hybgen/gen/sweep.hpp"
#include "hybgen/rt/settings.hpp"

namespace {

using namespace hybgen::gen;

/// What every subcommand is asked to work on: the model file, its --set
/// overrides and, for a Lie-group model, which system (--unreduced).
struct Request {
  std::string path;                             ///< The .model file.
  std::vector<std::string> sets;                ///< --set KEY=VALUE, in order.
  ReduceTarget target = ReduceTarget::Reduced;  ///< --unreduced: the twin on T*G.

  /// The front end on the request, with the derivation watchdog armed.
  [[nodiscard]] FrontendOptions options() const {
    FrontendOptions o;
    o.target = target;
    o.sets = sets;
    o.watchdog = true;
    return o;
  }
};

/// `hybgen check`: parse, check and derive; with `preflight`, also the run's pre-flight scan.
int cmd_check(const Request& req, bool preflight, const BuildOptions& build, bool quiet) {
  const Frontend fe(SourceText::load(req.path), req.options());
  fe.print_warnings(std::cerr);
  const auto count = [](std::size_t n, const char* what) {
    return std::to_string(n) + " " + what + (n == 1 ? "" : "s");
  };
  // The rules a run applies before it builds (setting_rules.hpp), so that `check` does not say
  // "ok" to a model `run` refuses; with --preflight, "ok" only after the scan passed.
  if (fe.model.sim.present) check_runnable(fe);
  if (preflight)
    if (const int rc = run_preflight(fe, build, quiet); rc != 0) return rc;
  std::cout << fe.src.path() << ": ok: model '" << fe.model.name << "', "
            << count(fe.model.state.size(), "state") << ", " << count(fe.sys.modes.size(), "mode")
            << ", " << count(fe.sys.guards.size(), "guard") << "\n";
  return 0;
}

/// `hybgen derive`: the derived equations as text, LaTeX or JSON.
int cmd_derive(const Request& req, const std::string& format, bool standalone) {
  if (standalone && format != "latex")
    throw UsageError("--standalone makes a LaTeX document: use it with --format latex");
  const Frontend fe(SourceText::load(req.path), req.options());
  if (format == "json") {
    std::cout << derive_json(fe.sys).dump(2) << "\n";
  } else if (format == "latex") {
    std::cout << (standalone ? derive_latex_document(fe.sys) : derive_latex(fe.sys));
  } else {
    std::cout << derive_text(fe.sys);
  }
  if (format == "latex") fe.print_warnings(std::cerr);  // text lists them; json carries them
  return 0;
}

/// `hybgen generate`: the kernel header and the derivation report into `dir`.
int cmd_generate(const Request& req, std::string dir) {
  const Frontend fe(SourceText::load(req.path), req.options());
  fe.print_warnings(std::cerr);
  const GeneratedFiles files = emit(fe.sys);  // stage 4: IR -> sources
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

/// `hybgen build`: the runner's path on stdout.
int cmd_build(const Request& req, const BuildOptions& build) {
  const Frontend fe(SourceText::load(req.path), req.options());
  fe.print_warnings(std::cerr);
  std::cout << build_model_runner(fe, build, false).executable << "\n";
  return 0;
}

/// `hybgen run`.
int cmd_run(const Request& req, const RunOptions& options) {
  const Frontend fe(SourceText::load(req.path), req.options());
  fe.print_warnings(std::cerr);
  return run_to_outputs(fe, options);
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
  std::string model, format = "text", out;
  std::vector<std::string> sets;
  BuildOptions bopt;
  bool quiet = false;
  auto add_build = [&](CLI::App* sub) {
    sub->add_option("--cache", bopt.cache_dir,
                    "build cache directory (default: $HYBGEN_CACHE or ~/.cache/hybgen)");
    sub->add_flag("--inline-runtime", bopt.inline_runtime,
                  "compile the whole runtime with the kernels inlined (about 35 s; a faster solve) "
                  "instead of linking the precompiled runtime (about two seconds); see "
                  "bench/runner_build.sh");
  };
  bool unreduced = false;
  auto add_model = [&](CLI::App* sub) {
    sub->add_option("MODEL", model, "the .model file")->required();
    sub->add_flag("--unreduced", unreduced,
                  "Lie-group models: the 2n-dimensional impact system on T*G instead of the "
                  "reduced one");
    sub->add_option("--set", sets, "override a parameter or setting: KEY=VALUE (repeatable)")
        ->type_name("KEY=VALUE");
  };
  bool preflight = false;
  auto* check = app.add_subcommand("check", "parse the model and verify its hypotheses");
  add_model(check);
  check->add_flag("--preflight", preflight,
                  "also build the runner (cached) and run the pre-flight scan that `run` makes "
                  "at t = 0 on the model's grid and method");
  add_build(check);
  check->add_flag("-q,--quiet", quiet, "no progress output (with --preflight)");
  auto* derive = app.add_subcommand("derive", "print the derived equations");
  add_model(derive);
  derive->add_option("--format", format, "text, latex or json")
      ->check(CLI::IsMember({"text", "latex", "json"}));
  bool standalone = false;
  derive->add_flag(
      "--standalone", standalone,
      "with --format latex: a whole document for pdflatex (Debian: texlive-latex-base; "
      "default: a fragment to paste, which needs amsmath)");
  auto* generate = app.add_subcommand("generate", "write the kernel header and derivation report");
  add_model(generate);
  generate->add_option("-o,--output", out, "output directory (default: generated/<model>)");
  auto* build = app.add_subcommand("build", "generate and compile the runner (cached)");
  add_model(build);
  add_build(build);
  build->add_flag("-v,--verbose", bopt.verbose,
                  "print the compiler command (a cached runner: the command that built it)");
  auto* run = app.add_subcommand("run", "derive, build and run: evolve the initial density");
  add_model(run);
  run->add_option("--out", out,
                  "output directory (default: out/<file>, the model file's name without .model)");
  add_build(run);
  run->footer(
      "\nSettings (--set KEY=VALUE, or KEY VALUE in the model's simulation block; also\n"
      "grid=N1xN2..., domain.<state>=[a,b], any parameter, and observe.NAME=[MODE:]EXPR,\n"
      "an observable whose mean every method reports with an error; docs/settings.md,\n"
      "docs/methods.md):\n" +
      hybgen::rt::settings_help());
  run->add_flag("-q,--quiet", quiet, "no progress output");
  int ranks = 0;
  run->add_option("--ranks", ranks,
                  "run on N MPI ranks (mpiexec -n N): the same as --set backend=mpi --set "
                  "ranks=N (docs/distributed.md)")
      ->check(CLI::Range(1, 1000000));
  std::size_t jobs = 0;
  auto* sweep = app.add_subcommand(
      "sweep", "run one runner over a grid of parameter or setting values, into one table");
  add_model(sweep);
  sweep->get_option("--set")->description(
      "KEY=A:B:N (N equally spaced values from A to B), KEY=v1,v2,... (a list), or "
      "KEY=VALUE (every point); the points are every combination (repeatable)");
  sweep->add_option("--out", out,
                    "output directory (default: out/<file>-sweep): sweep.csv, sweep.json and "
                    "one directory of run outputs per point");
  sweep->add_option("-j,--jobs", jobs, "runners at a time (default: one per core)")
      ->check(CLI::Range(std::size_t{1}, kMaxChildren));
  add_build(sweep);
  sweep->add_flag("-q,--quiet", quiet, "no progress output");
  sweep->footer(
      "\nExample: hybgen sweep models/bouncing_ball.model --set e=0.5:1.0:6 --set t_end=5\n"
      "Each point is derived as `hybgen run` derives it; all points share one runner.\n"
      "A point that fails leaves its row (status, exit) and the sweep exits with its code.\n"
      "Settings: hybgen run --help, docs/settings.md.\n");

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
  if (ranks > 0) {
    sets.push_back("backend=mpi");
    sets.push_back("ranks=" + std::to_string(ranks));
  }
  const Request req{model, sets, unreduced ? ReduceTarget::Unreduced : ReduceTarget::Reduced};
  try {
    if (*check) return cmd_check(req, preflight, bopt, quiet);
    if (*derive) return cmd_derive(req, format, standalone);
    if (*generate) return cmd_generate(req, out);
    if (*build) return cmd_build(req, bopt);
    if (*run) return cmd_run(req, RunOptions{out, bopt, quiet});
    if (*sweep) {
      SweepOptions so;
      so.run = RunOptions{out, bopt, quiet};
      so.jobs = jobs;
      so.target = req.target;
      return run_sweep(req.path, parse_sweep(req.sets), so);
    }
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
