// The runner's main program instantiated for table models of one state dimension,
// HYBGEN_TABLE_DIM (runtime/CMakeLists.txt compiles this file once per dimension, so the
// dimensions build in parallel). See hybgen/rt/table_model.hpp.

#include "hybgen/rt/runner.hpp"
#include "hybgen/rt/table_model.hpp"

#ifndef HYBGEN_TABLE_DIM
#error "HYBGEN_TABLE_DIM must be defined by the build"
#endif

namespace hybgen::rt {

template <>
int table_runner_main_dim<HYBGEN_TABLE_DIM>(const ModelTable& table, int argc, char** argv,
                                            const Backend& backend) {
  using M = TableModel<HYBGEN_TABLE_DIM>;
  static_assert(HybridModel<M>);
  M::install(table);
  return runner_main<M>(argc, argv, backend);
}

}  // namespace hybgen::rt
