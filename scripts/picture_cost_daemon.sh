#!/usr/bin/env bash
# What does the repair picture cost the inbox daemon?  Runs `holefill watch` on a fresh
# inbox with `--picture false` and with `--picture true` in turn (A B A B ...), drops the
# bench's holed meshes into it all at once (renamed in, as a scanner does), and reads
# each file's time from its repair log (`daemon.seconds`: from taking the file to its
# log, the child's read, repair, picture and write and the daemon's publishing).
# Prints per mesh the median time without and with the picture and the median of the
# per-round ratios, then the median of the per-mesh ratios and the ratio of the sums;
# then the whole burst's wall time (from the drop to the last log published, and to
# the last picture), median over the rounds: what the pictures cost in throughput.
#
#   scripts/picture_cost_daemon.sh BIN [ROUNDS] [WORKERS]   (default 5 rounds, 1 worker)
#
# The holed inputs are the ones scripts/same_outputs.sh caches in $HOLES (default
# /work/bench-out/same-outputs-holes): hole seed 1 of every synthetic mesh
# (NAME-s1/holed.obj) and the natural scans (NAME/holed.obj); set SKIP to a regular
# expression of names to leave out (e.g. SKIP='plastic-vase|owl' for a quick run).
set -euo pipefail
if [ $# -lt 1 ]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
BIN=$(readlink -f "$1")
ROUNDS=${2:-5}
WORKERS=${3:-1}
HOLES=${HOLES:-/work/bench-out/same-outputs-holes}
SKIP=${SKIP:-'^$'}
[ -x "$BIN" ] || { echo "$BIN: not an executable" >&2; exit 2; }
[ -d "$HOLES" ] || { echo "$HOLES: no holed inputs (run scripts/same_outputs.sh once)" >&2; exit 2; }
tmp=$(mktemp -d)
daemon=""
trap '[ -n "$daemon" ] && kill "$daemon" 2>/dev/null; rm -rf "$tmp"' EXIT

mkdir -p "$tmp/src"
for d in "$HOLES"/*; do
  name=$(basename "$d")
  case "$name" in *-s2|*-s3) continue ;; esac
  [[ "$name" =~ $SKIP ]] && continue
  [ -f "$d/holed.obj" ] && cp "$d/holed.obj" "$tmp/src/$name.obj"
done
count=$(ls "$tmp"/src/*.obj | wc -l)

# one daemon run: picture on or off; appends "name seconds" lines to $tmp/times-MODE
run() {
  local mode=$1 dir=$tmp/run
  rm -rf "$dir"; mkdir -p "$dir/inbox"
  "$BIN" watch --inbox "$dir/inbox" --outbox "$dir/outbox" --workers "$WORKERS" \
    --picture "$mode" --settle-ms 200 >/dev/null 2>&1 &
  daemon=$!
  until [ -d "$dir/outbox" ]; do sleep 0.05; done
  for f in "$tmp"/src/*.obj; do cp "$f" "$dir/inbox/.$(basename "$f").part"; done
  local t0 t1 t2
  t0=$(date +%s.%N)
  for f in "$tmp"/src/*.obj; do b=$(basename "$f"); mv "$dir/inbox/.$b.part" "$dir/inbox/$b"; done
  until [ "$(ls "$dir"/outbox/*.repair.json 2>/dev/null | wc -l)" -ge "$count" ]; do sleep 0.02; done
  t1=$(date +%s.%N)
  if [ "$mode" = true ]; then
    until [ "$(ls "$dir"/outbox/*.repair.png 2>/dev/null | wc -l)" -ge "$count" ]; do sleep 0.02; done
  fi
  t2=$(date +%s.%N)
  echo "$t0 $t1 $t2" | awk '{print $2 - $1, $3 - $1}' >>"$tmp/burst-$mode"
  kill "$daemon"; wait "$daemon" 2>/dev/null || true; daemon=""
  python3 - "$dir/outbox" >>"$tmp/times-$mode" <<'PY'
import json, pathlib, sys
for p in sorted(pathlib.Path(sys.argv[1]).glob("*.repair.json")):
    d = json.loads(p.read_text())["daemon"]
    print(p.name[: -len(".obj.repair.json")], d["seconds"])
PY
}

run false; run true   # warm-up, not counted
: >"$tmp/times-false"; : >"$tmp/times-true"; : >"$tmp/burst-false"; : >"$tmp/burst-true"
for r in $(seq "$ROUNDS"); do
  if [ $((r % 2)) -eq 1 ]; then run false; run true; else run true; run false; fi
done

python3 - "$tmp/times-false" "$tmp/times-true" "$tmp/burst-false" "$tmp/burst-true" <<'PY'
import statistics as st, sys
def load(p):
    t = {}
    for line in open(p):
        n, s = line.split()
        t.setdefault(n, []).append(float(s))
    return t
a, b = load(sys.argv[1]), load(sys.argv[2])
print("%-22s %10s %10s %8s" % ("mesh", "without_s", "with_s", "ratio"))
ratios, sa, sb = [], 0.0, 0.0
for n in sorted(a):
    ma, mb = st.median(a[n]), st.median(b[n])
    r = st.median([y / x for x, y in zip(a[n], b[n])])
    ratios.append(r); sa += ma; sb += mb
    print("%-22s %10.3f %10.3f %8.3f" % (n, ma, mb, r))
print("%-22s %10.3f %10.3f %8.3f" % ("all (sum of medians)", sa, sb, sb / sa))
print("%-22s %10s %10s %8.3f" % ("median of the ratios", "", "", st.median(ratios)))
off = [float(l.split()[0]) for l in open(sys.argv[3])]
on = [l.split() for l in open(sys.argv[4])]
logs, pics = [float(l[0]) for l in on], [float(l[1]) for l in on]
print("burst wall time (median of %d rounds): without %.2f s; with: last log %.2f s (%.3fx), last picture %.2f s (%.3fx)"
      % (len(off), st.median(off), st.median(logs), st.median(logs) / st.median(off),
         st.median(pics), st.median(pics) / st.median(off)))
PY
