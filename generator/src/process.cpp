// Child processes and interrupts (process.hpp). Everything the signal handler touches is a
// volatile sig_atomic_t; a child's pid is registered before signals are unblocked and
// unregistered before it is reaped, so a forwarded signal never reaches a reused pid.

#include "hybgen/gen/process.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>

#include "hybgen/gen/errors.hpp"

extern char** environ;

namespace hybgen::gen {

namespace {

constexpr std::array<int, 3> kSignals{SIGINT, SIGTERM, SIGHUP};

/// The first signal that interrupted hybgen under a guard, 0 if none.
volatile std::sig_atomic_t g_interrupt = 0;
/// The running children's pids (0: a free slot): where an interrupt is forwarded.
volatile std::sig_atomic_t g_children[kMaxChildren] = {};

extern "C" void on_interrupt(int sig) {
  const int saved_errno = errno;
  if (g_interrupt == 0) g_interrupt = sig;
  for (std::size_t i = 0; i < kMaxChildren; ++i)
    if (g_children[i] > 0) ::kill(static_cast<pid_t>(g_children[i]), sig);  // signal-safe
  errno = saved_errno;
}

/// The three signals as a set (blocked around fork).
sigset_t signal_set() {
  sigset_t set;
  sigemptyset(&set);
  for (int sig : kSignals) sigaddset(&set, sig);
  return set;
}

/// The child's environment: hybgen's, with `env`'s variables replaced or added.
std::vector<std::string> child_environment(const Environment& env) {
  std::vector<std::string> out;
  for (char** e = environ; e && *e; ++e) {
    const std::string entry = *e;
    bool replaced = false;
    for (const auto& [k, v] : env) replaced = replaced || entry.rfind(k + "=", 0) == 0;
    if (!replaced) out.push_back(entry);
  }
  for (const auto& [k, v] : env) out.push_back(k + "=" + v);
  return out;
}

}  // namespace

InterruptGuard::InterruptGuard() {
  g_interrupt = 0;
  struct sigaction sa {};
  sa.sa_handler = on_interrupt;
  sa.sa_mask = signal_set();  // one handler at a time: the first signal is the one recorded
  sa.sa_flags = SA_RESTART;   // a write to stderr is not cut short by an interrupt
  for (std::size_t i = 0; i < kSignals.size(); ++i) {
    ::sigaction(kSignals[i], nullptr, &previous_[i]);
    if (previous_[i].sa_handler != SIG_IGN) ::sigaction(kSignals[i], &sa, nullptr);
  }
  // Children must be waited for: a SIGCHLD ignored by whoever started hybgen (inherited
  // across exec) would reap them unseen and make waitid fail.
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  ::sigaction(SIGCHLD, &dfl, &previous_child_);
}

InterruptGuard::~InterruptGuard() {
  restore();
}

void InterruptGuard::restore() const {
  for (std::size_t i = 0; i < kSignals.size(); ++i)
    ::sigaction(kSignals[i], &previous_[i], nullptr);
  ::sigaction(SIGCHLD, &previous_child_, nullptr);
}

int interrupt_signal() {
  return g_interrupt;
}

pid_t start_process(const std::string& exe, const std::string& arg, const InterruptGuard& guard,
                    const Environment& env) {
  return start_process(std::vector<std::string>{exe, arg}, guard, env);
}

std::string find_program(const std::string& name) {
  if (name.empty() || name.find('/') != std::string::npos) return name;
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/bin:/bin";
  std::size_t at = 0;
  while (at <= dirs.size()) {
    const std::size_t end = std::min(dirs.find(':', at), dirs.size());
    const std::string dir = end > at ? dirs.substr(at, end - at) : ".";
    const std::string candidate = dir + "/" + name;
    if (::access(candidate.c_str(), X_OK) == 0) return candidate;
    at = end + 1;
  }
  return "";
}

pid_t start_process(const std::vector<std::string>& command, const InterruptGuard& guard,
                    const Environment& env) {
  if (command.empty()) throw InternalError("start_process: an empty command");
  // Everything the child needs is prepared before fork: between fork and exec it calls
  // async-signal-safe functions only.
  const std::vector<std::string> envs = child_environment(env);
  std::vector<char*> envp;
  for (const auto& e : envs) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  std::vector<char*> argv;
  for (const auto& a : command) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::size_t slot = kMaxChildren;
  for (std::size_t i = 0; i < kMaxChildren && slot == kMaxChildren; ++i)
    if (g_children[i] == 0) slot = i;
  if (slot == kMaxChildren)
    throw InternalError("more than " + std::to_string(kMaxChildren) + " runners at once");

  std::fflush(stdout);
  std::fflush(stderr);
  const sigset_t blocked = signal_set();
  sigset_t mask;
  ::sigprocmask(SIG_BLOCK, &blocked, &mask);
  if (g_interrupt) {
    ::sigprocmask(SIG_SETMASK, &mask, nullptr);
    return -1;
  }
  const pid_t pid = ::fork();
  if (pid == 0) {
    guard.restore();
    ::sigprocmask(SIG_SETMASK, &mask, nullptr);
    ::execve(argv[0], argv.data(), envp.data());
    static const char msg[] = "hybgen: cannot execute the runner\n";
    [[maybe_unused]] const auto n = ::write(STDERR_FILENO, msg, sizeof msg - 1);
    ::_exit(70);
  }
  if (pid > 0) g_children[slot] = pid;
  ::sigprocmask(SIG_SETMASK, &mask, nullptr);
  if (pid < 0) throw InternalError(std::string("fork failed: ") + std::strerror(errno));
  return pid;
}

std::pair<pid_t, int> wait_process(pid_t pid) {
  // Wait without reaping first, so that the pid is not reused while a handler may still
  // forward a signal to it.
  siginfo_t info{};
  const idtype_t which = pid > 0 ? P_PID : P_ALL;
  while (::waitid(which, static_cast<id_t>(pid > 0 ? pid : 0), &info, WEXITED | WNOWAIT) < 0) {
    if (errno != EINTR) throw InternalError(std::string("waitid failed: ") + std::strerror(errno));
  }
  const pid_t done = info.si_pid;
  for (std::size_t i = 0; i < kMaxChildren; ++i)
    if (g_children[i] == done) g_children[i] = 0;
  int status = 0;
  while (::waitpid(done, &status, 0) < 0) {
    if (errno != EINTR) throw InternalError(std::string("waitpid failed: ") + std::strerror(errno));
  }
  if (g_interrupt) return {done, 128 + g_interrupt};
  if (WIFEXITED(status)) return {done, WEXITSTATUS(status)};
  const int sig = WTERMSIG(status);
  std::cerr << "hybgen: the runner was killed by signal " << sig << " (" << ::strsignal(sig)
            << ")\n";
  return {done, 70};
}

int run_process(const std::string& exe, const std::string& arg, const InterruptGuard& guard,
                const Environment& env) {
  return run_process(std::vector<std::string>{exe, arg}, guard, env);
}

int run_process(const std::vector<std::string>& command, const InterruptGuard& guard,
                const Environment& env) {
  const pid_t pid = start_process(command, guard, env);
  if (pid < 0) return 128 + g_interrupt;
  return wait_process(pid).second;
}

void stop_processes(const std::vector<pid_t>& pids) noexcept {
  for (const pid_t pid : pids) ::kill(pid, SIGTERM);
  for (const pid_t pid : pids) {
    try {
      (void)wait_process(pid);
    } catch (...) {  // already reaped: nothing left to wait for
    }
  }
}

void die_by_signal(int sig) {
  std::cout.flush();
  std::cerr.flush();
  std::signal(sig, SIG_DFL);
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, sig);
  ::sigprocmask(SIG_UNBLOCK, &set, nullptr);
  ::raise(sig);
  ::_exit(128 + sig);  // not reached: the default disposition of sig ends the process
}

}  // namespace hybgen::gen
