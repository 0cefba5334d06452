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
if(HYBGEN_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(HYBGEN_BUILD_BENCH)
  find_package(benchmark REQUIRED)
endif()
