#!/usr/bin/env bash
# Several servers on one map, on loopback: a PostgreSQL database, three sglc-server replicas on it and nginx in
# front (deploy/nginx/sglc-grpc.conf). Two robots drive the simulated route through nginx with queries, and one
# replica (the one solving the map's pose graph) is killed with SIGKILL part-way; the clients retry through the
# balancer. Then a probe measures how soon a scan one replica acknowledged is found by queries on another.
#
# Run on a fresh Debian 12 machine as root (it installs and builds first). Prints one JSON line and exits 1
# unless every scan a client saw acknowledged is stored and indexed on every surviving replica.
# Environment: SGLC_CLUSTER_FRAMES (default 0:1911:3, 637 scans), SGLC_CLUSTER_PORT (nginx's; replicas
# listen on the next three), SGLC_CLUSTER_DIR (var/cluster), SGLC_CLUSTER_BIN (build/bin),
# SGLC_CLUSTER_PROBES (200 visibility probes), SGLC_CLUSTER_SKIP_SETUP=1 (no install or build).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${SGLC_CLUSTER_SKIP_SETUP:-0}" != 1 ]; then
  scripts/install-deps.sh
  scripts/build.sh
fi
WORK=$(realpath -m "${SGLC_CLUSTER_DIR:-var/cluster}")
FRAMES=${SGLC_CLUSTER_FRAMES:-0:1911:3}
PORT=${SGLC_CLUSTER_PORT:-50070}
BIN=$(realpath "${SGLC_CLUSTER_BIN:-build/bin}")
rm -rf "$WORK" && mkdir -p "$WORK"

REPLICA_PIDS=()
FEEDERS=()
NGINX_PID=""
cleanup() {  # also on an interrupted run: the feeders would go on retrying
  for p in "${FEEDERS[@]}" "${REPLICA_PIDS[@]}" $NGINX_PID; do kill -TERM "$p" 2>/dev/null || true; done
  for p in "${FEEDERS[@]}" "${REPLICA_PIDS[@]}" $NGINX_PID; do wait "$p" 2>/dev/null || true; done
  tests/storage/pg_cluster.sh stop "$WORK/pg" >/dev/null 2>&1 || true
}
trap cleanup EXIT

healthy() {  # waits up to 30 s for a server to answer
  for _ in $(seq 300); do "$BIN/sglc" health --server "$1" >/dev/null 2>&1 && return 0; sleep 0.1; done
  echo "cluster-demo: $1 did not become healthy" >&2
  return 1
}

echo "== simulating the built-in route (frames $FRAMES, seed 7)" >&2
"$BIN/sglc-sim" --route loop --frames "$FRAMES" --seed 7 --out "$WORK/seq" >"$WORK/sim.log"

echo "== PostgreSQL on loopback" >&2
tests/storage/pg_cluster.sh start "$WORK/pg" >&2
ADMIN_URL=$(cat "$WORK/pg/url")
psql "$ADMIN_URL" -qc "CREATE DATABASE sglc" >/dev/null
DB_URL=${ADMIN_URL%/postgres}/sglc

echo "== three replicas on it, nginx in front on 127.0.0.1:$PORT" >&2
for i in 1 2 3; do
  "$BIN/sglc-server" --db "$DB_URL" --listen "127.0.0.1:$((PORT + i))" >"$WORK/replica$i.log" 2>&1 &
  REPLICA_PIDS+=($!)
done
for i in 1 2 3; do healthy "127.0.0.1:$((PORT + i))"; done
mkdir -p "$WORK/nginx" && chmod 777 "$WORK/nginx"
sed -e "s|127.0.0.1:50061|127.0.0.1:$((PORT + 1))|; s|127.0.0.1:50062|127.0.0.1:$((PORT + 2))|" \
  -e "s|127.0.0.1:50063|127.0.0.1:$((PORT + 3))|; s|listen 127.0.0.1:50051|listen 127.0.0.1:$PORT|" \
  -e "s|^pid .*|pid $WORK/nginx/nginx.pid;|; s|^error_log .*|error_log $WORK/nginx/error.log warn;|" \
  -e "s|^http {|http {\n  client_body_temp_path $WORK/nginx/body;\n  proxy_temp_path $WORK/nginx/proxy;\n  fastcgi_temp_path $WORK/nginx/fastcgi;\n  uwsgi_temp_path $WORK/nginx/uwsgi;\n  scgi_temp_path $WORK/nginx/scgi;|" \
  deploy/nginx/sglc-grpc.conf >"$WORK/nginx.conf"
nginx -t -c "$WORK/nginx.conf" -p "$WORK/nginx" >"$WORK/nginx-test.log" 2>&1 || { cat "$WORK/nginx-test.log" >&2; exit 1; }
nginx -c "$WORK/nginx.conf" -p "$WORK/nginx" -g 'daemon off;' 2>>"$WORK/nginx/error.log" &
NGINX_PID=$!
healthy "127.0.0.1:$PORT"

N=$(ls "$WORK/seq/velodyne" | wc -l)
HALF=$((N / 2))
echo "== two robots feed $N scans through nginx; one replica is killed part-way" >&2
START=$(date +%s.%N)
for robot in alpha bravo; do
  frames="0:$HALF" && [ $robot = bravo ] && frames="$HALF:"
  "$BIN/sglc" ingest --server "127.0.0.1:$PORT" --map demo --robot $robot --frames "$frames" --query \
    --exclude-recent 30 --json --no-progress --retries 20 "$WORK/seq" >"$WORK/$robot.jsonl" 2>"$WORK/$robot.err" &
  FEEDERS+=($!)
done
# At 40 % of the scans, kill the replica that holds the map's pose graph (the first replica if none does yet).
feeding() { for p in "${FEEDERS[@]}"; do kill -0 "$p" 2>/dev/null && return 0; done; return 1; }
while feeding && [ "$(cat "$WORK"/alpha.jsonl "$WORK"/bravo.jsonl | wc -l)" -lt $((N * 2 / 5)) ]; do sleep 0.2; done
VICTIM=1
for i in 1 2 3; do  # the replica whose latest word on the map is that it holds it
  grep '"event":"graph_owner","map":"demo"' "$WORK/replica$i.log" | tail -n 1 | grep -q '"held":true' && VICTIM=$i
done
KILLED_AT=$(date +%s.%N)
kill -KILL "${REPLICA_PIDS[$((VICTIM - 1))]}"
wait "${REPLICA_PIDS[$((VICTIM - 1))]}" 2>/dev/null || true
FEED_OK=1
for p in "${FEEDERS[@]}"; do wait "$p" || FEED_OK=0; done
END=$(date +%s.%N)
SURVIVORS=()
for i in 1 2 3; do [ $i != "$VICTIM" ] && SURVIVORS+=("127.0.0.1:$((PORT + i))"); done

# Every surviving replica's view of the map (its index included), and the pose graph settled.
sleep 3
for s in "${SURVIVORS[@]}"; do "$BIN/sglc" stats --server "$s" --map demo --json >"$WORK/stats-${s##*:}.json"; done

echo "== visibility across replicas" >&2
"$BIN/sglc-bench-visibility" --servers "$(IFS=,; echo "${SURVIVORS[*]}")" --seq "$WORK/seq" --map visibility \
  --scans "${SGLC_CLUSTER_PROBES:-200}" >"$WORK/visibility.json" || true

/usr/bin/python3 - "$WORK" "$VICTIM" "$KILLED_AT" "$START" "$END" "$FEED_OK" <<'EOF'
import datetime, glob, json, sys
work, victim, killed_at, start, end, feed_ok = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]), sys.argv[6] == "1"
acked, intra, inter = set(), 0, 0
for robot in ("alpha", "bravo"):
    for line in open(f"{work}/{robot}.jsonl"):
        r = json.loads(line)
        acked.add(r["scan_id"])
        for c in r["loops"]:
            if c.get("verified"):
                intra, inter = (intra + 1, inter) if c["robot"] == robot else (intra, inter + 1)
stats = [json.load(open(f)) for f in sorted(glob.glob(f"{work}/stats-*.json"))]
def field(s, *names):
    for n in names:
        for k, v in s.items():
            if k == n: return v
            if isinstance(v, dict) and n in v: return v[n]
    return None
stored = [field(s, "scans") for s in stats]
indexed = [field(s, "index_entries") for s in stats]
# Failover: the first time after the kill that a surviving replica took the map's pose graph.
failover = None
for i in (1, 2, 3):
    if i == victim: continue
    for line in open(f"{work}/replica{i}.log"):
        if '"event":"graph_owner"' not in line or '"held":true' not in line or '"map":"demo"' not in line: continue
        ts = datetime.datetime.strptime(json.loads(line)["ts"], "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=datetime.timezone.utc).timestamp()
        if ts > killed_at and (failover is None or ts - killed_at < failover): failover = ts - killed_at
try:
    vis = json.load(open(f"{work}/visibility.json"))
except Exception:
    vis = {}
ok = feed_ok and all(s == len(acked) for s in stored) and all(x == len(acked) for x in indexed)
print(json.dumps({
    "replicas": 3, "killed_replica": victim, "scans_acknowledged": len(acked),
    "scans_stored": stored[0] if stored else None, "indexed_per_surviving_replica": indexed,
    "intra_robot_loops": intra, "inter_robot_loops": inter,
    "keyframes_per_s": round(len(acked) / (end - start), 1),
    "visibility_ms_p50": vis.get("visibility_ms", {}).get("p50"), "visibility_ms_p99": vis.get("visibility_ms", {}).get("p99"),
    "visibility_probe_query_ms": vis.get("query_ms_median"), "visibility_not_found": vis.get("not_found_within_timeout"),
    "pose_graph_failover_s": None if failover is None else round(failover, 2),
    "acknowledged_equals_stored": ok}))
sys.exit(0 if ok else 1)
EOF
