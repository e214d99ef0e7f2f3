#!/bin/bash
# Throughput of the NATS queue workers beside the inbox daemon (docs/worker.md, "Measured").
# usage: scripts/queue_throughput.sh HOLEFILL_BIN MESH_DIR queue|daemon N
#   queue N:  all meshes submitted to a fresh nats-server (loopback, temporary store),
#             then N workers (--workers 1 each); seconds until `results` has every log
#   daemon N: all meshes renamed into a fresh inbox of `watch --workers N`; seconds
#             until the outbox holds every log
set -euo pipefail
hf=$1; src=$2; mode=$3; n=$4
count=$(ls "$src"/*.obj | wc -l)
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
if [ "$mode" = queue ]; then
  port=$((15000 + RANDOM % 1000)); url=nats://127.0.0.1:$port
  nats-server -js -a 127.0.0.1 -p "$port" -sd "$tmp/js" >/dev/null 2>&1 & server=$!
  sleep 1
  "$hf" submit --nats "$url" "$src"/*.obj >/dev/null 2>&1
  t0=$(date +%s.%N); pids=""
  for _ in $(seq "$n"); do "$hf" worker --nats "$url" --workers 1 >/dev/null 2>&1 & pids="$pids $!"; done
  until "$hf" results --nats "$url" "$tmp/out" >/dev/null 2>&1 && [ "$(ls "$tmp"/out/*.repair.json 2>/dev/null | wc -l)" -ge "$count" ]; do sleep 0.2; done
  t1=$(date +%s.%N)
  kill $pids $server; wait 2>/dev/null || true
else
  mkdir -p "$tmp/inbox"
  "$hf" watch --inbox "$tmp/inbox" --workers "$n" >/dev/null 2>&1 & daemon=$!
  sleep 1
  for f in "$src"/*.obj; do cp "$f" "$tmp/inbox/.$(basename "$f").part"; done
  t0=$(date +%s.%N)
  for f in "$src"/*.obj; do b=$(basename "$f"); mv "$tmp/inbox/.$b.part" "$tmp/inbox/$b"; done
  until [ "$(ls "$tmp"/outbox/*.repair.json 2>/dev/null | wc -l)" -ge "$count" ]; do sleep 0.1; done
  t1=$(date +%s.%N)
  kill $daemon; wait 2>/dev/null || true
fi
secs=$(echo "$t1 - $t0" | bc)
echo "$mode N=$n: $count scans in $secs s = $(echo "60 * $count / $secs" | bc) scans/min"
