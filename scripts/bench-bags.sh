#!/bin/bash
# Reading speed of bags against a sequence directory (docs/PERFORMANCE.md, "Reading bags"): the simulator's
# built-in route (every 2nd frame, HDL-64), written as MCAP with zstd and with lz4 chunks
# and as a rosbag2 .db3 by tests/interop/write_bag.mjs, then read whole by build/bin/sglc-bench-bags.
#   scripts/bench-bags.sh            # FRAMES=0:1911:2 REPEAT=5 WORK=/tmp
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-0:1911:2}
REPEAT=${REPEAT:-5}
mkdir -p "${WORK:=/tmp}"
WORK=$(mktemp -d "$WORK/sglc-bench-bags.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
build/bin/sglc-sim --route loop --frames "$FRAMES" --quiet --out "$WORK/seq" > /dev/null
for kind in zstd lz4 db3; do
  storage=mcap compression=$kind out="$WORK/drive-$kind.mcap"
  [ "$kind" = db3 ] && storage=db3 compression="" out="$WORK/drive-db3"
  printf '{"from_sequence": "%s", "points_topic": "/points", "odom_topic": "/odom", "storage": "%s", "compression": "%s"}' \
    "$WORK/seq" "$storage" "$compression" > "$WORK/$kind.json"
  node tests/interop/write_bag.mjs "$WORK/$kind.json" "$out"
done
du -sh "$WORK/seq/velodyne" "$WORK/drive-zstd.mcap" "$WORK/drive-lz4.mcap" "$WORK/drive-db3" >&2
build/bin/sglc-bench-bags --dir "$WORK/seq" --mcap-zstd "$WORK/drive-zstd.mcap" --mcap-lz4 "$WORK/drive-lz4.mcap" \
  --db3 "$WORK/drive-db3" --repeat "$REPEAT"
