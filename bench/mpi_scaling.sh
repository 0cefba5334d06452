#!/usr/bin/env bash
# Strong and weak scaling of the MPI backend (docs/distributed.md) for every method on the
# 3-D SIR model (models/sir_3d.model) and the 5-D GL2 system (models/gl2.model).
#   strong: the same run on 1 and 2 ranks, one thread each (so only MPI is parallel);
#           efficiency = T1 / (2 T2);
#   weak:   2 ranks on twice the work (grid nodes, or particles); efficiency = T1 / T2.
# Per run: the solve time (summary.json seconds.solve), the largest rank's peak resident
# size, and for transfer/invariant the matrix bytes on the largest rank and the ghost
# entries a mat-vec receives (summed over the ranks: the communication per step).
# Needs build/bin/hybgen built with the MPI backend (scripts/setup.sh --mpi). Prints a
# Markdown table; takes about 10 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export HYBGEN_CACHE="$tmp/cache" OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export HYBGEN_MPIEXEC=${HYBGEN_MPIEXEC:-"mpiexec --oversubscribe"}
hybgen=build/bin/hybgen

run() {  # run OUT ARGS...: one run, its figures as "solve peak_MB matrix_MB ghosts"
  local out=$tmp/$1; shift
  rm -rf "$out"
  $hybgen run "$@" --set threads=1 --set outputs=netcdf -q --out "$out" >/dev/null
  python3 - "$out/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
op = s.get("transfer") or s.get("invariant") or {}
print(f"{s['seconds']['solve']:.3f} {s['peak_memory_bytes_per_rank'] / 1e6:.0f} "
      f"{op.get('matrix_bytes_per_rank', 0) / 1e6:.1f} {op.get('ghost_entries', 0)}")
PY
}

printf '| model | method | work | ranks | solve s | efficiency | peak MB/rank | matrix MB/rank | ghosts/step |\n'
printf '|---|---|---|---|---|---|---|---|---|\n'
for case in "sir_3d 41x41x41 41x41x82 --set t_end=2 --set dt=0.5" \
            "gl2 11x11x11x11x11 11x11x11x11x22 --set t_end=0.5 --set dt=0.5"; do
  read -r model grid1 grid2 rest <<<"$case"
  for method in characteristics transfer invariant particles; do
    extra=(--set "method=$method")
    if [[ $method == particles ]]; then
      w1=(--set grid="$grid1" --set particles=200000); w2=(--set grid="$grid1" --set particles=400000)
      work1="2e5 particles"; work2="4e5 particles"
    else
      w1=(--set grid="$grid1"); w2=(--set grid="$grid2"); work1=$grid1; work2=$grid2
    fi
    # shellcheck disable=SC2086
    read -r t1 p1 m1 g1 <<<"$(run a models/$model.model "${extra[@]}" "${w1[@]}" $rest)"
    # shellcheck disable=SC2086
    read -r t2 p2 m2 g2 <<<"$(run b models/$model.model "${extra[@]}" "${w1[@]}" $rest --ranks 2)"
    # shellcheck disable=SC2086
    read -r t3 p3 m3 g3 <<<"$(run c models/$model.model "${extra[@]}" "${w2[@]}" $rest --ranks 2)"
    python3 - "$model" "$method" "$work1" "$work2" "$t1 $p1 $m1 $g1" "$t2 $p2 $m2 $g2" "$t3 $p3 $m3 $g3" <<'PY'
import sys
model, method, work1, work2 = sys.argv[1:5]
(t1, p1, m1, g1), (t2, p2, m2, g2), (t3, p3, m3, g3) = (a.split() for a in sys.argv[5:8])
t1, t2, t3 = float(t1), float(t2), float(t3)
print(f"| {model} | {method} | {work1} | 1 | {t1:.2f} | | {p1} | {m1} | {g1} |")
print(f"| | | {work1} | 2 | {t2:.2f} | strong {t1 / (2 * t2):.2f} | {p2} | {m2} | {g2} |")
print(f"| | | {work2} | 2 | {t3:.2f} | weak {t1 / t3:.2f} | {p3} | {m3} | {g3} |")
PY
  done
done
echo "($(nproc) cores, $(date -u +%Y-%m-%d); one thread per rank)"
