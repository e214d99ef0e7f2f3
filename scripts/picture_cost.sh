#!/usr/bin/env bash
# What does the repair picture cost?  Times `holefill fill IN OUT --report LOG` with and
# without `--picture PNG` (the daemon draws the same picture in the same child process)
# on the bench's holed meshes, the two in turn (A B A B ...), and prints per mesh the
# median wall time of each and the median of the pair ratios (with/without), then the
# ratio of the summed medians over all meshes.
#
#   scripts/picture_cost.sh BIN [PAIRS]        (PAIRS default 5)
#
# The holed inputs are the ones scripts/same_outputs.sh caches in $HOLES (default
# /work/bench-out/same-outputs-holes): hole seed 1 of every synthetic mesh
# (NAME-s1/holed.obj) and the natural scans (NAME/holed.obj). Run same_outputs.sh once
# to make them. One warm-up run of each command per mesh is not counted.
set -euo pipefail
if [ $# -lt 1 ]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
BIN=$(readlink -f "$1")
PAIRS=${2:-5}
HOLES=${HOLES:-/work/bench-out/same-outputs-holes}
[ -x "$BIN" ] || { echo "$BIN: not an executable" >&2; exit 2; }
[ -d "$HOLES" ] || { echo "$HOLES: no holed inputs (run scripts/same_outputs.sh once)" >&2; exit 2; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# seconds of one run (exit 0 and 2 are both results: 2 = some hole left open)
run() {
  local t0 t1
  t0=$(date +%s.%N)
  "$@" >/dev/null 2>&1 || [ $? -eq 2 ]
  t1=$(date +%s.%N)
  echo "$t1 - $t0" | bc -l
}

median() { sort -g | awk '{a[NR]=$1} END {if (NR%2) print a[(NR+1)/2]; else print (a[NR/2]+a[NR/2+1])/2}'; }

printf '%-22s %10s %10s %8s\n' mesh without_s with_s ratio
sum_a=0; sum_b=0
for d in "$HOLES"/*; do
  name=$(basename "$d")
  case "$name" in *-s2|*-s3) continue ;; esac
  in="$d/holed.obj"
  [ -f "$in" ] || continue
  a=(fill "$in" "$tmp/a.obj" --report "$tmp/a.json")
  b=(fill "$in" "$tmp/b.obj" --report "$tmp/b.json" --picture "$tmp/b.png")
  run "$BIN" "${a[@]}" >/dev/null
  run "$BIN" "${b[@]}" >/dev/null
  : >"$tmp/ta"; : >"$tmp/tb"; : >"$tmp/r"
  for _ in $(seq "$PAIRS"); do
    ta=$(run "$BIN" "${a[@]}")
    tb=$(run "$BIN" "${b[@]}")
    echo "$ta" >>"$tmp/ta"; echo "$tb" >>"$tmp/tb"
    echo "$tb / $ta" | bc -l >>"$tmp/r"
  done
  ma=$(median <"$tmp/ta"); mb=$(median <"$tmp/tb"); mr=$(median <"$tmp/r")
  printf '%-22s %10.3f %10.3f %8.3f\n' "$name" "$ma" "$mb" "$mr"
  sum_a=$(echo "$sum_a + $ma" | bc -l); sum_b=$(echo "$sum_b + $mb" | bc -l)
done
printf '%-22s %10.3f %10.3f %8.3f\n' "all (sum of medians)" "$sum_a" "$sum_b" "$(echo "$sum_b / $sum_a" | bc -l)"
