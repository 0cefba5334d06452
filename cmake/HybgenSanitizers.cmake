# Hardening builds; see docs/hardening.md.
#
# HYBGEN_SANITIZE=ON: AddressSanitizer + UndefinedBehaviorSanitizer on every
#   target (compile and link), and — through HYBGEN_RUNNER_EXTRA_FLAGS, which
#   generator/CMakeLists.txt passes to build.cpp's runner_flags() — on every
#   runner that `hybgen build` compiles, so generated kernels run under the
#   sanitizers too. Any finding aborts (-fno-sanitize-recover=all).
#
# HYBGEN_FUZZ=ON (clang only): instrument every target for libFuzzer
#   (-fsanitize=fuzzer-no-link,address,undefined) and build the harnesses of
#   fuzz/ (fuzz/run.sh does all of it).
option(HYBGEN_SANITIZE "Build with AddressSanitizer + UndefinedBehaviorSanitizer (runners too)" OFF)
option(HYBGEN_FUZZ "Build the libFuzzer harnesses of fuzz/ (requires clang)" OFF)

if(HYBGEN_SANITIZE AND HYBGEN_FUZZ)
  message(FATAL_ERROR "HYBGEN_SANITIZE and HYBGEN_FUZZ are separate builds; enable one")
endif()

# UBSan without three of its checks, whose findings ASan makes already, nearly, and which were
# most of the sanitized build's time: `null` (a null dereference faults, and ASan reports the
# fault with its stack; a member access through null that loads nothing goes unseen),
# `object-size` (an access past an object is ASan's shadow-memory check) and `alignment`
# (x86-64 loads misaligned scalars; Eigen's aligned types are allocated aligned).
# GCC 12, -O1 -g1, tests/validation/test_fold.cpp, alone: 65 s with all of UBSan, 34 s
# without these three, 26 s under ASan alone (docs/hardening.md). float-cast-overflow, which
# GCC's -fsanitize=undefined leaves out, is added: a NaN or huge double cast to a grid index is the
# runtime's likeliest undefined behaviour (the fuzz build keeps all of UBSan on the front end).
set(HYBGEN_SANITIZER_FLAGS -fsanitize=address,undefined,float-cast-overflow
                           -fno-sanitize=null,alignment,object-size -fno-omit-frame-pointer
                           -fno-sanitize-recover=all)
# Extra flags for generated runners (a string; empty unless sanitizing).
set(HYBGEN_RUNNER_EXTRA_FLAGS "")

if(HYBGEN_SANITIZE)
  add_compile_options(${HYBGEN_SANITIZER_FLAGS})
  add_link_options(${HYBGEN_SANITIZER_FLAGS})
  string(JOIN " " HYBGEN_RUNNER_EXTRA_FLAGS ${HYBGEN_SANITIZER_FLAGS})
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    # GCC's manual (-fsanitize=address): "sanitizers tend to increase the rate
    # of false positive warnings ... We recommend against combining -Werror and
    # [the use of] sanitizers." GCC 12 + ASan reports -Warray-bounds in the
    # dead >16-element branch of std::sort on a 2-element std::array
    # (runtime/include/hybgen/rt/core/ode.hpp, EventLocator::scan), in the bench and
    # in every runner. The flow-sensitive warnings stay errors in the normal
    # -Werror build; here they are off or only warnings (ASan checks bounds at
    # run time anyway). Runners are compiled by the same compiler.
    add_compile_options(-Wno-array-bounds -Wno-error=maybe-uninitialized
                        -Wno-error=null-dereference -Wno-error=stringop-overflow)
    string(APPEND HYBGEN_RUNNER_EXTRA_FLAGS " -Wno-array-bounds")
  endif()
endif()

if(HYBGEN_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "HYBGEN_FUZZ needs clang (e.g. -DCMAKE_CXX_COMPILER=clang++)")
  endif()
  # Coverage instrumentation for libFuzzer on every target; only the harness
  # executables link libFuzzer itself (-fsanitize=fuzzer, fuzz/CMakeLists.txt).
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=all)
  add_link_options(-fsanitize=address,undefined)
endif()

# Sanitizer defaults compiled into every executable we link (tests, hybgen,
# fuzzers), so that a sanitized binary behaves the same under ctest, under
# gtest_discover_tests at build time, under libFuzzer and by hand. The
# environment (ASAN_OPTIONS, UBSAN_OPTIONS, LSAN_OPTIONS) still overrides them.
#
# Leak suppressions — third-party leaks only, never hybgen's:
#  - libcln.so: CLN's static initialisers allocate objects that are never
#    freed (cl_prin_globals_init_helper -> cl_make_heap_string, 26 bytes,
#    reported by every program that links GiNaC, even `--gtest_list_tests`).
#    CLN is built without frame pointers, so the fast unwinder's stack of such
#    an allocation ends inside libcln.so and the module is all a suppression
#    can match. It hides only memory that CLN itself allocated: a GiNaC object
#    leaked by hybgen is allocated by libginac or by our code and is reported.
#  - GiNaC 1.8.6 is not exception-safe when evaluation hits a pole: the
#    temporaries it has allocated so far are never freed when it throws
#    (e.g. `(p^2/(2*m)).subs(m == 0)` throws "power::eval(): division by zero"
#    and leaks 40 bytes per term from mul::combine_ex_with_coeff_to_pair —
#    reproduced by a 10-line program using GiNaC alone). hybgen evaluates at
#    sample points and catches such errors by design (derive.cpp's Evaluator,
#    is_identically_zero), so each allocation site inside GiNaC that the
#    fuzzer showed leaking on a throw is listed by its function name. A
#    GiNaC object leaked by hybgen's own code is still reported: the leaked
#    block that holds it is allocated by our code, not by these functions.
#    GiNaC::power::subs: `(-2*pow(x, y)).subs(lst{x == 0, y == -1})` throws
#    from inside subs() and leaks the 40-byte power it had allocated (GiNaC
#    alone reproduces it); hybgen meets it when it evaluates a flow with x^y
#    at sample points on a guard x*y = 0 (fuzz/regressions/frontend/
#    leak-ginac-pole-in-power-subs.model, found by the session-4 campaign).
# Runners never link GiNaC/CLN and run with no suppressions at all.
set(HYBGEN_LSAN_SUPPRESSIONS
    "leak:libcln.so"
    "leak:GiNaC::mul::combine_ex_with_coeff_to_pair"
    "leak:GiNaC::power::subs")
string(JOIN "\\n" HYBGEN_LSAN_SUPPRESSIONS_C ${HYBGEN_LSAN_SUPPRESSIONS})
string(JOIN "\n" HYBGEN_LSAN_SUPPRESSIONS_FILE ${HYBGEN_LSAN_SUPPRESSIONS})
set(HYBGEN_ASAN_DEFAULTS "detect_leaks=1:check_initialization_order=1")
set(HYBGEN_UBSAN_DEFAULTS "print_stacktrace=1:halt_on_error=1")
# print_suppressions=0: LSan would otherwise print its "Suppressions used"
# table to stderr at every exit, before stdout is flushed, which garbles the
# CLI output that the end-to-end tests parse (`derive --format json`).
set(HYBGEN_LSAN_DEFAULTS "print_suppressions=0")

if(HYBGEN_SANITIZE OR HYBGEN_FUZZ)
  # The same suppressions as a file, for LSAN_OPTIONS=suppressions=<file>.
  file(WRITE ${PROJECT_BINARY_DIR}/hybgen-lsan.supp "${HYBGEN_LSAN_SUPPRESSIONS_FILE}\n")
  file(CONFIGURE OUTPUT ${PROJECT_BINARY_DIR}/hybgen_sanitizer_defaults.cpp CONTENT [=[
// Generated by cmake/HybgenSanitizers.cmake: sanitizer defaults of hybgen's executables.
extern "C" {
__attribute__((visibility("default"), used)) const char* __asan_default_options();
__attribute__((visibility("default"), used)) const char* __ubsan_default_options();
__attribute__((visibility("default"), used)) const char* __lsan_default_options();
__attribute__((visibility("default"), used)) const char* __lsan_default_suppressions();
const char* __asan_default_options() { return "@HYBGEN_ASAN_DEFAULTS@"; }
const char* __ubsan_default_options() { return "@HYBGEN_UBSAN_DEFAULTS@"; }
const char* __lsan_default_options() { return "@HYBGEN_LSAN_DEFAULTS@"; }
const char* __lsan_default_suppressions() { return "@HYBGEN_LSAN_SUPPRESSIONS_C@\n"; }
}
]=] @ONLY)
  add_library(hybgen_sanitizer_defaults OBJECT ${PROJECT_BINARY_DIR}/hybgen_sanitizer_defaults.cpp)
  # Every target created from here on (in this directory and below) links it.
  link_libraries(hybgen_sanitizer_defaults)
endif()
