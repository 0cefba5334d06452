#!/usr/bin/env bash
# CI's hardening stage (issue 5), after the README's test command:
#  1. the test suite under AddressSanitizer + UndefinedBehaviorSanitizer
#     (CMake preset `asan`: hybgen, the tests and every generated runner the
#     tests build), in build-asan/, less four end-to-end runs (see below);
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
# All tests but four end-to-end runs that each compile one more sanitized runner to check a
# number: their runtime paths (transfer, invariant, constant resets) run sanitized in
# tests/rt and tests/validation, and they run unsanitized in the first stage.
# The differential test of derive runs 20 random models here instead of 300 (GiNaC under ASan:
# 300 took 516 s; tests/gen/test_derive_random.cpp, HYBGEN_RANDOM_MODELS).
HYBGEN_RANDOM_MODELS=20 ctest --preset asan --output-on-failure \
  -E "^Cli\.(TransferNeverCreatesMass|ThermostatInvariantDensity|SawtoothHasNoInverse|IntegrateAndFireInvariant)"
echo "ci-hardening: fuzz smoke" >&2
fuzz/run.sh smoke
echo "ci-hardening: done in $((SECONDS - start)) s" >&2
