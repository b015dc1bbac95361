#!/usr/bin/env python3
"""End-to-end tests of build/bin/sglc-server on loopback, through the generated sglc.v1 stubs.

Usage: test_server.py SERVER_BINARY PYTHON_STUB_DIR SHARED_DATA_DIR SIM_BINARY SGLC_CLI
Starts real servers on free loopback ports with temporary databases. Exit 77 when grpcio/numpy are missing.
"""
import csv
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

try:
    import grpc
    import numpy as np
    from grpc_health.v1 import health_pb2, health_pb2_grpc  # noqa: F401  (optional)
except ImportError:
    try:
        import grpc
        import numpy as np
        health_pb2 = None
    except ImportError as e:
        print(f"SKIP: {e} (needs Debian's python3-grpcio and python3-numpy; run with /usr/bin/python3)")
        sys.exit(77)

SERVER, STUBS, DATA, SIM, CLI = sys.argv[1:6]
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
from harness import Server, expect_code, free_port  # noqa: E402,F401

pb, rpc = harness.configure(SERVER, STUBS)

SEQ = os.path.join(DATA, "semantickitti_scans", "sequences", "00")
HAVE_DATA = os.path.isdir(SEQ)


def load_scan(frame):
    pts = np.fromfile(os.path.join(SEQ, "velodyne", frame + ".bin"), dtype="<f4").reshape(-1, 4)[:, :3]
    lab = np.fromfile(os.path.join(SEQ, "labels", frame + ".label"), dtype="<u4")
    return pb.Scan(points=np.ascontiguousarray(pts).tobytes(), labels=lab.tobytes())


def synthetic_scan(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-20, 20, size=(n, 3)).astype("<f4")
    lab = rng.choice(np.array([40, 50, 70, 80, 10], dtype="<u4"), size=n)
    return pb.Scan(points=pts.tobytes(), labels=lab.tobytes())


def reference_pose():
    with open(os.path.join(DATA, "semantickitti_scans", "pairs.txt")) as f:
        for line in f:
            c = line.split()
            if c and c[0] == "00" and c[1] == "000052" and c[2] == "004501":
                T = np.eye(4)
                T[:3, :] = np.array([float(v) for v in c[7:19]]).reshape(3, 4)
                return T
    raise RuntimeError("pairs.txt has no 52-4501 row")


def pose_error(T, G):
    dt = np.linalg.norm(T[:3, 3] - G[:3, 3])
    c = (np.trace(T[:3, :3].T @ G[:3, :3]) - 1) / 2
    return dt, np.degrees(np.arccos(np.clip(c, -1, 1)))


def key(robot, seq, session="run", m="m"):
    return pb.ScanKey(map=m, robot=robot, session=session, seq=seq)


# ------------------------------------------------------------------------------------------------ tests

def test_inter_robot_loop_and_restart(tmp):
    if not HAVE_DATA:
        print("  skipped: real scans absent")
        return
    db = os.path.join(tmp, "map.db")
    s = Server(db)
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"))
        r_b = s.loop.Ingest(pb.IngestRequest(key=key("b", 4501), scan=load_scan("004501"), query=True))
        assert r_b.scan_id > 0 and len(r_b.loops) == 0, "the first scan has no loop"
        opts = pb.QueryOptions(scope=pb.SCOPE_OTHER_ROBOTS, top_k=3)
        r_a = s.loop.Ingest(pb.IngestRequest(key=key("a", 52), scan=load_scan("000052"), query=True,
                                             query_options=opts))
        assert len(r_a.loops) == 1, f"expected the inter-robot loop, got {len(r_a.loops)}"
        loop = r_a.loops[0]
        assert loop.scan_id == r_b.scan_id and loop.robot == "b" and loop.verified and loop.refined
        T = np.array(loop.t_query_candidate.m).reshape(4, 4)  # maps b (candidate) into a (query)
        dt, dr = pose_error(T, reference_pose())
        assert dt < 0.10 and dr < 0.5, f"pose error {dt:.3f} m {dr:.3f} deg"
        print(f"  inter-robot loop: score {loop.score:.3f}, inliers {loop.inliers}, RTE {dt:.4f} m, RRE {dr:.4f} deg")
        # The refined loop carries its information matrix: 6x6, symmetric, positive definite.
        info = np.array(loop.information).reshape(6, 6)
        assert np.allclose(info, info.T, rtol=1e-9, atol=1e-9 * np.abs(info).max()), "information is symmetric"
        assert np.linalg.eigvalsh(info).min() > 0, "information is positive definite"
        # Same-robot scope finds nothing; query by stored id finds the other scan with the inverse pose.
        same = s.loop.Query(pb.QueryRequest(map="m", scan_id=r_a.scan_id,
                                            options=pb.QueryOptions(scope=pb.SCOPE_SAME_ROBOT)))
        assert len(same.candidates) == 0
        by_id = s.loop.Query(pb.QueryRequest(map="m", scan_id=r_b.scan_id))
        assert [c.scan_id for c in by_id.candidates] == [r_a.scan_id]
        Tba = np.array(by_id.candidates[0].t_query_candidate.m).reshape(4, 4)
        dt, dr = pose_error(np.linalg.inv(Tba), reference_pose())
        assert dt < 0.10 and dr < 0.5, f"reverse query pose error {dt:.3f} m {dr:.3f} deg"
        # Verifying a named scan gives the same loop as the search did; a scan of nowhere is NOT_FOUND.
        named = s.loop.Query(pb.QueryRequest(map="m", scan_id=r_a.scan_id,
                                             options=pb.QueryOptions(verify_scan_ids=[r_b.scan_id])))
        assert [c.scan_id for c in named.candidates] == [r_b.scan_id] and named.candidates[0].verified
        assert list(named.candidates[0].t_query_candidate.m) == list(loop.t_query_candidate.m)
        assert abs(named.candidates[0].descriptor_distance - loop.descriptor_distance) < 1e-5
        expect_code(grpc.StatusCode.NOT_FOUND, lambda: s.loop.Query(pb.QueryRequest(
            map="m", scan_id=r_a.scan_id, options=pb.QueryOptions(verify_scan_ids=[r_b.scan_id + 100]))),
            "verify an unknown scan")
        expect_code(grpc.StatusCode.INVALID_ARGUMENT, lambda: s.loop.Query(pb.QueryRequest(
            map="m", scan_id=r_a.scan_id, options=pb.QueryOptions(verify_scan_ids=[r_b.scan_id, r_b.scan_id]))),
            "verify a scan twice")
        # Relocalization: a scan sent in the call, nothing stored.
        # Scan 52 itself is stored as robot a: it comes first with an identity pose, then b's scan.
        reloc = s.loop.Query(pb.QueryRequest(map="m", scan=load_scan("000052")))
        assert [c.scan_id for c in reloc.candidates] == [r_a.scan_id, r_b.scan_id], reloc
        dt, dr = pose_error(np.array(reloc.candidates[0].t_query_candidate.m).reshape(4, 4), np.eye(4))
        assert dt < 0.01 and dr < 0.05, f"self-relocalization is off by {dt:.4f} m {dr:.4f} deg"
        stats_before = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert stats_before.scans == 2 and stats_before.robots == 2
        answer_before = [(c.scan_id, round(c.score, 9), tuple(round(v, 9) for v in c.t_query_candidate.m))
                         for c in s.loop.Query(pb.QueryRequest(map="m", scan_id=r_a.scan_id)).candidates]
    finally:
        # A crash, not a clean shutdown: every acknowledged scan must survive.
        s.stop(signal.SIGKILL)
    s = Server(db)
    try:
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert st.scans == 2 and st.index_entries == 2, f"after restart: {st}"
        answer_after = [(c.scan_id, round(c.score, 9), tuple(round(v, 9) for v in c.t_query_candidate.m))
                        for c in s.loop.Query(pb.QueryRequest(map="m", scan_id=r_a.scan_id)).candidates]
        assert answer_after == answer_before, "answers changed across a restart"
        info = s.admin.GetScan(pb.GetScanRequest(scan_id=r_a.scan_id, include_graph=True))
        assert info.key.robot == "a" and info.key.seq == 52 and len(info.nodes) > 10
        assert len(info.scan_descriptor) == 231
    finally:
        assert s.stop() == 0, "graceful shutdown exits 0"


def test_known_loop_pose(tmp):
    """A candidate whose landmarks are unlabelled is verified from its background alone; with background-only
    loops switched off verification rejects it, and the known loop gets a pose only when asked."""
    if not HAVE_DATA:
        print("  skipped: real scans absent")
        return
    bare = load_scan("004501")
    lab = np.frombuffer(bare.labels, dtype="<u4").copy()
    lab[np.isin(lab & 0xFFFF, [10, 18, 20, 71, 80])] = 0  # cars, trucks, other vehicles, trunks, poles
    bare.labels = lab.tobytes()
    for background in (True, False):
        extra = () if background else ("--set", "engine.verify.background_max_nodes=0")
        s = Server(os.path.join(tmp, f"known-{background}.db"), extra)
        try:
            check_known_loop(s, bare, background)
        finally:
            assert s.stop() == 0


def check_known_loop(s, bare, background):
    s.admin.CreateMap(pb.CreateMapRequest(name="m"))
    r_b = s.loop.Ingest(pb.IngestRequest(key=key("b", 4501), scan=bare))
    r_a = s.loop.Ingest(pb.IngestRequest(key=key("a", 52), scan=load_scan("000052")))

    def ask(**kw):
        return s.loop.Query(pb.QueryRequest(map="m", scan_id=r_a.scan_id,
                                            options=pb.QueryOptions(verify_scan_ids=[r_b.scan_id], **kw)))
    if background:
        found = ask().candidates
        assert len(found) == 1 and found[0].verified and found[0].refined, found
        dt, dr = pose_error(np.array(found[0].t_query_candidate.m).reshape(4, 4), reference_pose())
        assert dt < 0.10 and dr < 0.5, f"background-only loop pose error {dt:.3f} m {dr:.3f} deg"
        print(f"  loop from the background alone: RTE {dt:.4f} m, RRE {dr:.4f} deg")
        return
    assert len(ask().candidates) == 0, "not a verified loop"
    rejected = ask(include_rejected=True).candidates
    assert len(rejected) == 1 and not rejected[0].verified and not rejected[0].refined
    known = ask(known_loops=True).candidates
    assert len(known) == 1 and not known[0].verified and known[0].refined, known
    dt, dr = pose_error(np.array(known[0].t_query_candidate.m).reshape(4, 4), reference_pose())
    assert dt < 0.10 and dr < 0.5, f"known-loop pose error {dt:.3f} m {dr:.3f} deg"
    assert len(known[0].information) == 36 and 0 < known[0].fitness <= 1
    print(f"  known loop without landmarks: RTE {dt:.4f} m, RRE {dr:.4f} deg, fitness {known[0].fitness:.3f}")
    expect_code(grpc.StatusCode.INVALID_ARGUMENT, lambda: ask(known_loops=True, refine=False, refine_set=True),
                "known_loops without refinement")


def test_unlabelled_scans(tmp):
    """Scans sent without labels are labelled by the server; the real loop is found from them; a scan whose
    labels the label set does not know gets a warning; GetServerInfo says what the server expects."""
    s = Server(os.path.join(tmp, "raw.db"))
    try:
        info = s.admin.GetServerInfo(pb.GetServerInfoRequest())
        assert info.label_preset == "semantickitti" and info.labeller_mode == "auto", info
        assert [c.name for c in info.node_classes] == ["vehicle", "trunk", "pole"] and list(info.road) == [40]
        assert info.descriptor_dim > 0 and info.max_points > 0 and "labeller:" in info.engine_config
        # The loop model's version (the built-in file's version line) and the bar it is held to.
        with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "core", "models",
                               "loop_model.txt")) as f:
            version = next(l.split()[1] for l in f if l.startswith("version "))
        assert info.loop_model == version and "min_probability: " + repr(info.min_probability) in info.engine_config, info
        s.admin.CreateMap(pb.CreateMapRequest(name="m"))
        if HAVE_DATA:
            a, b = load_scan("000052"), load_scan("004501")
            a.labels, b.labels = b"", b""
            # store_raw with an unlabelled scan once crashed the server (labels read past an empty list).
            r_a = s.loop.Ingest(pb.IngestRequest(key=key("a", 52), scan=a, store_raw=True))
            assert r_a.label_source == pb.LABELS_COMPUTED, r_a.label_source
            r_b = s.loop.Ingest(pb.IngestRequest(key=key("b", 4501), scan=b, query=True))
            assert r_b.label_source == pb.LABELS_COMPUTED
            loops = [c for c in r_b.loops if c.scan_id == r_a.scan_id and c.verified]
            assert loops, f"the unlabelled loop was not found: {r_b.loops}"
            dt, dr = pose_error(np.linalg.inv(np.array(loops[0].t_query_candidate.m).reshape(4, 4)), reference_pose())
            assert dt < 0.06 and dr < 0.25, f"unlabelled loop pose error {dt:.3f} m {dr:.3f} deg"
            print(f"  unlabelled real loop through the server: RTE {dt:.4f} m, RRE {dr:.4f} deg")
            labelled = s.loop.Ingest(pb.IngestRequest(key=key("c", 52), scan=load_scan("000052")))
            assert labelled.label_source == pb.LABELS_PROVIDED and not labelled.warnings
        # Labels of another label set (here: all 3000): stored, with a warning that says why no loop can come.
        pts = (np.random.default_rng(3).random((2000, 3), dtype=np.float32) * 20).astype("<f4")
        odd = pb.Scan(points=pts.tobytes(), labels=np.full(2000, 3000, dtype="<u4").tobytes())
        r = s.loop.Ingest(pb.IngestRequest(key=key("d", 1), scan=odd))
        assert any("no point carries a label" in w for w in r.warnings), r.warnings
        log = open(os.path.join(tmp, "raw.db.log"), errors="replace").read()
        assert "scan_warning" in log, "the warning is not in the server's log"
    finally:
        assert s.stop() == 0


def test_bad_inputs(tmp):
    s = Server(os.path.join(tmp, "bad.db"), extra=["--max-message-mb", "1"])
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"))
        good = synthetic_scan()
        C = grpc.StatusCode
        cases = [
            (C.INVALID_ARGUMENT, pb.IngestRequest(key=key("r", 1), scan=pb.Scan(points=b"\0" * 13, labels=b"")),
             "12"),
            (C.INVALID_ARGUMENT, pb.IngestRequest(key=key("r", 1), scan=pb.Scan(points=b"\0" * 24, labels=b"\0" * 4)),
             "labels"),
            (C.INVALID_ARGUMENT, pb.IngestRequest(key=key("r", 1), scan=pb.Scan()), "empty"),
            (C.INVALID_ARGUMENT, pb.IngestRequest(
                key=key("r", 1),
                scan=pb.Scan(points=np.array([[0, 0, np.nan]], dtype="<f4").tobytes(), labels=b"\0" * 4)), "finite"),
            (C.INVALID_ARGUMENT, pb.IngestRequest(key=key("", 1), scan=good), "robot"),
            (C.INVALID_ARGUMENT, pb.IngestRequest(key=key("r", 1), scan=good,
                                                  odometry_pose=pb.Transform(m=[1.0] * 5)), "16"),
            (C.NOT_FOUND, pb.IngestRequest(key=key("r", 1, m="nomap"), scan=good), "nomap"),
            (C.INVALID_ARGUMENT, pb.IngestRequest(key=key("r", 1), scan=good, query=True,
                                                  query_options=pb.QueryOptions(top_k=1000)), "top_k"),
        ]
        for code, req, word in cases:
            msg = expect_code(code, lambda: s.loop.Ingest(req, timeout=30), f"ingest ({word})")
            assert word.lower() in msg.lower(), f"message '{msg}' does not mention '{word}'"
        # Oversized message: refused by the transport.
        big = pb.Scan(points=b"\0" * (12 * 100000), labels=b"\0" * (4 * 100000))
        expect_code(C.RESOURCE_EXHAUSTED, lambda: s.loop.Ingest(pb.IngestRequest(key=key("r", 1), scan=big)),
                    "oversized message")
        # Duplicate key: the identical request again is a retry (OK, the stored scan); anything else is refused.
        first = s.loop.Ingest(pb.IngestRequest(key=key("r", 7), scan=good, stamp=1.5))
        again = s.loop.Ingest(pb.IngestRequest(key=key("r", 7), scan=good, stamp=1.5))
        assert not first.already_stored and again.already_stored and again.scan_id == first.scan_id, (first, again)
        expect_code(C.ALREADY_EXISTS, lambda: s.loop.Ingest(pb.IngestRequest(key=key("r", 7), scan=good, stamp=2.5)),
                    "duplicate key, another stamp")
        expect_code(C.NOT_FOUND, lambda: s.loop.Query(pb.QueryRequest(map="m", scan_id=999999)), "unknown scan")
        expect_code(C.INVALID_ARGUMENT, lambda: s.loop.Query(pb.QueryRequest(map="m")), "query without source")
        expect_code(C.INVALID_ARGUMENT, lambda: s.loop.Query(pb.QueryRequest(
            map="m", scan=good, options=pb.QueryOptions(scope=pb.SCOPE_SAME_ROBOT))), "same-robot scope without robot")
        expect_code(C.NOT_FOUND, lambda: s.admin.ListRobots(pb.ListRobotsRequest(map="nomap")), "unknown map")
        expect_code(C.NOT_FOUND, lambda: s.admin.DeleteRobot(pb.DeleteRobotRequest(map="m", robot="ghost")),
                    "unknown robot")
        expect_code(C.INVALID_ARGUMENT, lambda: s.admin.Backup(pb.BackupRequest(path="/etc/x.db")), "absolute path")
        # Chunked ingest: a header plus two chunks make a valid scan; a bad concatenation is refused.
        n = 3000
        pts = np.random.default_rng(1).uniform(-10, 10, (n, 3)).astype("<f4").tobytes()
        lab = np.full(n, 40, dtype="<u4").tobytes()
        chunks = [pb.IngestChunk(header=pb.IngestRequest(key=key("r", 100))),
                  pb.IngestChunk(points=pts[:12 * 1000], labels=lab[:4 * 1000]),
                  pb.IngestChunk(points=pts[12 * 1000:], labels=lab[4 * 1000:])]
        assert s.loop.IngestChunked(iter(chunks)).scan_id > 0
        bad_chunks = [pb.IngestChunk(header=pb.IngestRequest(key=key("r", 101))), pb.IngestChunk(points=pts[:7])]
        expect_code(C.INVALID_ARGUMENT, lambda: s.loop.IngestChunked(iter(bad_chunks)), "torn chunks")
        # Nothing was stored by any failed call: two good scans only.
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert st.scans == 2 and st.index_entries == 2, f"stored after failures: {st}"
        # Deadline: far too short for fingerprinting; the scan must not be stored.
        expect_code(C.DEADLINE_EXCEEDED,
                    lambda: s.loop.Ingest(pb.IngestRequest(key=key("r", 200), scan=synthetic_scan(60000)),
                                          timeout=0.002), "deadline")
        time.sleep(0.5)
        assert s.admin.GetStats(pb.GetStatsRequest(map="m")).scans == 2, "a timed-out ingest was stored"
    finally:
        assert s.stop() == 0


def test_tokens(tmp):
    tokens = os.path.join(tmp, "tokens.txt")
    with open(tokens, "w") as f:
        f.write("# admin\nadmin-token-123 *\nfleet-token-456 m\n")
    s = Server(os.path.join(tmp, "auth.db"), extra=["--tokens", tokens])
    try:
        C = grpc.StatusCode
        admin = [("authorization", "Bearer admin-token-123")]
        fleet = [("authorization", "Bearer fleet-token-456")]
        expect_code(C.UNAUTHENTICATED, lambda: s.admin.ListMaps(pb.ListMapsRequest()), "no token")
        expect_code(C.UNAUTHENTICATED, lambda: s.admin.ListMaps(
            pb.ListMapsRequest(), metadata=[("authorization", "Bearer wrong-token-0")]), "wrong token")
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), metadata=admin)
        s.admin.CreateMap(pb.CreateMapRequest(name="secret"), metadata=admin)
        assert [m.name for m in s.admin.ListMaps(pb.ListMapsRequest(), metadata=fleet).maps] == ["m"]
        s.loop.Ingest(pb.IngestRequest(key=key("r", 1), scan=synthetic_scan()), metadata=fleet)
        expect_code(C.PERMISSION_DENIED, lambda: s.loop.Ingest(
            pb.IngestRequest(key=key("r", 1, m="secret"), scan=synthetic_scan()), metadata=fleet), "other map")
        expect_code(C.PERMISSION_DENIED, lambda: s.admin.Backup(pb.BackupRequest(path="b.db"), metadata=fleet),
                    "backup needs all maps")
        r = s.admin.Backup(pb.BackupRequest(path="b.db"), metadata=admin)
        assert r.bytes > 0 and os.path.exists(r.path)
    finally:
        assert s.stop() == 0


def test_concurrent_clients(tmp):
    # More robots streaming at once than compute threads: calls queue for the engine instead of being refused.
    s = Server(os.path.join(tmp, "conc.db"), extra=("--threads", "1", "--max-calls", "64"))
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"))
        errors, done = [], []

        def robot(i):
            try:
                ch = grpc.insecure_channel(s.addr)
                stub = rpc.LoopClosureStub(ch)
                reqs = [pb.IngestRequest(key=key(f"r{i}", q), scan=synthetic_scan(3000, seed=100 * i + q), query=True)
                        for q in range(6)]
                seqs = [r.seq for r in stub.IngestStream(iter(reqs), timeout=120)]
                if seqs != list(range(6)):
                    errors.append(f"robot {i}: responses out of order {seqs}")
                for q in range(6):
                    stub.Query(pb.QueryRequest(map="m", scan=synthetic_scan(3000, seed=100 * i + q)), timeout=60)
                ch.close()
                done.append(i)
            except Exception as e:  # noqa: BLE001
                errors.append(f"robot {i}: {e}")

        threads = [threading.Thread(target=robot, args=(i,)) for i in range(20)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=180)
        assert not errors, errors
        assert len(done) == 20
        st = s.admin.GetStats(pb.GetStatsRequest(map="m"))
        assert st.scans == 120 and st.robots == 20 and st.index_entries == 120, st
    finally:
        assert s.stop() == 0



def read_kitti_poses(path, Tr):
    rows = np.loadtxt(path).reshape(-1, 3, 4)
    out = []
    for r in rows:
        P = np.eye(4)
        P[:3, :] = r
        out.append(np.linalg.inv(Tr) @ P @ Tr)
    return out


def ate(est, gt):
    """RMSE of positions after the best rigid alignment of est onto gt (Horn/Umeyama, no scale)."""
    a = np.array([T[:3, 3] for T in est])
    b = np.array([T[:3, 3] for T in gt])
    ma, mb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((b - mb).T @ (a - ma))
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return float(np.sqrt(np.mean(np.sum((b - (a - ma) @ R.T - mb) ** 2, axis=1))))


def test_config_file(tmp):
    # The pose_graph section is read and checked; mistakes end the server with a message naming the key.
    good = os.path.join(tmp, "good.yaml")
    with open(good, "w") as f:
        f.write("pose_graph:\n  odometry_sigma_per_m: 0.02\n  odometry_sigma_deg_per_m: 0.01\n"
                "  loop_sigma_m: 0.05\n  debounce_ms: 50\n")
    s = Server(os.path.join(tmp, "a.db"), ["--config", good])
    try:
        assert s.admin.ListMaps(pb.ListMapsRequest(), timeout=10) is not None
    finally:
        assert s.stop() == 0
    for text, expected in [("pose_graph:\n  odometry_sigma: 0.02\n", "unknown parameter 'pose_graph.odometry_sigma'"),
                           ("pose_graph:\n  loss_scale: -1\n", "pose_graph.loss_scale must be > 0"),
                           ("pose_graph:\n  loop_sigma_deg: 0\n", "pose_graph.loop_sigma_deg must be > 0"),
                           # Checked once all keys are read: either order of the two keys gives the error.
                           ("pose_graph:\n  odometry_sigma_m: 0\n  odometry_sigma_per_m: 0\n",
                            "pose_graph.odometry_sigma_m and pose_graph.odometry_sigma_per_m must be > 0 in sum"),
                           ("pose_graph:\n  odometry_sigma_per_m: 0\n  odometry_sigma_m: 0\n",
                            "pose_graph.odometry_sigma_m and pose_graph.odometry_sigma_per_m must be > 0 in sum"),
                           ("posegraph:\n  loss_scale: 1\n", "unknown section 'posegraph'")]:
        bad = os.path.join(tmp, "bad.yaml")
        with open(bad, "w") as f:
            f.write(text)
        r = subprocess.run([SERVER, "--db", os.path.join(tmp, "b.db"), "--listen", f"127.0.0.1:{free_port()}",
                            "--config", bad], capture_output=True, text=True, timeout=60)
        assert r.returncode != 0 and expected in r.stderr, (text, r.returncode, r.stderr)


def check_exports(s, tmp, est, n, loops):
    """sglc trajectory --format tum, sglc loops and sglc export agree with the server's poses and loops."""
    tum = os.path.join(tmp, "a.tum")
    subprocess.run([CLI, "trajectory", "--server", s.addr, "--map", "m", "--robot", "a", "--format", "tum",
                    "--out", tum], check=True, stdout=subprocess.DEVNULL, timeout=60)
    rows = np.loadtxt(tum)
    # evo's TUM rules: 8 columns, increasing stamps, unit quaternions.
    assert rows.shape == (n, 8) and np.all(np.diff(rows[:, 0]) > 0)
    assert np.allclose(rows[:, 0], 1000.0 + 0.8 * np.arange(n), atol=1e-6)
    assert np.allclose(np.linalg.norm(rows[:, 4:8], axis=1), 1.0, atol=1e-6)
    assert np.allclose(rows[:, 1:4], np.array([T[:3, 3] for T in est]), atol=1e-6)
    edges = s.graph.GetLoops(pb.GetLoopsRequest(map="m")).loops
    assert len(edges) == loops and [e.id for e in edges] == sorted(e.id for e in edges)
    page = s.graph.GetLoops(pb.GetLoopsRequest(map="m", page_size=7))
    assert len(page.loops) == 7 and page.next_page_token == page.loops[-1].id
    rest = s.graph.GetLoops(pb.GetLoopsRequest(map="m", page_token=page.next_page_token)).loops
    assert [e.id for e in page.loops] + [e.id for e in rest] == [e.id for e in edges], "pages cover every loop once"
    only_b = s.graph.GetLoops(pb.GetLoopsRequest(map="m", robot="b")).loops
    assert 0 < len(only_b) < len(edges) and all("b" in (e.query.robot, e.candidate.robot) for e in only_b)
    expect_code(grpc.StatusCode.NOT_FOUND, lambda: s.graph.GetLoops(pb.GetLoopsRequest(map="m", robot="ghost")),
                "loops of an unknown robot")
    # Filter names that no robot can have are refused before they are echoed: no control characters, and no
    # 200 kB name turning the answer into RESOURCE_EXHAUSTED (the echo exceeded the client's metadata limit).
    for call in (lambda r: s.graph.GetLoops(pb.GetLoopsRequest(map="m", robot=r)),
                 lambda r: s.graph.GetPoses(pb.GetPosesRequest(map="m", robot=r)),
                 lambda r: s.admin.ListSessions(pb.ListSessionsRequest(map="m", robot=r)),
                 lambda r: s.admin.DeleteRobot(pb.DeleteRobotRequest(map="m", robot=r))):
        for bad in ("a\nb", "\x00x", "x" * 200000):
            try:
                call(bad)
                raise AssertionError(f"robot {bad[:8]!r} accepted")
            except grpc.RpcError as e:
                assert e.code() == grpc.StatusCode.INVALID_ARGUMENT and len(e.details()) < 200, (e.code(), e.details())
    cli = [CLI, "loops", "--server", s.addr, "--map", "m", "--format"]
    lines = subprocess.run(cli + ["json"], check=True, capture_output=True, text=True, timeout=60).stdout.splitlines()
    js = [json.loads(l) for l in lines]
    assert [j["id"] for j in js] == [e.id for e in edges]
    assert np.allclose(js[0]["T"], list(edges[0].t_query_candidate.m))
    csv_rows = list(csv.DictReader(io.StringIO(
        subprocess.run(cli + ["csv"], check=True, capture_output=True, text=True, timeout=60).stdout)))
    assert len(csv_rows) == loops and int(csv_rows[-1]["candidate_scan"]) == edges[-1].candidate.scan_id
    bad = subprocess.run(cli + ["g2o"], capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0 and "sglc export --map m --format g2o" in bad.stderr, bad.stderr

    # The whole graph as the server weighs it: every scan with odometry a vertex (frame order, named in
    # graph.ids.csv), odometry edges within sessions, one edge per loop.
    out = os.path.join(tmp, "export")
    r = subprocess.run([CLI, "export", "--server", s.addr, "--map", "m", "--format", "g2o", "--out", out],
                       check=True, capture_output=True, text=True, timeout=60)
    assert f"{loops} loops" in r.stderr and "warning" not in r.stderr, r.stderr
    g2o = open(os.path.join(out, "graph.g2o")).read().splitlines()
    vertices = [l.split() for l in g2o if l.startswith("VERTEX_SE3:QUAT ")]
    g2o_edges = [l.split() for l in g2o if l.startswith("EDGE_SE3:QUAT ")]
    all_poses = s.graph.GetPoses(pb.GetPosesRequest(map="m")).poses
    sessions = {(p.robot, p.session) for p in all_poses}
    assert len(vertices) == len(all_poses) and [int(v[1]) for v in vertices] == list(range(len(all_poses)))
    assert len(g2o_edges) == len(all_poses) - len(sessions) + loops
    assert all(len(e) == 3 + 7 + 21 for e in g2o_edges) and all(len(v) == 9 for v in vertices)
    ids = list(csv.DictReader(open(os.path.join(out, "graph.ids.csv"))))
    by_scan = {p.scan_id: p for p in all_poses}
    assert sorted(int(row["scan_id"]) for row in ids) == sorted(by_scan)
    for row, v in zip(ids, vertices):  # each vertex at the server's pose of the scan it names
        T = np.array(by_scan[int(row["scan_id"])].t_map_scan.m).reshape(4, 4)
        assert (row["robot"], int(row["seq"])) == (by_scan[int(row["scan_id"])].robot, by_scan[int(row["scan_id"])].seq)
        assert np.allclose([float(x) for x in v[2:5]], T[:3, 3], atol=1e-6)
    assert [r_["robot"] for r_ in ids] == sorted(r_["robot"] for r_ in ids), "robots in order"
    assert open(os.path.join(out, "graph.left_out.csv")).read().splitlines() == [
        "loop_id,query_scan,candidate_scan,reason"]
    r = subprocess.run([CLI, "export", "--server", s.addr, "--map", "m", "--format", "json", "--robot", "a",
                        "--out", out], check=True, capture_output=True, text=True, timeout=60)
    js = json.load(open(os.path.join(out, "graph.json")))
    assert len(js["nodes"]) == n and {x["robot"] for x in js["nodes"]} == {"a"}
    kinds = [e["kind"] for e in js["edges"]]
    assert kinds.count("odometry") == n - 1 and 0 < kinds.count("loop") < loops
    assert len(js["left_out"]) == loops - kinds.count("loop"), "loops to robot b are listed, not dropped"
    assert all("robot 'b'" in x["reason"] for x in js["left_out"])
    # MCAP for Foxglove, read back by @mcap/core (streaming with CRCs, and indexed through the summary).
    subprocess.run([CLI, "export", "--server", s.addr, "--map", "m", "--format", "mcap", "--out", out], check=True,
                   capture_output=True, timeout=60)
    interop = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "interop")
    assert shutil.which("node") and os.path.isdir(os.path.join(interop, "node_modules", "@mcap", "core")), \
        "node or tests/interop/node_modules is missing: run scripts/install-deps.sh"
    got = json.loads(subprocess.run(["node", os.path.join(interop, "read_mcap.mjs"), os.path.join(out, "graph.mcap")],
                                    check=True, capture_output=True, text=True, timeout=120).stdout)
    assert got["indexed"]["schemas"] == ["foxglove.PosesInFrame", "foxglove.SceneUpdate", "sglc.LoopList"]
    assert got["indexed"]["channels"] == ["/sglc/loop_list", "/sglc/loops", "/sglc/odometry/a", "/sglc/odometry/b",
                                          "/sglc/trajectory/a", "/sglc/trajectory/b"]
    for robot in ("a", "b"):
        traj = got["messages"][f"/sglc/trajectory/{robot}"][0]["data"]
        mine = [p for p in all_poses if p.robot == robot]
        assert traj["frame_id"] == "map" and len(traj["poses"]) == len(mine)
        T = np.array(mine[-1].t_map_scan.m).reshape(4, 4)
        last = traj["poses"][-1]["position"]
        assert np.allclose([last["x"], last["y"], last["z"]], T[:3, 3], atol=1e-6)
    scene = got["messages"]["/sglc/loops"][0]["data"]["entities"]
    assert sum(len(e["lines"][0]["points"]) for e in scene) == 2 * loops
    listed = got["messages"]["/sglc/loop_list"][0]["data"]["loops"]
    assert len(listed) == loops and all(0 < lp["score"] and 0 <= lp["weight"] <= 1 for lp in listed)
    assert {lp["inter_robot"] for lp in listed} == {True, False}
    assert all(lp["inter_robot"] == (lp["from"]["robot"] != lp["to"]["robot"]) for lp in listed)
    expect_code(grpc.StatusCode.INVALID_ARGUMENT,
                lambda: list(s.graph.ExportGraph(pb.ExportGraphRequest(map="m", format="xml"))), "unknown format")
    expect_code(grpc.StatusCode.NOT_FOUND,
                lambda: list(s.graph.ExportGraph(pb.ExportGraphRequest(map="m", robots=["ghost"]))), "unknown robot")
    expect_code(grpc.StatusCode.INVALID_ARGUMENT,
                lambda: list(s.graph.ExportGraph(pb.ExportGraphRequest(map="m", robots=["a"] * 1001))), "1001 robots")
    expect_code(grpc.StatusCode.INVALID_ARGUMENT,
                lambda: list(s.graph.ExportGraph(pb.ExportGraphRequest(map="m", robots=["a\nb"]))), "a bad name")


def test_pose_graph(tmp):
    # A drive of the built-in route (every 8th frame) with 2 % odometry drift, as two robots: "a" drives it
    # all, "b" the second half with its odometry in an unrelated frame. Loops correct both.
    seq = os.path.join(tmp, "seq")
    subprocess.run([SIM, "--route", "loop", "--frames", "::8", "--odom-noise", "0.02", "--out", seq], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=300)
    Tr = np.eye(4)
    for line in open(os.path.join(seq, "calib.txt")):
        if line.startswith("Tr:"):
            Tr[:3, :] = np.array([float(v) for v in line.split()[1:13]]).reshape(3, 4)
    gt = read_kitti_poses(os.path.join(seq, "poses.txt"), Tr)
    odom = read_kitti_poses(os.path.join(seq, "odometry.txt"), Tr)
    n = len(gt)
    offset = np.eye(4)
    c, s_ = np.cos(1.0), np.sin(1.0)
    offset[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    offset[:3, 3] = [50.0, -20.0, 3.0]

    def scan(i):
        name = f"{i:06d}"
        pts = np.fromfile(os.path.join(seq, "velodyne", name + ".bin"), dtype="<f4").reshape(-1, 4)[:, :3]
        lab = np.fromfile(os.path.join(seq, "labels", name + ".label"), dtype="<u4")
        return pb.Scan(points=np.ascontiguousarray(pts).tobytes(), labels=lab.tobytes())

    def tf(T):
        return pb.Transform(m=[float(v) for v in T.reshape(-1)])

    db = os.path.join(tmp, "graph.db")
    # The server's odometry model matches the simulated drift (2 % per axis, 0.01 deg/m in heading).
    cfg = os.path.join(tmp, "graph.yaml")
    with open(cfg, "w") as f:
        f.write("pose_graph:\n  odometry_sigma_per_m: 0.02\n  odometry_sigma_deg_per_m: 0.01\n")
    s = Server(db, ["--config", cfg])
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"))
        C = grpc.StatusCode
        expect_code(C.NOT_FOUND, lambda: s.graph.GetPoses(pb.GetPosesRequest(map="nomap")), "poses of an unknown map")
        expect_code(C.INVALID_ARGUMENT, lambda: s.graph.GetPoses(pb.GetPosesRequest(map="m", session="x")),
                    "session without robot")
        expect_code(C.INVALID_ARGUMENT, lambda: s.graph.GetPoses(pb.GetPosesRequest(map="m", page_size=20000)),
                    "page too large")
        expect_code(C.NOT_FOUND, lambda: s.graph.GetPoses(pb.GetPosesRequest(map="m", robot="ghost")), "unknown robot")
        opts = pb.QueryOptions(exclude_recent=12, top_k=3)
        reqs = [pb.IngestRequest(key=key("a", i), scan=scan(i), odometry_pose=tf(odom[i]), query=True,
                                 query_options=opts, stamp=1000.0 + 0.8 * i) for i in range(n)]
        half = n // 2
        reqs += [pb.IngestRequest(key=key("b", i), scan=scan(i), odometry_pose=tf(offset @ odom[i]), query=True,
                                  query_options=opts) for i in range(half, n)]
        # Every verified loop becomes one edge of the pose graph.
        loops = sum(l.verified for r in s.loop.IngestStream(iter(reqs), timeout=600) for l in r.loops)
        assert loops > 20, f"only {loops} loops"
        # The optimiser runs off the request path: wait for its converged solve of every scan and loop.
        events = s.graph.WatchMap(pb.WatchMapRequest(map="m"), timeout=300)
        for ev in events:
            assert not ev.failed, ev.error
            if ev.nodes == n + (n - half) and ev.loops == loops and ev.converged:
                break
        events.cancel()
        assert ev.graph_version >= 1 and ev.converged, ev
        poses, token = [], 0
        while True:  # paged
            r = s.graph.GetPoses(pb.GetPosesRequest(map="m", robot="a", page_token=token, page_size=50))
            poses += r.poses
            token = r.next_page_token
            if not token:
                break
        assert [p.seq for p in poses] == list(range(n)), "one pose per scan of robot a, in order"
        assert all(p.optimised and p.connected for p in poses)
        est = [np.array(p.t_map_scan.m).reshape(4, 4) for p in poses]
        ate_odom, ate_opt = ate(odom, gt), ate(est, gt)
        print(f"  robot a: ATE odometry {ate_odom:.3f} m -> optimised {ate_opt:.3f} m over {n} scans, {loops} loops")
        assert ate_opt < ate_odom / 3, f"ATE {ate_odom:.3f} -> {ate_opt:.3f}"
        frames = {(f.robot, f.session): f for f in s.graph.GetSessionFrames(pb.GetSessionFramesRequest(map="m")).sessions}
        fb = frames[("b", "run")]
        assert fb.connected, "robot b was linked to the map by inter-robot loops"
        # b's frame undoes the offset: its first scan lands where it truly is (up to a's remaining error).
        T = np.array(fb.t_map_session.m).reshape(4, 4)
        dt, dr = pose_error(T @ offset @ odom[half], gt[half])
        b_poses = [np.array(p.t_map_scan.m).reshape(4, 4)
                   for p in s.graph.GetPoses(pb.GetPosesRequest(map="m", robot="b")).poses]
        ate_b = ate(b_poses, gt[half:])
        # Both robots drove frames half..n: in one common frame their poses there must coincide.
        gap = np.mean([pose_error(pb_, est[half + k])[0] for k, pb_ in enumerate(b_poses)])
        print(f"  robot b: first scan placed {dt:.3f} m / {dr:.3f} deg from the truth, ATE {ate_b:.3f} m, "
              f"mean gap to robot a on the same frames {gap:.3f} m")
        assert dt < 2.5 and dr < 3.0 and ate_b < ate_odom / 2 and gap < 0.3, (dt, dr, ate_b, gap)
        before = [(p.scan_id, tuple(p.t_map_scan.m)) for p in s.graph.GetPoses(pb.GetPosesRequest(map="m")).poses]
        # The command line writes the same trajectory in KITTI format.
        out = os.path.join(tmp, "a.txt")
        subprocess.run([CLI, "trajectory", "--server", s.addr, "--map", "m", "--robot", "a", "--out", out], check=True,
                       stdout=subprocess.DEVNULL, timeout=60)
        rows = np.loadtxt(out).reshape(-1, 3, 4)
        assert len(rows) == n and np.allclose(rows, np.array([T[:3, :] for T in est]), atol=1e-6)
        frames_list = [l.split() for l in open(out + ".frames") if not l.startswith("#")]
        assert [int(f[2]) for f in frames_list] == list(range(n)) and all(f[0] == "a" for f in frames_list)
        check_exports(s, tmp, est, n, loops)
    finally:
        s.stop(signal.SIGKILL)
    s = Server(db, ["--config", cfg])
    try:
        after = [(p.scan_id, tuple(p.t_map_scan.m)) for p in s.graph.GetPoses(pb.GetPosesRequest(map="m")).poses]
        assert len(after) == len(before), "poses lost on restart"
        a_before = dict(before)
        moved = max(np.abs(np.array(m) - np.array(a_before[i])).max() for i, m in after)
        assert moved < 0.05, f"poses moved by {moved} across a restart"
        # Deleting robot b takes its scans and loops out of the graph, which is solved again at once.
        events = s.graph.WatchMap(pb.WatchMapRequest(map="m"), timeout=60)
        removed = s.admin.DeleteRobot(pb.DeleteRobotRequest(map="m", robot="b")).scans_removed
        assert removed == n - half, removed
        for ev in events:
            if ev.nodes == n:
                break
        events.cancel()
        assert ev.nodes == n and ev.loops < loops, (ev.nodes, ev.loops)
        left = s.graph.GetPoses(pb.GetPosesRequest(map="m")).poses
        assert len(left) == n and all(p.optimised for p in left), len(left)
        # Deleting the map ends its watchers with NOT_FOUND (they would otherwise wait for a map that is gone).
        events = s.graph.WatchMap(pb.WatchMapRequest(map="m"), timeout=60)
        assert next(events).nodes == n  # the latest event: the watch is in place
        s.admin.DeleteMap(pb.DeleteMapRequest(map="m"))
        try:
            for ev in events:
                pass
            raise AssertionError("the watch outlived its map")
        except grpc.RpcError as e:
            assert e.code() == grpc.StatusCode.NOT_FOUND and "was deleted" in e.details(), (e.code(), e.details())
    finally:
        assert s.stop() == 0

def main():
    tests = [test_inter_robot_loop_and_restart, test_known_loop_pose, test_unlabelled_scans, test_bad_inputs, test_tokens, test_concurrent_clients, test_config_file,
             test_pose_graph]
    harness.run(tests, "sglc-server-test-")

if __name__ == "__main__":
    main()
