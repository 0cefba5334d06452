#pragma once
/// \file run.hpp
/// Stages 5 and 6 for a derived model: build its runner (cached) and run it on the
/// configuration of docs/design.md ("Runner contract"), inside an output transaction
/// (outputs.hpp) and under an interrupt guard (process.hpp).

#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "hybgen/gen/build.hpp"
#include "hybgen/gen/frontend.hpp"
#include "hybgen/gen/outputs.hpp"

namespace hybgen::gen {

/// How `hybgen run` and `hybgen sweep` build and run.
struct RunOptions {
  std::string out;     ///< Output directory ("": default_out_dir: out/<file>, out/<file>-sweep).
  BuildOptions build;  ///< How to build the runner.
  bool quiet = false;  ///< No progress output.
};

/// The command line that runs `runner` on `config`: the runner itself, or with backend=mpi
/// the MPI launcher ($HYBGEN_MPIEXEC, split at spaces, else `mpiexec`) with `-n ranks`
/// first. Throws UsageError when the launcher is not found.
std::vector<std::string> runner_command(const rt::Settings& settings, const std::string& runner,
                                        const std::string& config);

/// Throw the error that stops `fe`'s model from running at all: no simulation block, or a
/// broken rule of runtime/include/hybgen/rt/setting_rules.hpp (a method that inverts the
/// resets with a reset that has no inverse off its guard is located at the reset).
void check_runnable(const Frontend& fe);

/// The guards of `fe` whose reset has an inverse on its guard only (derive.cpp), by index and
/// name: the fact setting_rules.hpp's inverse rule needs.
std::vector<std::pair<std::size_t, std::string>> guards_without_inverse(const Frontend& fe);

/// The runner's configuration for `m` (read by read_config, runtime/include/hybgen/rt/
/// runner.hpp): the runner writes into `out_dir`; `final_out_dir` is where the outputs end
/// up (its messages name it).
nlohmann::json run_config(const Model& m, const std::string& out_dir,
                          const std::string& final_out_dir, bool quiet);

/// What a run's files record of where they came from (the configuration's `provenance`,
/// written into run.nc's attributes by runtime/src/io/netcdf.cpp): the model's path, text
/// and SHA-256, the derived equations as `hybgen derive` prints them (text and LaTeX: the
/// report typesets the LaTeX), and hybgen's version.
nlohmann::json run_provenance(const Frontend& fe);

/// If hybgen has been interrupted (process.hpp), abandon `tx`'s staging directory, say that
/// the previous outputs are unchanged and end hybgen by the signal; else return. Asked to
/// stop, hybgen never swaps, even after its runners succeeded.
void stop_if_interrupted(OutputTransaction& tx);

/// The output directory of a run of `fe` without --out: `out/<file><suffix>`, <file> the
/// model file's name without its extension (the model's name when it has no file).
std::string default_out_dir(const Frontend& fe, const std::string& suffix = "");

/// `hybgen run`: build, run into a staging directory, and swap it in on success. Returns
/// the exit code (the runner's on failure, OUT unchanged); on an interrupt, removes the
/// staging directory and ends hybgen by the signal. (The runner's own chain is
/// runtime/include/hybgen/rt/runner.hpp, `run_chain`.)
int run_to_outputs(const Frontend& fe, const RunOptions& options);

/// `hybgen check --preflight`: build the runner and run only its pre-flight scan (the checks
/// `run` makes at t = 0, preflight.hpp) on the model's grid and method. Nothing is written
/// but a configuration in a temporary directory, removed afterwards. Returns 0, or 3 with
/// the scan's failure.
int run_preflight(const Frontend& fe, const BuildOptions& build, bool quiet);

}  // namespace hybgen::gen
