// A runner's entry point when built against the library: dispatch on the table's state
// dimension to the instantiation of runner_dim.cpp. See hybgen/rt/table_model.hpp.

#include <cstdio>
#include <utility>

#include "hybgen/rt/core/backend.hpp"
#include "hybgen/rt/exit_codes.hpp"
#include "hybgen/rt/table_model.hpp"

namespace hybgen::rt {

namespace {

template <int... Ns>
int dispatch(std::integer_sequence<int, Ns...>, const ModelTable& table, int argc, char** argv,
             const Backend& backend) {
  int status = exit_status(ExitCode::Internal);
  // Ns are 0-based: dimension Ns + 1.
  ((table.n_state == Ns + 1
        ? (status = table_runner_main_dim<Ns + 1>(table, argc, argv, backend), true)
        : false) ||
   ...);
  return status;
}

}  // namespace

int table_runner_main(const ModelTable& table, int argc, char** argv, const Backend& backend) {
  if (!table_fits(table.n_state, table.n_guard)) {
    std::fprintf(stderr,
                 "hybgen: error: the runtime library runs models of 1 to %d states and at most "
                 "%d guards; '%s' has %d states and %d guards (hybgen build compiles such a "
                 "model with the runtime inlined)\n",
                 kTableMaxState, kTableMaxGuards, table.name, table.n_state, table.n_guard);
    return exit_status(ExitCode::Internal);
  }
  return dispatch(std::make_integer_sequence<int, kTableMaxState>{}, table, argc, argv, backend);
}

int table_runner_main(const ModelTable& table, int argc, char** argv) {
  return table_runner_main(table, argc, argv, serial_backend());
}

}  // namespace hybgen::rt
