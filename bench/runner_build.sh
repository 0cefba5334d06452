#!/usr/bin/env bash
# What a runner costs to build and what the precompiled runtime costs at run time
# (generator/src/build.cpp, runtime/include/hybgen/rt/table_model.hpp): for each model, a
# cold build against the library and one with --inline-runtime (the whole runtime compiled
# with the kernels inlined), then the solve seconds of each method with both runners on the
# same configuration, best of three. Needs build/bin/hybgen (scripts/setup.sh). Uses a fresh
# cache in a temporary directory; takes a few minutes (the inline builds dominate).
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export HYBGEN_CACHE="$tmp/cache"
hybgen=build/bin/hybgen
printf '%-34s %10s %10s\n' "cold build (s)" library inline
seconds() { # wall seconds of "$@", its output discarded
  local t0 t1
  t0=$(date +%s.%N)
  "$@" >/dev/null 2>&1
  t1=$(date +%s.%N)
  python3 -c "print(f'{$t1 - $t0:.1f}')"
}
for model in bouncing_ball sir_3d gl2; do
  printf '%-34s %10s %10s\n' "$model" "$(seconds $hybgen build models/$model.model)" \
    "$(seconds $hybgen build --inline-runtime models/$model.model)"
done
echo
printf '%-34s %10s %10s %8s\n' "solve (s), best of 3" library inline ratio
for spec in "bouncing_ball|characteristics|--set grid=301x301 --set budget=off" \
  "bouncing_ball|transfer|--set grid=151x151" "bouncing_ball|particles|--set particles=2000000" \
  "sir_3d|characteristics|--set budget=off" "sir_3d|transfer|" \
  "gl2|characteristics|--set budget=off" "gl2|particles|"; do
  IFS='|' read -r model method extra <<<"$spec"
  best() {
    local b=1e9
    for _ in 1 2 3; do
      # shellcheck disable=SC2086
      $hybgen run models/$model.model --set method=$method $extra $1 --out "$tmp/out" -q >/dev/null
      s=$(python3 -c "import json;print(json.load(open('$tmp/out/summary.json'))['seconds']['solve'])")
      b=$(python3 -c "print(min($b, $s))")
    done
    echo "$b"
  }
  lib=$(best "")
  inl=$(best --inline-runtime)
  printf '%-34s %10.3f %10.3f %8.2f\n' "$model $method" "$lib" "$inl" \
    "$(python3 -c "print($lib / $inl)")"
done
