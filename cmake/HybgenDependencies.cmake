# Every dependency comes from a Debian package; nothing is downloaded.
find_package(PkgConfig REQUIRED)
pkg_check_modules(GINAC REQUIRED IMPORTED_TARGET ginac>=1.8)
# run.nc (runtime/src/io/netcdf.cpp): NetCDF-4 through Debian's libnetcdf.
pkg_check_modules(NETCDF REQUIRED IMPORTED_TARGET netcdf>=4.6)
# The pictures (runtime/src/io/figures.cpp): PNG, PDF and SVG from one drawing.
pkg_check_modules(CAIRO REQUIRED IMPORTED_TARGET cairo>=1.16)
# Cairo's fonts (figures.cpp frees fontconfig's caches at exit under AddressSanitizer).
pkg_check_modules(FONTCONFIG REQUIRED IMPORTED_TARGET fontconfig)
# The frame pictures' fast PNG encoder (runtime/src/io/figures.cpp, write_png).
find_package(PNG REQUIRED)
# animation.gif (runtime/src/io/animation.cpp): giflib (Debian ships no pkg-config file).
find_package(GIF 5 REQUIRED)
find_package(OpenMP REQUIRED COMPONENTS CXX)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(OpenSSL REQUIRED COMPONENTS Crypto)
# Sparse transfer operators (runtime/transfer.hpp) and their spectra (invariant.hpp).
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(Spectra REQUIRED)
# The distributed backend (`--set backend=mpi`, runtime/src/mpi/): MPI, PETSc and SLEPc
# from Debian's packages (libopenmpi-dev, petsc-dev, slepc-dev; scripts/setup.sh --mpi), and
# parallel NetCDF (libnetcdf-mpi-dev: run.nc written by every rank, runtime/src/mpi/parallel_io.cpp).
# AUTO builds it when all four are found; ON requires them; OFF leaves it out.
set(HYBGEN_MPI AUTO CACHE STRING "Build the MPI/PETSc/SLEPc backend: AUTO, ON or OFF")
set_property(CACHE HYBGEN_MPI PROPERTY STRINGS AUTO ON OFF)
set(HYBGEN_WITH_MPI OFF)
if(NOT HYBGEN_MPI STREQUAL "OFF")
  set(_mpi_required "")
  if(HYBGEN_MPI STREQUAL "ON")
    set(_mpi_required REQUIRED)
  endif()
  set(MPI_CXX_SKIP_MPICXX ON)  # the C API only: no libmpi_cxx
  find_package(MPI COMPONENTS CXX ${_mpi_required})
  pkg_check_modules(PETSC ${_mpi_required} IMPORTED_TARGET PETSc>=3.18)
  pkg_check_modules(SLEPC ${_mpi_required} IMPORTED_TARGET SLEPc>=3.18)
  # Debian's netcdf-mpi.pc names the serial headers' directory; netcdf_par.h is under its
  # prefix (/usr/lib/<arch>/netcdf/mpi/include).
  pkg_check_modules(NETCDF_MPI ${_mpi_required} netcdf-mpi>=4.7.4)
  if(NETCDF_MPI_FOUND)
    pkg_get_variable(_netcdf_mpi_prefix netcdf-mpi prefix)
    find_path(NETCDF_MPI_INCLUDE_DIR netcdf_par.h PATHS "${_netcdf_mpi_prefix}/include" NO_DEFAULT_PATH)
  endif()
  if(MPI_CXX_FOUND AND PETSC_FOUND AND SLEPC_FOUND AND NETCDF_MPI_FOUND AND NETCDF_MPI_INCLUDE_DIR)
    set(HYBGEN_WITH_MPI ON)
  elseif(HYBGEN_MPI STREQUAL "ON")
    message(FATAL_ERROR "HYBGEN_MPI=ON: netcdf_par.h of libnetcdf-mpi-dev not found")
  endif()
endif()
message(STATUS "hybgen: the MPI backend (backend=mpi): ${HYBGEN_WITH_MPI}")
if(HYBGEN_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(HYBGEN_BUILD_BENCH)
  find_package(benchmark REQUIRED)
endif()
