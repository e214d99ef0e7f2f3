#!/usr/bin/env bash
# Fill time of two holefill builds, A against B: `holefill fill` run in turn (A B A B
# ...) on each holed input, PAIRS pairs after one warm-up each, and its FILL_TIME_S
# (smoothing + filling, no I/O) read. Prints per input the median of each and the
# median of the pair ratios (A / B).
#
#   scripts/fill_ab.sh BIN_A BIN_B [PAIRS]        (PAIRS default 5)
#
# POLICY=FILE fills under that policy (e.g. one method forced).
#
# The holed inputs are the ones scripts/same_outputs.sh caches in $HOLES (default
# /work/bench-out/same-outputs-holes): NAME-s1, -s2, -s3/holed.obj, hole seeds 1-3 of
# every synthetic mesh of the bench.
set -euo pipefail
if [ $# -lt 2 ]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
A=$(readlink -f "$1"); B=$(readlink -f "$2"); PAIRS=${3:-5}
HOLES=${HOLES:-/work/bench-out/same-outputs-holes}
[ -d "$HOLES" ] || { echo "$HOLES: no holed inputs (run scripts/same_outputs.sh once)" >&2; exit 2; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
ft() { { "$1" fill "$2" "$tmp/o.obj" ${POLICY:+--policy "$POLICY"} 2>/dev/null || true; } | sed -n 's/^FILL_TIME_S=//p'; }
printf '%-22s %10s %10s %8s\n' input a_fill_s b_fill_s ratio
for d in "$HOLES"/*-s[123]; do
  in=$d/holed.obj
  [ -f "$in" ] || continue
  ft "$A" "$in" >/dev/null; ft "$B" "$in" >/dev/null
  : >"$tmp/t"
  for _ in $(seq "$PAIRS"); do echo "$(ft "$A" "$in") $(ft "$B" "$in")" >>"$tmp/t"; done
  python3 - "$(basename "$d")" "$tmp/t" <<'PY'
import statistics as st, sys
p = [tuple(map(float, l.split())) for l in open(sys.argv[2]) if l.split()]
a, b = [x for x, _ in p], [y for _, y in p]
print("%-22s %10.5f %10.5f %8.3f" % (sys.argv[1], st.median(a), st.median(b), st.median([x / y for x, y in p])))
PY
done
