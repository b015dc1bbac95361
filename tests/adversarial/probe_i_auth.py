"""I. Auth: no token, a wrong or malformed token -> UNAUTHENTICATED; a token for another map -> PERMISSION_DENIED
on every path into that map; ListMaps shows only the maps a token may see; nothing is stored on refusal."""
import os

import adv_harness as h

CLASS = "I"
TITLE = "bearer tokens"

ADMIN, FLEET = "admin-token-123", "fleet-token-456"


def run(tmp):
    pb, C = h.pb, h.C
    path = os.path.join(tmp, "tokens.txt")
    with open(path, "w") as f:
        f.write(f"# admin\n{ADMIN} *\n{FLEET} m\n")
    admin = [("authorization", f"Bearer {ADMIN}")]
    fleet = [("authorization", f"Bearer {FLEET}")]

    def prepare(s):
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30, metadata=admin)
        s.admin.CreateMap(pb.CreateMapRequest(name="secret"), timeout=30, metadata=admin)
        s.loop.Ingest(pb.IngestRequest(key=h.key("r", 1, m="secret"), scan=h.synthetic_scan(2000, seed=91)),
                      timeout=30, metadata=admin)

    fx = h.Fixture(tmp, "i", extra=["--tokens", path], token=ADMIN, prepare=prepare)
    s = fx.server()
    by = h.Bystander(s)
    scan = h.synthetic_scan(2000, seed=92)

    def calls(md, m):
        ingest = pb.IngestRequest(key=h.key("r", 5, m=m), scan=scan)
        return [("Ingest", lambda t: fx.server().loop.Ingest(ingest, timeout=t, metadata=md)),
                ("IngestStream", lambda t: list(fx.server().loop.IngestStream(iter([ingest]), timeout=t,
                                                                              metadata=md))),
                ("IngestChunked", lambda t: fx.server().loop.IngestChunked(iter([pb.IngestChunk(header=ingest)]),
                                                                           timeout=t, metadata=md)),
                ("Query", lambda t: fx.server().loop.Query(pb.QueryRequest(map=m, scan=scan), timeout=t,
                                                           metadata=md)),
                ("GetStats", lambda t: fx.server().admin.GetStats(pb.GetStatsRequest(map=m), timeout=t,
                                                                  metadata=md)),
                ("ListRobots", lambda t: fx.server().admin.ListRobots(pb.ListRobotsRequest(map=m), timeout=t,
                                                                      metadata=md)),
                ("DeleteRobot", lambda t: fx.server().admin.DeleteRobot(pb.DeleteRobotRequest(map=m, robot="r"),
                                                                        timeout=t, metadata=md)),
                ("GetPoses", lambda t: fx.server().graph.GetPoses(pb.GetPosesRequest(map=m), timeout=t,
                                                                  metadata=md)),
                ("WatchMap", lambda t: next(iter(fx.server().graph.WatchMap(pb.WatchMapRequest(map=m), timeout=t,
                                                                            metadata=md))))]

    for label, md, code in (("no_token", None, C.UNAUTHENTICATED),
                            ("wrong_token", [("authorization", "Bearer wrong-token-0")], C.UNAUTHENTICATED),
                            ("not_bearer", [("authorization", f"Basic {ADMIN}")], C.UNAUTHENTICATED),
                            ("empty_bearer", [("authorization", "Bearer ")], C.UNAUTHENTICATED),
                            ("other_maps_token", fleet, C.PERMISSION_DENIED)):
        def one(md=md, code=code):
            problems = []
            for name, call in calls(md, "secret"):
                try:
                    h.expect_error(fx.server(), call, code, m="secret")
                except AssertionError as e:
                    problems.append(f"{name}: {e}")
            assert not problems, "; ".join(problems)
        h.probe(f"I.{label}_refused_on_every_method", one)

    def listmaps_filtered():
        got = [m.name for m in fx.server().admin.ListMaps(pb.ListMapsRequest(), timeout=30, metadata=fleet).maps]
        assert got == ["m"], f"expected ListMaps to show only ['m'] to the fleet token, got {got}"
        got = sorted(m.name for m in fx.server().admin.ListMaps(pb.ListMapsRequest(), timeout=30,
                                                                metadata=admin).maps)
        assert got == ["bystander", "m", "secret"], f"expected every map for the admin token, got {got}"
    h.probe("I.listmaps_shows_only_allowed_maps", listmaps_filtered)

    def whole_db_calls():
        s = fx.server()
        h.expect_error(s, lambda t: s.admin.GetStats(pb.GetStatsRequest(), timeout=t, metadata=fleet),
                       C.PERMISSION_DENIED)
        h.expect_error(s, lambda t: s.admin.Backup(pb.BackupRequest(path="x.db"), timeout=t, metadata=fleet),
                       C.PERMISSION_DENIED)
    h.probe("I.whole_database_calls_need_all_maps", whole_db_calls)

    def fleet_allowed():
        s = fx.server()
        ingest = pb.IngestRequest(key=h.key("r", 7), scan=scan)
        h.expect_ok(s, lambda t: s.loop.Ingest(ingest, timeout=t, metadata=fleet), stored=1)
    h.probe("I.token_works_on_its_own_map", fleet_allowed)
    h.probe("I.other_clients_unaffected", by.finish)
    fx.stop()
