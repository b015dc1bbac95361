#!/usr/bin/python3
"""Ingest throughput with and without live-view viewers attached (sglc-server --viz-listen).

Usage: scripts/bench_viz.py [BUILD_DIR] [--rounds 3] [--frames ::4] [--viewers 10]
One server; rounds alternate a map ingested with no viewer and one ingested while VIEWERS viewers watch: all but
one are @foxglove/ws-protocol clients subscribed to every topic (keyframe points included, so ingest copies each
scan's points), the last a socket that subscribes to the map's topics and never reads again. Each round
ingests the simulator's loop route (not a KITTI path) with `sglc ingest --query` into a new map: 5 scans, then
the viewers come, then the rest is timed. Prints per round the wall time, the
server's CPU time (from /proc) per scan, the viewers' CPU and messages; then medians and ratios."""
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
args = sys.argv[1:]


def opt(name, default):
    return args[args.index(name) + 1] if name in args else default


BUILD = args[0] if args and not args[0].startswith("--") else os.path.join(ROOT, "build")
ROUNDS = int(opt("--rounds", "3"))
FRAMES = opt("--frames", "::4")
VIEWERS = int(opt("--viewers", "10"))
BIN = os.path.join(BUILD, "bin")
CLIENT = os.path.join(ROOT, "tests", "interop", "viz_client.mjs")
sys.path.insert(0, os.path.join(ROOT, "tests", "interop"))
from stalled_viewer import stalled_viewer  # noqa: E402


def cpu_seconds(pid):
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime + stime


def logged_port(log, event):
    for _ in range(600):
        for line in open(log):
            if f'"event":"{event}"' in line:
                return json.loads(line)["port"]
        time.sleep(0.05)
    sys.exit(f"the server logged no {event} line")


def metric(port, name):
    text = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=30).read().decode()
    m = re.search(rf"^{re.escape(name)} ([0-9.e+-]+)$", text, re.M)
    return float(m.group(1)) if m else 0.0


def ingest(port, m, seq, frames):
    subprocess.run([os.path.join(BIN, "sglc"), "ingest", "--server", f"127.0.0.1:{port}", "--map", m, "--robot", "a",
                    "--frames", frames, "--query", "--no-progress", seq], check=True, stdout=subprocess.DEVNULL)


def main():
    work = tempfile.mkdtemp(prefix="sglc-bench-viz-")
    seq = os.path.join(work, "seq")
    subprocess.run([os.path.join(BIN, "sglc-sim"), "--route", "loop", "--frames", FRAMES, "--out", seq], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    frames = len(os.listdir(os.path.join(seq, "velodyne")))
    log = os.path.join(work, "server.log")
    server = subprocess.Popen([os.path.join(BIN, "sglc-server"), "--db", os.path.join(work, "bench.db"), "--listen",
                               "127.0.0.1:0", "--viz-listen", "127.0.0.1:0", "--metrics-listen", "127.0.0.1:0",
                               "--sync-normal"], stdout=open(log, "w"), stderr=subprocess.STDOUT)
    try:
        grpc_port, viz_port, metrics_port = (logged_port(log, e) for e in ("listening", "viz", "metrics"))
        rows = []
        for r in range(ROUNDS):
            for viewers in (0, VIEWERS):
                watchers, stalled = None, None
                m = f"bench{r}-{viewers}"
                # The map's first scans before the viewers come, so that the stalled one subscribes to its topics.
                ingest(grpc_port, m, seq, "0:5")
                if viewers:
                    watchers = subprocess.Popen(["node", CLIENT, f"ws://127.0.0.1:{viz_port}/", "--hold", "--viewers",
                                                 str(viewers - 1)], stdout=subprocess.PIPE, text=True)
                    while metric(metrics_port, "sglc_viz_viewers") < viewers - 1:
                        time.sleep(0.2)
                    stalled, _ = stalled_viewer(viz_port, f"/sglc/{m}/")
                    while metric(metrics_port, "sglc_viz_viewers") < viewers:
                        time.sleep(0.2)
                skipped0 = metric(metrics_port, 'sglc_viz_messages_total{result="skipped"}')
                cpu0, t0 = cpu_seconds(server.pid), time.monotonic()
                ingest(grpc_port, m, seq, "5:")
                wall, cpu = time.monotonic() - t0, cpu_seconds(server.pid) - cpu0
                scans = frames - 5
                row = {"round": r, "viewers": viewers, "wall_s": wall, "scans_per_s": scans / wall,
                       "server_cpu_ms_per_scan": 1000 * cpu / scans}
                if watchers:
                    viewer_cpu = cpu_seconds(watchers.pid)
                    watchers.send_signal(signal.SIGTERM)
                    seen = json.loads(watchers.communicate(timeout=60)[0].strip().splitlines()[-1])
                    stalled.close()
                    row.update(viewer_cpu_s=viewer_cpu, messages_per_viewer=statistics.median(seen["messages"]),
                               skipped=metric(metrics_port, 'sglc_viz_messages_total{result="skipped"}') - skipped0)
                rows.append(row)
                print(json.dumps(row), flush=True)
        summary = {}
        for viewers in (0, VIEWERS):
            mine = [x for x in rows if x["viewers"] == viewers]
            summary[viewers] = {k: statistics.median(x[k] for x in mine)
                                for k in ("scans_per_s", "server_cpu_ms_per_scan")}
        print(json.dumps({"scans": frames - 5, "rounds": ROUNDS, "median": summary,
                          "throughput_ratio": summary[VIEWERS]["scans_per_s"] / summary[0]["scans_per_s"],
                          "server_cpu_ratio": summary[VIEWERS]["server_cpu_ms_per_scan"] /
                          summary[0]["server_cpu_ms_per_scan"]}))
    finally:
        server.send_signal(signal.SIGTERM)
        server.wait(timeout=60)


if __name__ == "__main__":
    main()
