#pragma once
/// \file shell.hpp
/// Running a shell command from a test and capturing what it printed: the common core of
/// the end-to-end tests' `hybgen(...)` helpers (each builds its own command line).

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace hybgen::testing {

/// How a shell command ended and what it wrote to its standard output.
struct ShellResult {
  int code = -1;    ///< Exit status; 128 if killed by a signal; −1 if it could not start.
  std::string out;  ///< Standard output (append " 2>&1" to the command for stderr too).
};

/// Run `cmd` with /bin/sh (popen) and wait for it.
inline ShellResult run_shell(const std::string& cmd) {
  ShellResult r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  std::size_t got;
  while ((got = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, got);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128;
  return r;
}

}  // namespace hybgen::testing
