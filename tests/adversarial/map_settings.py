#!/usr/bin/env python3
"""A map records the settings that shape its fingerprints, and a server made with other ones refuses it.

Part 1 (a SQLite map): a server with the default settings creates map m and stores a scan; restarted with
another label preset, then with another labeller setting, it answers Ingest, IngestStream and Query (by scan and
by scan id) FAILED_PRECONDITION naming the first differing key with the map's value and its own, stores nothing,
and still serves GetStats, ListMaps and ListRobots, and a new map of its own; restarted with another
verification setting only (engine.verify.min_probability) it ingests and queries m as before.

Part 2 (two replicas on the storage tests' PostgreSQL cluster, when there is one): replica 0 (defaults) creates
m; replica 1 (nuScenes preset), started before the map was created, and replica 2 (nuScenes), started after,
both refuse m with FAILED_PRECONDITION, while replica 0 goes on ingesting.

Usage: map_settings.py SERVER_BINARY PYTHON_STUB_DIR; SGLC_TEST_PG names a file holding the test cluster's URL
(CTest's pg_cluster fixture; part 2 is skipped without it). Exit 0 pass, 1 fail, 77 skipped (no grpc/numpy).
"""
import os
import sys
import tempfile
import time

try:
    import grpc  # noqa: F401
    import numpy  # noqa: F401
except ImportError as e:
    print(f"SKIP: {e} (needs Debian's python3-grpcio and python3-numpy; run with /usr/bin/python3)")
    sys.exit(77)

sys.dont_write_bytecode = True
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adv_harness as h  # noqa: E402

NUSCENES = ["--set", "engine.labels.preset=nuscenes"]
CELL = ["--set", "engine.labeller.cell_m=0.3"]
VERIFY_ONLY = ["--set", "engine.verify.min_probability=0.7"]
problems = []


def check(name, ok, detail=""):
    print(f"{'PASS' if ok else 'FAIL'} map_settings.{name}" + ("" if ok else f": {detail}"), flush=True)
    if not ok:
        problems.append(name)


def code_of(call):
    """(status code name, details) of a call: ("OK", "") when it succeeds."""
    try:
        call()
        return "OK", ""
    except grpc.RpcError as e:
        return e.code().name, e.details() or ""


def ingest(s, seq, m="m", robot="r"):
    return s.loop.Ingest(h.pb.IngestRequest(key=h.key(robot, seq, m=m), scan=h.synthetic_scan(1500, seed=seq)),
                         timeout=60)


def expect_refused(s, name, key, map_value, server_value):
    """Every way into map m is refused with FAILED_PRECONDITION naming `key` and both values; nothing is stored."""
    before = s.admin.GetStats(h.pb.GetStatsRequest(map="m"), timeout=30).scans
    calls = {
        "Ingest": lambda: ingest(s, 100),
        "IngestStream": lambda: list(s.loop.IngestStream(iter([h.pb.IngestRequest(
            key=h.key("r", 101), scan=h.synthetic_scan(1500, seed=101))]), timeout=60)),
        "Query(scan)": lambda: s.loop.Query(h.pb.QueryRequest(map="m", scan=h.synthetic_scan(1500, seed=5)),
                                            timeout=60),
        "Query(scan_id)": lambda: s.loop.Query(h.pb.QueryRequest(map="m", scan_id=1), timeout=60),
    }
    want = f"map 'm' was built with {key} = {map_value}; this server has {server_value}"
    for what, call in calls.items():
        code, details = code_of(call)
        check(f"{name}.{what}", code == "FAILED_PRECONDITION" and want in details,
              f"expected FAILED_PRECONDITION with \"{want}\", got {code}: {h.short(details, 300)}")
    after = s.admin.GetStats(h.pb.GetStatsRequest(map="m"), timeout=30).scans
    check(f"{name}.stores_nothing", after == before, f"scans {before} -> {after}")
    maps = [m.name for m in s.admin.ListMaps(h.pb.ListMapsRequest(), timeout=30).maps]
    robots = [r.name for r in s.admin.ListRobots(h.pb.ListRobotsRequest(map="m"), timeout=30).robots]
    check(f"{name}.admin_still_answers", "m" in maps and robots == ["r"], f"maps {maps}, robots {robots}")


def part_sqlite(tmp):
    db = os.path.join(tmp, "map.db")
    s = h.Server(db)
    s.admin.CreateMap(h.pb.CreateMapRequest(name="m"), timeout=30)
    ingest(s, 0)
    ingest(s, 1)
    s.stop()

    s = h.Server(db, NUSCENES)
    expect_refused(s, "preset", "labels.preset", "semantickitti", "nuscenes")
    s.admin.CreateMap(h.pb.CreateMapRequest(name="n"), timeout=30)  # a map of its own settings is fine
    code, details = code_of(lambda: ingest(s, 0, m="n"))
    check("preset.own_map_ingests", code == "OK", f"{code}: {h.short(details)}")
    s.stop()

    s = h.Server(db, CELL)
    expect_refused(s, "labeller", "labeller.cell_m", "0.25", "0.3")
    code, _ = code_of(lambda: ingest(s, 1, m="n"))
    check("labeller.refuses_the_other_map_too", code == "FAILED_PRECONDITION", code)
    s.stop()

    s = h.Server(db, VERIFY_ONLY)
    code, details = code_of(lambda: ingest(s, 2))
    check("verify_only.ingests", code == "OK", f"{code}: {h.short(details)}")
    code, details = code_of(lambda: s.loop.Query(h.pb.QueryRequest(map="m", scan_id=1), timeout=60))
    check("verify_only.queries", code == "OK", f"{code}: {h.short(details)}")
    s.stop()


def logged(server, event, **fields):
    """Whether the server's log has a JSON line of `event` with these fields."""
    with open(server.log_path, errors="replace") as f:
        lines = f.read().splitlines()
    want = [f'"event":"{event}"'] + [f'"{k}":"{v}"' for k, v in fields.items()]
    return any(all(w in line.replace(" ", "") for w in want) for line in lines)


def part_older_map(tmp):
    """A map from before settings were recorded (schema 6) gets those of the first server that opens it."""
    import sqlite3
    db = os.path.join(tmp, "old.db")
    s = h.Server(db)
    s.admin.CreateMap(h.pb.CreateMapRequest(name="m"), timeout=30)
    ingest(s, 0)
    s.stop()
    con = sqlite3.connect(db)
    con.executescript("DROP TABLE places; ALTER TABLE maps DROP COLUMN retired_scans; "
                      "ALTER TABLE maps DROP COLUMN retired_bytes; "
                      "DROP TABLE map_settings; ALTER TABLE maps DROP COLUMN settings_hash; "
                      "ALTER TABLE loops DROP COLUMN probability; PRAGMA user_version=6;")
    con.close()
    s = h.Server(db, CELL)
    check("older_map.recorded_and_logged", logged(s, "map_settings_recorded", map="m"), h.short(s.log_tail(3), 300))
    code, details = code_of(lambda: ingest(s, 1))
    check("older_map.first_server_ingests", code == "OK", f"{code}: {h.short(details)}")
    s.stop()
    s = h.Server(db)
    expect_refused(s, "older_map", "labeller.cell_m", "0.3", "0.25")
    check("older_map.refusal_logged", logged(s, "map_settings_differ", map="m", key="labeller.cell_m"),
          h.short(s.log_tail(3), 300))
    s.stop()




def part_replicas(tmp, base_url):
    db = f"sglc_settings_{os.getpid()}"
    url = h.fresh_database(base_url, db)
    servers = []
    try:
        servers.append(h.Server(url, log_path=os.path.join(tmp, "r0.log")))
        servers.append(h.Server(url, NUSCENES, log_path=os.path.join(tmp, "r1.log")))  # before the map exists
        servers[0].admin.CreateMap(h.pb.CreateMapRequest(name="m"), timeout=30)
        ingest(servers[0], 0)
        servers.append(h.Server(url, NUSCENES, log_path=os.path.join(tmp, "r2.log")))  # after
        t_end = time.monotonic() + 60
        while not any(m.name == "m" for m in servers[1].admin.ListMaps(h.pb.ListMapsRequest(), timeout=30).maps):
            assert time.monotonic() < t_end, "replica 1 never saw the map replica 0 created"
            time.sleep(0.1)
        for i in (1, 2):
            code, details = code_of(lambda: ingest(servers[i], 10 + i))
            want = "map 'm' was built with labels.preset = semantickitti; this server has nuscenes"
            check(f"replica{i}.ingest_refused", code == "FAILED_PRECONDITION" and want in details,
                  f"{code}: {h.short(details, 300)}")
            code, details = code_of(lambda: servers[i].loop.Query(
                h.pb.QueryRequest(map="m", scan=h.synthetic_scan(1500, seed=3)), timeout=60))
            check(f"replica{i}.query_refused", code == "FAILED_PRECONDITION", f"{code}: {h.short(details)}")
        code, details = code_of(lambda: ingest(servers[0], 1))
        check("replica0.ingests", code == "OK", f"{code}: {h.short(details)}")
        stored = int(h.psql(url, "SELECT count(*) FROM scans"))
        check("replicas.stored_only_replica0s", stored == 2, f"{stored} scans stored")
    finally:
        for s in servers:
            s.stop()
        h.drop_database(base_url, db)


def main():
    if len(sys.argv) < 3:
        print(__doc__)
        sys.exit(2)
    h.setup(sys.argv[1], sys.argv[2], "", "")
    base_url = h.pg_url()
    try:
        with tempfile.TemporaryDirectory(prefix="sglc-settings-") as tmp:
            part_sqlite(tmp)
            part_older_map(tmp)
            if base_url:
                part_replicas(tmp, base_url)
            else:
                print("SKIP map_settings.replicas: no PostgreSQL test cluster (run through ctest, or set SGLC_TEST_PG)")
    finally:
        h.end_leftovers()
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
