#!/usr/bin/env bash
# CI's hardening stage (issue 5), after the README's test command:
#  1. the whole test suite under AddressSanitizer + UndefinedBehaviorSanitizer
#     (CMake preset `asan`: hybgen, the tests and every generated runner the
#     tests build), in build-asan/;
#  2. a fuzz smoke run of about a minute (fuzz/run.sh smoke), in build-fuzz/.
# Any sanitizer report fails a test (halt_on_error), any fuzzer finding fails
# the smoke run. Set HYBGEN_SKIP_HARDENING=1 to skip both (local use).
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ "${HYBGEN_SKIP_HARDENING:-}" == 1 ]]; then
  echo "ci-hardening: skipped (HYBGEN_SKIP_HARDENING=1)" >&2
  exit 0
fi
start=$SECONDS
echo "ci-hardening: ASan + UBSan build (preset asan)" >&2
cmake --preset asan >/dev/null
cmake --build --preset asan -j"$(nproc)"
echo "ci-hardening: test suite under ASan + UBSan" >&2
ctest --preset asan --output-on-failure
echo "ci-hardening: fuzz smoke" >&2
fuzz/run.sh smoke
echo "ci-hardening: done in $((SECONDS - start)) s" >&2
