# `cmake --install build --prefix P` installs what `hybgen run` needs anywhere, and a CMake
# package for C++ users (docs/install.md):
#   P/bin/hybgen
#   P/include/hybgen/rt/...        the runtime's headers (the generated runners include them)
#   P/lib/libhybgen_runner.a       the runtime compiled for 1..6 states (runners link it)
#   P/lib/libhybgen_numerics.a     the eigen-solvers and almost-invariant sets (runners link it)
#   P/lib/libhybgen_io.a           the writers (run.nc, pictures, arrays)
#   P/lib/libhybgen_mpi.a          the MPI backend, when built (runners with backend=mpi)
#   P/lib/cmake/hybgen/            hybgenConfig.cmake: find_package(hybgen) gives hybgen::rt,
#                                  hybgen::numerics, hybgen::io and hybgen::runner
#   P/lib/python3.X/dist-packages/hybgen/
#                                  the Python package (python/hybgen): hybgen.run and
#                                  hybgen.sweep call P/bin/hybgen and open its outputs
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
set_target_properties(hybgen_numerics PROPERTIES EXPORT_NAME numerics)
set_target_properties(hybgen_runner PROPERTIES EXPORT_NAME runner)
install(TARGETS hybgen_rt hybgen_numerics hybgen_io hybgen_runner EXPORT hybgenTargets
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

# The Python package, where Debian's python3 looks without PYTHONPATH when P is /usr/local or
# /usr (its sys.path has /usr/local/lib/python3.X/dist-packages and /usr/lib/python3.X/...).
# Plain `lib`, not CMAKE_INSTALL_LIBDIR: pure-Python packages live there even where the
# libraries go to lib64 or lib/<multiarch> (GNUInstallDirs' choice for P = /usr on Debian).
# Other distributions look in site-packages: set HYBGEN_INSTALL_PYTHONDIR. Without an
# interpreter the package is skipped; hybgen itself does not need Python.
find_package(Python3 COMPONENTS Interpreter)
if(NOT Python3_Interpreter_FOUND)
  message(STATUS "hybgen: no Python 3 interpreter found; the Python package (python/hybgen) "
                 "will not be installed")
  return()
endif()
set(HYBGEN_INSTALL_PYTHONDIR
    "lib/python${Python3_VERSION_MAJOR}.${Python3_VERSION_MINOR}/dist-packages"
    CACHE STRING "Where `cmake --install` puts the Python package (relative: to the prefix)")
# _install.py: the path from the installed package to bin/hybgen, relative so that the
# prefix can move (`cmake --install --prefix`); python/hybgen/__init__.py, find_exe, reads it.
# An absolute HYBGEN_INSTALL_PYTHONDIR or CMAKE_INSTALL_BINDIR holds for the configured prefix.
foreach(dir HYBGEN_INSTALL_PYTHONDIR CMAKE_INSTALL_BINDIR)
  if(IS_ABSOLUTE "${${dir}}")
    set(_full_${dir} "${${dir}}")
  else()
    set(_full_${dir} "${CMAKE_INSTALL_PREFIX}/${${dir}}")
  endif()
endforeach()
file(RELATIVE_PATH _hybgen_exe_from_package "${_full_HYBGEN_INSTALL_PYTHONDIR}/hybgen"
     "${_full_CMAKE_INSTALL_BINDIR}/hybgen")
file(CONFIGURE OUTPUT ${PROJECT_BINARY_DIR}/python/_install.py @ONLY CONTENT [[
# Written by cmake/HybgenInstall.cmake: the hybgen beside this package.
hybgen_exe = "@_hybgen_exe_from_package@"
]])
install(DIRECTORY python/hybgen DESTINATION ${HYBGEN_INSTALL_PYTHONDIR}
        FILES_MATCHING PATTERN "*.py" PATTERN "__pycache__" EXCLUDE)
install(FILES ${PROJECT_BINARY_DIR}/python/_install.py
        DESTINATION ${HYBGEN_INSTALL_PYTHONDIR}/hybgen)
