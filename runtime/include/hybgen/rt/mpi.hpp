#pragma once
/// \file mpi.hpp
/// The entry point of a runner built with `--set backend=mpi` (generator/src/build.cpp):
/// `main` hands its body to `mpi_main`, which starts MPI, PETSc and SLEPc, runs the body
/// with the MPI backend (core/backend.hpp; runtime/src/mpi/) and finishes them. The
/// implementation is the library hybgen::mpi, built when MPI, PETSc and SLEPc are found
/// (runtime/CMakeLists.txt); nothing else in the runtime includes MPI.
///
/// Command line: `runner CONFIG.json [PETSc options…]` under any MPI launcher (mpiexec,
/// srun); the options after the config, and those in $PETSC_OPTIONS, go to PETSc and
/// SLEPc (`-eps_type arnoldi`, `-eps_ncv 80`, `-log_view`, …). PETSc's signal handler is
/// off unless asked for (`-no_signal_handler false`): an interrupt from hybgen ends a rank
/// as it ends a one-process runner.

#include "hybgen/rt/core/backend.hpp"

namespace hybgen::rt {

/// A runner's main program over a backend: runner_main<M> or table_runner_main.
using RunnerBody = int (*)(int argc, char** argv, const Backend& backend);

/// Start MPI, PETSc and SLEPc, run `body(2, {argv[0], CONFIG}, backend)` on every rank, and
/// finish them; returns this rank's exit code (exit_codes.hpp). A usage error (no config)
/// is exit 2, a failure to start MPI or PETSc exit 70.
int mpi_main(int argc, char** argv, RunnerBody body);

}  // namespace hybgen::rt
