"""sglc.Client against a real sglc-server, with the real loop pair KITTI 00 000052-004501."""
import json
import os
import subprocess
import sys
import threading

import numpy as np
import pytest

import sglc
from conftest import BUILD, REPO, pose_error


def test_requests_without_a_server():
    c = sglc.Client("127.0.0.1:1", chunk_bytes=16 * 100, timeout=5)
    pts, lab = np.zeros((500, 3), np.float32), np.arange(500, dtype=np.uint32)
    req = c.ingest_request("m", "r", "s", 7, pts, lab, stamp=1.5, query=True, scope="other", top_k=3)
    chunks = list(c._chunks(req))
    assert len(chunks) == 1 + 5 and chunks[0].HasField("header") and not chunks[0].header.scan.points
    assert b"".join(x.points for x in chunks[1:]) == req.scan.points
    assert b"".join(x.labels for x in chunks[1:]) == req.scan.labels
    assert chunks[0].header.query_options.scope == sglc.SCOPES["other"] and chunks[0].header.stamp == 1.5
    assert not req.query_options.HasField("exclude_recent")  # the server's default, as every client
    with pytest.raises(ValueError, match="scope"):
        c.query_options(scope="galaxy")
    with pytest.raises(ValueError, match="without query=True"):
        c.ingest_request("m", "r", "s", 7, pts, top_k=3)
    with pytest.raises(ValueError, match="either scan_id or points"):
        c.query("m")
    with pytest.raises(sglc.UnavailableError):
        c.list_maps()
    assert not c.serving(timeout=2)
    c.close()


def test_integer_arguments_must_be_integers():
    c = sglc.Client("127.0.0.1:1", timeout=5)
    pts = np.zeros((5, 3), np.float32)
    for bad in (1.5, 2.0, True, "7", np.float32(3)):
        with pytest.raises(TypeError, match="seq must be an integer"):
            c.ingest_request("m", "r", "s", bad, pts)
        with pytest.raises(TypeError, match="seq must be an integer"):
            c.query("m", points=pts, seq=bad)
        with pytest.raises(TypeError, match="scan_id must be an integer"):
            c.query("m", scan_id=bad)
        with pytest.raises(TypeError, match="top_k must be an integer"):
            c.query_options(top_k=bad)
        with pytest.raises(TypeError, match=r"verify_scan_ids\[\] must be an integer"):
            c.query_options(verify_scan_ids=[1, bad])
        with pytest.raises(TypeError, match="scan_id must be an integer"):
            c.get_scan(bad)
    with pytest.raises(TypeError, match="not a bool"):
        c.ingest_request("m", "r", "s", np.bool_(True), pts)
    # Python and NumPy integers of any width are integers.
    for good in (7, np.int64(7), np.uint16(7), np.int32(7)):
        assert c.ingest_request("m", "r", "s", good, pts).key.seq == 7
        assert c.query_options(top_k=good, exclude_recent=good).top_k == 7
    c.close()


def test_ingest_stream_items_of_the_wrong_type_are_a_type_error():
    c = sglc.Client("127.0.0.1:1", timeout=5)
    for bad in (("m", "r", "s", 1, np.zeros((5, 3))), None, 42):
        with pytest.raises(TypeError, match="item 0 is a .*expected a sglc.ScanInput or a dict"):
            next(c.ingest_stream([bad]))
    c.close()


def test_service_flow(client, kitti, reference_pose):
    info = client.server_info()
    assert info.label_preset == "semantickitti" and info.labeller_mode == "auto" and info.version
    assert info.node_classes == ["vehicle", "trunk", "pole"] and info.label_ids["road"] and info.max_points > 0
    assert info.loop_model and 0 < info.min_probability <= 1, (info.loop_model, info.min_probability)
    assert client.create_map("py").name == "py"
    client.ensure_map("py")  # idempotent
    assert [m.name for m in client.list_maps()] == ["py"]

    p52, l52 = kitti("000052")
    p4501, l4501 = kitti("004501")
    a = client.ingest("py", "a", "00", 52, p52, l52, stamp=10.0, odometry_pose=np.eye(4))
    assert isinstance(a, sglc.IngestResult) and a.seq == 52 and a.loops == [] and a.label_source == "provided"
    # KITTI's own (N, 4) array and int64 labels are accepted as they are.
    raw = np.hstack([p4501, np.zeros((len(p4501), 1), np.float32)])
    b = client.ingest("py", "b", "00", 4501, raw, l4501.astype(np.int64), query=True, scope="other",
                      odometry_pose=np.eye(4))
    assert len(b.loops) >= 1 and b.loops[0].scan_id == a.scan_id and b.loops[0].robot == "a"
    loop = b.loops[0]
    dt, dr = pose_error(loop.T, np.linalg.inv(reference_pose))
    assert dt < 0.2 and dr < 1.0, (dt, dr)
    assert loop.information.shape == (6, 6) and np.linalg.eigvalsh(loop.information).min() > 0

    q = client.query("py", scan_id=a.scan_id, scope="other")
    hit = [x for x in q.candidates if x.scan_id == b.scan_id]
    assert len(hit) == 1 and hit[0].verified
    assert hit[0].probability is not None and 0.0 <= hit[0].probability <= 1.0 and hit[0].evidence is None
    q = client.query("py", scan_id=a.scan_id, scope="other", include_evidence=True, include_rejected=True)
    assert q.candidates and all(isinstance(x.evidence, sglc.Evidence) for x in q.candidates)
    # A loop has no reason; a rejected candidate says why (the evidence that fell shortest, or no pose).
    assert all((x.reason == "") == x.verified for x in q.candidates), [(x.verified, x.reason) for x in q.candidates]
    dt, dr = pose_error(hit[0].T, reference_pose)
    assert dt < 0.2 and dr < 1.0
    q = client.query("py", points=p4501, labels=l4501, top_k=5)  # relocalization: a scan not stored
    assert any(x.scan_id == a.scan_id for x in q.candidates)

    again = client.ingest("py", "a", "00", 52, p52, l52, stamp=10.0, odometry_pose=np.eye(4))
    assert again.already_stored and again.scan_id == a.scan_id  # a retry answers the stored scan
    p88, l88 = kitti("000088")
    with pytest.raises(sglc.AlreadyExistsError) as e:
        client.ingest("py", "a", "00", 52, p88, l88)
    assert e.value.code_name == "ALREADY_EXISTS" and "52" in e.value.details
    with pytest.raises(sglc.NotFoundError):
        client.list_robots("nosuch")
    with pytest.raises(sglc.InvalidArgumentError):
        client.create_map("bad/name\n")

    # Admin views, as dataclasses.
    assert sorted(r.name for r in client.list_robots("py")) == ["a", "b"]
    s = client.list_sessions("py", "a")
    assert len(s) == 1 and (s[0].first_seq, s[0].last_seq, s[0].scans) == (52, 52, 1)
    g = client.get_scan(a.scan_id, include_graph=True)
    assert (g.robot, g.seq, g.stamp) == ("a", 52, 10.0) and g.nodes and g.descriptor is not None
    assert np.array_equal(g.odometry_pose, np.eye(4))
    st = client.stats("py")
    assert (st.scans, st.robots) == (2, 2)
    assert client.backup("py-backup.db").bytes > 0


def test_pose_graph_calls(client, kitti):
    client.create_map("graph")
    frames = ["000052", "000088", "000850", "004501"]
    with client.watch("graph") as watch:
        for robot in ("r1", "r2"):
            for i, f in enumerate(frames if robot == "r1" else frames[::-1][:1]):
                p, lab = kitti(f)
                T = np.eye(4)
                T[0, 3] = 5.0 * i
                client.ingest("graph", robot, "run", i, p, lab, stamp=100.0 + i, odometry_pose=T, query=True,
                              scope="other")
        event = next(watch)  # r2's scan closed a loop with r1's: the graph is solved
    assert isinstance(event, sglc.MapEvent) and event.graph_version >= 1 and event.loops >= 1 and not event.failed
    loops = client.loops("graph")
    assert loops and all(isinstance(e, sglc.LoopEdge) for e in loops)
    assert {loops[0].query.robot, loops[0].candidate.robot} == {"r1", "r2"}
    assert loops[0].T.shape == (4, 4) and loops[0].information.shape == (6, 6)
    # The loop model's probability as recorded, or None (unknown) for a loop no model judged: a verified loop at
    # probability 0 (verification before the model) is recorded as unknown.
    assert loops[0].probability is None or 0.0 < loops[0].probability <= 1.0
    assert [e.id for e in client.loops("graph", page_size=1)] == [e.id for e in loops]  # paging loses nothing
    assert [e.id for e in client.loops("graph", robot="r2")] == [e.id for e in loops]
    with pytest.raises(sglc.NotFoundError):
        client.loops("graph", robot="nosuch")
    poses = client.poses("graph", page_size=2)
    assert [p.seq for p in poses if p.robot == "r1"] == [0, 1, 2, 3] and all(p.stamp is not None for p in poses)
    assert [p.scan_id for p in poses] == sorted(p.scan_id for p in poses)
    frames_ = client.session_frames("graph")
    assert {(f.robot, f.session) for f in frames_} == {("r1", "run"), ("r2", "run")}
    assert all(f.T.shape == (4, 4) for f in frames_)
    with pytest.raises(sglc.NotFoundError):
        client.poses("no-such-map")


def test_streaming_ingest(client, kitti):
    client.create_map("stream")
    frames = ["000052", "000088", "000850", "004501"]
    scans = (sglc.ScanInput("stream", "d", "run", i, *kitti(f), query=True, query_options={"exclude_recent": 0})
             for i, f in enumerate(frames))
    results = list(client.ingest_stream(scans, window=2))
    assert [r.seq for r in results] == [0, 1, 2, 3]
    assert any(x.seq == 0 for x in results[3].loops)  # 4501 finds 52 on the stream
    # Dicts work too; a conflicting key ends the stream with its status, after the earlier results.
    bad = [dict(map="stream", robot="d", session="run2", seq=9, points=kitti("000088")[0]),
           dict(map="stream", robot="d", session="run", seq=1, points=kitti("000850")[0])]
    got = []
    with pytest.raises(sglc.AlreadyExistsError):
        for r in client.ingest_stream(bad):
            got.append(r.seq)
    assert got == [9]
    # Stopping early cancels the stream; the scans answered before were stored.
    gen = client.ingest_stream(dict(map="stream", robot="e", session="s", seq=i, points=kitti(f)[0])
                               for i, f in enumerate(frames))
    first = next(gen)
    gen.close()
    assert first.seq == 0 and client.get_scan(first.scan_id).robot == "e"


def test_concurrent_clients(server, kitti):
    """Several threads with their own clients ingest at once (the package holds no global state)."""
    with sglc.Client(server) as c:
        c.create_map("threads")
    errors = []

    def run(robot):
        try:
            with sglc.Client(server, timeout=120) as c:
                for i, f in enumerate(["000052", "000088"]):
                    c.ingest("threads", robot, "s", i, *kitti(f))
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(f"t{k}",)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with sglc.Client(server) as c:
        assert c.stats("threads").scans == 6


def test_unlabelled_scans(client, kitti):
    client.create_map("raw")
    u = client.ingest("raw", "u", "00", 52, kitti("000052")[0])
    assert u.label_source == "computed"
    u2 = client.ingest("raw", "u", "00", 4501, kitti("004501")[0], query=True, exclude_recent=50)
    assert any(x.scan_id == u.scan_id and x.verified for x in u2.loops)


def test_example_runs(server, kitti_dir):
    env = dict(os.environ, PYTHONPATH=os.path.join(BUILD, "python"))
    ex = subprocess.run([sys.executable, os.path.join(REPO, "client", "python", "examples", "two_robots.py"), "--server", server,
                         "--data", kitti_dir], capture_output=True, text=True, timeout=300, env=env)
    assert ex.returncode == 0, ex.stderr
    assert "inter-robot loop" in ex.stdout and "robot alice" in ex.stdout


def test_delete_map(client, server, kitti):
    client.create_map("gone")
    client.ingest("gone", "r", "s", 1, *kitti("000052"))
    client.ingest("gone", "r", "s", 2, *kitti("000088"))
    cli = os.path.join(BUILD, "bin", "sglc")
    if os.access(cli, os.X_OK):  # the command line refuses without --yes and says what would go
        refused = subprocess.run([cli, "delete-map", "gone", "--server", server], capture_output=True, text=True,
                                 timeout=60)
        assert refused.returncode == 1 and "holds 2 scans" in refused.stderr and "--yes" in refused.stderr
        assert client.stats("gone").scans == 2
        done = subprocess.run([cli, "delete-map", "gone", "--yes", "--json", "--server", server],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 0 and '"scans_removed":2' in done.stdout, done.stdout + done.stderr
    else:
        assert client.delete_map("gone") == 2
    assert "gone" not in [m.name for m in client.list_maps()]
    with pytest.raises(sglc.NotFoundError):
        client.delete_map("gone")
    # A map of the same name starts empty, and its first scans do not meet the deleted ones.
    client.create_map("gone")
    r = client.ingest("gone", "q", "s", 1, *kitti("004501"), query=True)
    assert r.loops == [] and client.stats("gone").scans == 1


def test_a_page_token_that_does_not_grow_ends_paging_with_an_error():
    """A server whose next_page_token never advances must not keep the client paging forever."""
    class Stuck:
        def GetPoses(self, request, timeout=None, metadata=None):
            r = sglc.pb2.GetPosesResponse(next_page_token=5)
            r.poses.add(scan_id=5)
            return r

    c = sglc.Client("127.0.0.1:1")
    c._graph = Stuck()
    with pytest.raises(sglc.InternalError, match="does not follow"):
        c.poses("m")
    c.close()


def test_unavailable_is_retried_up_to_max_attempts():
    """A call answered UNAVAILABLE (a replica behind a balancer going away) is retried by gRPC's retry policy."""
    import grpc
    from concurrent import futures
    calls = {"n": 0, "unavailable": 0}

    def list_maps(request, context):
        calls["n"] += 1
        if calls["unavailable"] > 0:
            calls["unavailable"] -= 1
            context.abort(grpc.StatusCode.UNAVAILABLE, "upstream connect error")
        return sglc.pb2.ListMapsResponse()

    handler = grpc.method_handlers_generic_handler("sglc.v1.MapAdmin", {"ListMaps": grpc.unary_unary_rpc_method_handler(
        list_maps, request_deserializer=sglc.pb2.ListMapsRequest.FromString,
        response_serializer=sglc.pb2.ListMapsResponse.SerializeToString)})
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=2))
    server.add_generic_rpc_handlers((handler,))
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        calls.update(n=0, unavailable=2)
        with sglc.Client(f"127.0.0.1:{port}") as c:
            assert c.list_maps() == []
        assert calls["n"] == 3
        calls.update(n=0, unavailable=1)
        with sglc.Client(f"127.0.0.1:{port}", max_attempts=1) as c:
            with pytest.raises(sglc.UnavailableError):
                c.list_maps()
        assert calls["n"] == 1
        with pytest.raises(ValueError):
            sglc.Client(f"127.0.0.1:{port}", max_attempts=6)
    finally:
        server.stop(0)


def test_export_lists_every_loop(client, kitti):
    """Client.export: the graph of the scans with odometry; a loop of a scan sent without odometry is listed
    (loops() too), never dropped."""
    p52, l52 = kitti("000052")
    p4501, l4501 = kitti("004501")
    client.create_map("exp")
    client.ingest("exp", "a", "run", 0, p52, l52, odometry_pose=np.eye(4))
    b = client.ingest("exp", "b", "run", 0, p4501, l4501, odometry_pose=np.eye(4), query=True)
    assert any(x.verified for x in b.loops)
    c = client.ingest("exp", "c", "run", 0, p4501, l4501, query=True)  # no odometry pose: no graph node
    verified_c = sum(x.verified for x in c.loops)
    assert verified_c >= 1
    assert len(client.loops("exp")) == sum(x.verified for x in b.loops) + verified_c
    files, summary = client.export("exp")
    assert set(files) == {"graph.g2o", "graph.ids.csv", "graph.left_out.csv"}
    assert summary["nodes"] == 2 and summary["loop_edges"] >= 1 and summary["loops_left_out"] == verified_c
    g2o = files["graph.g2o"].decode().splitlines()
    assert sum(line.startswith("VERTEX_SE3:QUAT ") for line in g2o) == 2
    left = files["graph.left_out.csv"].decode().splitlines()
    assert len(left) == 1 + verified_c and all("no odometry pose" in row for row in left[1:])
    js, _ = client.export("exp", format="json", robots=["a"])
    assert [n["robot"] for n in json.loads(js["graph.json"])["nodes"]] == ["a"]
    with pytest.raises(sglc.InvalidArgumentError, match="format"):
        client.export("exp", format="xml")
    with pytest.raises(sglc.NotFoundError):
        client.export("nosuchmap")


def test_every_log_line_has_an_event_and_the_level_filters(tmp_path):
    """Each JSON log line names its event (RPC lines "rpc"); --log-level warn keeps failed calls only."""
    from conftest import start_server
    for level, expect_ok_lines in (("info", True), ("warn", False)):
        d = tmp_path / level
        d.mkdir()
        proc, address, _ = start_server(d, ["--log-level", level])
        try:
            with sglc.Client(address, timeout=60) as c:
                c.create_map("m")
                with pytest.raises(sglc.NotFoundError):
                    c.list_robots("nosuch")
        finally:
            proc.terminate()
            proc.wait(timeout=60)
        lines = [json.loads(line) for f in sorted(d.glob("server*.log")) for line in f.read_text().splitlines()
                 if line.startswith("{")]
        assert lines and all("event" in line for line in lines), [x for x in lines if "event" not in x][:3]
        rpcs = [x for x in lines if x["event"] == "rpc"]
        assert any(x["method"] == "ListRobots" and x["code"] == "NOT_FOUND" and x["level"] == "warning" for x in rpcs)
        assert any(x["method"] == "CreateMap" and x["code"] == "OK" for x in rpcs) == expect_ok_lines, level
    r = subprocess.run([os.path.join(os.environ.get("SGLC_BUILD_DIR", ""), "bin", "sglc-server"), "--log-level", "loud",
                        "--dump-config"], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "log_level" in r.stderr, r.stderr


def test_the_default_address_is_sglc_server(monkeypatch):
    monkeypatch.setenv("SGLC_SERVER", "127.0.0.1:1")
    with sglc.Client(max_attempts=1) as c:  # port 1: nobody listens
        assert c.address == "127.0.0.1:1"
        with pytest.raises(sglc.UnavailableError):
            c.list_maps(timeout=10)
    monkeypatch.delenv("SGLC_SERVER")
    with sglc.Client() as c:
        assert c.address == "127.0.0.1:50051"
