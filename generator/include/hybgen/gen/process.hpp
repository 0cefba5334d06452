#pragma once
/// \file process.hpp
/// Runners as child processes of hybgen, and what an interrupt does to them.
///
/// While an InterruptGuard is alive, SIGINT, SIGTERM and SIGHUP do not end hybgen: the
/// first one is recorded (interrupt_signal()) and forwarded to every running child, so
/// that the caller can remove what it staged and say that the previous outputs are
/// unchanged, then end by that signal (die_by_signal) as an interrupted program should.
/// A signal that hybgen was started ignoring (nohup, a background job) stays ignored.

#include <sys/types.h>

#include <array>
#include <csignal>
#include <string>
#include <utility>
#include <vector>

namespace hybgen::gen {

/// Most children running at once (the slots the signal handler forwards to).
inline constexpr std::size_t kMaxChildren = 64;

/// Installs the interrupt handler for its lifetime (one at a time).
class InterruptGuard {
 public:
  /// Install the handler and forget any earlier interrupt.
  InterruptGuard();
  /// Restore the dispositions hybgen had.
  ~InterruptGuard();
  InterruptGuard(const InterruptGuard&) = delete;             ///< One guard, one owner.
  InterruptGuard& operator=(const InterruptGuard&) = delete;  ///< Not assignable.
  /// Restore the earlier dispositions (in a child before exec, and at the end).
  void restore() const;

 private:
  std::array<struct sigaction, 3> previous_{};
  struct sigaction previous_child_ {};
};

/// The signal that interrupted hybgen while a guard was alive, 0 if none.
int interrupt_signal();

/// Environment variables to set in a child, on top of hybgen's own.
using Environment = std::vector<std::pair<std::string, std::string>>;

/// Start `exe arg` as a child under `guard` and return its pid, or -1 if hybgen has
/// already been interrupted (nothing is started). Signals are blocked from before fork
/// until the child's pid is registered, so none is caught where it would be forwarded
/// nowhere. Throws InternalError if fork fails or kMaxChildren are running.
pid_t start_process(const std::string& exe, const std::string& arg, const InterruptGuard& guard,
                    const Environment& env = {});

/// start_process for a whole command line: `command[0]` (a path) with the arguments
/// `command` (command[0] included, as argv). Throws InternalError on an empty command.
pid_t start_process(const std::vector<std::string>& command, const InterruptGuard& guard,
                    const Environment& env = {});

/// The path of the program `name`: itself when it contains a '/', else the first
/// executable file of that name on $PATH; "" when there is none.
std::string find_program(const std::string& name);

/// Wait for the child `pid` (or any child when -1) and return its pid and exit code:
/// its exit status; 70 if it was killed by a signal (said on stderr); 128 + the signal if
/// hybgen was interrupted.
std::pair<pid_t, int> wait_process(pid_t pid = -1);

/// start_process then wait_process: the child's exit code by the same rule.
int run_process(const std::string& exe, const std::string& arg, const InterruptGuard& guard,
                const Environment& env = {});

/// start_process then wait_process for a whole command line.
int run_process(const std::vector<std::string>& command, const InterruptGuard& guard,
                const Environment& env = {});

/// Send SIGTERM to each child of `pids` and wait for it (when a caller unwinds while
/// children run: none is left running or unreaped). Never throws.
void stop_processes(const std::vector<pid_t>& pids) noexcept;

/// End hybgen by `sig` itself (default disposition, unblocked): the caller sees a death by
/// that signal, not an exit (a shell reports 128 + sig).
[[noreturn]] void die_by_signal(int sig);

}  // namespace hybgen::gen
