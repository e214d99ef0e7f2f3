#!/usr/bin/env bash
# What does the repair picture cost in instructions?  Runs `holefill fill` under
# callgrind (every thread counted) without and with `--picture` on the holed inputs
# scripts/same_outputs.sh caches (hole seed 1 and the natural scans), and prints
# "mesh off on" instruction counts. Deterministic up to the rayon workers' idle
# spinning (a few M), unlike wall or CPU time on a shared 2-core machine.
#
#   scripts/picture_cost_instr.sh BIN [OUT_DIR]     (SKIP: a regex of names to leave out)
BIN=$1; OUT=${2:-$(mktemp -d)}; SKIP=${SKIP:-"^$"}
mkdir -p $OUT
H=${HOLES:-/work/bench-out/same-outputs-holes}
[ -x "$BIN" ] && [ -d "$H" ] || { echo "usage: $0 BIN [OUT_DIR] (holed inputs in $H: run scripts/same_outputs.sh once)" >&2; exit 2; }
for d in $H/*; do n=$(basename $d); case $n in *-s2|*-s3) continue;; esac; [[ "$n" =~ $SKIP ]] && continue
  for mode in off on; do
    extra=(); [ $mode = on ] && extra=(--picture $OUT/$n.png)
    valgrind --tool=callgrind --callgrind-out-file=$OUT/$n.$mode.cg $BIN fill $d/holed.obj $OUT/$n.$mode.obj --report $OUT/$n.$mode.json "${extra[@]}" >/dev/null 2>$OUT/$n.$mode.err
    grep -h Collected $OUT/$n.$mode.err | awk -v n=$n -v m=$mode '{print n, m, $4}'
  done
done
