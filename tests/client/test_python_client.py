#!/usr/bin/python3
"""Tests of the Python client package (client/python/sglc_client) and of client/python/example.py.

Usage: test_python_client.py --server-bin PATH [--server-bin PATH ...] --stubs DIR --package DIR --data DIR

The packing checks need nothing. The rest starts the first existing --server-bin (or $SGLC_SERVER_BIN) on a
free loopback port with a fresh database and runs the real loop pair of DIR/semantickitti_scans through it.
Exit status: 0 all passed, 1 a check failed, 77 skipped (no server binary or no real data; the packing
checks still ran). Prints "N passed, M failed" last.
"""
import argparse
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time

ap = argparse.ArgumentParser()
ap.add_argument("--server-bin", action="append", default=[])
ap.add_argument("--stubs", required=True)
ap.add_argument("--package", required=True)
ap.add_argument("--data", required=True)
args = ap.parse_args()

sys.path.insert(0, args.package)
import numpy as np  # noqa: E402

import sglc_client  # noqa: E402

passed = 0
failures = []


def check(cond, what):
    global passed
    if cond:
        passed += 1
    else:
        failures.append(what)
        print("FAIL:", what)


def raises(exc, fn, *a, **kw):
    try:
        fn(*a, **kw)
    except exc as e:
        return e
    return None


def finish(skip_reason=None):
    if skip_reason:
        print("SKIP:", skip_reason)
    print(f"{passed} passed, {len(failures)} failed")
    sys.exit(1 if failures else (77 if skip_reason else 0))


# ---------------------------------------------------------------------------------------------------------
# Packing (no server)

rng = np.random.default_rng(5)
pts = rng.uniform(-80, 80, size=(500, 3)).astype(np.float32)
lab = rng.integers(0, 2**32, size=500, dtype=np.uint64).astype(np.uint32)
pb, lb = sglc_client.pack_scan(pts, lab)
check(len(pb) == 500 * 12 and len(lb) == 500 * 4, "packed sizes are 12 and 4 bytes per point")
p2, l2 = sglc_client.unpack_scan(pb, lb)
check(np.array_equal(p2, pts) and np.array_equal(l2, lab), "numpy round trip is exact")
check(sglc_client.pack_scan(pb, lb) == (pb, lb), "packed bytes pass through unchanged")
check(sglc_client.pack_points([[1.0, -2.0, 0.5]]) == bytes.fromhex("0000803f000000c00000003f"),
      "points are float32 little-endian x, y, z")
check(sglc_client.pack_labels([0x00010028]) == bytes.fromhex("28000100"), "labels are uint32 little-endian")
check(sglc_client.pack_points(np.float64([[1, 2, 3]])) == np.float32([1, 2, 3]).tobytes(), "float64 input converts")
check(raises(ValueError, sglc_client.pack_points, b"\0" * 13) is not None, "13 point bytes rejected")
check(raises(ValueError, sglc_client.pack_labels, b"\0" * 6) is not None, "6 label bytes rejected")
check(raises(ValueError, sglc_client.pack_scan, pts, lab[:-1]) is not None, "point/label count mismatch rejected")
check(raises(ValueError, sglc_client.pack_points, np.zeros((4, 4))) is not None, "(N, 4) points rejected")
p_only, l_none = sglc_client.pack_scan(np.zeros((5, 3), dtype=np.float32))
check(len(p_only) == 60 and l_none == b"", "a scan without labels packs no label bytes (the server labels it)")
check(raises(ValueError, sglc_client.pack_labels, np.float32([1.5])) is not None, "float labels rejected")
check(raises(ValueError, sglc_client.pack_labels, [-1]) is not None, "negative labels rejected")
check(raises(ValueError, sglc_client.unpack_scan, b"\0" * 24, b"\0" * 4) is not None, "unpack count mismatch rejected")
M = np.eye(4)
M[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90 deg about z
M[0, 3] = 5.0
vals = sglc_client.transform_values(M)
check(vals[3] == 5.0 and vals[4] == 1.0 and vals[1] == -1.0 and len(vals) == 16, "transforms are row-major")
zero = np.zeros((4, 4))
zero[3, 3] = 1.0
for name, bad in (("all-zero rotation", zero), ("scaled", np.diag([2.0, 2.0, 2.0, 1.0])),
                  ("reflection", np.diag([1.0, 1.0, -1.0, 1.0])), ("NaN", np.full((4, 4), np.nan))):
    err = raises(ValueError, sglc_client.transform_values, bad)
    check(err is not None and "rigid" in str(err), f"{name} transform rejected before sending")
check(sglc_client.rigid_motion_error(list(np.eye(4).astype(np.float32).astype(float).ravel())) is None,
      "float-rounded identity accepted")
check(np.array_equal(sglc_client.to_matrix(vals), M), "transform round trip")
check(raises(ValueError, sglc_client.to_matrix, [0.0] * 15) is not None, "15-value transform rejected")

# Stubs: an explicit wrong path is an error that names it; the right one loads.
err = raises(ImportError, sglc_client.Client, "127.0.0.1:1", stubs_path="/nonexistent-stubs")
check(err is not None and "/nonexistent-stubs" in str(err), "a wrong stubs_path is reported")
try:
    sglc_client.load_stubs(args.stubs)
except ImportError as e:
    check(False, f"generated stubs load: {e}")
    finish()
client0 = sglc_client.Client("127.0.0.1:1", stubs_path=args.stubs, chunk_bytes=16 * 100)
req = client0.ingest_request("m", "r", "s", 7, pts, lab, stamp=1.5, query=True, scope="other", top_k=3)
chunks = list(client0._chunks(req))
check(len(chunks) == 1 + 5 and chunks[0].HasField("header") and not chunks[0].header.scan.points,
      "chunking: header first, without the scan")
check(b"".join(c.points for c in chunks[1:]) == pb and b"".join(c.labels for c in chunks[1:]) == lb,
      "chunks concatenate to the scan")
check(chunks[0].header.query_options.scope == sglc_client.SCOPES["other"] and chunks[0].header.stamp == 1.5,
      "the header keeps the request's options")
check(raises(ValueError, client0.query_options, scope="galaxy") is not None, "unknown scope rejected")
o = client0.query_options(verify_scan_ids=[4, 9], known_loops=True)
check(list(o.verify_scan_ids) == [4, 9] and o.known_loops and not o.include_rejected,
      "query_options carries verify_scan_ids and known_loops")
check(raises(ValueError, client0.query, "m") is not None, "query without a source rejected")
e = raises(sglc_client.SglcError, client0.list_maps)
check(e is not None and e.code_name == "UNAVAILABLE", f"unreachable server gives UNAVAILABLE (got {e})")
client0.close()

# ---------------------------------------------------------------------------------------------------------
# Against a real server

candidates = ([os.environ["SGLC_SERVER_BIN"]] if os.environ.get("SGLC_SERVER_BIN") else []) + args.server_bin
server_bin = next((c for c in candidates if os.access(c, os.X_OK)), None)
if server_bin is None:
    finish(f"sglc-server not built (looked at {', '.join(candidates)}); server tests skipped")
seq_dir = os.path.join(args.data, "semantickitti_scans", "sequences", "00")
if not os.path.isfile(os.path.join(seq_dir, "velodyne", "000052.bin")):
    finish(f"{seq_dir} not found (real SemanticKITTI scans are needed); server tests skipped")

ref = None
with open(os.path.join(args.data, "semantickitti_scans", "pairs.txt")) as f:
    for line in f:
        c = line.split()
        if c and not c[0].startswith("#") and c[0] == "00" and c[1] == "000052" and c[2] == "004501":
            ref = np.vstack([np.float64(c[7:19]).reshape(3, 4), [0, 0, 0, 1]])  # T_a_b: maps 4501 into 52
check(ref is not None, "pairs.txt has the 000052-004501 row")
if ref is None:
    finish()


def pose_error(T, R):
    dt = float(np.linalg.norm(T[:3, 3] - R[:3, 3]))
    c = (np.trace(T[:3, :3].T @ R[:3, :3]) - 1) / 2
    return dt, float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def check_pose(T, R, what):
    dt, dr = pose_error(T, R)
    print(f"{what}: {dt:.3f} m, {dr:.3f} deg from the reference")
    check(dt < 0.2 and dr < 1.0, f"{what}: pose within 0.2 m / 1 deg (got {dt:.3f} m, {dr:.3f} deg)")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def read_np(frame):
    cloud = np.fromfile(os.path.join(seq_dir, "velodyne", frame + ".bin"), dtype="<f4").reshape(-1, 4)
    return cloud[:, :3], np.fromfile(os.path.join(seq_dir, "labels", frame + ".label"), dtype="<u4")


def read_bytes(frame):
    return sglc_client.read_kitti_scan(os.path.join(seq_dir, "velodyne", frame + ".bin"),
                                       os.path.join(seq_dir, "labels", frame + ".label"))


tmp = tempfile.mkdtemp(prefix="sglc-py-test-")
server = None
try:
    # Start the server (retry with another port if the free one was taken in between).
    for attempt in range(3):
        address = f"127.0.0.1:{free_port()}"
        log = open(os.path.join(tmp, f"server{attempt}.log"), "wb")
        server = subprocess.Popen([server_bin, "--db", os.path.join(tmp, "map.db"), "--listen", address],
                                  stdout=log, stderr=subprocess.STDOUT)
        deadline = time.time() + 60
        up = False
        while time.time() < deadline and server.poll() is None:
            with sglc_client.Client(address, stubs_path=args.stubs, timeout=1.0) as probe:  # fresh channel each try
                try:
                    probe.list_maps()
                    up = True
                except sglc_client.SglcError as e:
                    up = e.code_name not in ("UNAVAILABLE", "DEADLINE_EXCEEDED")
            if up:
                break
            time.sleep(0.05)
        if up:
            break
        server.kill()
        server.wait()
        server = None
    check(server is not None, "sglc-server starts")
    if server is None:
        finish()

    c = sglc_client.Client(address, stubs_path=args.stubs, timeout=60)
    info = c.server_info()
    check(info.label_preset == "semantickitti" and info.labeller_mode == "auto" and info.version != ""
          and [n.name for n in info.node_classes] == ["vehicle", "trunk", "pole"] and info.max_points > 0,
          f"server_info: preset, labeller mode, label map, limits ({info.label_preset}, {info.labeller_mode})")
    check(c.create_map("py").name == "py", "create_map")
    c.ensure_map("py")
    check([m.name for m in c.list_maps()] == ["py"], "list_maps")

    # Robot a from numpy arrays; robot b from bytes, querying other robots: candidate 52, T = inverse(T_a_b).
    p52, l52 = read_np("000052")
    a = c.ingest("py", "a", "00", 52, p52, l52)
    check(a.seq == 52 and len(a.loops) == 0, "ingest from numpy arrays")
    p4501, l4501 = read_bytes("004501")
    b = c.ingest("py", "b", "00", 4501, p4501, l4501, query=True, scope="other")
    check(len(b.loops) >= 1 and b.loops[0].scan_id == a.scan_id and b.loops[0].robot == "a",
          "4501 (robot b) finds 52 (robot a)")
    if b.loops:
        check_pose(sglc_client.to_matrix(b.loops[0].t_query_candidate), np.linalg.inv(ref), "query 4501 -> 52")
        info = sglc_client.information_matrix(b.loops[0])
        check(info is not None and info.shape == (6, 6) and np.allclose(info, info.T, rtol=1e-9, atol=1e-9 * abs(info).max())
              and np.linalg.eigvalsh(info).min() > 0, "a refined loop carries a 6x6 positive definite information matrix")
    check(sglc_client.information_matrix([]) is None, "no information: None")
    try:
        sglc_client.information_matrix([1.0] * 5)
        check(False, "information_matrix rejects a wrong length")
    except ValueError as e:
        check("36" in str(e), "information_matrix names the expected length")

    q = c.query("py", scan_id=a.scan_id, scope="other")
    hit = [x for x in q.candidates if x.scan_id == b.scan_id]
    check(len(hit) == 1 and hit[0].verified, "query by id: 52 finds 4501")
    if hit:
        check_pose(sglc_client.to_matrix(hit[0].t_query_candidate), ref, "query 52 -> 4501")
    q = c.query("py", points=p4501, labels=l4501, top_k=5)
    check(any(x.scan_id == a.scan_id for x in q.candidates), "query by scan (relocalization)")

    # Chunked: a small limit routes the scan through IngestChunked; it must still match.
    small = sglc_client.Client(address, stubs_path=args.stubs, timeout=60, chunk_bytes=200_000)
    r = small.ingest("py", "c", "00", 52, p52, l52)
    r = small.ingest("py", "c", "00", 4501, p4501, l4501, query=True, scope="same", exclude_recent=50)
    check(any(x.seq == 52 and x.robot == "c" for x in r.loops), "chunked ingests store usable scans")
    small.close()

    # A robot's run over the stream.
    with c.open_session() as s:
        s.send("py", "d", "run", 88, *read_bytes("000088"))
        s.send("py", "d", "run", 4501, p4501, l4501, query=True, scope="all")
        first, second = s.next(), s.next()
        check(first.seq == 88 and second.seq == 4501, "stream answers in order")
        check(any(x.scan_id == a.scan_id for x in second.loops), "stream query finds robot a's scan")
        check(s.finish() == [], "finish with nothing outstanding")
    with c.open_session() as s:
        s.send("py", "d", "run2", 850, *read_bytes("000850"))
        s.send("py", "d", "run", 88, *read_bytes("000850"))  # another scan under a stored key
        check(s.next().seq == 850, "scan before the failure is answered")
        e = raises(sglc_client.SglcError, s.next)
        check(e is not None and e.code_name == "ALREADY_EXISTS", f"a key's second scan ends the stream with ALREADY_EXISTS ({e})")

    # Admin.
    st = c.stats()
    check((st.maps, st.robots, st.scans) == (1, 4, 7), f"stats counts (got maps {st.maps} robots {st.robots} scans {st.scans})")
    check(sorted(x.name for x in c.list_robots("py")) == ["a", "b", "c", "d"], "list_robots")
    check(len(c.list_sessions("py", "d")) == 2, "list_sessions")
    g = c.get_scan(a.scan_id, include_graph=True)
    check(g.key.robot == "a" and g.key.seq == 52 and len(g.nodes) > 0, "get_scan with graph")
    check(c.delete_session("py", "d", "run2") == 1, "delete_session")
    check(c.delete_robot("py", "c") == 2, "delete_robot")
    check(c.stats("py").scans == 4, "stats after deletes")
    bk = c.backup("py-backup.db")
    check(bk.bytes > 0, "backup")
    e = raises(sglc_client.SglcError, c.list_robots, "nosuch")
    check(e is not None and e.code_name == "NOT_FOUND", "unknown map gives NOT_FOUND")
    again = c.ingest("py", "a", "00", 52, p52, l52)
    check(again.already_stored and again.scan_id == a.scan_id, "the identical ingest again is a retry: the stored scan")
    p88, l88 = read_bytes("000088")
    e = raises(sglc_client.SglcError, c.ingest, "py", "a", "00", 52, p88, l88)
    check(e is not None and e.code_name == "ALREADY_EXISTS", "another scan under a stored key gives ALREADY_EXISTS")
    # Points only (no labels): the server labels the scans, says so, and finds the loop from them.
    c.create_map("raw")
    u = c.ingest("raw", "u", "00", 52, p52)
    check(u.label_source == c.pb2.LABELS_COMPUTED, "ingest without labels: labels computed by the server")
    u2 = c.ingest("raw", "u", "00", 4501, p4501, query=True, exclude_recent=50)
    check(any(x.scan_id == u.scan_id and x.verified for x in u2.loops), "the loop is found without labels")
    c.close()

    # The example runs and finds the loop.
    env = dict(os.environ, SGLC_PYTHON_STUBS=args.stubs)
    ex = subprocess.run([sys.executable, os.path.join(args.package, "example.py"), "--server", address, "--data", seq_dir],
                        capture_output=True, text=True, timeout=120, env=env)
    check(ex.returncode == 0 and "inter-robot loop" in ex.stdout and "robot alice" in ex.stdout,
          f"example.py runs (exit {ex.returncode}): {ex.stdout[-300:]} {ex.stderr[-300:]}")
finally:
    if server is not None:
        server.terminate()
        try:
            server.wait(timeout=15)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
    shutil.rmtree(tmp, ignore_errors=True)

finish()
