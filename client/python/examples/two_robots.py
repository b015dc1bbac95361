#!/usr/bin/python3
"""sglc example: two robots see the same place; the second one finds the inter-robot loop.

Robot "alice" stores KITTI 00 frame 52, robot "bob" stores frame 4501 (3 m away, 4449 frames later) and
asks for loops with other robots as it does. Then alice's scan is queried by id, the map is listed, and the
same pair is matched in-process with sglc.Engine (no server).

    pip install ./client/python          # or: PYTHONPATH=build/python after building
    /usr/bin/python3 client/python/examples/two_robots.py --server 127.0.0.1:50051 \\
        [--data ../shared/data/semantickitti_scans/sequences/00]

Needs a running sglc-server. Exits non-zero with one line on stderr on any failure.
"""
import argparse
import os
import sys

import sglc

REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", ".."))
DEFAULT_DATA = os.path.normpath(os.path.join(REPO, "..", "shared", "data", "semantickitti_scans", "sequences", "00"))


def read(seq_dir, frame):
    return sglc.read_kitti_scan(os.path.join(seq_dir, "velodyne", frame + ".bin"),
                                os.path.join(seq_dir, "labels", frame + ".label"))


def describe(loop):
    t = loop.T[:3, 3]
    return (f"scan {loop.scan_id} (robot {loop.robot}, session {loop.session}, seq {loop.seq}): "
            f"score {loop.score:.3f}, {loop.inliers} inliers, t = ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}) m")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--server", default="127.0.0.1:50051")
    ap.add_argument("--token", default=os.environ.get("SGLC_TOKEN"))
    ap.add_argument("--map", default="example")
    ap.add_argument("--data", default=DEFAULT_DATA, help="SemanticKITTI sequence directory with frames 000052 and 004501")
    args = ap.parse_args()

    for frame in ("000052", "004501"):
        if not os.path.isfile(os.path.join(args.data, "velodyne", frame + ".bin")):
            sys.exit(f"two_robots.py: error: {args.data} has no velodyne/{frame}.bin (give --data)")
    points_a, labels_a = read(args.data, "000052")
    points_b, labels_b = read(args.data, "004501")

    with sglc.Client(args.server, token=args.token) as client:
        client.create_map(args.map)
        for robot in ("alice", "bob"):  # start from a clean slate when run again
            try:
                client.delete_robot(args.map, robot)
            except sglc.NotFoundError:
                pass

        a = client.ingest(args.map, "alice", "run1", 52, points_a, labels_a)
        print(f"alice stored frame 52 as scan {a.scan_id} ({len(points_a)} points, {a.timing.total_ms:.0f} ms)")
        b = client.ingest(args.map, "bob", "run1", 4501, points_b, labels_b, query=True, scope="other", top_k=3)
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

    # The engine in-process: the same pair, no server (when this installation has the engine module).
    try:
        engine = sglc.Engine()
    except ImportError as e:
        print(f"in-process: skipped ({e})")
        return 0 if b.loops else 1
    m = engine.match(engine.fingerprint(points_a, labels_a), engine.fingerprint(points_b, labels_b))
    t = m.T[:3, 3]
    print(f"in-process: loop {m.is_loop}, score {m.score:.3f}, t = ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}) m")
    return 0 if b.loops and m.is_loop else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (sglc.SglcError, ImportError, OSError, ValueError) as e:
        print(f"two_robots.py: error: {e}", file=sys.stderr)
        sys.exit(1)
