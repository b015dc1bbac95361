"""A. Malformed scans, names, ids and options: the right status, a message naming the problem, nothing stored."""

import numpy as np

import adv_harness as h

CLASS = "A"
TITLE = "malformed scans, names, ids and options"


def run(tmp):
    pb, C = h.pb, h.C
    fx = h.Fixture(tmp, "a", prepare=lambda s: s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30))
    by = h.Bystander(fx.server())
    good = h.synthetic_scan(3000, seed=1)
    pts_good, lab_good = h.synthetic_arrays(3000, seed=1)

    def with_point(value):
        p = pts_good.copy()
        p[17, 1] = value
        return pb.Scan(points=p.tobytes(), labels=lab_good.tobytes())

    def ingest(req):
        return lambda t: fx.server().loop.Ingest(req, timeout=t)

    def query(options=None, **kw):
        req = pb.QueryRequest(map=kw.pop("map", "m"), scan=kw.pop("scan", good), options=options or pb.QueryOptions(),
                              **kw)
        return lambda t: fx.server().loop.Query(req, timeout=t)

    def ingest_query(options):
        return ingest(pb.IngestRequest(key=h.key("r", 900), scan=good, query=True, query_options=options))

    k = h.key
    IA, NF, RE = C.INVALID_ARGUMENT, C.NOT_FOUND, C.RESOURCE_EXHAUSTED
    too_many = 2_000_001  # one above the server's default point limit; ~32 MB, under the 64 MB message limit
    cases = [
        # scans
        ("ingest_points_not_multiple_of_12", ingest(pb.IngestRequest(key=k("r", 1), scan=pb.Scan(
            points=b"\0" * 13, labels=b"\0" * 4))), IA, ("12",), ()),
        ("ingest_labels_not_multiple_of_4", ingest(pb.IngestRequest(key=k("r", 1), scan=pb.Scan(
            points=b"\0" * 12, labels=b"\0" * 5))), IA, ("labels",), ()),
        ("ingest_point_label_count_mismatch", ingest(pb.IngestRequest(key=k("r", 1), scan=pb.Scan(
            points=b"\0" * 24, labels=b"\0" * 4))), IA, ("points", "labels"), ()),
        ("ingest_empty_scan", ingest(pb.IngestRequest(key=k("r", 1), scan=pb.Scan())), IA, ("empty",), ()),
        ("ingest_nan_coordinate", ingest(pb.IngestRequest(key=k("r", 1), scan=with_point(np.nan))), IA, (),
         ("finite", "nan")),
        ("ingest_inf_coordinate", ingest(pb.IngestRequest(key=k("r", 1), scan=with_point(-np.inf))), IA, (),
         ("finite", "inf")),
        ("ingest_above_max_points", ingest(pb.IngestRequest(key=k("r", 1), scan=pb.Scan(
            points=b"\0" * (12 * too_many), labels=b"\0" * (4 * too_many)))), RE, ("points",), ()),
        ("query_nan_coordinate", query(scan=with_point(np.nan)), IA, (), ("finite", "nan")),
        ("ingest_nan_stamp", ingest(pb.IngestRequest(key=k("r", 1), scan=good, stamp=float("nan"))), IA,
         ("stamp",), ()),
        ("ingest_inf_stamp", ingest(pb.IngestRequest(key=k("r", 1), scan=good, stamp=float("inf"))), IA,
         ("stamp",), ()),
        ("query_nan_stamp", query(robot="r", stamp=float("nan")), IA, ("stamp",), ()),
        ("query_inf_stamp", query(robot="r", stamp=float("-inf")), IA, ("stamp",), ()),
        # names
        ("ingest_empty_map_name", ingest(pb.IngestRequest(key=k("r", 1, m=""), scan=good)), IA, ("map",), ()),
        ("ingest_empty_robot_name", ingest(pb.IngestRequest(key=k("", 1), scan=good)), IA, ("robot",), ()),
        ("ingest_empty_session_name", ingest(pb.IngestRequest(key=k("r", 1, session=""), scan=good)), IA,
         ("session",), ()),
        ("ingest_257_byte_robot_name", ingest(pb.IngestRequest(key=k("r" * 257, 1), scan=good)), IA,
         ("robot",), ()),
        ("ingest_257_byte_session_name", ingest(pb.IngestRequest(key=k("r", 1, session="s" * 257), scan=good)),
         IA, ("session",), ()),
        ("ingest_control_char_robot_name", ingest(pb.IngestRequest(key=k("a\x01b", 1), scan=good)), IA,
         ("robot",), ()),
        ("ingest_newline_session_name", ingest(pb.IngestRequest(key=k("r", 1, session="s\nx"), scan=good)), IA,
         ("session",), ()),
        ("ingest_del_char_map_name", ingest(pb.IngestRequest(key=k("r", 1, m="m\x7f"), scan=good)), IA,
         ("map",), ()),
        ("createmap_empty_name", lambda t: fx.server().admin.CreateMap(pb.CreateMapRequest(name=""), timeout=t),
         IA, ("name",), ()),
        ("createmap_257_byte_name", lambda t: fx.server().admin.CreateMap(pb.CreateMapRequest(name="n" * 257),
                                                                           timeout=t), IA, ("name",), ()),
        ("createmap_control_char_name", lambda t: fx.server().admin.CreateMap(pb.CreateMapRequest(name="x\ty"),
                                                                               timeout=t), IA, ("name",), ()),
        # unknown maps and ids
        ("ingest_unknown_map", ingest(pb.IngestRequest(key=k("r", 1, m="nomap"), scan=good)), NF, ("nomap",), ()),
        ("query_unknown_map", query(map="nomap"), NF, ("nomap",), ()),
        ("getstats_unknown_map", lambda t: fx.server().admin.GetStats(pb.GetStatsRequest(map="nomap"), timeout=t),
         NF, ("nomap",), ()),
        ("listrobots_unknown_map", lambda t: fx.server().admin.ListRobots(pb.ListRobotsRequest(map="nomap"),
                                                                           timeout=t), NF, ("nomap",), ()),
        ("getposes_unknown_map", lambda t: fx.server().graph.GetPoses(pb.GetPosesRequest(map="nomap"), timeout=t),
         NF, ("nomap",), ()),
        ("getscan_unknown_id", lambda t: fx.server().admin.GetScan(pb.GetScanRequest(scan_id=987654), timeout=t),
         NF, ("987654",), ()),
        ("getscan_negative_id", lambda t: fx.server().admin.GetScan(pb.GetScanRequest(scan_id=-5), timeout=t),
         NF, (), ()),
        ("query_unknown_scan_id", lambda t: fx.server().loop.Query(pb.QueryRequest(map="m", scan_id=987654),
                                                                    timeout=t), NF, ("987654",), ()),
        ("deletesession_unknown_robot", lambda t: fx.server().admin.DeleteSession(pb.DeleteSessionRequest(
            map="m", robot="ghost", session="run"), timeout=t), NF, ("ghost",), ()),
        # options
        ("query_top_k_101", query(pb.QueryOptions(top_k=101)), IA, ("top_k",), ()),
        ("ingest_query_top_k_101", ingest_query(pb.QueryOptions(top_k=101)), IA, ("top_k",), ()),
        ("query_candidates_201", query(pb.QueryOptions(candidates=201)), IA, ("candidates",), ()),
        ("query_negative_exclude_recent", query(pb.QueryOptions(exclude_recent=-1)), IA, ("exclude_recent",), ()),
        ("query_nan_exclude_seconds", query(pb.QueryOptions(exclude_seconds=float("nan"))), IA,
         ("exclude_seconds",), ()),
        ("query_nan_min_score", query(pb.QueryOptions(min_score=float("nan"))), IA, ("min_score",), ()),
        ("ingest_query_nan_min_score", ingest_query(pb.QueryOptions(min_score=float("nan"))), IA,
         ("min_score",), ()),
        ("query_unknown_scope", query(pb.QueryOptions(scope=99)), IA, ("unknown scope",), ()),
        ("query_unknown_scope_missing_map", query(pb.QueryOptions(scope=99), map="nomap"), NF, ("nomap",), ()),
        ("ingest_query_unknown_scope_missing_map", ingest(pb.IngestRequest(
            key=k("r", 901, m="nomap"), scan=good, query=True, query_options=pb.QueryOptions(scope=99))), NF,
         ("nomap",), ()),
        ("query_known_loops_without_refine", query(pb.QueryOptions(known_loops=True, refine=False,
                                                                   refine_set=True)), IA, ("known_loops",), ()),
        ("query_verify_201_scans", query(pb.QueryOptions(verify_scan_ids=list(range(1, 202)))), IA, ("200",), ()),
        ("getposes_page_size_10001", lambda t: fx.server().graph.GetPoses(pb.GetPosesRequest(
            map="m", page_size=10001), timeout=t), IA, ("page_size",), ()),
        ("getposes_negative_page_token", lambda t: fx.server().graph.GetPoses(pb.GetPosesRequest(
            map="m", page_token=-1), timeout=t), IA, ("page_token",), ()),
    ]
    for name, call, code, words, any_words in cases:
        h.probe(f"A.{name}", lambda c=call, code=code, w=words, a=any_words:
                h.expect_error(fx.server(), c, code, words=w, any_words=a))

    # The limits are inclusive: 256-byte names and exactly max points are stored.
    def names_256():
        r = h.expect_ok(fx.server(), ingest(pb.IngestRequest(key=k("r" * 256, 1, session="s" * 256), scan=good)),
                        stored=1)
        got = fx.server().admin.GetScan(pb.GetScanRequest(scan_id=r.scan_id), timeout=30)
        assert got.key.robot == "r" * 256 and got.key.session == "s" * 256, "names came back changed"
    h.probe("A.ingest_256_byte_names_accepted", names_256)

    h.probe("A.other_clients_unaffected", by.finish)
    fx.stop()
