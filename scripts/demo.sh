#!/usr/bin/env bash
# The main job on a fresh Debian 12 machine (as root): install, build what the demo runs, simulate a labelled
# city drive with loops and odometry that drifts 2 % of the distance (a wheel odometry; a LiDAR odometry
# drifts about 1 %), start
# sglc-server on an embedded SQLite map on a free port, feed the drive to it as two robots (the first half as
# "alpha", the second as "bravo"), print every loop it finds with its pose error against the simulator's
# ground truth, then the pose graph's work: the trajectory error of the drifting odometry and of the server's
# optimised poses, and a picture of both against the truth (var/demo/demo.png).
#
# For a test (tests/deploy): SGLC_DEMO_SKIP_SETUP=1 skips installing and building, SGLC_DEMO_BUILD names the
# build tree (default build), SGLC_DEMO_FRAMES the simulator's frames (default 0:1911:3), SGLC_DEMO_WORK the
# work directory (default var/demo).
set -euo pipefail
cd "$(dirname "$0")/.."
START=$SECONDS
B=${SGLC_DEMO_BUILD:-build}
phase() { echo "== [$1/6] $2 ($((SECONDS - START)) s)"; }
phase 1 "installing Debian packages (scripts/install-deps.sh; quiet unless it fails)"
if [ "${SGLC_DEMO_SKIP_SETUP:-0}" != 1 ]; then
  scripts/install-deps.sh > var-install.log 2>&1 || { cat var-install.log; exit 1; }
  rm -f var-install.log
fi
phase 2 "building sglc-server, sglc, sglc-sim and the Python stubs (scripts/build.sh; tests are scripts/test.sh's)"
if [ "${SGLC_DEMO_SKIP_SETUP:-0}" != 1 ]; then
  SGLC_BUILD_TARGETS="sglc-server sglc sglc-sim sglc_proto_python" scripts/build.sh > var-build.log 2>&1 ||
    { tail -n 40 var-build.log; exit 1; }
  rm -f var-build.log
fi
for b in sglc-server sglc sglc-sim; do [ -x "$B/bin/$b" ] || { echo "demo: $B/bin/$b was not built" >&2; exit 1; }; done
WORK=${SGLC_DEMO_WORK:-var/demo}
rm -rf "$WORK" && mkdir -p "$WORK"
phase 3 "simulating the built-in route (every 3rd frame, seed 7, odometry drifting 2 % of the distance)"
"$B/bin/sglc-sim" --route loop --frames "${SGLC_DEMO_FRAMES:-0:1911:3}" --seed 7 --odom-noise 0.02 --out "$WORK/seq" > "$WORK/sim.log"
tail -n 3 "$WORK/sim.log"
PORT=${SGLC_DEMO_PORT:-$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')}
export SGLC_SERVER="127.0.0.1:$PORT"   # every sglc command below talks to it
phase 4 "starting sglc-server on $SGLC_SERVER (SGLC_SERVER=$SGLC_SERVER; map database $WORK/map.db)"
"$B/bin/sglc-server" --db "$WORK/map.db" --listen "$SGLC_SERVER" --set pose_graph.global_interval_s=2 \
  --viz-listen "127.0.0.1:${SGLC_DEMO_VIZ_PORT:-0}" > "$WORK/server.log" 2>&1 &
SERVER=$!
trap 'kill -TERM $SERVER 2>/dev/null; wait $SERVER 2>/dev/null || true' EXIT
for _ in $(seq 300); do "$B/bin/sglc" health >/dev/null 2>&1 && break; sleep 0.1; done
VIZ=$(sed -n 's/.*"event":"viz".*"port":\([0-9]*\).*/\1/p' "$WORK/server.log")
echo "   watch it live: http://127.0.0.1:$VIZ/ in a browser, or ws://127.0.0.1:$VIZ in Foxglove"
N=$(ls "$WORK/seq/velodyne" | wc -l)
HALF=$((N / 2))
phase 5 "ingesting $N scans with their drifting odometry: alpha = 0..$((HALF - 1)), bravo = $HALF..$((N - 1))"
for robot in alpha bravo; do
  frames="0:$HALF"; [ $robot = bravo ] && frames="$HALF:"
  "$B/bin/sglc" ingest --map demo --robot $robot --frames "$frames" --poses "$WORK/seq/odometry.txt" --query \
    --exclude-recent 30 --json --no-progress "$WORK/seq" > "$WORK/$robot.jsonl"
  echo "   $robot: $(wc -l < "$WORK/$robot.jsonl") scans stored ($((SECONDS - START)) s)"
done
phase 6 "loops and the pose graph"
/usr/bin/python3 scripts/demo_report.py "$WORK" "$SGLC_SERVER" "$B/python"   # also draws $WORK/demo.png
"$B/bin/sglc" stats
echo "== done in $((SECONDS - START)) s"
