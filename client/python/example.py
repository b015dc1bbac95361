#!/usr/bin/python3
"""sglc_client example: two robots see the same place; the second one finds the inter-robot loop.

Robot "alice" stores KITTI 00 frame 52, robot "bob" stores frame 4501 (3 m away, 4449 frames later) and
asks for loops with other robots as it does. Then alice's scan is queried by id, and the map is listed.

    SGLC_PYTHON_STUBS=build/python PYTHONPATH=client/python /usr/bin/python3 client/python/example.py \\
        --server 127.0.0.1:50051 [--data ../shared/data/semantickitti_scans/sequences/00]

Needs a running sglc-server. Exits non-zero with one line on stderr on any failure.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # run from anywhere: find sglc_client beside us

import numpy as np  # noqa: E402

import sglc_client  # noqa: E402

REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
DEFAULT_DATA = os.path.normpath(os.path.join(REPO, "..", "shared", "data", "semantickitti_scans", "sequences", "00"))


def read_scan_numpy(seq_dir, frame):
    """KITTI .bin + SemanticKITTI .label as numpy arrays: points (N, 3) float32, labels (N,) uint32."""
    cloud = np.fromfile(os.path.join(seq_dir, "velodyne", frame + ".bin"), dtype="<f4").reshape(-1, 4)
    labels = np.fromfile(os.path.join(seq_dir, "labels", frame + ".label"), dtype="<u4")
    return cloud[:, :3], labels


def describe(loop):
    T = sglc_client.to_matrix(loop.t_query_candidate)
    t = T[:3, 3]
    return (f"scan {loop.scan_id} (robot {loop.robot}, session {loop.session}, seq {loop.seq}): "
            f"score {loop.score:.3f}, {loop.inliers} inliers, t = ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}) m")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--server", default="127.0.0.1:50051")
    ap.add_argument("--token", default=os.environ.get("SGLC_TOKEN"))
    ap.add_argument("--map", default="example")
    ap.add_argument("--data", default=DEFAULT_DATA, help="SemanticKITTI sequence directory with frames 000052 and 004501")
    ap.add_argument("--stubs", help="directory holding sglc/v1/sglc_pb2.py (default: $SGLC_PYTHON_STUBS, build/python)")
    args = ap.parse_args()

    for frame in ("000052", "004501"):
        if not os.path.isfile(os.path.join(args.data, "velodyne", frame + ".bin")):
            sys.exit(f"example.py: error: {args.data} has no velodyne/{frame}.bin (give --data)")

    with sglc_client.Client(args.server, token=args.token, stubs_path=args.stubs) as client:
        client.ensure_map(args.map)
        for robot in ("alice", "bob"):  # start from a clean slate when run again
            try:
                client.delete_robot(args.map, robot)
            except sglc_client.SglcError as e:
                if e.code_name != "NOT_FOUND":
                    raise

        # alice: numpy arrays.
        points, labels = read_scan_numpy(args.data, "000052")
        a = client.ingest(args.map, "alice", "run1", 52, points, labels)
        print(f"alice stored frame 52 as scan {a.scan_id} ({len(points)} points, {a.timing.total_ms:.0f} ms)")

        # bob: packed bytes, and a query for other robots' scans before storing.
        points_bytes, labels_bytes = sglc_client.read_kitti_scan(
            os.path.join(args.data, "velodyne", "004501.bin"), os.path.join(args.data, "labels", "004501.label"))
        b = client.ingest(args.map, "bob", "run1", 4501, points_bytes, labels_bytes, query=True, scope="other", top_k=3)
        print(f"bob stored frame 4501 as scan {b.scan_id}; {len(b.loops)} inter-robot loop(s):")
        for loop in b.loops:
            print("  " + describe(loop))

        # The same place from alice's side, by scan id.
        q = client.query(args.map, scan_id=a.scan_id, scope="other")
        print(f"query of scan {a.scan_id}: {len(q.candidates)} candidate(s)")
        for c in q.candidates:
            print("  " + describe(c))

        robots = ", ".join(f"{r.name} ({r.scans} scans)" for r in client.list_robots(args.map))
        s = client.stats(args.map)
        print(f"map {args.map}: robots {robots}; {s.scans} scans, {s.sessions} sessions")
        return 0 if b.loops else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (sglc_client.SglcError, ImportError, OSError, ValueError) as e:
        print(f"example.py: error: {e}", file=sys.stderr)
        sys.exit(1)
