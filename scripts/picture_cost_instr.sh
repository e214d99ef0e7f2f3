#!/usr/bin/env bash
# What does the repair picture cost in instructions?  Runs `holefill fill` under
# callgrind (every thread counted) without and with `--picture` on the holed inputs
# scripts/same_outputs.sh caches (hole seed 1 and the natural scans), and prints
# "mesh off on" instruction counts. Deterministic up to the rayon workers' idle
# spinning (a few M), unlike wall or CPU time on a shared 2-core machine.
#
#   scripts/picture_cost_instr.sh BIN [OUT_DIR]     (SKIP: a regex of names to leave out)
set -uo pipefail
if [ $# -lt 1 ]; then
  sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
BIN=$(readlink -f "$1")
OUT=${2:-$(mktemp -d)}
SKIP=${SKIP:-'^$'}
HOLES=${HOLES:-/work/bench-out/same-outputs-holes}
[ -x "$BIN" ] || { echo "$BIN: not an executable" >&2; exit 2; }
[ -d "$HOLES" ] || { echo "$HOLES: no holed inputs (run scripts/same_outputs.sh once)" >&2; exit 2; }
mkdir -p "$OUT"
for d in "$HOLES"/*; do
  n=$(basename "$d")
  case "$n" in *-s2|*-s3) continue ;; esac
  [[ "$n" =~ $SKIP ]] && continue
  for mode in off on; do
    extra=()
    [ "$mode" = on ] && extra=(--picture "$OUT/$n.png")
    valgrind --tool=callgrind --callgrind-out-file="$OUT/$n.$mode.cg" "$BIN" fill "$d/holed.obj" \
      "$OUT/$n.$mode.obj" --report "$OUT/$n.$mode.json" "${extra[@]}" >/dev/null 2>"$OUT/$n.$mode.err"
    grep -h Collected "$OUT/$n.$mode.err" | awk -v n="$n" -v m="$mode" '{print n, m, $4}'
  done
done
