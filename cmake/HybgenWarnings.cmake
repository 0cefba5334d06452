# hybgen::warnings — an interface target that carries the project's warning
# flags; link it PRIVATE to every target we build from our own sources.
add_library(hybgen_warnings INTERFACE)
add_library(hybgen::warnings ALIAS hybgen_warnings)
target_compile_options(hybgen_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  -Wnon-virtual-dtor -Wold-style-cast -Wcast-align -Woverloaded-virtual
  -Wnull-dereference -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough)
if(HYBGEN_WERROR)
  target_compile_options(hybgen_warnings INTERFACE -Werror)
  # GCC 12.0-12.2 report the operands its own AVX-512 intrinsics leave undefined on purpose
  # (_mm256_undefined_pd in avx512fintrin.h, reached through Eigen's reductions) as
  # uninitialized wherever they are inlined into our code: under -march=native on a machine
  # with AVX-512 a test calling Eigen's normalize() failed to build. Warnings there, not errors
  # (runtime/include/hybgen/rt/core/sparse.hpp silences them around Eigen's own headers).
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 12.3)
    target_compile_options(hybgen_warnings INTERFACE -Wno-error=maybe-uninitialized
                                                     -Wno-error=uninitialized)
  endif()
endif()
