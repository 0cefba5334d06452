// hybgen: .model text --parse--> AST --check--> Model --derive--> IR --emit-->
// generated sources --build--> runner --run--> densities.
//
// Every failure is a hybgen::gen::Error mapped to the exit codes of docs/design.md;
// anything else that escapes is a bug (exit 70).

#include <fcntl.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
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
#include "hybgen/gen/reduce.hpp"
#include "hybgen/rt/settings.hpp"

namespace {

using namespace hybgen::gen;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

/// What every subcommand is asked to work on: the model file, its --set
/// overrides and, for a Lie-group model, which system (--unreduced).
struct Request {
  std::string path;                             ///< The .model file.
  std::vector<std::string> sets;                ///< --set KEY=VALUE, in order.
  ReduceTarget target = ReduceTarget::Reduced;  ///< --unreduced: the twin on T*G.
};

/// The front half of the pipeline, shared by every subcommand.
struct Frontend {
  SourceText src;
  Model model;
  HybridSystem sys;
  std::vector<double> file_params;  ///< The parameters' values in the file, before --set.
  double seconds = 0;

  explicit Frontend(const Request& req) : src(SourceText::load(req.path)) {
    const auto t0 = Clock::now();
    ModelAst ast = parse(src);  // stage 1: text -> AST
    if (is_lie_model(ast)) {
      LieModel lie = [&] {
        const Watchdog watchdog(src.path(), DeriveLimits{}.derive_seconds);
        return check_lie(ast, src);  // stage 2: AST -> LieModel
      }();
      const Watchdog watchdog(src.path(), lie.base.limits.derive_seconds);
      model = reduce(lie, src, req.target);  // reduce: LieModel -> Model (general kind)
    } else {
      if (req.target == ReduceTarget::Unreduced)
        throw UsageError("--unreduced applies to Lie-group models only ('" + src.path() +
                         "' is a general model)");
      model = check(ast, src);  // stage 2: AST -> Model
    }
    for (const auto& p : model.params) file_params.push_back(p.value_d);
    apply_overrides(model, req.sets);  //          --set KEY=VALUE
    {
      // A single GiNaC operation cannot be interrupted: past the derivation's
      // own budget (checked between operations) the watchdog ends the process
      // with a located error naming the object being derived.
      const Watchdog watchdog(src.path(), model.limits.derive_seconds);
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

/// The signal (SIGINT, SIGTERM, SIGHUP) that interrupted `hybgen run`, 0 if none.
volatile std::sig_atomic_t g_interrupt = 0;
/// The runner's pid while it runs, else 0: where an interrupt is forwarded.
volatile std::sig_atomic_t g_runner = 0;

extern "C" void on_interrupt(int sig) {
  const int saved_errno = errno;
  g_interrupt = sig;
  if (g_runner > 0) ::kill(static_cast<pid_t>(g_runner), sig);  // async-signal-safe
  errno = saved_errno;
}

/// While alive, SIGINT, SIGTERM and SIGHUP do not end hybgen: they are recorded in
/// g_interrupt and forwarded to the runner, so that `hybgen run` can remove its staging
/// directory and say that the previous outputs are unchanged. A signal that hybgen was
/// started ignoring (nohup, a background job) stays ignored.
class InterruptGuard {
 public:
  /// Install the handler.
  InterruptGuard() {
    g_interrupt = 0;
    struct sigaction sa {};
    sa.sa_handler = on_interrupt;
    sigemptyset(&sa.sa_mask);
    for (std::size_t i = 0; i < kSignals.size(); ++i) {
      ::sigaction(kSignals[i], nullptr, &previous_[i]);
      if (previous_[i].sa_handler != SIG_IGN) ::sigaction(kSignals[i], &sa, nullptr);
    }
  }
  /// The three signals as a set (to block them around fork).
  static sigset_t signal_set() {
    sigset_t set;
    sigemptyset(&set);
    for (int sig : kSignals) sigaddset(&set, sig);
    return set;
  }
  /// Restore the dispositions hybgen had (at the end, and in the runner's child before exec).
  void restore() const {
    for (std::size_t i = 0; i < kSignals.size(); ++i)
      ::sigaction(kSignals[i], &previous_[i], nullptr);
  }
  ~InterruptGuard() { restore(); }
  InterruptGuard(const InterruptGuard&) = delete;             ///< One guard, one owner.
  InterruptGuard& operator=(const InterruptGuard&) = delete;  ///< Not assignable.

 private:
  static constexpr std::array<int, 3> kSignals{SIGINT, SIGTERM, SIGHUP};
  std::array<struct sigaction, 3> previous_{};
};

/// End hybgen by `sig` itself (default disposition, unblocked), as the shell convention
/// for a cleaned-up interrupt asks: the caller sees a death by that signal, not an exit.
void die_by_signal(int sig) {
  std::cout.flush();
  std::cerr.flush();
  std::signal(sig, SIG_DFL);
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, sig);
  ::sigprocmask(SIG_UNBLOCK, &set, nullptr);
  ::raise(sig);
}

/// Run `exe config` under `guard` and return its exit code: 70 if it was killed by a signal,
/// 128 + the signal if hybgen was interrupted (before the runner started, nothing is run).
/// The signals are blocked from before fork until g_runner names the child, so that none
/// is caught in the child before exec (where it would be forwarded nowhere): a signal sent
/// then stays pending, in the parent until it is unblocked, in the child until exec's
/// restored dispositions take it.
int run_process(const std::string& exe, const std::string& config, const InterruptGuard& guard) {
  std::fflush(stdout);
  std::fflush(stderr);
  const sigset_t blocked = InterruptGuard::signal_set();
  sigset_t mask;
  ::sigprocmask(SIG_BLOCK, &blocked, &mask);
  if (g_interrupt) {
    ::sigprocmask(SIG_SETMASK, &mask, nullptr);
    return 128 + g_interrupt;
  }
  pid_t pid = ::fork();
  if (pid == 0) {
    guard.restore();
    ::sigprocmask(SIG_SETMASK, &mask, nullptr);
    ::execl(exe.c_str(), exe.c_str(), config.c_str(), static_cast<char*>(nullptr));
    std::perror("hybgen: cannot execute the runner");
    ::_exit(70);
  }
  if (pid > 0) g_runner = pid;
  ::sigprocmask(SIG_SETMASK, &mask, nullptr);
  if (pid < 0) throw InternalError("fork failed");
  // Wait without reaping first, so that the pid is not reused while a handler may still
  // forward a signal to it.
  siginfo_t info{};
  while (::waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOWAIT) < 0) {
    if (errno != EINTR) throw InternalError("waitid failed");
  }
  g_runner = 0;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) throw InternalError("waitpid failed");
  }
  if (g_interrupt) return 128 + g_interrupt;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  const int sig = WTERMSIG(status);
  std::cerr << "hybgen: the runner was killed by signal " << sig << " (" << ::strsignal(sig)
            << ")\n";
  return 70;
}

int run_preflight(Frontend& fe, const BuildOptions& build, bool quiet);

/// `hybgen check`: parse, check and derive; with `preflight`, also the run's pre-flight scan.
int cmd_check(const Request& req, bool preflight, const BuildOptions& build, bool quiet) {
  Frontend fe(req);
  fe.print_warnings();
  std::cout << fe.src.path() << ": ok: model '" << fe.model.name << "', " << fe.model.state.size()
            << " states, " << fe.sys.modes.size() << " modes, " << fe.sys.guards.size()
            << " guards\n";
  if (!preflight) return 0;
  std::cout.flush();
  return run_preflight(fe, build, quiet);
}

int cmd_derive(const Request& req, const std::string& format) {
  Frontend fe(req);
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

int cmd_generate(const Request& req, std::string dir) {
  Frontend fe(req);
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

BuildResult do_build(Frontend& fe, const BuildOptions& options, bool quiet) {
  // The runner reads the parameter values from its configuration (run_config), and its
  // kernels take them as par[]: its header carries the file's defaults, not the --set
  // values, so that the cache key (build.cpp) does not change with them and another value
  // reuses the cached runner (tests/e2e/test_cli.cpp, ParameterValuesReuseTheRunner).
  Model file_model = fe.model;
  for (std::size_t j = 0; j < file_model.params.size(); ++j)
    file_model.params[j].value_d = fe.file_params[j];
  HybridSystem file_sys = fe.sys;
  file_sys.model = &file_model;
  GeneratedFiles files = emit(file_sys);  // stage 4: IR -> sources
  BuildOptions opt = options;
  opt.progress = !quiet;
  if (!quiet) std::cerr << "hybgen: building the runner of '" << fe.model.name << "'...\n";
  BuildResult b = build_runner(files, fe.model.name, opt);  // stage 5: sources -> runner
  if (!quiet) {
    char took[48];
    std::snprintf(took, sizeof took, "(built in %.1f s) ", b.seconds);
    std::cerr << "hybgen: runner " << (b.cached ? "(cached) " : took) << b.executable << "\n";
  }
  return b;
}

int cmd_build(const Request& req, const BuildOptions& build) {
  Frontend fe(req);
  fe.print_warnings();
  BuildResult b = do_build(fe, build, false);
  std::cout << b.executable << "\n";
  return 0;
}

/// An exclusive, non-blocking flock on `lock_path`, held until destruction: two runs into
/// the same output directory cannot interleave; the second one is refused (exit 2).
class OutputLock {
 public:
  /// Lock `lock_path` (created if missing); `shown` is OUT as the user wrote it. Throws
  /// UsageError if another process holds the lock.
  OutputLock(const std::string& lock_path, const std::string& shown) {
    fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd_ < 0)
      throw UsageError("cannot create the lock file '" + lock_path + "': " + std::strerror(errno));
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      ::close(fd_);
      if (err == EWOULDBLOCK) throw UsageError("another hybgen run is writing to '" + shown + "'");
      throw UsageError("cannot lock '" + lock_path + "': " + std::strerror(err));
    }
  }
  /// Not copyable (one lock, one owner).
  OutputLock(const OutputLock&) = delete;
  /// Not copyable.
  OutputLock& operator=(const OutputLock&) = delete;
  /// Releases the lock; the (empty) lock file stays, so that no other run can lock a file
  /// that is about to be unlinked.
  ~OutputLock() { ::close(fd_); }

 private:
  int fd_ = -1;
};

/// The first entry of `dir` that cannot be a run output — a subdirectory, or a file other
/// than .npy/.png/.vti/.json or an atomic write's temporary — or "" if there is none.
std::string foreign_entry(const fs::path& dir) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string n = e.path().filename().string();
    const std::string x = e.path().extension().string();
    const bool output = x == ".npy" || x == ".png" || x == ".vti" || x == ".json";
    if (!e.is_regular_file(ec) || !(output || n.find(".tmp.") != std::string::npos)) return n;
  }
  return ec ? dir.filename().string() : "";
}

/// Best effort: make renames in `dir` durable.
void sync_directory(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

/// How swap_into_place ended.
struct SwapResult {
  std::string error;     ///< Empty on success.
  std::string stranded;  ///< Where the outputs are when a failed rollback left OUT missing.
};

/// Put the finished staging directory in the place of `target` (which holds earlier outputs
/// when `had_outputs`); on success the old outputs, if any, are under the staging name,
/// to be removed. Invariant: a `.old-` directory is always a complete set of outputs, and
/// at every instant either target holds a complete set (old or new) or, between the two
/// renames of the fallback, the old set is `old` and the next run restores it; what is
/// under a `.partial-` name is never restored, so it may be deleted in place. The exchange
/// (renameat2 RENAME_EXCHANGE) leaves no instant without target; the fallback (filesystems
/// without it) moves target to `old`, staging to target, then `old` to the staging name.
SwapResult swap_into_place(const fs::path& staging, const fs::path& target, const fs::path& old,
                           bool had_outputs) {
  if (had_outputs) {
    if (::renameat2(AT_FDCWD, staging.c_str(), AT_FDCWD, target.c_str(), RENAME_EXCHANGE) == 0)
      return {};
    if (errno != EINVAL && errno != ENOSYS)
      return {std::string("cannot exchange it with the new outputs: ") + std::strerror(errno), {}};
    if (::rename(target.c_str(), old.c_str()) != 0)
      return {std::string("cannot move it aside: ") + std::strerror(errno), {}};
  }
  if (::rename(staging.c_str(), target.c_str()) != 0) {
    const std::string err =
        "cannot move the new outputs into it: " + std::string(std::strerror(errno));
    if (had_outputs && ::rename(old.c_str(), target.c_str()) != 0)
      return {err + "; nor could the previous outputs be moved back (" + std::strerror(errno) + ")",
              "the previous outputs are in '" + old.string() + "', the new ones in '" +
                  staging.string() + "'"};
    return {err, {}};
  }
  if (had_outputs && ::rename(old.c_str(), staging.c_str()) != 0)
    std::cerr << "hybgen: warning: the previous outputs stay in '" << old.string()
              << "': " << std::strerror(errno) << "\n";
  return {};
}

/// The runner's configuration for model m (the run contract read by `read_config`,
/// runtime/include/hybgen/rt/runner.hpp): the runner writes into `out_dir`; `final_out_dir`
/// is where the outputs end up (its messages name it).
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

/// `hybgen check --preflight`: build the runner (cached) and run only its pre-flight scan
/// (the checks `run` makes at t = 0, preflight.hpp) on the model's grid and method, so that
/// `check` and `run` agree. Nothing is written but a config file in a fresh temporary
/// directory, removed afterwards. Exit 0, or 3 with the scan's failure.
int run_preflight(Frontend& fe, const BuildOptions& build, bool quiet) {
  const Model& m = fe.model;
  if (!m.sim.present)
    throw ModelError(m.path, {1, 1},
                     "the model has no simulation block, so there is no grid "
                     "for the pre-flight scan");
  BuildResult b = do_build(fe, build, quiet);
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
    write_file_atomic(config, cfg.dump(2) + "\n");
    rc = run_process(b.executable, config, interrupt_guard);
  } catch (...) {
    fs::remove_all(dir, ec);
    throw;
  }
  fs::remove_all(dir, ec);
  if (rc > 128) die_by_signal(rc - 128);
  return rc;
}

/// `hybgen run`: the runner writes into a fresh staging directory `OUT.partial-<pid>` next
/// to OUT; only when it succeeds is the staging directory swapped into place
/// (swap_into_place), and the old outputs removed. A failed run removes the staging
/// directory and leaves OUT as it was. The lock `OUT.lock` serialises runs into the same OUT;
/// a run that finds OUT missing but a complete `OUT.old-<pid>` of a run killed mid-swap
/// restores it first.
int cmd_run(const Request& req, std::string out, const BuildOptions& build, bool quiet) {
  Frontend fe(req);
  fe.print_warnings();
  const Model& m = fe.model;
  if (!m.sim.present)
    throw ModelError(m.path, {1, 1},
                     "the model has no simulation block, so there is nothing to run");
  // The backward characteristics need the inverse of every reset; a reset injective on its
  // guard only has none (derive.cpp): refuse before building, at the reset, with the methods
  // that apply.
  if (m.sim.settings.word<"method">() == "characteristics")
    for (std::size_t gi = 0; gi < fe.sys.guards.size(); ++gi)
      if (fe.sys.guards[gi].inverse_on_guard_only)
        throw fe.src.error(m.guards[gi].reset_loc,
                           "the reset of guard '" + m.guards[gi].name +
                               "' has no inverse in the whole state space (it is locally "
                               "injective on its guard only), which the characteristics method "
                               "needs; use "
                               "--set method=transfer, invariant or particles");
  if (out.empty()) out = "out/" + m.name;
  // OUT as an absolute path without a trailing separator; its siblings share its name.
  fs::path target = fs::absolute(fs::path(out)).lexically_normal();
  if (target.filename().empty()) target = target.parent_path();
  if (target == target.root_path())
    throw UsageError("cannot use '" + out + "' as the output directory");
  const fs::path parent = target.parent_path();
  const std::string name = target.filename().string();
  std::error_code ec;
  fs::create_directories(parent, ec);
  if (ec) throw UsageError("cannot create the output directory '" + out + "': " + ec.message());
  const OutputLock lock((parent / (name + ".lock")).string(), out);

  // OUT is replaced as a whole: refuse anything but a directory of earlier outputs.
  if (fs::exists(target, ec)) {
    if (!fs::is_directory(target, ec))
      throw UsageError("the output directory '" + out + "' exists and is not a directory");
    const fs::path cwd = fs::current_path(ec);
    if (!ec &&
        std::mismatch(target.begin(), target.end(), cwd.begin(), cwd.end()).first == target.end())
      throw UsageError("refusing to replace '" + out +
                       "': it is (or contains) the current directory; choose another --out");
    if (const std::string f = foreign_entry(target); !f.empty())
      throw UsageError("refusing to replace '" + out + "': it holds '" + f +
                       "', which hybgen did not write (a run replaces the whole directory); "
                       "choose another --out");
  }
  // Leftovers of runs that were killed (we hold the lock, so nobody else is using them):
  // staging directories are incomplete and go; an old-outputs directory is complete, and
  // if OUT is missing (a run killed between the fallback's two renames) it is OUT again.
  std::vector<fs::path> leftovers;
  for (const auto& e : fs::directory_iterator(parent, ec)) {
    const std::string n = e.path().filename().string();
    if (n.rfind(name + ".partial-", 0) == 0 || n.rfind(name + ".old-", 0) == 0)
      leftovers.push_back(e.path());
  }
  std::sort(leftovers.begin(), leftovers.end());
  for (const auto& p : leftovers) {
    if (p.filename().string().rfind(name + ".old-", 0) == 0 && !fs::exists(target, ec) &&
        ::rename(p.c_str(), target.c_str()) == 0) {
      std::cerr << "hybgen: restored the outputs of an interrupted run from '" << p.string()
                << "' to '" << out << "'\n";
      continue;
    }
    fs::remove_all(p, ec);
  }

  BuildResult b = do_build(fe, build, quiet);
  // From here on an interrupt removes the staging directory instead of leaving it.
  const InterruptGuard interrupt_guard;
  const std::string tag = std::to_string(::getpid());
  const fs::path staging = parent / (name + ".partial-" + tag);
  const fs::path old = parent / (name + ".old-" + tag);
  fs::remove_all(staging, ec);
  fs::create_directory(staging, ec);
  if (ec)
    throw UsageError("cannot create the staging directory '" + staging.string() +
                     "': " + ec.message());
  const bool had_outputs = fs::exists(target, ec);
  auto unchanged = [&] {
    return had_outputs ? "the previous outputs in '" + out + "' are unchanged"
                       : "nothing was written to '" + out + "'";
  };

  nlohmann::json cfg = run_config(m, staging.string(), out, quiet);
  cfg["seconds"] = {{"derive", fe.seconds}, {"build", b.seconds}};
  const std::string config = (staging / "config.json").string();
  try {
    write_file_atomic(config, cfg.dump(2) + "\n");
  } catch (const std::runtime_error& e) {
    fs::remove_all(staging, ec);
    throw UsageError(std::string(e.what()) + "; " + unchanged());
  }
  int rc = 70;
  try {
    rc = run_process(b.executable, config, interrupt_guard);
  } catch (...) {
    fs::remove_all(staging, ec);
    throw;
  }
  if (rc == 0 && g_interrupt) rc = 128 + g_interrupt;  // finished, but asked to stop: no swap
  if (rc > 128) {
    fs::remove_all(staging, ec);
    if (::isatty(STDERR_FILENO)) std::cerr << '\n';  // end a progress bar's line
    std::cerr << "hybgen: interrupted by signal " << rc - 128 << " (" << ::strsignal(rc - 128)
              << "); " << unchanged() << "\n";
    die_by_signal(rc - 128);  // so that a calling shell or script stops too
    return rc;
  }
  if (rc != 0) {
    fs::remove_all(staging, ec);
    std::cerr << "hybgen: the run failed (exit " << rc << "); " << unchanged() << "\n";
    return rc;
  }
  // The config as it applies to OUT (the runner has finished with the staging path).
  cfg["out_dir"] = out;
  try {
    write_file_atomic(config, cfg.dump(2) + "\n");
  } catch (const std::runtime_error& e) {
    fs::remove_all(staging, ec);
    throw InternalError(std::string(e.what()) + "; " + unchanged());
  }
  // Swap: the new outputs into OUT, the old ones (if any) under the staging name, removed.
  if (const SwapResult sw = swap_into_place(staging, target, old, had_outputs); !sw.error.empty()) {
    if (!sw.stranded.empty())
      throw InternalError("cannot replace the outputs in '" + out + "': " + sw.error + "; " +
                          sw.stranded);
    fs::remove_all(staging, ec);
    throw InternalError("cannot replace the outputs in '" + out + "': " + sw.error + "; " +
                        unchanged());
  }
  sync_directory(parent);
  if (had_outputs && fs::exists(staging, ec)) {
    fs::remove_all(staging, ec);
    if (ec)
      std::cerr << "hybgen: warning: cannot remove the previous outputs '" << staging.string()
                << "': " << ec.message() << "\n";
  }
  return 0;
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
                  "instead of linking the precompiled runtime (under a second); see "
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
  auto* generate = app.add_subcommand("generate", "write the kernel header and derivation report");
  add_model(generate);
  generate->add_option("-o,--output", out, "output directory (default: generated/<model>)");
  auto* build = app.add_subcommand("build", "generate and compile the runner (cached)");
  add_model(build);
  add_build(build);
  build->add_flag("-v,--verbose", bopt.verbose, "print the compiler command");
  auto* run = app.add_subcommand("run", "derive, build and run: evolve the initial density");
  add_model(run);
  run->add_option("--out", out, "output directory (default: out/<model>)");
  add_build(run);
  run->footer(
      "\nSettings (--set KEY=VALUE, or KEY VALUE in the model's simulation block; also\n"
      "grid=N1xN2..., domain.<state>=[a,b] and any parameter; docs/settings.md):\n" +
      hybgen::rt::settings_help());
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
  const Request req{model, sets, unreduced ? ReduceTarget::Unreduced : ReduceTarget::Reduced};
  try {
    if (*check) return cmd_check(req, preflight, bopt, quiet);
    if (*derive) return cmd_derive(req, format);
    if (*generate) return cmd_generate(req, out);
    if (*build) return cmd_build(req, bopt);
    if (*run) return cmd_run(req, out, bopt, quiet);
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
