"""E. Bytes that are not a protobuf message, sent as the request of every unary method (and WatchMap):
INVALID_ARGUMENT with a message, not INTERNAL with an empty one; the server stays up, nothing is stored."""
import time

import adv_harness as h

CLASS = "E"
TITLE = "random bytes as unary requests"


def methods():
    pb = h.pb
    return [("LoopClosure", "Ingest", pb.IngestRequest), ("LoopClosure", "Query", pb.QueryRequest),
            ("MapAdmin", "CreateMap", pb.CreateMapRequest), ("MapAdmin", "ListMaps", pb.ListMapsRequest),
            ("MapAdmin", "ListRobots", pb.ListRobotsRequest), ("MapAdmin", "ListSessions", pb.ListSessionsRequest),
            ("MapAdmin", "GetScan", pb.GetScanRequest), ("MapAdmin", "DeleteSession", pb.DeleteSessionRequest),
            ("MapAdmin", "DeleteRobot", pb.DeleteRobotRequest), ("MapAdmin", "GetStats", pb.GetStatsRequest),
            ("MapAdmin", "Backup", pb.BackupRequest), ("PoseGraph", "GetPoses", pb.GetPosesRequest),
            ("PoseGraph", "GetSessionFrames", pb.GetSessionFramesRequest),
            ("PoseGraph", "GetLoops", pb.GetLoopsRequest),
            ("PoseGraph", "WatchMap", pb.WatchMapRequest)]


def run(tmp):
    pb, C = h.pb, h.C

    def prepare(s):
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        s.loop.Ingest(pb.IngestRequest(key=h.key("e", 1), scan=h.synthetic_scan(2000, seed=51)), timeout=30)

    fx = h.Fixture(tmp, "e", prepare=prepare)
    by = h.Bystander(fx.server())
    for i, (service, method, req_cls) in enumerate(methods()):
        blobs = h.garbage_for(req_cls, count=4, seed=100 + i)

        def one_method(service=service, method=method, blobs=blobs):
            s = fx.server()
            path = f"/sglc.v1.{service}/{method}"
            if method == "WatchMap":
                mc = s.channel.unary_stream(path, request_serializer=lambda b: b,
                                            response_deserializer=pb.MapEvent.FromString)

                def call(data, t):
                    return next(iter(mc(data, timeout=t)))
            else:
                mc = s.channel.unary_unary(path, request_serializer=lambda b: b, response_deserializer=lambda b: b)

                def call(data, t):
                    return mc(data, timeout=t)
            before = s.snapshot()
            for data in blobs:
                t0 = time.monotonic()
                try:
                    call(data, 30)
                    raise AssertionError(f"expected INVALID_ARGUMENT, got OK (for bytes {data.hex()})")
                except h.grpc.RpcError as e:
                    h.record(e)
                    got, msg = e.code(), e.details() or ""
                    assert got == C.INVALID_ARGUMENT and msg.strip(), \
                        f"expected INVALID_ARGUMENT with a message, got {got.name}: '{h.short(msg)}' (for bytes {data.hex()})"
                except StopIteration:
                    raise AssertionError(f"expected INVALID_ARGUMENT, got OK with no events (for bytes {data.hex()})")
                elapsed = time.monotonic() - t0
                assert elapsed < 40, f"the call took {elapsed:.1f} s, past its 30 s deadline"
            s.assert_alive()
            after = s.snapshot()
            assert after == before, f"expected nothing stored, (maps, scans, index entries) went {before} -> {after}"
        h.probe(f"E.{method}_{len(blobs)}_garbage_requests", one_method)
    h.probe("E.other_clients_unaffected", by.finish)
    fx.stop()
