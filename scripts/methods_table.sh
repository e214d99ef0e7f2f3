#!/usr/bin/env bash
# The README's "Methods table": runs the shared bench once, in one session, with
# holefill's default policy, each method forced alone for the middle and large classes
# (small holes: "fan", no fallback) and the peers cgal_fair and meshlib_nicely; then
# prints the table and checks in every repair log that each hole was closed by the
# forced method itself.
#
#   scripts/methods_table.sh [HOLEFILL_BINARY] [OUT_DIR]
#
# Defaults: target/release/holefill of this checkout, /tmp/holefill-methods-table.
# BENCH (default ../shared/bench), DATA (default $BENCH/../bench-data/meshes) and
# SEEDS (hole seeds, default 1-5; the natural scans count once) can be set in the
# environment. Takes about 6 minutes per seed on 2 cores.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=$(realpath "${1:-$ROOT/target/release/holefill}")
OUT=${2:-/tmp/holefill-methods-table}
BENCH=$(realpath "${BENCH:-$ROOT/../shared/bench}")
DATA=$(realpath "${DATA:-$BENCH/../bench-data/meshes}")
SEEDS=${SEEDS:-1-5}
METHODS="min_area_fair advancing_front wavefront hpde lssvm_poisson"
mkdir -p "$OUT/policies"
args=(--only cgal_fair,meshlib_nicely --data "$DATA" --out "$OUT/bench")
args+=(--system "default=$BIN fill {in} {out} --report {out}.json")
for m in $METHODS; do
  printf '[dispatch]\nsmall = ["fan"]\nmiddle = ["%s"]\nlarge = ["%s"]\n' "$m" "$m" \
    > "$OUT/policies/$m.toml"
  args+=(--system "$m=$BIN fill {in} {out} --policy $OUT/policies/$m.toml --report {out}.json")
done
echo "holefill: $BIN ($("$BIN" --version))" >&2
echo "bench:    $BENCH, data $DATA, seeds $SEEDS, output $OUT/bench" >&2
rm -rf "$OUT/bench"
"$BENCH/seeds.py" --seeds "$SEEDS" "${args[@]}" > "$OUT/bench.log" 2>&1 || { tail -20 "$OUT/bench.log"; exit 1; }
"$BENCH/.venv/bin/python" "$ROOT/scripts/methods_table.py" "$OUT/bench" default $METHODS
