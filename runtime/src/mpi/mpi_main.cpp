// The entry point of an MPI runner (hybgen/rt/mpi.hpp).

#include <mpi.h>
#include <slepcsys.h>

#include <cstdio>
#include <exception>

#include "hybgen/rt/exit_codes.hpp"
#include "hybgen/rt/mpi.hpp"
#include "mpi_backend.hpp"

namespace hybgen::rt {

int mpi_main(int argc, char** argv, RunnerBody body) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s CONFIG.json [PETSc options] (written by `hybgen run`)\n",
                 argc ? argv[0] : "runner");
    return exit_status(ExitCode::UsageError);
  }
  // OpenMP threads work inside a rank; only the main thread calls MPI.
  int provided = 0;
  if (MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
    std::fprintf(stderr, "hybgen: error: MPI_Init_thread failed\n");
    return exit_status(ExitCode::Internal);
  }
  // Before SlepcInitialize, so that the command line and $PETSC_OPTIONS can still say
  // otherwise: PETSc's handler would turn hybgen's forwarded interrupt into an error report.
  PetscOptionsSetValue(nullptr, "-no_signal_handler", "true");
  if (SlepcInitialize(&argc, &argv, nullptr, nullptr) != 0) {
    std::fprintf(stderr, "hybgen: error: PETSc/SLEPc failed to start\n");
    MPI_Finalize();
    return exit_status(ExitCode::Internal);
  }
  int status = exit_status(ExitCode::Internal);
  try {
    const mpi::MpiBackend backend;
    char* args[] = {argv[0], argv[1], nullptr};
    status = body(2, args, backend);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "hybgen: error: %s\n", e.what());
  }
  SlepcFinalize();
  MPI_Finalize();
  return status;
}

}  // namespace hybgen::rt
