#!/usr/bin/env bash
# Do two builds give the same outputs?  Runs OLD_BIN and NEW_BIN (`holefill fill`) on
# every mesh of the shared bench with the bench's own synthetic holes for hole seeds
# 1-3, and on the natural scans (their own holes), and compares byte for byte: the
# repaired mesh, the repair log (JSON) with its timing fields removed ("ms", "read_ms",
# "smooth_ms", "fill_ms", "write_ms", "attributes_ms", "picture_ms"), the printed
# summary with its times removed, and the exit status. Every policy sets limits.hole_time_ms = 0 (no time limit), so that
# no result depends on how loaded the machine is.
#
#   scripts/same_outputs.sh OLD_BIN NEW_BIN [OUT_DIR]
#
# Runs (each on every input unless said otherwise):
#   default policy, limits.threads = 1 and = 2;
#   each method forced alone for middle and large holes (small: "fan"), as the
#   README's methods table does, threads = 2 (min_area_fair, advancing_front,
#   wavefront, hpde, lssvm_poisson; the last two, which take seconds a hole past 70
#   boundary vertices, up to 70, larger holes with "wavefront"), hole seed 1 and the
#   natural scans;
#   one policy that switches on the optional passes (smoothing, tooth removal, long-edge
#   split, dihedral weight, other wavefront placement), threads = 2, seed 1 and natural.
#
# The holed inputs come from the bench's generator (holegen.py, as run.py calls it)
# and are cached in $HOLES (default /work/bench-out/same-outputs-holes; made once).
# BENCH (default ../shared/bench beside the checkout) and DATA (default
# $BENCH/../bench-data/meshes) can be set in the environment. JOBS (default 2) runs
# that many inputs at once. Prints one line per difference and a total; exits 1 when
# anything differs. Takes 2-4 minutes on 2 cores.
set -euo pipefail
if [ $# -lt 2 ]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OLD=$(realpath "$1")
NEW=$(realpath "$2")
OUT=${3:-$(mktemp -d /tmp/same-outputs.XXXXXX)}
BENCH=$(realpath "${BENCH:-$ROOT/../shared/bench}")
DATA=$(realpath "${DATA:-$BENCH/../bench-data/meshes}")
HOLES=${HOLES:-/work/bench-out/same-outputs-holes}
JOBS=${JOBS:-2}
PY="$BENCH/.venv/bin/python"
SEEDS="1 2 3"
METHODS="min_area_fair advancing_front wavefront hpde lssvm_poisson"

mkdir -p "$HOLES" "$OUT/policies"
natural=$(grep -v '^#' "$DATA/natural.txt" | sed '/^\s*$/d' || true)
is_natural() { grep -qx "$1" <<<"$natural"; }

# --- the holed inputs (cached) ---
inputs_seed1=()
inputs_all=()
for f in "$DATA"/*.obj; do
  name=$(basename "$f" .obj)
  if is_natural "$name"; then
    d="$HOLES/$name"
    if [ ! -s "$d/holed.obj" ]; then
      echo "holegen: $name (natural)" >&2
      "$PY" "$BENCH/holegen.py" "$f" "$d" --natural > /dev/null
    fi
    inputs_seed1+=("$d/holed.obj")
    inputs_all+=("$d/holed.obj")
    continue
  fi
  for s in $SEEDS; do
    d="$HOLES/$name-s$s"
    if [ ! -s "$d/holed.obj" ]; then
      echo "holegen: $name seed $s" >&2
      "$PY" "$BENCH/holegen.py" "$f" "$d" --seed "$s" > /dev/null
    fi
    inputs_all+=("$d/holed.obj")
    [ "$s" = 1 ] && inputs_seed1+=("$d/holed.obj")
  done
done

# --- the policies ---
# no time limit anywhere: a method that runs out of time on a loaded machine would make
# the outputs differ by timing alone
printf '[limits]\nthreads = 1\nhole_time_ms = 0\n' > "$OUT/policies/t1.toml"
printf '[limits]\nthreads = 2\nhole_time_ms = 0\n' > "$OUT/policies/t2.toml"
for m in $METHODS; do
  case $m in
    # seconds a hole past 70 boundary vertices: those go to the default method
    hpde | lssvm_poisson) large='"wavefront"' mid=70 ;;
    *) large="\"$m\"" mid=50 ;;
  esac
  printf '[dispatch]\nmiddle_max = %s\nsmall = ["fan"]\nmiddle = ["%s"]\nlarge = [%s]\n' \
    "$mid" "$m" "$large" > "$OUT/policies/$m.toml"
  printf '[limits]\nthreads = 2\nhole_time_ms = 0\n' >> "$OUT/policies/$m.toml"
done
cat > "$OUT/policies/options.toml" <<'EOF'
[clean]
remove_teeth = true
split_long_edges = 2.0
[refine]
weight = "dihedral_area"
[wavefront]
placement = "interpolated"
[smooth]
enabled = true
scope = "rings"
weights = "cotangent"
[limits]
threads = 2
hole_time_ms = 0
EOF

# --- the runs: "policy|input" lines ---
jobs_file="$OUT/jobs.txt"
: > "$jobs_file"
for p in t1 t2; do
  for i in "${inputs_all[@]}"; do echo "$p|$i" >> "$jobs_file"; done
done
for p in $METHODS options; do
  for i in "${inputs_seed1[@]}"; do echo "$p|$i" >> "$jobs_file"; done
done

# one run of both binaries, then the comparison; prints DIFF lines
compare_one() {
  local p=${1%%|*} i=${1#*|}
  local tag
  tag="$p/$(basename "$(dirname "$i")")"
  local side rc
  for side in old new; do
    local bin=$OLD
    [ "$side" = new ] && bin=$NEW
    local d="$OUT/runs/$side/$tag"
    mkdir -p "$d"
    rc=0
    (cd "$d" && "$bin" fill "$i" out.obj --policy "$OUT/policies/$p.toml" --report log.json \
      > stdout.txt 2> stderr.txt) || rc=$?
    echo "$rc" > "$d/rc"
    # timings aside
    if [ -f "$d/log.json" ]; then
      sed -E '/^\s*"(ms|read_ms|smooth_ms|fill_ms|write_ms|attributes_ms|picture_ms)":/d' "$d/log.json" > "$d/log.cmp"
    fi
    sed -E 's/ +[0-9.]+ ms//; /^FILL_TIME_S=/d' "$d/stdout.txt" > "$d/stdout.cmp"
  done
  local o="$OUT/runs/old/$tag" n="$OUT/runs/new/$tag" f
  for f in rc out.obj log.cmp stdout.cmp stderr.txt; do
    if [ -f "$o/$f" ] || [ -f "$n/$f" ]; then
      cmp -s "$o/$f" "$n/$f" || echo "DIFF $tag $f"
    fi
  done
  echo "RAN $tag rc=$(cat "$o/rc")"
}
export -f compare_one
export OLD NEW OUT

echo "old: $OLD" >&2
echo "new: $NEW" >&2
echo "runs: $(wc -l < "$jobs_file") (output in $OUT)" >&2
start=$SECONDS
xargs -d '\n' -P "$JOBS" -I{} bash -c 'compare_one "$@"' _ {} < "$jobs_file" > "$OUT/result.txt"
ran=$(grep -c '^RAN ' "$OUT/result.txt" || true)
diffs=$(grep -c '^DIFF ' "$OUT/result.txt" || true)
grep '^DIFF ' "$OUT/result.txt" | sort || true
nonzero=$(grep '^RAN ' "$OUT/result.txt" | grep -vc 'rc=0$' || true)
echo "$ran runs, $diffs differences, $nonzero runs with a non-zero exit status (both builds), $((SECONDS - start)) s"
[ "$diffs" = 0 ]
