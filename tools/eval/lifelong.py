#!/usr/bin/python3
"""Long-term ("lifelong map") simulation driver for the SGLC server.

For each arm (off: map.max_versions_per_place=0, on: =2; both map.session_retention_h=0) a fresh server and
database; every epoch renders two sessions through one world with sglc-sim (robot "car": HDL-64, robot "bot":
VLP-16, drifting odometry), ingests every frame with query on into map "district", compacts, and records stats,
server RSS, ingest latencies and pose-graph solve times. After the last epoch a "visitor" (HDL-64) relocalizes
(Query, not stored) at later epochs. Renders are made once per epoch and shared by the arms. The district
follows a KITTI path (--path: 00 by default; a fitting or validation path only).

    PYTHONPATH=build/python /usr/bin/python3 tools/eval/lifelong.py --epochs 3 --out /tmp/ll

Results: OUT/results.json, OUT/<arm>.csv (one row per epoch), OUT/<arm>_reloc.csv, OUT/summary.txt.
Relocalization truth: horizontal (xy) distance below --positive-m (3 m, tools/eval's positive_m default).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
BIN = os.path.join(REPO, "build", "bin")
sys.path.insert(0, os.path.join(REPO, "build", "python"))
import sglc  # noqa: E402

# The KITTI path (ground-truth poses from the shared data beside the repository) and its calibration: 00's own
# calib.txt, KITTI's 04-10 Tr for the others (as tools/eval does). Only the fitting paths (00, 05, 08) and the
# validation paths (07, 09, 10) may be run; every other path is kept for checks this project does not see.
DATA = os.environ.get("SGLC_DATA", os.path.join(REPO, "..", "shared", "data"))
PATHS = ("00", "05", "08", "07", "09", "10")
POSES = os.path.join(DATA, "kitti_odometry_gt_poses", "poses", "00.txt")
CALIB = os.path.join(DATA, "semantickitti_scans", "sequences", "00", "calib.txt")


def use_path(path):
    global POSES, CALIB
    if path not in PATHS:
        sys.exit(f"lifelong.py: --path {path!r}: only {', '.join(PATHS)} (fitting and validation paths)")
    POSES = os.path.join(DATA, "kitti_odometry_gt_poses", "poses", f"{path}.txt")
    if path != "00":
        CALIB = os.path.join(REPO, "tools", "sim", "calib", "kitti-04-10-calib.txt")
SEED = 11
MAP = "district"
ROBOTS = (("car", "hdl64"), ("bot", "vlp16"))
ARMS = {"off": 0, "on": 2}


def log(msg):
    print(time.strftime("%H:%M:%S"), msg, flush=True)


def pct(values, q):
    return float(np.percentile(values, q)) if len(values) else None


def read_poses(path):
    rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    out = np.tile(np.eye(4), (len(rows), 1, 1))
    out[:, :3, :4] = rows.reshape(-1, 3, 4)
    return out


# ----------------------------------------------------------------------------------------------------------
# Rendering


def render(out_dir, epoch, sensor, frames, odom_noise, threads):
    """Renders one session with sglc-sim into out_dir (skipped when a finished render is there)."""
    done = os.path.join(out_dir, ".done")
    if os.path.exists(done):
        return out_dir
    if os.path.exists(out_dir):
        shutil.rmtree(out_dir)
    os.makedirs(os.path.dirname(out_dir), exist_ok=True)
    cmd = [os.path.join(BIN, "sglc-sim"), "--poses", POSES, "--calib", CALIB, "--seed", str(SEED), "--realistic",
           "--epoch", str(epoch), "--frames", frames, "--sensor", sensor, "--out", out_dir, "--quiet",
           "--threads", str(threads)]
    if odom_noise > 0:
        cmd += ["--odom-noise", str(odom_noise)]
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"sglc-sim failed ({r.returncode}): {' '.join(cmd)}\n{r.stdout}")
    with open(done, "w") as f:
        f.write(" ".join(cmd) + "\n")
    return out_dir


def drop_scans(render_dir):
    """Deletes a render's point clouds and labels, keeping its small text files (poses, odometry, frames)."""
    for sub in ("velodyne", "labels"):
        shutil.rmtree(os.path.join(render_dir, sub), ignore_errors=True)


def frame_count(render_dir):
    with open(os.path.join(render_dir, "frames.txt")) as f:
        return sum(1 for line in f if line.strip())


# ----------------------------------------------------------------------------------------------------------
# Server


class Server:
    def __init__(self, arm, versions, out_dir, retention_h, extra_sets):
        self.arm = arm
        self.dir = os.path.join(out_dir, arm)
        if os.path.exists(self.dir):
            shutil.rmtree(self.dir)
        os.makedirs(self.dir)
        self.log_path = os.path.join(self.dir, "server.log")
        cmd = [os.path.join(BIN, "sglc-server"), "--listen", "127.0.0.1:0", "--db",
               os.path.join(self.dir, "db", "x.db"), "--sync-normal",
               "--set", f"map.max_versions_per_place={versions}",
               "--set", f"map.session_retention_h={retention_h}"]
        for s in extra_sets:
            cmd += ["--set", s]
        self.cmd = cmd
        self.log_file = open(self.log_path, "wb")
        self.proc = subprocess.Popen(cmd, stdout=self.log_file, stderr=subprocess.STDOUT)
        self.port = None
        deadline = time.time() + 60
        while self.port is None:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server {arm} exited with {self.proc.returncode}; see {self.log_path}")
            if time.time() > deadline:
                raise RuntimeError(f"server {arm} did not listen within 60 s; see {self.log_path}")
            with open(self.log_path, "rb") as f:
                for line in f:
                    ev = parse_line(line)
                    if ev and ev.get("event") == "listening":
                        self.port = int(ev["port"])
                        break
            time.sleep(0.1)
        self.client = sglc.Client(f"127.0.0.1:{self.port}", timeout=600)

    def rss_kb(self):
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        return None

    def cpu_s(self):
        with open(f"/proc/{self.proc.pid}/stat") as f:
            parts = f.read().rsplit(")", 1)[1].split()
        return (int(parts[11]) + int(parts[12])) / os.sysconf("SC_CLK_TCK")

    def log_offset(self):
        self.log_file.flush()
        return os.path.getsize(self.log_path)

    def log_events(self, begin, end=None):
        with open(self.log_path, "rb") as f:
            f.seek(begin)
            data = f.read() if end is None else f.read(end - begin)
        return [e for e in (parse_line(line) for line in data.splitlines()) if e is not None]

    def stop(self):
        try:
            self.client.close()
        except Exception:
            pass
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log_file.close()


_JSON_START = re.compile(rb"\{")


def parse_line(line):
    """The JSON object of a server log line (the line may carry a prefix), or None."""
    line = line.strip()
    m = _JSON_START.search(line)
    if not m:
        return None
    try:
        ev = json.loads(line[m.start():])
    except ValueError:
        return None
    return ev if isinstance(ev, dict) else None


# ----------------------------------------------------------------------------------------------------------
# Ingest one epoch into one arm


def ingest_epoch(server, epoch, renders, stamps_base):
    c = server.client
    wall_ms, total_ms, loops_found, kept, placed, warnings = [], [], 0, 0, 0, {}
    off0 = server.log_offset()
    t0 = time.time()
    for robot, rdir in renders:
        n = frame_count(rdir)
        odom = read_poses(os.path.join(rdir, "odometry.txt"))
        times = np.loadtxt(os.path.join(rdir, "times.txt"), ndmin=1)
        for k in range(n):
            pts, lab = sglc.read_kitti_scan(os.path.join(rdir, "velodyne", f"{k:06d}.bin"),
                                            os.path.join(rdir, "labels", f"{k:06d}.label"))
            req = c.ingest_request(MAP, robot, f"e{epoch}", k, pts, lab, stamp=stamps_base + float(times[k]),
                                   odometry_pose=odom[k], query=True)
            t = time.perf_counter()
            r = c.ingest_message(req)
            wall_ms.append((time.perf_counter() - t) * 1e3)
            total_ms.append(r.timing.total_ms)
            loops_found += sum(1 for l in r.loops if l.verified)
            kept += int(r.kept)
            placed += int(r.place_id != 0)
            for w in r.warnings:
                key = w.split(":")[0][:80]
                warnings[key] = warnings.get(key, 0) + 1
    ingest_s = time.time() - t0
    t1 = time.time()
    comp = c.compact(MAP)
    compact_s = time.time() - t1
    st = c.stats(MAP)
    return {
        "epoch": epoch, "ingest_s": ingest_s, "compact_s": compact_s, "log_begin": off0,
        "ingested": len(wall_ms), "verified_loops": loops_found, "placed_at_ingest": placed, "kept_at_ingest": kept,
        "ingest_warnings": warnings,
        "wall_ms": wall_ms, "total_ms": total_ms,
        "compaction": vars(comp),
        "stats": {k: getattr(st, k) for k in ("scans", "index_entries", "db_bytes", "fingerprint_bytes", "places",
                                              "versions", "retired_scans", "retired_bytes", "sessions",
                                              "pose_graph_failed", "pose_graph_error")},
        "rss_kb": server.rss_kb(), "server_cpu_s": server.cpu_s(),
    }


def finish_epoch_logs(server, rec, end):
    """Pose-graph solves and warnings logged from the epoch's start up to `end` (the next epoch's start)."""
    solves, events = [], {}
    for ev in server.log_events(rec["log_begin"], end):
        name = ev.get("event")
        if name == "optimised" and ev.get("map") == MAP:
            solves.append({"ms": ev.get("ms"), "global": ev.get("global"), "nodes": ev.get("nodes"),
                           "loops": ev.get("loops"), "converged": ev.get("converged")})
        level = str(ev.get("level", "")).lower()
        if name in ("place_not_recorded", "loop_not_recorded") or level in ("warn", "warning", "error", "critical"):
            events[name or level] = events.get(name or level, 0) + 1
    rec["solves"] = solves
    rec["log_events"] = events


def summarise_epoch(rec, dim):
    ms = [s["ms"] for s in rec["solves"] if s["ms"] is not None]
    st = rec["stats"]
    return {
        "epoch": rec["epoch"], "scans": st["scans"], "index_entries": st["index_entries"],
        "index_vector_bytes": st["index_entries"] * dim * 4, "db_bytes": st["db_bytes"],
        "fingerprint_bytes": st["fingerprint_bytes"], "places": st["places"], "versions": st["versions"],
        "retired_scans": st["retired_scans"], "retired_bytes": st["retired_bytes"], "rss_kb": rec["rss_kb"],
        "server_cpu_s": round(rec["server_cpu_s"], 2),
        "ingested": rec["ingested"], "verified_loops": rec["verified_loops"],
        "placed_at_ingest": rec["placed_at_ingest"], "kept_at_ingest": rec["kept_at_ingest"],
        "compact_retired": rec["compaction"]["retired"], "compact_loops_moved": rec["compaction"]["loops_moved"],
        "compact_loops_dropped": rec["compaction"]["loops_dropped"],
        "compact_open_sessions": rec["compaction"]["open_sessions"],
        "compact_promoted": rec["compaction"]["promoted"], "compact_demoted": rec["compaction"]["demoted"],
        "total_ms_p50": pct(rec["total_ms"], 50), "total_ms_p99": pct(rec["total_ms"], 99),
        "wall_ms_p50": pct(rec["wall_ms"], 50), "wall_ms_p99": pct(rec["wall_ms"], 99),
        "solves": len(ms), "solve_ms_p50": pct(ms, 50), "solve_ms_p99": pct(ms, 99),
        "solve_ms_max": max(ms) if ms else None,
        "ingest_s": round(rec["ingest_s"], 2), "compact_s": round(rec["compact_s"], 3),
        "log_events": json.dumps(rec["log_events"], sort_keys=True),
        "ingest_warnings": json.dumps(rec["ingest_warnings"], sort_keys=True),
    }


# ----------------------------------------------------------------------------------------------------------
# Relocalization


def relocalize(server, qdir, qepoch, qframes_tag, truth, positive_m, negative_m):
    """Every frame of the visitor's render queries the map (not stored). truth[(robot, session, seq)] -> xy."""
    c = server.client
    qposes = read_poses(os.path.join(qdir, "poses.txt"))
    map_xy = np.array(list(truth.values())) if truth else np.zeros((0, 2))
    rows = []
    for k in range(frame_count(qdir)):
        pts, lab = sglc.read_kitti_scan(os.path.join(qdir, "velodyne", f"{k:06d}.bin"),
                                        os.path.join(qdir, "labels", f"{k:06d}.label"))
        p = qposes[k, :2, 3]
        nearest = float(np.min(np.linalg.norm(map_xy - p, axis=1))) if len(map_xy) else float("inf")
        t = time.perf_counter()
        r = c.query(MAP, points=pts, labels=lab, robot="visitor", session=f"q{qepoch}", seq=k)
        wall = (time.perf_counter() - t) * 1e3
        top = next((x for x in r.candidates if x.verified), None)
        row = {"query_epoch": qepoch, "frames": qframes_tag, "frame": k, "nearest_map_m": round(nearest, 3),
               "has_true": nearest < positive_m, "wall_ms": round(wall, 2), "total_ms": round(r.timing.total_ms, 2),
               "verified": top is not None, "robot": "", "session": "", "seq": -1, "distance_m": None,
               "probability": None, "outcome": "none"}
        if top is not None:
            key = (top.robot, top.session, top.seq)
            row.update(robot=top.robot, session=top.session, seq=top.seq, probability=top.probability)
            if key in truth:
                d = float(np.linalg.norm(truth[key] - p))
                row["distance_m"] = round(d, 3)
                row["outcome"] = "true" if d < positive_m else ("false" if d >= negative_m else "between")
            else:
                row["outcome"] = "unknown_key"
        rows.append(row)
    n = len(rows)
    with_place = sum(r["has_true"] for r in rows)
    verified = sum(r["verified"] for r in rows)
    true = sum(r["outcome"] == "true" for r in rows)
    false = sum(r["outcome"] == "false" for r in rows)
    return rows, {
        "query_epoch": qepoch, "frames": qframes_tag, "queries": n, "queries_with_true_place": with_place,
        "verified_top1": verified, "correct_top1": true, "false_top1": false,
        "between_top1": sum(r["outcome"] == "between" for r in rows),
        "recall_at_1": true / n if n else None,                     # correct top-1 / queries (the brief's)
        "precision": true / verified if verified else None,         # correct / verified top-1
        "recall_at_1_with_place": true / with_place if with_place else None,  # tools/eval's definition
        "precision_eval": true / (true + false) if true + false else None,    # tools/eval: band excluded
        "correct_top1_5m": sum(r["distance_m"] is not None and r["distance_m"] < 5.0 for r in rows),
        "query_total_ms_p50": pct([r["total_ms"] for r in rows], 50),
        "query_total_ms_p99": pct([r["total_ms"] for r in rows], 99),
        "query_wall_ms_p50": pct([r["wall_ms"] for r in rows], 50),
        "query_wall_ms_p99": pct([r["wall_ms"] for r in rows], 99),
    }


# ----------------------------------------------------------------------------------------------------------
# Summary


def fmt_bytes(b):
    return "-" if b is None else f"{b / 2**20:.1f} MiB"


def f1(x, nd=1):
    return "-" if x is None else f"{x:.{nd}f}"


def summary_table(results, report_epochs):
    arms = list(results["arms"])
    out = []
    for e in report_epochs:
        out.append(f"\n== after epoch {e} (index {e - 1}) ==")
        out.append(f"{'metric':<34}" + "".join(f"{a:>26}" for a in arms))

        def row(name, fn):
            vals = []
            for a in arms:
                rows = results["arms"][a]["epochs"]
                r = rows[e - 1] if len(rows) >= e else None
                vals.append(fn(r) if r else "-")
            out.append(f"{name:<34}" + "".join(f"{v:>26}" for v in vals))

        row("scans kept", lambda r: str(r["scans"]))
        row("places / versions", lambda r: f"{r['places']} / {r['versions']}")
        row("retired scans (total)", lambda r: str(r["retired_scans"]))
        row("DB bytes", lambda r: fmt_bytes(r["db_bytes"]))
        row("index entries", lambda r: str(r["index_entries"]))
        row("index vectors (entries x dim x 4)", lambda r: fmt_bytes(r["index_vector_bytes"]))
        row("server RSS", lambda r: fmt_bytes(r["rss_kb"] * 1024))
        row("ingest server total ms p50/p99", lambda r: f"{f1(r['total_ms_p50'])} / {f1(r['total_ms_p99'])}")
        row("ingest client wall ms p50/p99", lambda r: f"{f1(r['wall_ms_p50'])} / {f1(r['wall_ms_p99'])}")
        row("pose-graph solves (n)", lambda r: str(r["solves"]))
        row("pose-graph ms/solve p50/p99", lambda r: f"{f1(r['solve_ms_p50'])} / {f1(r['solve_ms_p99'])}")
        row("compact retired / moved / dropped",
            lambda r: f"{r['compact_retired']} / {r['compact_loops_moved']} / {r['compact_loops_dropped']}")
        row("compact promoted / demoted", lambda r: f"{r['compact_promoted']} / {r['compact_demoted']}")
    out.append("\n== relocalization (visitor, HDL-64; Query, not stored) ==")
    out.append(f"{'query set':<34}" + "".join(f"{a:>26}" for a in arms))
    keys = []
    for a in arms:
        for s in results["arms"][a].get("relocalization", []):
            if (s["query_epoch"], s["frames"]) not in keys:
                keys.append((s["query_epoch"], s["frames"]))
    for qe, fr in keys:
        vals, vals2, vals3, vals4, vals5 = [], [], [], [], []
        for a in arms:
            s = next((x for x in results["arms"][a].get("relocalization", [])
                      if x["query_epoch"] == qe and x["frames"] == fr), None)
            if s is None:
                for v in (vals, vals2, vals3, vals4, vals5):
                    v.append("-")
                continue
            vals.append(f"R@1 {f1(s['recall_at_1'], 3)} P {f1(s['precision'], 3)}")
            vals2.append(f"{s['correct_top1']}/{s['verified_top1']}/{s['queries']} ({s['queries_with_true_place']} w/ place)")
            vals3.append(f"R@1wp {f1(s['recall_at_1_with_place'], 3)} Pev {f1(s['precision_eval'], 3)}")
            c5 = s["correct_top1_5m"]
            vals4.append(f"R@1 {c5 / s['queries']:.3f} P {c5 / s['verified_top1'] if s['verified_top1'] else 0:.3f}")
            vals5.append(f"{f1(s['query_total_ms_p50'])}/{f1(s['query_total_ms_p99'])} | "
                         f"{f1(s['query_wall_ms_p50'])}/{f1(s['query_wall_ms_p99'])}")
        out.append(f"{f'epoch {qe} frames {fr}':<34}" + "".join(f"{v:>26}" for v in vals))
        out.append(f"{'  correct/verified/queries':<34}" + "".join(f"{v:>26}" for v in vals2))
        out.append(f"{'  eval-style (w/ place, band out)':<34}" + "".join(f"{v:>26}" for v in vals3))
        out.append(f"{'  at 5 m horizontal instead':<34}" + "".join(f"{v:>26}" for v in vals4))
        out.append(f"{'  query ms p50/p99 server|wall':<34}" + "".join(f"{v:>26}" for v in vals5))
    off = results["arms"].get("off", {}).get("epochs", [])
    if off:
        one = off[0]["scans"]
        out.append(f"\none epoch stores (off arm, scans after epoch 1): {one}")
        for a in arms:
            rows = results["arms"][a]["epochs"]
            if rows:
                out.append(f"  {a}: {rows[-1]['scans']} scans after epoch {len(rows)} = "
                           f"{rows[-1]['scans'] / one:.2f} x one epoch")
    return "\n".join(out)


# ----------------------------------------------------------------------------------------------------------


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--epochs", type=int, default=100)
    ap.add_argument("--path", default="00", help="KITTI path the district follows (00, 05, 08; 07, 09, 10)")
    ap.add_argument("--frames", default="0:1200:15", help="district keyframes (sglc-sim --frames)")
    ap.add_argument("--query-frames", action="append", default=None,
                    help="visitor frames (repeatable; default 7:1200:30)")
    ap.add_argument("--query-epochs", default="100,365")
    ap.add_argument("--arms", default="off,on", help="comma-separated of off (versions 0), on (versions 2)")
    ap.add_argument("--versions-on", type=int, default=2)
    ap.add_argument("--retention-h", type=float, default=0)
    ap.add_argument("--odom-noise", type=float, default=0.01)
    ap.add_argument("--positive-m", type=float, default=3.0, help="tools/eval positive_m default")
    ap.add_argument("--negative-m", type=float, default=20.0, help="tools/eval negative_m default")
    ap.add_argument("--parallel", action="store_true", help="ingest the arms at once (one thread each)")
    ap.add_argument("--keep-renders", action="store_true", help="keep point clouds after use")
    ap.add_argument("--sim-threads", type=int, default=2)
    ap.add_argument("--set", action="append", default=[], help="extra server --set KEY=VALUE for every arm")
    ap.add_argument("--stop-file", default="", help="when this file exists at the end of a --stop-epochs epoch, "
                    "stop there and relocalize (announced in the log and results)")
    ap.add_argument("--stop-epochs", default="50", help="comma-separated epoch counts where --stop-file is checked")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    use_path(a.path)
    qsets = a.query_frames or ["7:1200:30"]
    arms = [x for x in a.arms.split(",") if x]
    versions = {"off": 0, "on": a.versions_on}
    os.makedirs(a.out, exist_ok=True)
    renders_root = os.path.join(a.out, "renders")
    results = {"config": {k: v for k, v in vars(a).items()}, "command": sys.argv, "started": time.time(),
               "poses": POSES, "calib": CALIB, "seed": SEED, "arms": {}}
    servers = {}
    try:
        for arm in arms:
            servers[arm] = Server(arm, versions[arm], a.out, a.retention_h, a.set)
            info = servers[arm].client.server_info()
            servers[arm].client.create_map(MAP)
            results["arms"][arm] = {"versions": versions[arm], "server_cmd": servers[arm].cmd,
                                    "port": servers[arm].port, "descriptor_dim": info.descriptor_dim,
                                    "server_version": info.version, "loop_model": info.loop_model,
                                    "min_probability": info.min_probability, "epochs": [], "raw": []}
            log(f"arm {arm}: server pid {servers[arm].proc.pid} port {servers[arm].port} "
                f"dim {info.descriptor_dim} version {info.version}")
        truth = {}  # (robot, session, seq) -> xy of the true LiDAR pose
        pending = {arm: None for arm in arms}
        for e in range(a.epochs):
            te = time.time()
            renders = []
            for robot, sensor in ROBOTS:
                d = render(os.path.join(renders_root, f"e{e}", robot), e, sensor, a.frames, a.odom_noise,
                           a.sim_threads)
                renders.append((robot, d))
                poses = read_poses(os.path.join(d, "poses.txt"))
                for k in range(len(poses)):
                    truth[(robot, f"e{e}", k)] = poses[k, :2, 3].copy()
            render_s = time.time() - te
            recs = {}

            def run(arm):
                srv = servers[arm]
                if pending[arm] is not None:
                    prev = pending[arm]
                    finish_epoch_logs(srv, prev, srv.log_offset())
                    store_epoch(results, arm, prev)
                recs[arm] = ingest_epoch(srv, e, renders, stamps_base=e * 86400.0)
                pending[arm] = recs[arm]

            if a.parallel:
                threads = [threading.Thread(target=run, args=(arm,)) for arm in arms]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                missing = [arm for arm in arms if arm not in recs]
                if missing:
                    raise RuntimeError(f"epoch {e}: arms {missing} failed (see the traceback above)")
            else:
                for arm in arms:
                    run(arm)
            if not a.keep_renders:
                for _, d in renders:
                    drop_scans(d)
            msg = " | ".join(f"{arm}: scans {recs[arm]['stats']['scans']} versions {recs[arm]['stats']['versions']} "
                             f"retired {recs[arm]['compaction']['retired']} p50 {pct(recs[arm]['total_ms'], 50):.0f} ms "
                             f"ingest {recs[arm]['ingest_s']:.0f}s rss {recs[arm]['rss_kb'] // 1024} MiB"
                             for arm in arms)
            log(f"epoch {e}: render {render_s:.1f}s total {time.time() - te:.0f}s | {msg}")
            write_outputs(results, a.out, partial=True)
            stops = {int(x) for x in a.stop_epochs.split(",") if x}
            if a.stop_file and e + 1 in stops and e + 1 < a.epochs and os.path.exists(a.stop_file):
                log(f"STOP: {a.stop_file} exists: stopping after {e + 1} of {a.epochs} epochs")
                results["stopped_early_after"] = e + 1
                break
        # Let trailing solves land, then close the last epoch's records.
        time.sleep(2)
        for arm in arms:
            if pending[arm] is not None:
                finish_epoch_logs(servers[arm], pending[arm], servers[arm].log_offset())
                store_epoch(results, arm, pending[arm])
                pending[arm] = None
        # Relocalization.
        for arm in arms:
            results["arms"][arm]["relocalization"] = []
            results["arms"][arm]["relocalization_rows"] = []
        for qe in [int(x) for x in a.query_epochs.split(",") if x]:
            for qf in qsets:
                tag = qf.replace(":", "-")
                qdir = render(os.path.join(renders_root, f"visitor_q{qe}_{tag}"), qe, "hdl64", qf, 0, a.sim_threads)
                for arm in arms:
                    rows, s = relocalize(servers[arm], qdir, qe, qf, truth, a.positive_m, a.negative_m)
                    results["arms"][arm]["relocalization"].append(s)
                    results["arms"][arm]["relocalization_rows"] += rows
                    log(f"relocalize {arm} epoch {qe} frames {qf}: R@1 {s['recall_at_1']} P {s['precision']} "
                        f"({s['correct_top1']}/{s['verified_top1']}/{s['queries']})")
                if not a.keep_renders:
                    drop_scans(qdir)
        for arm in arms:
            st = servers[arm].client.stats(MAP)
            results["arms"][arm]["final_stats"] = vars(st)
            results["arms"][arm]["final_rss_kb"] = servers[arm].rss_kb()
            results["arms"][arm]["final_server_cpu_s"] = servers[arm].cpu_s()
    finally:
        for arm, srv in servers.items():
            if arm in results["arms"]:
                results["arms"][arm]["server_exit"] = None
            srv.stop()
            if arm in results["arms"]:
                results["arms"][arm]["server_exit"] = srv.proc.returncode
        results["finished"] = time.time()
        write_outputs(results, a.out, partial=False)
    n = min(len(results["arms"][arm]["epochs"]) for arm in arms)
    report = sorted({x for x in (10, 50, 100) if x <= n} | {n})
    text = summary_table(results, report)
    with open(os.path.join(a.out, "summary.txt"), "w") as f:
        f.write(text + "\n")
    print(text)


def store_epoch(results, arm, rec):
    dim = results["arms"][arm]["descriptor_dim"]
    results["arms"][arm]["epochs"].append(summarise_epoch(rec, dim))
    results["arms"][arm]["raw"].append({"epoch": rec["epoch"], "wall_ms": [round(x, 2) for x in rec["wall_ms"]],
                                        "total_ms": [round(x, 2) for x in rec["total_ms"]],
                                        "solves": rec["solves"], "compaction": rec["compaction"]})


def write_outputs(results, out, partial):
    path = os.path.join(out, "results.json")
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(dict(results, partial=partial), f, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
    os.replace(tmp, path)
    for arm, r in results["arms"].items():
        if r["epochs"]:
            with open(os.path.join(out, f"{arm}.csv"), "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=list(r["epochs"][0]))
                w.writeheader()
                w.writerows(r["epochs"])
        if r.get("relocalization_rows"):
            with open(os.path.join(out, f"{arm}_reloc.csv"), "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=list(r["relocalization_rows"][0]))
                w.writeheader()
                w.writerows(r["relocalization_rows"])


if __name__ == "__main__":
    main()
