"""F. Idempotent ingest: a retried identical request (the client never saw the first answer) succeeds with the
same scan id, and with query=true finds the loops again; a different scan under a stored key is ALREADY_EXISTS
with a message naming the key; the scan is counted once."""
import adv_harness as h

CLASS = "F"
TITLE = "idempotent ingest"

ROBOT, SESSION = "robot-F", "sess-F"


def run(tmp):
    pb, C = h.pb, h.C
    fx = h.Fixture(tmp, "f", prepare=lambda s: s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30))
    s = fx.server()
    by = h.Bystander(s)
    # A stored scan the query will find as a loop: the real revisit 4501 <-> 52, or the same synthetic scan.
    if h.HAVE_DATA:
        base, query = h.load_scan("004501"), h.load_scan("000052")
    else:
        base = query = h.synthetic_scan(4000, seed=61)
    s.loop.Ingest(pb.IngestRequest(key=h.key("other", 4501, session="base"), scan=base), timeout=30)
    req = pb.IngestRequest(key=h.key(ROBOT, 52, session=SESSION), scan=query, query=True, stamp=12.5,
                           query_options=pb.QueryOptions(top_k=3))
    before = s.snapshot()
    first = {}

    def call(t):
        return fx.server().loop.Ingest(req, timeout=t)

    def first_ok():
        first["r"] = h.expect_ok(s, call, stored=1)
        h.note(f"first ingest: scan {first['r'].scan_id}, {len(first['r'].loops)} loop(s)")
    h.probe("F.first_ingest_ok", first_ok)
    second = {}

    def retry_same_id():
        assert "r" in first, "the first ingest failed"
        try:
            second["r"] = r = call(30)
        except h.grpc.RpcError as e:
            h.record(e)
            raise AssertionError(f"expected the identical retry to be OK with scan id {first['r'].scan_id}, got "
                                 f"{e.code().name}: '{h.short(e.details())}'")
        assert r.scan_id == first["r"].scan_id, f"expected scan id {first['r'].scan_id}, got {r.scan_id}"
        assert r.seq == 52, f"expected seq 52 echoed, got {r.seq}"
    h.probe("F.identical_retry_ok_same_scan_id", retry_same_id)

    def retry_loops():
        assert "r" in second, "the retry failed"
        a = [c.scan_id for c in first["r"].loops]
        b = [c.scan_id for c in second["r"].loops]
        if a:
            assert b, f"expected the retry to return the loops again ({a}), it returned none"
            assert b == a, f"expected the same loops {a}, got {b}"
        else:
            h.note("the first ingest found no loop; nothing to compare")
    h.probe("F.identical_retry_returns_loops_again", retry_loops)

    def counted_once():
        after = fx.server().snapshot()
        assert after[1] == before[1] + 1 and after[2] == before[2] + 1, \
            f"expected the scan counted once, (maps, scans, index entries) went {before} -> {after}"
        sessions = fx.server().admin.ListSessions(pb.ListSessionsRequest(map="m", robot=ROBOT), timeout=30).sessions
        assert [(x.name, x.scans) for x in sessions] == [(SESSION, 1)], f"sessions: {sessions}"
    h.probe("F.identical_retry_counted_once", counted_once)

    def different_scan():
        other = pb.IngestRequest(key=h.key(ROBOT, 52, session=SESSION), scan=h.synthetic_scan(3000, seed=62))
        h.expect_error(fx.server(), lambda t: fx.server().loop.Ingest(other, timeout=t), C.ALREADY_EXISTS,
                       words=(ROBOT, SESSION, "52"))
    h.probe("F.different_scan_same_key_already_exists", different_scan)

    def identical_in_stream():
        s = fx.server()
        r1 = pb.IngestRequest(key=h.key(ROBOT, 100, session=SESSION), scan=h.synthetic_scan(3000, seed=63))
        rs = h.expect_ok(s, lambda t: list(s.loop.IngestStream(iter([r1, r1]), timeout=t)), stored=1)
        assert len(rs) == 2 and rs[0].scan_id == rs[1].scan_id, \
            f"expected two responses with one scan id, got {[x.scan_id for x in rs]}"
    h.probe("F.identical_request_twice_in_one_stream", identical_in_stream)

    def identical_chunked():
        s = fx.server()
        scan = h.synthetic_scan(3000, seed=64)

        def send(t):
            chunks = [pb.IngestChunk(header=pb.IngestRequest(key=h.key(ROBOT, 200, session=SESSION)),
                                     points=scan.points[:12000], labels=scan.labels[:4000]),
                      pb.IngestChunk(points=scan.points[12000:], labels=scan.labels[4000:])]
            return s.loop.IngestChunked(iter(chunks), timeout=t)
        a = h.expect_ok(s, send, stored=1)
        b = h.expect_ok(s, send, stored=0)
        assert a.scan_id == b.scan_id, f"expected one scan id, got {a.scan_id} and {b.scan_id}"
    h.probe("F.identical_chunked_retry_ok_same_scan_id", identical_chunked)
    h.probe("F.other_clients_unaffected", by.finish)
    fx.stop()
