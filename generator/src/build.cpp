// Stage 5 (build): generated sources -> cached runner executable.

#include "hybgen/gen/build.hpp"

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <thread>
#include <vector>

#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/hash.hpp"
#include "hybgen/rt/table_model.hpp"

#ifndef HYBGEN_RUNTIME_INCLUDE
#error "HYBGEN_RUNTIME_INCLUDE must be defined by the build"
#endif
#ifndef HYBGEN_RUNTIME_LIBRARY
#error "HYBGEN_RUNTIME_LIBRARY (the path of hybgen::runner) must be defined by the build"
#endif
#ifndef HYBGEN_IO_LIBRARY
#error "HYBGEN_IO_LIBRARY (the path of hybgen::io) must be defined by the build"
#endif
#ifndef HYBGEN_NUMERICS_LIBRARY
#error "HYBGEN_NUMERICS_LIBRARY (the path of hybgen::numerics) must be defined by the build"
#endif
#ifndef HYBGEN_INSTALL_BINDIR
#define HYBGEN_INSTALL_BINDIR "bin"
#endif
#ifndef HYBGEN_INSTALL_INCLUDEDIR
#define HYBGEN_INSTALL_INCLUDEDIR "include"
#endif
#ifndef HYBGEN_INSTALL_LIBDIR
#define HYBGEN_INSTALL_LIBDIR "lib"
#endif
#ifndef HYBGEN_CXX_COMPILER
#define HYBGEN_CXX_COMPILER "c++"
#endif
#ifndef HYBGEN_RUNNER_LIBS
#define HYBGEN_RUNNER_LIBS "-lcairo -lfontconfig -lpng -lgif"
#endif
#ifndef HYBGEN_NETCDF_LIBS
#define HYBGEN_NETCDF_LIBS "-lnetcdf"
#endif
#ifndef HYBGEN_RUNNER_INCLUDES
#define HYBGEN_RUNNER_INCLUDES ""
#endif
#ifndef HYBGEN_MPI_LIBS
#define HYBGEN_MPI_LIBS ""
#endif
#ifndef HYBGEN_OPENMP_FLAGS
#define HYBGEN_OPENMP_FLAGS "-fopenmp"
#endif

namespace hybgen::gen {

namespace fs = std::filesystem;

namespace {

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'')
      out += "'\\''";
    else
      out += c;
  }
  return out + "'";
}

/// Run a shell command, capturing stdout+stderr; returns the exit status.
int run_capture(const std::string& cmd, std::string& output) {
  output.clear();
  FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  std::array<char, 4096> buf{};
  std::size_t got;
  while ((got = std::fread(buf.data(), 1, buf.size(), p)) > 0) output.append(buf.data(), got);
  int status = ::pclose(p);
  if (status == -1) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

/// The runner's compiler: $HYBGEN_CXX when set and not empty (a path or a name on PATH),
/// else the compiler hybgen was configured with.
std::string runner_compiler() {
  if (const char* c = std::getenv("HYBGEN_CXX"); c && *c) return c;
  return HYBGEN_CXX_COMPILER;
}

/// The compiler's name and `--version` output: part of the cache key, so that changing
/// HYBGEN_CXX (or upgrading the compiler) rebuilds the runner.
std::string compiler_identity() {
  static const std::string id = [] {
    std::string out;
    const std::string cxx = runner_compiler();
    run_capture(shell_quote(cxx) + " --version", out);
    return cxx + "\n" + out;
  }();
  return id;
}

}  // namespace

std::string runner_target() {
  static const std::string target = [] {
    const std::string cxx = shell_quote(runner_compiler());
    std::string out;
    // GCC: the target options with -march=native resolved (-march=znver3, every -m<isa>).
    if (run_capture(cxx + " -march=native -Q --help=target 2>/dev/null", out) == 0 &&
        out.find("-march=") != std::string::npos)
      return out;
    // Clang: the driver's job line carries -target-cpu and the -target-feature list.
    out.clear();
    run_capture(cxx + " -march=native -### -x c++ -c /dev/null -o /dev/null 2>&1", out);
    return out;
  }();
  return target;
}

namespace {

/// Where the runtime's headers and libraries are (RuntimeLocation).
struct RuntimeLocation {
  std::string include;           ///< The directory holding hybgen/rt/.
  std::string runner_library;    ///< libhybgen_runner.a (hybgen::runner).
  std::string numerics_library;  ///< libhybgen_numerics.a (hybgen::numerics).
  std::string io_library;        ///< libhybgen_io.a (hybgen::io).
  std::string mpi_library;       ///< libhybgen_mpi.a (hybgen::mpi), "" without the backend.
};

/// The MPI backend's library in the build tree, "" when hybgen was built without it.
constexpr const char* kBuildTreeMpiLibrary =
#ifdef HYBGEN_MPI_LIBRARY
    HYBGEN_MPI_LIBRARY;
#else
    "";
#endif

/// Beside an installed hybgen (PREFIX/BINDIR/hybgen finds PREFIX/INCLUDEDIR/hybgen/rt and
/// PREFIX/LIBDIR/libhybgen_*.a, the layout cmake/HybgenInstall.cmake installs), else the
/// build tree hybgen was built in: `hybgen build` works from any directory either way.
const RuntimeLocation& runtime_location() {
  static const RuntimeLocation where = [] {
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) {
      fs::path prefix = exe.parent_path();
      for (const auto& part : fs::path(HYBGEN_INSTALL_BINDIR)) {
        (void)part;
        prefix = prefix.parent_path();
      }
      const fs::path mpi = prefix / HYBGEN_INSTALL_LIBDIR / "libhybgen_mpi.a";
      const RuntimeLocation installed{
          (prefix / HYBGEN_INSTALL_INCLUDEDIR).string(),
          (prefix / HYBGEN_INSTALL_LIBDIR / "libhybgen_runner.a").string(),
          (prefix / HYBGEN_INSTALL_LIBDIR / "libhybgen_numerics.a").string(),
          (prefix / HYBGEN_INSTALL_LIBDIR / "libhybgen_io.a").string(),
          *kBuildTreeMpiLibrary != '\0' && fs::exists(mpi) ? mpi.string() : std::string()};
      if (fs::exists(fs::path(installed.include) / "hybgen/rt/runner.hpp") &&
          fs::exists(installed.runner_library) && fs::exists(installed.numerics_library) &&
          fs::exists(installed.io_library))
        return installed;
    }
    return RuntimeLocation{HYBGEN_RUNTIME_INCLUDE, HYBGEN_RUNTIME_LIBRARY, HYBGEN_NUMERICS_LIBRARY,
                           HYBGEN_IO_LIBRARY, kBuildTreeMpiLibrary};
  }();
  return where;
}

/// Hash of every runtime header (paths relative to the include root + content) and, when the
/// runner links it, of the precompiled runtime library (a runner with the runtime inlined
/// does not change with it). The libraries' hashes are remembered in `memo_dir`.
std::string runtime_fingerprint(bool library, bool mpi, const fs::path& memo_dir) {
  std::vector<std::string> files;
  const RuntimeLocation& rt = runtime_location();
  const fs::path rt_include = fs::path(rt.include) / "hybgen" / "rt";
  for (const auto& e : fs::recursive_directory_iterator(rt_include))
    if (e.is_regular_file()) files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  std::string all;
  for (const auto& f : files) {
    all += fs::relative(f, rt_include).string() + '\n';
    all += sha256_hex(read_file(f)) + '\n';
  }
  try {
    if (library) all += "library\n" + file_sha256(rt.runner_library, memo_dir) + '\n';
    all += "numerics\n" + file_sha256(rt.numerics_library, memo_dir) + '\n';
    all += "writers\n" + file_sha256(rt.io_library, memo_dir) + '\n';
    if (mpi) all += "mpi\n" + file_sha256(rt.mpi_library, memo_dir) + '\n';
  } catch (const std::exception& e) {
    throw BuildError(std::string("the runtime library is missing (build the targets "
                                 "hybgen_runner, hybgen_numerics and hybgen_io): ") +
                     e.what());
  }
  return sha256_hex(all);
}

/// While alive and stderr is a terminal, a line on stderr that counts the seconds of the
/// compile, rewritten each second and cleared at the end (a cold build takes tens of
/// seconds; without it the user sees nothing move). Silent when stderr is not a terminal.
class CompileClock {
 public:
  /// Start counting for the runner of `model`, if `enabled`.
  CompileClock(const std::string& model, bool enabled) {
    if (!enabled || ::isatty(STDERR_FILENO) == 0) return;
    thread_ = std::thread([this, model] {
      const auto t0 = std::chrono::steady_clock::now();
      std::unique_lock lock(mutex_);
      while (!cv_.wait_for(lock, std::chrono::seconds(1), [this] { return done_; })) {
        const auto s =
            std::chrono::duration_cast<std::chrono::seconds>(std::chrono::steady_clock::now() - t0)
                .count();
        std::fprintf(stderr, "\rhybgen: compiling the runner of '%s'... %lld s", model.c_str(),
                     static_cast<long long>(s));
        shown_ = true;
      }
      if (shown_) std::fprintf(stderr, "\r\033[K");
    });
  }
  /// Stop and clear the line.
  ~CompileClock() {
    if (!thread_.joinable()) return;
    {
      const std::lock_guard lock(mutex_);
      done_ = true;
    }
    cv_.notify_one();
    thread_.join();
  }
  /// Not copyable.
  CompileClock(const CompileClock&) = delete;
  /// Not copyable.
  CompileClock& operator=(const CompileClock&) = delete;

 private:
  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false, shown_ = false;
};

/// The runner's translation unit: the kernels and their table, whose `main` enters the
/// precompiled runtime; or, for a model outside the library's shapes, the whole runtime
/// instantiated for the generated struct.
std::string runner_source(const GeneratedFiles& files, const std::string& model_name, bool library,
                          bool mpi) {
  const std::string head = "// Generated by hybgen " + std::string(generator_version()) +
                           " -- DO NOT EDIT. Runner of model '" + model_name + "'.\n#include \"" +
                           files.header_name + "\"\n\n";
  const std::string type = "hybgen_model::" + model_struct_name(model_name);
  // backend=mpi: the same body, entered through mpi_main (hybgen/rt/mpi.hpp).
  if (mpi && library)
    return head +
           "#include <hybgen/rt/mpi.hpp>\n#include <hybgen/rt/table_model.hpp>\n\n"
           "int main(int argc, char** argv) {\n"
           "  static const hybgen::rt::ModelTable table = hybgen::rt::make_table<" +
           type +
           ">();\n  return hybgen::rt::mpi_main(\n      argc, argv, [](int c, char** v, const "
           "hybgen::rt::Backend& b) { return hybgen::rt::table_runner_main(table, c, v, b); });\n"
           "}\n";
  if (mpi)
    return head +
           "#include <hybgen/rt/mpi.hpp>\n#include <hybgen/rt/runner.hpp>\n\n"
           "int main(int argc, char** argv) {\n  return hybgen::rt::mpi_main(\n      argc, argv, "
           "[](int c, char** v, const hybgen::rt::Backend& b) { return "
           "hybgen::rt::runner_main<" +
           type + ">(c, v, b); });\n}\n";
  if (library)
    return head +
           "#include <hybgen/rt/table_model.hpp>\n\nint main(int argc, char** argv) {\n"
           "  static const hybgen::rt::ModelTable table = hybgen::rt::make_table<" +
           type + ">();\n  return hybgen::rt::table_runner_main(table, argc, argv);\n}\n";
  return head +
         "#include <hybgen/rt/runner.hpp>\n\nint main(int argc, char** argv) {\n  return "
         "hybgen::rt::runner_main<" +
         type + ">(argc, argv);\n}\n";
}

}  // namespace

std::string file_sha256(const std::string& path, const fs::path& memo_dir) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return sha256_hex(read_file(path));  // throws, naming it
  const std::string stamp = std::to_string(st.st_size) + " " + std::to_string(st.st_mtim.tv_sec) +
                            "." + std::to_string(st.st_mtim.tv_nsec) + " ";
  const fs::path memo = memo_dir / (".file-" + sha256_hex(path).substr(0, 32) + ".sha256");
  std::error_code ec;
  if (fs::exists(memo, ec)) {
    try {
      const std::string m = read_file(memo.string());
      if (m.size() == stamp.size() + 64 && m.compare(0, stamp.size(), stamp) == 0)
        return m.substr(stamp.size());
    } catch (const std::exception&) {  // unreadable: hash again
    }
  }
  const std::string h = sha256_hex(read_file(path));
  try {
    fs::create_directories(memo_dir);
    write_file_atomic(memo.string(), stamp + h);
  } catch (const std::exception&) {  // a read-only cache still builds
  }
  return h;
}

std::string default_cache_dir() {
  if (const char* c = std::getenv("HYBGEN_CACHE"); c && *c) return c;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/hybgen";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/hybgen";
  return "/tmp/hybgen-cache-" + std::to_string(::getuid());
}

bool mpi_available() {
  return !runtime_location().mpi_library.empty();
}

bool runner_uses_library(const GeneratedFiles& files, const BuildOptions& options) {
  return !options.inline_runtime && rt::table_fits(files.n_state, files.n_guard);
}

std::string runner_flags(bool werror) {
  std::string f = "-std=c++20 -O3 -march=native -DNDEBUG -Wall -Wextra ";
  f += HYBGEN_OPENMP_FLAGS;
  // Third-party headers of the runtime (Eigen, Spectra) as -isystem directories.
  if (const std::string inc = HYBGEN_RUNNER_INCLUDES; !inc.empty()) f += " " + inc;
  if (werror) f += " -Werror";
#ifdef HYBGEN_RUNNER_EXTRA_FLAGS
  // The sanitizer flags hybgen itself was built with (HYBGEN_SANITIZE), so
  // that generated kernels run under ASan/UBSan too; empty otherwise.
  if (const std::string extra = HYBGEN_RUNNER_EXTRA_FLAGS; !extra.empty()) f += " " + extra;
#endif
  return f;
}

BuildResult build_runner(const GeneratedFiles& files, const std::string& model_name,
                         const BuildOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  const bool library = runner_uses_library(files, options);
  if (options.mpi && !mpi_available())
    throw BuildError(
        "backend=mpi: this hybgen was built without the MPI backend (it needs MPI, PETSc and "
        "SLEPc: `bash scripts/setup.sh --mpi` installs them and rebuilds hybgen with it)");
  const std::string main_src = runner_source(files, model_name, library, options.mpi);
  const std::string flags = runner_flags(options.werror);
  const std::string libs =
      (options.mpi ? shell_quote(runtime_location().mpi_library) + " " : std::string()) +
      (library ? shell_quote(runtime_location().runner_library) + " " : std::string()) +
      shell_quote(runtime_location().numerics_library) + " " +
      shell_quote(runtime_location().io_library) + " " + HYBGEN_RUNNER_LIBS +
      // NetCDF: the serial library, or in an MPI runner the parallel one (in HYBGEN_MPI_LIBS),
      // never both: the writers' calls and parallel_io.cpp's must reach the same library.
      (options.mpi ? std::string(" ") + HYBGEN_MPI_LIBS : std::string(" ") + HYBGEN_NETCDF_LIBS);
  const std::string root = options.cache_dir.empty() ? default_cache_dir() : options.cache_dir;
  const std::string key =
      sha256_hex(std::string(generator_version()) + '\n' + files.header + '\n' + main_src + '\n' +
                 runtime_fingerprint(library, options.mpi, fs::path(root)) + '\n' +
                 compiler_identity() + '\n' + runner_target() + '\n' + flags + '\n' + libs);
  BuildResult r;
  r.key = key;
  r.directory = root + "/" + model_struct_name(model_name) + "-" + key.substr(0, 16);
  r.executable = r.directory + "/runner";
  const std::string stamp = r.directory + "/runner.sha256";
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };

  // A cache hit needs the runner and a stamp holding its own hash: a
  // truncated or corrupted entry fails the check and is rebuilt.
  std::error_code ec;
  if (fs::exists(r.executable, ec) && fs::exists(stamp, ec)) {
    try {
      if (read_file(stamp) == sha256_hex(read_file(r.executable)) + "\n") {
        r.cached = true;
        r.seconds = elapsed();
        // -v says what a compile would have run: the command that built this entry, the
        // first line of its build.log ("$ CMD").
        if (options.verbose) {
          std::string built_by = "(its build.log is missing)";
          try {  // a diagnostic: an unreadable log must not make the entry a miss
            const std::string log = read_file(r.directory + "/build.log");
            built_by = log.substr(0, log.find('\n'));
            if (built_by.rfind("$ ", 0) == 0) built_by.erase(0, 2);
          } catch (const std::exception&) {
          }
          std::fprintf(stderr, "hybgen: cached runner %s, compiled by: %s\n", r.executable.c_str(),
                       built_by.c_str());
        }
        return r;
      }
    } catch (const std::exception&) {
      // fall through and rebuild
    }
  }
  fs::create_directories(r.directory, ec);
  if (ec)
    throw BuildError("cannot create the build cache directory '" + r.directory +
                     "': " + ec.message());
  try {
    write_file_atomic(r.directory + "/" + files.header_name, files.header);
    write_file_atomic(r.directory + "/main.cpp", main_src);
  } catch (const std::exception& e) {
    throw BuildError(e.what());
  }
  const std::string tag = std::to_string(::getpid());
  const std::string tmp_exe = r.executable + ".tmp." + tag;
  const std::string log = r.directory + "/build.log";
  const std::string cmd = shell_quote(runner_compiler()) + " " + flags + " -I" +
                          shell_quote(runtime_location().include) + " -I" +
                          shell_quote(r.directory) + " " + shell_quote(r.directory + "/main.cpp") +
                          " -o " + shell_quote(tmp_exe) + " " + libs;
  // Said only when a compile happens (a cache hit says "(cached)" afterwards, run.cpp).
  if (options.progress)
    std::fprintf(stderr, "hybgen: compiling the runner of '%s' (%s)...\n", model_name.c_str(),
                 runner_uses_library(files, options) ? "linking the precompiled runtime"
                                                     : "the whole runtime inlined");
  if (options.verbose) std::fprintf(stderr, "hybgen: %s\n", cmd.c_str());
  std::string output;
  int status = 0;
  {
    const CompileClock clock(model_name, options.progress);
    status = run_capture(cmd, output);
  }
  try {
    write_file_atomic(log, "$ " + cmd + "\n" + output);
  } catch (const std::exception&) {
    // the log is best effort; the status decides
  }
  if (status != 0) {
    ::unlink(tmp_exe.c_str());
    throw BuildError("compiling the generated code of '" + model_name + "' failed (exit status " +
                     std::to_string(status) + "); compiler log: " + log);
  }
  if (::rename(tmp_exe.c_str(), r.executable.c_str()) != 0) {
    ::unlink(tmp_exe.c_str());
    throw BuildError("cannot install the runner '" + r.executable + "'");
  }
  try {
    write_file_atomic(stamp, sha256_hex(read_file(r.executable)) + "\n");
  } catch (const std::exception& e) {
    throw BuildError(e.what());
  }
  r.seconds = elapsed();
  return r;
}

BuildResult build_model_runner(const Frontend& fe, const BuildOptions& options, bool quiet) {
  // The kernels take the parameters as par[]; the header carries the file's values only as
  // defaults (tests/e2e/test_cli.cpp, ParameterValuesReuseTheRunner).
  Model file_model = fe.model;
  for (std::size_t j = 0; j < file_model.params.size(); ++j)
    file_model.params[j].value_d = fe.file_params[j];
  HybridSystem file_sys = fe.sys;
  file_sys.model = &file_model;
  const GeneratedFiles files = emit(file_sys);  // stage 4: IR -> sources
  BuildOptions opt = options;
  opt.progress = !quiet;
  opt.mpi = fe.model.sim.settings.word<"backend">() == "mpi";
  BuildResult b = build_runner(files, fe.model.name, opt);  // stage 5: sources -> runner
  if (!quiet) {
    char took[48];
    std::snprintf(took, sizeof took, "(built in %.1f s) ", b.seconds);
    std::cerr << "hybgen: runner " << (b.cached ? "(cached) " : took) << b.executable << "\n";
  }
  return b;
}

}  // namespace hybgen::gen
