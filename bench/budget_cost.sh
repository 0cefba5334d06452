#!/usr/bin/env bash
# The cost of the characteristics mass budget against the solve (README, "Run outputs"): runs
# the shipped 2-D/3-D models and a pendulum at a wall (bench/models/pendulum_wall.model) with
# budget=fast and budget=full and prints solve / budget seconds, whether the budget closes,
# its largest defect and error bar, and the points each cubature traced (volume/faces/atom).
# Needs build/bin/hybgen (scripts/setup.sh); runners are built on first use (cached).
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for spec in "models/bouncing_ball.model|" "models/bouncing_ball.model|--set e=0.8" \
  "models/filippov.model|" "models/sir.model|" "models/sir_3d.model|" \
  "models/chaplygin_energy.model|" "bench/models/pendulum_wall.model|"; do
  model=${spec%%|*}
  extra=${spec#*|}
  for b in fast full; do
    out="$tmp/out"
    rm -rf "$out"
    # shellcheck disable=SC2086
    if ! build/bin/hybgen run "$model" $extra --set budget=$b --out "$out" -q 2>"$tmp/log"; then
      echo "$model $extra budget=$b: failed"
      cat "$tmp/log"
      continue
    fi
    python3 - "$out/summary.json" "$(basename "$model" .model) $extra budget=$b" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
b = s["budget"]
print(f"{sys.argv[2]:36s} solve {s['seconds']['solve']:7.3f} s  budget {s['seconds']['budget']:7.3f} s"
      f"  closes {str(b['closes']):5s} defect {max(abs(x) for x in b['defect']):.1e}"
      f" bar {max(b['defect_error']):.1e}  points {b['volume_points']}/{b['face_points']}/{b['atom_points']}")
PY
  done
done
