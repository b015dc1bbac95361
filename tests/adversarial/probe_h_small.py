"""H. Small ones: GetScan of another map's scan looks exactly like a missing scan; Backup names that are not a
plain file name are refused without leaking server paths or leaving files; CreateMap is idempotent; SCOPE_SESSIONS
through the structured QueryOptions.session_refs works for robots whose names contain '/'."""
import os
import re

import adv_harness as h

CLASS = "H"
TITLE = "GetScan across maps, Backup names, CreateMap twice, session_refs"

TOKEN_A, TOKEN_B = "token-A-aaaaaaaa", "token-B-bbbbbbbb"


def getscan_other_map(tmp):
    pb, C = h.pb, h.C
    path = os.path.join(tmp, "tokens.txt")
    with open(path, "w") as f:
        f.write(f"{TOKEN_A} mapA\n{TOKEN_B} mapB\n")
    a = [("authorization", f"Bearer {TOKEN_A}")]
    b = [("authorization", f"Bearer {TOKEN_B}")]
    s = h.Server(os.path.join(tmp, "tokens.db"), ["--tokens", path], token=TOKEN_A)
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="mapA"), timeout=30, metadata=a)
        s.admin.CreateMap(pb.CreateMapRequest(name="mapB"), timeout=30, metadata=b)
        scan = h.synthetic_scan(2000, seed=81)
        id_a = s.loop.Ingest(pb.IngestRequest(key=h.key("ra", 1, m="mapA"), scan=scan), timeout=30, metadata=a).scan_id
        id_b = s.loop.Ingest(pb.IngestRequest(key=h.key("rb", 1, m="mapB"), scan=scan), timeout=30, metadata=b).scan_id
        missing = max(id_a, id_b) + 1000
        s.admin.GetScan(pb.GetScanRequest(scan_id=id_a), timeout=30, metadata=a)  # its own map's scan: fine
        msgs = {}
        for what, sid in (("mapB's scan", id_b), ("a missing scan", missing)):
            try:
                s.admin.GetScan(pb.GetScanRequest(scan_id=sid), timeout=30, metadata=a)
                raise AssertionError(f"expected NOT_FOUND for {what} with token A, got OK")
            except h.grpc.RpcError as e:
                h.record(e)
                assert e.code() == C.NOT_FOUND and e.details(), \
                    f"expected NOT_FOUND for {what} with token A, got {e.code().name}: '{h.short(e.details())}'"
                msgs[what] = e.details()
        shape_b = re.sub(r"\d+", "N", msgs["mapB's scan"])
        shape_missing = re.sub(r"\d+", "N", msgs["a missing scan"])
        assert shape_b == shape_missing, (f"expected the same message shape as for a missing scan "
                                          f"('{shape_missing}'), got '{shape_b}'")
        leak = msgs["mapB's scan"]
        assert "mapB" not in leak, f"expected no map name in the message, got '{leak}'"
        s.assert_alive()
    finally:
        s.stop()


def backups(tmp):
    pb, C = h.pb, h.C
    dbdir = os.path.join(tmp, "bk")
    os.makedirs(dbdir)
    s = h.Server(os.path.join(dbdir, "map.db"))
    bdir = os.path.join(dbdir, "backups")

    def bad_names():
        problems = []
        for name in ["x\x00y.db", "b" * 300, "../x", "a/b", "", "/tmp/abs.db", ".", ".."]:
            try:
                msg = h.expect_error(s, lambda t, n=name: s.admin.Backup(pb.BackupRequest(path=n), timeout=t),
                                     C.INVALID_ARGUMENT, check_stored=False, deadline=60)
                if tmp in msg or dbdir in msg or h.ABS_PATH.search(msg):
                    problems.append(f"{name[:20]!r}: expected no server path in the message, got '{h.short(msg)}'")
            except AssertionError as e:
                problems.append(f"{name[:20]!r}: {e}")
            left = os.listdir(bdir) if os.path.isdir(bdir) else []
            if left:
                problems.append(f"{name[:20]!r}: expected no file left in the backup directory, found {left}")
                for f in left:
                    p = os.path.join(bdir, f)
                    if os.path.isfile(p):
                        os.remove(p)
        assert not problems, "; ".join(problems)

    def retry_then_exists():
        r = h.expect_ok(s, lambda t: s.admin.Backup(pb.BackupRequest(path="good.db"), timeout=t), deadline=60)
        assert r.bytes > 0 and os.path.isfile(r.path), f"expected a backup file, got {r.path} ({r.bytes} bytes)"
        h.expect_error(s, lambda t: s.admin.Backup(pb.BackupRequest(path="good.db"), timeout=t), C.ALREADY_EXISTS,
                       check_stored=False, deadline=60)

    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        s.loop.Ingest(pb.IngestRequest(key=h.key("b", 1), scan=h.synthetic_scan(2000, seed=82)), timeout=30)
        h.probe("H.backup_bad_names_invalid_argument_no_path_no_file", bad_names)
        h.probe("H.backup_retry_succeeds_then_already_exists", retry_then_exists)
        s.assert_alive()
    finally:
        s.stop()


def createmap_twice(tmp):
    pb = h.pb
    s = h.Server(os.path.join(tmp, "create.db"))
    try:
        first = s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        s.loop.Ingest(pb.IngestRequest(key=h.key("c", 1), scan=h.synthetic_scan(2000, seed=83)), timeout=30)
        again = h.expect_ok(s, lambda t: s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=t), stored=0)
        assert again.name == "m" and again.scans == 1 and again.descriptor_dim == first.descriptor_dim, \
            f"expected the existing map (1 scan) back, got {again}"
        maps = [m.name for m in s.admin.ListMaps(pb.ListMapsRequest(), timeout=30).maps]
        assert maps == ["m"], f"expected one map, got {maps}"
    finally:
        s.stop()


def session_refs(tmp):
    pb = h.pb
    s = h.Server(os.path.join(tmp, "refs.db"))
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        scan = h.synthetic_scan(3000, seed=84)
        for robot, session in (("fleet/a", "s1"), ("fleet/a", "s2"), ("fleet", "a/s1"), ("other", "s1")):
            for seq in range(2):
                s.loop.Ingest(pb.IngestRequest(key=h.key(robot, seq, session=session), scan=scan), timeout=30)
        opts = pb.QueryOptions(scope=pb.SCOPE_SESSIONS, include_rejected=True, top_k=20, candidates=20)
        ref = opts.session_refs.add()
        ref.robot, ref.session = "fleet/a", "s1"
        r = h.expect_ok(s, lambda t: s.loop.Query(pb.QueryRequest(map="m", scan=scan, options=opts), timeout=t))
        got = sorted({(c.robot, c.session) for c in r.candidates})
        assert got == [("fleet/a", "s1")], f"expected candidates only from robot 'fleet/a' session 's1', got {got}"
    finally:
        s.stop()


def run(tmp):
    h.probe("H.getscan_other_maps_scan_looks_missing", getscan_other_map, tmp)
    h.probe("H.backup_server_alive_after_backup_probes", backups, tmp)  # runs the two Backup probes first
    h.probe("H.createmap_existing_ok", createmap_twice, tmp)
    if "session_refs" in h.pb.QueryOptions.DESCRIPTOR.fields_by_name:
        h.probe("H.scope_sessions_session_refs_robot_with_slash", session_refs, tmp)
    else:
        h.skip("H.scope_sessions_session_refs_robot_with_slash", "QueryOptions.session_refs is not in the stubs")
