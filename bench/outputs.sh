#!/usr/bin/env bash
# What writing a run's outputs costs against solving it (runtime/src/io/run_outputs.cpp):
# the paper's configuration (models/bouncing_ball.model: 75 x 75, 51 frames), the runner
# cached, for each choice of `outputs`: the solve and the budget (summary.json), the
# writing (summary.json's `output`) and `hybgen run` end to end (wall clock), median of 5.
# Needs build/bin/hybgen (scripts/setup.sh). Uses a fresh cache in a temporary directory.
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export HYBGEN_CACHE="$tmp/cache"
hybgen=build/bin/hybgen
$hybgen build models/bouncing_ball.model >/dev/null 2>&1  # warm the cache
printf '%-28s %9s %9s %9s %11s %8s\n' outputs solve budget output end-to-end files
for outputs in default netcdf png pdf gif html npy netcdf+png+pdf+gif+html+svg+npy+vti; do
  set_outputs=()
  [[ $outputs == default ]] || set_outputs=(--set "outputs=$outputs")
  rows=()
  for _ in 1 2 3 4 5; do
    rm -rf "$tmp/out"
    t0=$(date +%s.%N)
    $hybgen run models/bouncing_ball.model "${set_outputs[@]}" --out "$tmp/out" -q >/dev/null
    t1=$(date +%s.%N)
    rows+=("$(python3 -c "
import json; s = json.load(open('$tmp/out/summary.json'))['seconds']
print(f\"{s['solve']:.3f} {s['budget']:.3f} {s['output']:.3f} {$t1 - $t0:.3f}\")")")
  done
  files=$(find "$tmp/out" -type f | wc -l)
  python3 - "$outputs" "$files" "${rows[@]}" <<'PY'
import statistics, sys
name, files, rows = sys.argv[1], sys.argv[2], [list(map(float, r.split())) for r in sys.argv[3:]]
med = [statistics.median(c) for c in zip(*rows)]
print(f"{name:28s} {med[0]:9.3f} {med[1]:9.3f} {med[2]:9.3f} {med[3]:11.3f} {files:>8s}")
PY
done
echo "(seconds, median of 5; $(nproc) cores; $(date -u +%Y-%m-%d))"
