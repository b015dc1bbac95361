"""D. A message that is not valid protobuf in the middle of a client stream: the call fails INVALID_ARGUMENT
(the stream held an invalid message) instead of ending the stream as if the client had finished (which stored a
half scan, or dropped the rest of a run, in silence)."""
import adv_harness as h

CLASS = "D"
TITLE = "corrupt messages inside client streams"

GARBAGE = b"\xff" * 10
SAYS_INVALID = ("invalid", "not a valid", "pars", "malformed", "corrupt", "decode")


def says_invalid_message(msg):
    low = (msg or "").lower()
    return "message" in low and any(w in low for w in SAYS_INVALID)


def run(tmp):
    pb, C = h.pb, h.C
    fx = h.Fixture(tmp, "d", prepare=lambda s: s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30))
    by = h.Bystander(fx.server())
    scan = h.realistic_scan("000052", seed=41)
    n = len(scan.labels) // 4
    half = n // 2

    def chunked_raw(s):
        return s.channel.stream_unary("/sglc.v1.LoopClosure/IngestChunked", request_serializer=lambda b: b,
                                      response_deserializer=pb.IngestResponse.FromString)

    def stream_raw(s):
        return s.channel.stream_stream("/sglc.v1.LoopClosure/IngestStream", request_serializer=lambda b: b,
                                       response_deserializer=pb.IngestResponse.FromString)

    def first_chunk(seq):
        return pb.IngestChunk(header=pb.IngestRequest(key=h.key("d", seq, session="chunked")),
                              points=scan.points[:12 * half], labels=scan.labels[:4 * half]).SerializeToString()

    second_chunk = pb.IngestChunk(points=scan.points[12 * half:], labels=scan.labels[4 * half:]).SerializeToString()

    def chunked(messages):
        def call(t):
            return chunked_raw(fx.server())(iter(messages), timeout=t)
        return lambda: h.expect_error(fx.server(), call, C.INVALID_ARGUMENT, any_words=SAYS_INVALID,
                                      words=("message",))

    h.probe("D.ingestchunked_garbage_between_halves",
            chunked([first_chunk(1), GARBAGE, second_chunk]))
    h.probe("D.ingestchunked_garbage_first", chunked([GARBAGE, first_chunk(2), second_chunk]))
    h.probe("D.ingestchunked_garbage_last", chunked([first_chunk(3), second_chunk, GARBAGE]))

    def stream_case(garbage_first):
        s = fx.server()
        before = s.snapshot()
        good = [pb.IngestRequest(key=h.key("d", seq, session="stream"), scan=scan).SerializeToString()
                for seq in ((10, 11) if not garbage_first else (20, 21))]
        messages = [GARBAGE, good[0]] if garbage_first else [good[0], GARBAGE, good[1]]
        responses, err = [], None
        call = stream_raw(s)(iter(messages), timeout=60)
        try:
            for r in call:
                responses.append(r)
        except h.grpc.RpcError as e:
            h.record(e)
            err = e
        want = 0 if garbage_first else 1
        got = f"{len(responses)} response(s) then " + (f"{err.code().name}: '{h.short(err.details())}'" if err
                                                         else "OK")
        assert err is not None and len(responses) == want and err.code() == C.INVALID_ARGUMENT \
            and says_invalid_message(err.details()), \
            f"expected {want} response(s) then INVALID_ARGUMENT saying the stream held an invalid message, got {got}"
        s.assert_alive()
        after = s.snapshot()
        assert after[1] == before[1] + want and after[2] == before[2] + want, \
            f"expected {want} scan(s) stored, (maps, scans, index entries) went {before} -> {after}"
        if responses:
            info = s.admin.GetScan(pb.GetScanRequest(scan_id=responses[0].scan_id), timeout=30)
            assert info.key.seq == 10, f"expected the first request's scan (seq 10) stored, got seq {info.key.seq}"

    h.probe("D.ingeststream_garbage_between_requests", stream_case, False)
    h.probe("D.ingeststream_garbage_first", stream_case, True)

    # The same streams without the garbage work (the probes above fail for the garbage alone).
    def clean():
        s = fx.server()
        r = h.expect_ok(s, lambda t: chunked_raw(s)(iter([first_chunk(4), second_chunk]), timeout=t), stored=1)
        assert r.scan_id > 0
        msgs = [pb.IngestRequest(key=h.key("d", seq, session="stream"), scan=scan).SerializeToString()
                for seq in (30, 31)]
        rs = h.expect_ok(s, lambda t: list(stream_raw(s)(iter(msgs), timeout=t)), stored=2)
        assert [r.seq for r in rs] == [30, 31]
    h.probe("D.clean_streams_still_work", clean)
    h.probe("D.other_clients_unaffected", by.finish)
    fx.stop()
