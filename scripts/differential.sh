#!/usr/bin/env bash
# The density-level differential campaign (tests/validation/test_differential.cpp):
#   scripts/differential.sh N [FIRST_SEED]
# runs N random models (tests/support/random_run_model.hpp) through `hybgen run` and compares
# every node with an independent backward tracer (tests/support/independent_tracer.hpp). One
# line per model and per disagreement; the last line is `N models, K disagreements`. Exit 0
# when K = 0. Needs the build of the README's test command (build/, scripts/setup.sh --tests);
# BUILD_DIR=DIR uses another.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ $# -lt 1 || ! "$1" =~ ^[0-9]+$ || "$1" -lt 1 ]]; then
  echo "usage: scripts/differential.sh N [FIRST_SEED]   (N models from FIRST_SEED, default 1)" >&2
  exit 2
fi
first=${2:-1}
if [[ ! "$first" =~ ^[0-9]+$ ]]; then
  echo "scripts/differential.sh: FIRST_SEED must be a non-negative integer, not '$first'" >&2
  exit 2
fi
build=${BUILD_DIR:-build}
exe="$build/tests/validation_test_differential"
if [[ ! -x "$exe" ]]; then
  echo "scripts/differential.sh: $exe not found: build it first (scripts/setup.sh --tests, or" \
    "cmake --build $build --target validation_test_differential hybgen)" >&2
  exit 2
fi
# gtest's own lines are left out; the verdict is the test's exit status.
set +e
HYBGEN_DIFFERENTIAL_MODELS="$1" HYBGEN_DIFFERENTIAL_SEED="$first" "$exe" \
  --gtest_filter='Differential.RandomModelsAgreeWithAnIndependentTracer' --gtest_brief=1 | grep --line-buffered -v '^\(Running main\|\[\)'
status=${PIPESTATUS[0]}
exit "$status"
