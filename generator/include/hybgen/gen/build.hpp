#pragma once
/// \file build.hpp
/// Stage 5 (build): generated sources -> runner executable, compiled against
/// the runtime and cached by a content hash of everything that affects it
/// (kernel header, runner source, runtime headers, compiler identity, the target
/// CPU as the compiler resolves -march=native, flags, generator version). The
/// header carries the model file's parameter defaults: values set at run time do
/// not change the key. Concurrent builds of the same model are safe: each
/// compiles to a private temporary name and renames into place.

#include <string>

#include "hybgen/gen/emit.hpp"

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
  /// Compile the transfer-operator methods (transfer, invariant) into the runner. They pull
  /// in Eigen and Spectra, which more than double the compile time, so a runner for
  /// characteristics or particles is built without them (-DHYBGEN_RUNNER_WITHOUT_TRANSFER;
  /// a separate cache entry, since the flags are part of the key).
  bool with_transfer = true;
};

/// Whether `method` needs a runner built with the transfer operator.
bool method_needs_transfer(const std::string& method);

/// The default cache root: $HYBGEN_CACHE, else $XDG_CACHE_HOME/hybgen, else
/// ~/.cache/hybgen.
std::string default_cache_dir();

/// What the runner's compiler makes of -march=native on this machine (GCC: its target
/// options, -march=znver3 and every -m<isa>; Clang: its driver's -target-cpu and
/// -target-features): part of the cache key, so that a cache shared by two CPUs (a home
/// directory on a cluster) never hands one the other's runner, which could die with SIGILL.
std::string runner_target();

/// The compiler flags a runner is built with (part of the cache key).
std::string runner_flags(bool werror, bool with_transfer = true);

/// Stage 5: build (or reuse) the runner of `files`. Throws BuildError (exit 4)
/// with the compiler log's path when compilation fails.
BuildResult build_runner(const GeneratedFiles& files, const std::string& model_name,
                         const BuildOptions& options);

}  // namespace hybgen::gen
