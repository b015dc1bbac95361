#!/usr/bin/env python3
"""Lifelong maps through a real sglc-server (docs/LIFELONG.md): places and versions answered at ingest,
`sglc compact` retiring what ended sessions added beyond each place's versions, the pose graph solved again
without them, relocalization as good after as before, totals that survive a restart, and nothing retired by a
server whose policy is off.

Usage: test_lifelong.py SERVER_BINARY PYTHON_STUB_DIR SIM_BINARY SGLC_CLI
"""
import json
import os
import signal
import subprocess
import sys
import time

try:
    import grpc
    import numpy as np
except ImportError as e:
    print(f"SKIP: {e} (needs Debian's python3-grpcio and python3-numpy; run with /usr/bin/python3)")
    sys.exit(77)

SERVER, STUBS, SIM, CLI = sys.argv[1:5]
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
from harness import Server  # noqa: E402

pb, rpc = harness.configure(SERVER, STUBS)


def render(tmp, name, *args):
    out = os.path.join(tmp, name)
    subprocess.run([SIM, "--route", "loop", "--odom-noise", "0.02", "--quiet", "--out", out, *args], check=True,
                   stdout=subprocess.DEVNULL, timeout=600)
    Tr = np.eye(4)
    for line in open(os.path.join(out, "calib.txt")):
        if line.startswith("Tr:"):
            Tr[:3, :] = np.array([float(v) for v in line.split()[1:13]]).reshape(3, 4)

    def poses(f):
        rows = np.loadtxt(os.path.join(out, f)).reshape(-1, 3, 4)
        Ts = np.tile(np.eye(4), (len(rows), 1, 1))
        Ts[:, :3, :] = rows
        return [np.linalg.inv(Tr) @ T @ Tr for T in Ts]

    frames = sorted(int(f[:-4]) for f in os.listdir(os.path.join(out, "velodyne")))
    return out, frames, poses("poses.txt"), poses("odometry.txt")


def scan(seq_dir, frame):
    name = f"{frame:06d}"
    pts = np.fromfile(os.path.join(seq_dir, "velodyne", name + ".bin"), dtype="<f4").reshape(-1, 4)[:, :3]
    lab = np.fromfile(os.path.join(seq_dir, "labels", name + ".label"), dtype="<u4")
    return pb.Scan(points=np.ascontiguousarray(pts).tobytes(), labels=lab.tobytes())


def tf(T):
    return pb.Transform(m=[float(v) for v in T.reshape(-1)])


def relocalization(s, queries, truth_of):
    """Share of the queries whose top-1 verified candidate is within 5 m of where the query truly is."""
    q_dir, q_frames, q_gt, _ = queries
    right = 0
    for i, f in enumerate(q_frames):
        r = s.loop.Query(pb.QueryRequest(map="m", scan=scan(q_dir, f), options=pb.QueryOptions(top_k=1)), timeout=120)
        top = [c for c in r.candidates if c.verified][:1]
        if top and np.linalg.norm(truth_of(top[0])[:2, 3] - q_gt[i][:2, 3]) < 5.0:
            right += 1
    return right / len(q_frames)


def test_lifelong(tmp):
    # Two days of the built-in route (every 8th frame): day 1 by robot a, day 2 (other parked cars and foliage)
    # by robot b; queries from a third day at other frames.
    days = {"a": render(tmp, "day1", "--frames", "::8"), "b": render(tmp, "day2", "--frames", "::8", "--epoch", "5")}
    queries = render(tmp, "day3", "--frames", "4::32", "--epoch", "9")
    db = os.path.join(tmp, "life.db")
    cfg = os.path.join(tmp, "life.yaml")
    with open(cfg, "w") as f:
        # The server's own compaction off: this part compacts with sglc compact, however long the drives take.
        f.write("map:\n  max_versions_per_place: 1\n  session_retention_h: 0\n  compact_interval_s: 0\n"
                "pose_graph:\n  odometry_sigma_per_m: 0.02\n  odometry_sigma_deg_per_m: 0.01\n")
    s = Server(db, ["--config", cfg])
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"))
        truth, kept = {}, {}
        for robot, (seq_dir, frames, gt, odom) in days.items():
            reqs = [pb.IngestRequest(key=pb.ScanKey(map="m", robot=robot, session="day", seq=f),
                                     scan=scan(seq_dir, f), odometry_pose=tf(odom[i]), query=True,
                                     query_options=pb.QueryOptions(exclude_recent=12, top_k=3))
                    for i, f in enumerate(frames)]
            for i, r in enumerate(s.loop.IngestStream(iter(reqs), timeout=900)):
                assert r.place_id > 0, r
                truth[r.scan_id] = gt[i]
                kept[r.scan_id] = r.kept
        total = len(kept)
        surplus = sum(not k for k in kept.values())
        b_ids = [i for i in kept if i > max(truth) - len(days["b"][1])]
        b_surplus = sum(not kept[i] for i in b_ids)
        print(f"  {total} scans stored, {surplus} of them beyond their places' one version ({b_surplus} of day 2's "
              f"{len(b_ids)})")
        # Day 2 drives the streets of day 1: most of its scans relocalize into day 1's places.
        assert b_surplus > len(b_ids) // 2, (b_surplus, len(b_ids))
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert st.scans == total and st.versions == total - surplus and st.retired_scans == 0, st

        def truth_of(c):
            return truth[c.scan_id]
        before = relocalization(s, queries, truth_of)

        # Compaction from the command line: every surplus scan retires (both sessions ended: retention 0).
        events = s.graph.WatchMap(pb.WatchMapRequest(map="m"), timeout=300)
        out = subprocess.run([CLI, "compact", "--map", "m", "--json", "--server", s.addr], capture_output=True,
                             text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        c = json.loads(out.stdout)
        print(f"  compact: {c}")
        assert c["policy_on"] and c["retired"] == surplus and c["placed"] == 0, c
        assert c["loops_moved"] > 0 and c["versions"] == total - surplus and c["retired_bytes"] > 0, c
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert st.scans == total - surplus == st.index_entries == st.versions, st
        assert st.retired_scans == surplus and st.retired_bytes == c["retired_bytes"], st
        # The pose graph is solved again over the scans that stay, with the retired scans' loops moved.
        for ev in events:
            assert not ev.failed, ev.error
            if ev.nodes == total - surplus and ev.converged:
                break
        events.cancel()
        assert ev.nodes == total - surplus, ev
        poses = s.graph.GetPoses(pb.GetPosesRequest(map="m", robot="a")).poses
        assert all(p.optimised for p in poses) and {p.scan_id for p in poses} <= set(kept), "poses of retired scans"
        after = relocalization(s, queries, truth_of)
        print(f"  relocalization Recall@1 (5 m) from day 3: {before:.3f} before compaction, {after:.3f} after")
        assert after >= 0.8 and after >= before - 0.05, (before, after)
        # Nothing more to do; retired scans are gone from the listings.
        again = s.admin.Compact(pb.CompactRequest(map="m"))
        assert again.retired == 0 and again.placed == 0, again
        retired_id = next(i for i, k in kept.items() if not k)
        harness.expect_code(grpc.StatusCode.NOT_FOUND, lambda: s.admin.GetScan(pb.GetScanRequest(scan_id=retired_id)),
                            "a retired scan")
        harness.expect_code(grpc.StatusCode.NOT_FOUND, lambda: s.admin.Compact(pb.CompactRequest(map="nomap")),
                            "compaction of an unknown map")
    finally:
        s.stop(signal.SIGKILL)
    # After a crash, the totals are as they were; a server with the policy off retires nothing.
    s = Server(db)
    try:
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert st.retired_scans == surplus and st.scans == total - surplus, st
        off = s.admin.Compact(pb.CompactRequest(map="m"))
        assert not off.policy_on and off.retired == 0 and off.versions == total - surplus, off
    finally:
        assert s.stop() == 0
    # The server compacts on its own (every second here): a third day's surplus retires without sglc compact.
    with open(cfg, "w") as f:
        f.write("map:\n  max_versions_per_place: 1\n  session_retention_h: 0\n  compact_interval_s: 1\n")
    s = Server(db, ["--config", cfg])
    try:
        q_dir, q_frames, _, q_odom = queries
        reqs = [pb.IngestRequest(key=pb.ScanKey(map="m", robot="c", session="day", seq=f), scan=scan(q_dir, f),
                                 odometry_pose=tf(q_odom[i]), query=True) for i, f in enumerate(q_frames)]
        c_surplus = sum(not r.kept for r in s.loop.IngestStream(iter(reqs), timeout=900))
        assert c_surplus > len(q_frames) // 2, (c_surplus, len(q_frames))
        deadline = time.monotonic() + 300  # a bound for a stuck timer, not a speed test
        while time.monotonic() < deadline:
            st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
            if st.retired_scans == surplus + c_surplus:
                break
            time.sleep(0.2)
        assert st.retired_scans == surplus + c_surplus and st.scans == st.versions, st
        print(f"  the server's own compaction retired day 3's {c_surplus} surplus scans")
    finally:
        assert s.stop() == 0


if __name__ == "__main__":
    harness.run([test_lifelong], "sglc-lifelong-test-")
