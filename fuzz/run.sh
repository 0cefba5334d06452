#!/usr/bin/env bash
# Build and run hybgen's libFuzzer harnesses (clang 14 from Debian: clang,
# libclang-rt-14-dev; scripts/setup.sh installs them).
#
#   fuzz/run.sh build               configure + build build-fuzz/ (HYBGEN_FUZZ=ON)
#   fuzz/run.sh smoke               build, then ~30 s (CI): both harnesses side
#                                   by side for SMOKE_SECONDS (default 25) from
#                                   the seeds
#   fuzz/run.sh campaign SECONDS [HARNESS]
#                                   build, then fuzz HARNESS (default
#                                   fuzz_frontend) for SECONDS with JOBS parallel
#                                   workers (default: nproc); the corpus grows in
#                                   build-fuzz/corpus/HARNESS across campaigns
#                                   (FUZZ_CORPUS_DIR=DIR: grow DIR instead; an
#                                   empty DIR starts again from the seeds)
#   fuzz/run.sh repro FILE... [HARNESS]
#                                   run inputs once (default fuzz_frontend)
#
# Every run uses -timeout=10 (a hang is a finding), -rss_limit_mb=2048 and
# leak detection; crash/hang/leak inputs land in build-fuzz/findings/. Each
# finding becomes a regression test in tests/gen/test_fuzz_regressions.cpp.
# Resource caps of fuzz_frontend: fuzz/frontend_pipeline.hpp.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=${FUZZ_BUILD_DIR:-$ROOT/build-fuzz}
CXX_FUZZ=${CXX_FUZZ:-clang++-14}
command -v "$CXX_FUZZ" >/dev/null || CXX_FUZZ=clang++

build() {
  cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_CXX_COMPILER="$CXX_FUZZ" \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHYBGEN_FUZZ=ON -DHYBGEN_WERROR=ON \
    -DHYBGEN_BUILD_TESTS=OFF -DHYBGEN_BUILD_BENCH=OFF >/dev/null
  cmake --build "$BUILD" -j"$(nproc)" --target fuzz_frontend fuzz_overrides
}

dict_of() { [[ $1 == fuzz_overrides ]] && echo "$ROOT/fuzz/overrides.dict" || echo "$ROOT/fuzz/model.dict"; }

# Seed corpus (read-only directories) of a harness: seeds and past findings.
seeds_of() {
  local d dirs
  if [[ $1 == fuzz_overrides ]]; then
    dirs=("$ROOT/fuzz/seeds/overrides" "$ROOT/fuzz/regressions/overrides")
  else
    dirs=("$ROOT/models" "$ROOT/fuzz/seeds/frontend" "$ROOT/fuzz/regressions/frontend")
  fi
  for d in "${dirs[@]}"; do [[ -d $d ]] && echo "$d"; done
  return 0
}

# fuzz HARNESS SECONDS CORPUS_DIR [extra libFuzzer flags...]
fuzz() {
  local h=$1 secs=$2 corpus=$3
  shift 3
  mkdir -p "$corpus" "$BUILD/findings/$h"
  # shellcheck disable=SC2046
  "$BUILD/fuzz/$h" "$corpus" $(seeds_of "$h") \
    -dict="$(dict_of "$h")" -max_len=4096 -timeout=10 -rss_limit_mb=2048 \
    -detect_leaks=1 -max_total_time="$secs" -print_final_stats=1 \
    -artifact_prefix="$BUILD/findings/$h/" "$@"
}

case "${1:-}" in
  build)
    build
    ;;
  smoke)
    build
    secs=${SMOKE_SECONDS:-25}
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    # The two harnesses side by side, one core each (each is one process).
    declare -A pid
    for h in fuzz_frontend fuzz_overrides; do
      echo "fuzz smoke: $h for ${secs} s" >&2
      fuzz "$h" "$secs" "$tmp/$h" 2>"$tmp/$h.log" &
      pid[$h]=$!
    done
    failed=0
    for h in fuzz_frontend fuzz_overrides; do
      if wait "${pid[$h]}"; then
        grep -E "stat::number_of_executed_units|Done [0-9]+ runs" "$tmp/$h.log" | sed "s/^/$h: /" >&2 || true
      else
        echo "fuzz smoke: $h failed:" >&2
        tail -n 60 "$tmp/$h.log" >&2
        failed=1
      fi
    done
    ((failed == 0)) || exit 1
    ;;
  campaign)
    secs=${2:?usage: fuzz/run.sh campaign SECONDS [HARNESS]}
    h=${3:-fuzz_frontend}
    build
    jobs=${JOBS:-$(nproc)}
    corpus=${FUZZ_CORPUS_DIR:-$BUILD/corpus/$h}
    if ((jobs > 1)); then
      fuzz "$h" "$secs" "$corpus" -fork="$jobs" -ignore_crashes=1 -ignore_timeouts=1 \
        -ignore_ooms=1
    else
      fuzz "$h" "$secs" "$corpus"
    fi
    echo "findings (if any): $BUILD/findings/$h/" >&2
    ls -l "$BUILD/findings/$h/" >&2
    ;;
  repro)
    shift
    h=fuzz_frontend
    files=()
    for a in "$@"; do
      if [[ $a == fuzz_* ]]; then h=$a; else files+=("$a"); fi
    done
    build
    "$BUILD/fuzz/$h" -timeout=10 -rss_limit_mb=2048 -detect_leaks=1 "${files[@]}"
    ;;
  *)
    sed -n '2,21p' "$0" >&2
    exit 2
    ;;
esac
