#!/usr/bin/env bash
# The main job on a fresh Debian 12 machine (as root): install, build, simulate a labelled city drive with
# loops, start sglc-server on its default embedded SQLite map, feed the drive to it as two robots (the first
# half as robot "alpha", the second half as robot "bravo"), and print every loop it finds, intra- and
# inter-robot, with the pose error against the simulator's ground truth.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh
WORK=var/demo
rm -rf "$WORK" && mkdir -p "$WORK"
echo "== simulating the built-in route (every 3rd frame, seed 7)"
build/bin/sglc-sim --route loop --frames 0:1911:3 --seed 7 --out "$WORK/seq" > "$WORK/sim.log"
tail -n 3 "$WORK/sim.log"
PORT=${SGLC_DEMO_PORT:-50051}
build/bin/sglc-server --db "$WORK/map.db" --listen "127.0.0.1:$PORT" > "$WORK/server.log" 2>&1 &
SERVER=$!
trap 'kill -TERM $SERVER 2>/dev/null; wait $SERVER 2>/dev/null || true' EXIT
for _ in $(seq 100); do build/bin/sglc health --server "127.0.0.1:$PORT" >/dev/null 2>&1 && break; sleep 0.1; done
N=$(ls "$WORK/seq/velodyne" | wc -l)
HALF=$((N / 2))
echo "== ingesting $N scans: alpha = 0..$((HALF - 1)), bravo = $HALF..$((N - 1))"
build/bin/sglc ingest --server "127.0.0.1:$PORT" --map demo --robot alpha --frames "0:$HALF" --query \
  --exclude-recent 30 --json --no-progress "$WORK/seq" > "$WORK/alpha.jsonl"
build/bin/sglc ingest --server "127.0.0.1:$PORT" --map demo --robot bravo --frames "$HALF:" --query \
  --exclude-recent 30 --json --no-progress "$WORK/seq" > "$WORK/bravo.jsonl"
/usr/bin/python3 scripts/demo_report.py "$WORK"   # also draws $WORK/demo.png
build/bin/sglc stats --server "127.0.0.1:$PORT"
