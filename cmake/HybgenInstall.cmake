# `cmake --install build --prefix P` installs what `hybgen run` needs anywhere, and a CMake
# package for C++ users (docs/install.md):
#   P/bin/hybgen
#   P/include/hybgen/rt/...        the runtime's headers (the generated runners include them)
#   P/lib/libhybgen_runner.a       the runtime compiled for 1..6 states (runners link it)
#   P/lib/libhybgen_io.a           the writers (run.nc, pictures, arrays)
#   P/lib/libhybgen_mpi.a          the MPI backend, when built (runners with backend=mpi)
#   P/lib/cmake/hybgen/            hybgenConfig.cmake: find_package(hybgen) gives hybgen::rt,
#                                  hybgen::io and hybgen::runner
# An installed hybgen finds its runtime beside itself (generator/src/build.cpp,
# runtime_location). Sanitized and fuzzing builds (cmake/HybgenSanitizers.cmake) check
# code; they are not installed.
if(HYBGEN_SANITIZE OR HYBGEN_FUZZ)
  return()
endif()
install(TARGETS hybgen RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY runtime/include/hybgen DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
set_target_properties(hybgen_rt PROPERTIES EXPORT_NAME rt)
set_target_properties(hybgen_io PROPERTIES EXPORT_NAME io)
set_target_properties(hybgen_runner PROPERTIES EXPORT_NAME runner)
install(TARGETS hybgen_rt hybgen_io hybgen_runner EXPORT hybgenTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
if(HYBGEN_WITH_MPI)
  # A file beside the others, not an exported target: runners link it by path (build.cpp).
  install(FILES $<TARGET_FILE:hybgen_mpi> DESTINATION ${CMAKE_INSTALL_LIBDIR})
endif()
install(EXPORT hybgenTargets NAMESPACE hybgen:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/hybgen)
include(CMakePackageConfigHelpers)
configure_package_config_file(cmake/hybgenConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/hybgenConfig.cmake
                              INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/hybgen)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/hybgenConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/hybgenConfig.cmake ${PROJECT_BINARY_DIR}/hybgenConfigVersion.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/hybgen)
