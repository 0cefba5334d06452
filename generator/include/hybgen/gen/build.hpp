#pragma once
/// \file build.hpp
/// Stage 5 (build): generated sources -> runner executable, cached by a content
/// hash of everything that affects its machine code (kernel header, runner
/// source, runtime headers and library, compiler identity, the target CPU as the
/// compiler resolves -march=native, flags, generator version). The header
/// carries the model file's parameter defaults, and the method and every other
/// setting are read at run time: one runner per model. Concurrent builds of the
/// same model are safe: each compiles to a private temporary name and renames
/// into place.
///
/// A runner is the model's kernels linked against the precompiled runtime
/// (`hybgen::runner`, runtime/include/hybgen/rt/table_model.hpp): one small
/// translation unit. A model outside the library's shapes (more states or guards
/// than it is instantiated for) is compiled with the whole runtime inlined
/// instead, which takes about 35 s.

#include <filesystem>
#include <string>

#include "hybgen/gen/emit.hpp"
#include "hybgen/gen/frontend.hpp"

namespace hybgen::gen {

/// Result of a build.
struct BuildResult {
  std::string executable;  ///< Path of the runner.
  std::string directory;   ///< Cache entry directory.
  std::string key;         ///< Content hash (cache key).
  bool cached = false;     ///< Whether an existing runner was reused.
  double seconds = 0;      ///< Wall time spent building.
};

/// Options of a build.
struct BuildOptions {
  std::string cache_dir;  ///< Cache root ("" = default_cache_dir()).
  bool werror = false;    ///< Compile with -Werror (tests).
  bool verbose = false;   ///< Print the compiler command.
  bool progress = false;  ///< Count the compile's seconds on stderr (a terminal only).
  /// Compile the whole runtime into the runner, kernels inlined, instead of linking the
  /// precompiled library (which a model outside its shapes always does).
  bool inline_runtime = false;
  /// Build against the MPI backend (hybgen::mpi: the setting backend=mpi); a hybgen built
  /// without it refuses (BuildError, saying what to install).
  bool mpi = false;
};

/// Whether this hybgen can build runners with backend=mpi (built with hybgen::mpi).
bool mpi_available();

/// Whether the runner of `files` is built against the precompiled runtime library (else
/// with the runtime inlined): the model fits the library's shapes and `inline_runtime` is off.
bool runner_uses_library(const GeneratedFiles& files, const BuildOptions& options);

/// The default cache root: $HYBGEN_CACHE, else $XDG_CACHE_HOME/hybgen, else
/// ~/.cache/hybgen.
std::string default_cache_dir();

/// SHA-256 of the file at `path`, remembered in `memo_dir` (a hidden file per path, beside
/// the cache's runner directories) under its size and modification time (nanoseconds):
/// hashing the 9 MB runtime library took 30 ms of every run. A file rewritten with the same
/// size within the same nanosecond would be missed; builds do not do that. An unreadable or
/// stale memo is ignored and rewritten. Throws what read_file throws for a missing file.
std::string file_sha256(const std::string& path, const std::filesystem::path& memo_dir);

/// What the runner's compiler makes of -march=native on this machine (GCC: its target
/// options, -march=znver3 and every -m<isa>; Clang: its driver's -target-cpu and
/// -target-features): part of the cache key, so that a cache shared by two CPUs (a home
/// directory on a cluster) never hands one the other's runner, which could die with SIGILL.
std::string runner_target();

/// The compiler flags a runner is built with (part of the cache key).
std::string runner_flags(bool werror);

/// Stage 5: build (or reuse) the runner of `files`. Throws BuildError (exit 4)
/// with the compiler log's path when compilation fails.
BuildResult build_runner(const GeneratedFiles& files, const std::string& model_name,
                         const BuildOptions& options);

/// Emit the runner's sources (with the file's parameter values, so that the cache key does
/// not change with --set: the runner reads the values from its configuration) and build or
/// reuse the runner. Says what it does on stderr unless `quiet`.
BuildResult build_model_runner(const Frontend& fe, const BuildOptions& options, bool quiet);

}  // namespace hybgen::gen
