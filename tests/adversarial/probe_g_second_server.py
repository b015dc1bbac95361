"""G. A second server on the same --listen address, or on the same --db, refuses to start (non-zero exit, a
message saying what is in use) and leaves the first one serving. (The suite-wide check that no status message
carries SQL runs last, as G.no_sql_in_status_messages.)"""
import os
import subprocess
import time

import adv_harness as h

CLASS = "G"
TITLE = "a second server on the same address or database"

WAIT = 30  # a refusing server exits at once; one still running after this long did not refuse


def second_server(tmp, tag, db, listen, words, while_serving=None):
    """Starts a second server that must refuse to start; while_serving(address) runs if it serves instead."""
    out, err = os.path.join(tmp, f"{tag}.out"), os.path.join(tmp, f"{tag}.err")
    h.wait_for_binary()
    with open(out, "wb") as fo, open(err, "wb") as fe:
        p = subprocess.Popen([h.SERVER, "--db", db, "--listen", listen, "--sync-normal"], stdout=fo, stderr=fe)
    h._PROCS.append(p)
    t0 = time.monotonic()
    serving = False
    while time.monotonic() - t0 < WAIT and p.poll() is None:
        time.sleep(0.2)
        logs = open(out, errors="replace").read() + open(err, errors="replace").read()
        if '"event":"serving"' in logs:
            time.sleep(1)  # let a refusal that comes late show up
            serving = p.poll() is None
            if serving and while_serving:
                while_serving(listen)
            break
    rc = p.poll()
    elapsed = time.monotonic() - t0
    if rc is None:
        p.kill()
        p.wait(timeout=30)
    stderr = open(err, errors="replace").read().strip()
    stdout = open(out, errors="replace").read().strip()
    if rc is None:
        state = "is serving" if serving else f"still runs after {WAIT} s"
        raise AssertionError(f"expected the second server to exit non-zero with a message containing "
                             f"{' / '.join(repr(w) for w in words)}, it {state} (stderr: '{h.short(stderr)}')")
    h.note(f"second server ({tag}) exited with code {rc} after {elapsed:.1f} s: '{h.short(stderr or stdout)}'")
    assert rc != 0, f"expected a non-zero exit code, got {rc}"
    for w in words:
        assert w.lower() in stderr.lower(), f"expected stderr to contain '{w}', got '{h.short(stderr)}'"


def run(tmp):
    pb, C = h.pb, h.C
    db = os.path.join(tmp, "first", "map.db")
    os.makedirs(os.path.dirname(db))
    os.makedirs(os.path.join(tmp, "second"))
    s = h.Server(db)
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        s.loop.Ingest(pb.IngestRequest(key=h.key("g", 1), scan=h.synthetic_scan(2000, seed=71)), timeout=30)
        seq = [1]

        def first_serves():
            s.assert_alive()
            st = s.admin.GetStats(pb.GetStatsRequest(map="m"), timeout=30)
            assert st.scans == seq[0], f"expected the first server to still hold {seq[0]} scans, it has {st.scans}"
            seq[0] += 1
            s.loop.Ingest(pb.IngestRequest(key=h.key("g", seq[0]), scan=h.synthetic_scan(2000, seed=70 + seq[0])),
                          timeout=30)

        h.probe("G.second_server_same_listen_refused",
                second_server, tmp, "same-listen", os.path.join(tmp, "second", "other.db"), s.addr, ("in use",))
        h.probe("G.first_server_unaffected_by_second_on_same_listen", first_serves)
        def both_write(addr):
            # Two servers on one database: the same key through each (what users would hit); the statuses
            # go to G.no_sql_in_status_messages.
            ch = h.channel(addr)
            try:
                for server_loop, seed in ((h.rpc.LoopClosureStub(ch), 75), (s.loop, 76)):
                    try:
                        server_loop.Ingest(pb.IngestRequest(key=h.key("dup", 1), scan=h.synthetic_scan(
                            2000, seed=seed)), timeout=30)
                    except h.grpc.RpcError as e:
                        h.record(e, "G two servers")
                        h.note(f"the same key through the other server: {h.status_of(e)}")
            finally:
                ch.close()

        h.probe("G.second_server_same_db_refused",
                second_server, tmp, "same-db", db, f"127.0.0.1:{h.free_port()}", ("in use by process",), both_write)
        h.probe("G.first_server_unaffected_by_second_on_same_db", first_serves)

        # Storage-level failures whose messages must not carry SQL (collected for G.no_sql_in_status_messages).
        scan = h.synthetic_scan(2000, seed=79)
        provocations = [
            lambda: s.loop.Ingest(pb.IngestRequest(key=h.key("g", 1), scan=scan), timeout=30),
            lambda: s.admin.DeleteSession(pb.DeleteSessionRequest(map="m", robot="g", session="nope"), timeout=30),
            lambda: s.admin.DeleteRobot(pb.DeleteRobotRequest(map="m", robot="nobody"), timeout=30),
            lambda: s.admin.ListSessions(pb.ListSessionsRequest(map="m", robot="nobody"), timeout=30),
            lambda: s.admin.ListSessions(pb.ListSessionsRequest(map="nomap"), timeout=30),
            lambda: s.admin.GetScan(pb.GetScanRequest(scan_id=2 ** 62), timeout=30),
            lambda: s.loop.Query(pb.QueryRequest(map="m", scan=scan, options=pb.QueryOptions(
                scope=pb.SCOPE_SESSIONS, sessions=["no-slash"])), timeout=30),
            lambda: s.loop.Query(pb.QueryRequest(map="m", scan=scan, options=pb.QueryOptions(
                scope=pb.SCOPE_SESSIONS, sessions=["a/b/c'; DROP TABLE scans; --"])), timeout=30),
            lambda: s.admin.Backup(pb.BackupRequest(path="g.db"), timeout=60),
            lambda: s.admin.Backup(pb.BackupRequest(path="g.db"), timeout=60),
        ]
        for p in provocations:
            try:
                p()
            except h.grpc.RpcError as e:
                h.record(e, "G provocation")
        h.probe("G.first_server_survives_storage_errors", s.assert_alive)
    finally:
        s.stop()
