#!/usr/bin/env bash
# Install what is missing (Debian 12 packages only) and build into build/: hybgen and its
# runtime library (what `hybgen run` needs), or with --tests everything (tests, benchmarks).
# Environment: BUILD_DIR (default build), HYBGEN_WERROR (ON in CI).
set -euo pipefail
targets=(--target hybgen)
case "${1:-}" in
  "") ;;
  --tests) targets=() ;;
  *) echo "usage: scripts/setup.sh [--tests]" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."

packages=(build-essential cmake ninja-build pkg-config libginac-dev libcln-dev libeigen3-dev
          libspectra-dev libgtest-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev libpng-dev
          libssl-dev
          clang-format   # scripts/check-format.sh (CI)
          python3-numpy  # an independent reader of the .npy outputs (tests/rt/test_output.cpp)
          clang libclang-rt-14-dev)  # clang + compiler-rt: libFuzzer harnesses (fuzz/run.sh)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}" >&2
  SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

BUILD_DIR=${BUILD_DIR:-build}
WERROR=${HYBGEN_WERROR:-$([[ "${CI:-}" == "true" ]] && echo ON || echo OFF)}
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release -DHYBGEN_WERROR="$WERROR" >/dev/null
cmake --build "$BUILD_DIR" -j"$(nproc)" "${targets[@]}"
