#!/usr/bin/env bash
# Install what is missing (Debian 12 packages only) and build into build/: hybgen and its
# runtime library (what `hybgen run` needs), or with --tests everything (tests, benchmarks).
# --mpi adds the distributed backend (MPI, PETSc, SLEPc, parallel NetCDF: --set backend=mpi, --ranks N;
# docs/distributed.md); --tests includes it, since CI runs its agreement tests.
# Environment: BUILD_DIR (default build), HYBGEN_WERROR (ON in CI).
set -euo pipefail
targets=(--target hybgen)
mpi=OFF
for arg in "$@"; do
  case "$arg" in
    --tests) targets=(); mpi=ON ;;
    --mpi) mpi=ON ;;
    *) echo "usage: scripts/setup.sh [--tests] [--mpi]" >&2; exit 2 ;;
  esac
done
cd "$(dirname "$0")/.."

# What hybgen and its runtime build with (every run needs these).
packages=(build-essential cmake ninja-build pkg-config libginac-dev libcln-dev libeigen3-dev
          libspectra-dev libcli11-dev nlohmann-json3-dev libssl-dev
          libnetcdf-dev                  # run.nc (runtime/src/io/netcdf.cpp)
          libcairo2-dev fonts-dejavu-core  # pictures (runtime/src/io/figures.cpp)
          libpng-dev libgif-dev          # frames (figures.cpp) and animation.gif (animation.cpp)
          libjs-katex)                   # report.html's equations (runtime/src/io/report.cpp)
# The distributed backend (--mpi, and --tests): Open MPI with its launcher, PETSc, SLEPc,
# and parallel NetCDF (run.nc written by every rank).
if [[ $mpi == ON ]]; then
  packages+=(libopenmpi-dev openmpi-bin petsc-dev slepc-dev libnetcdf-mpi-dev)
fi
# What the tests, the benchmarks and CI need besides (--tests).
if ((${#targets[@]} == 0)); then
  packages+=(libgtest-dev libbenchmark-dev
             clang-format                   # scripts/check-format.sh (CI)
             python3-numpy                  # an independent reader of .npy (tests/rt/test_output.cpp)
             python3-xarray python3-netcdf4 # an independent reader of run.nc (tests/e2e/test_run_nc.cpp)
             texlive-latex-base             # pdflatex: derive --format latex --standalone (tests/e2e/test_latex.cpp)
             chromium                       # headless: report.html (tests/e2e/test_report.cpp)
             clang libclang-rt-14-dev)      # clang + compiler-rt: libFuzzer harnesses (fuzz/run.sh)
fi
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
# Without --tests the test and benchmark packages may be missing: do not configure them.
EXTRAS=$( ((${#targets[@]} == 0)) && echo ON || echo OFF)
# --mpi requires the backend; otherwise it is built when its packages are there (AUTO).
MPI_OPTION=$([[ $mpi == ON ]] && echo ON || echo AUTO)
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release -DHYBGEN_WERROR="$WERROR" \
  -DHYBGEN_BUILD_TESTS="$EXTRAS" -DHYBGEN_BUILD_BENCH="$EXTRAS" -DHYBGEN_MPI="$MPI_OPTION" >/dev/null
cmake --build "$BUILD_DIR" -j"$(nproc)" "${targets[@]}"
