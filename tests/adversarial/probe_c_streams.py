"""C. Streams: idle streams must not starve other calls; a per-client stream limit (bearer token when tokens are
on, else peer IP; default 32) refuses the excess with RESOURCE_EXHAUSTED; IngestStreams that send nothing are
ended after --stream-idle-timeout-s (UNAVAILABLE, "idle"), WatchMap subscribers are not."""
import os
import threading
import time

import adv_harness as h

CLASS = "C"
TITLE = "streams: crowds of idle streams, per-client limits, idle timeout"

DEADLINE = 30


class Crowd:
    """Idle IngestStreams (they never send) and WatchMap subscribers, kept open until close()."""

    def __init__(self, addr, streams, watchers, md=None, channels=4, m="m"):
        self.event = threading.Event()
        self.channels = [h.grpc.insecure_channel(addr, options=h.CHANNEL_OPTIONS + [("grpc.use_local_subchannel_pool", 1)])
                         for _ in range(channels)]
        self.streams, self.watchers = [], []
        for i in range(streams):
            stub = h.rpc.LoopClosureStub(self.channels[i % channels])
            self.streams.append(stub.IngestStream(h.blocking_requests(self.event), timeout=600, metadata=md))
        for i in range(watchers):
            stub = h.rpc.PoseGraphStub(self.channels[i % channels])
            self.watchers.append(stub.WatchMap(h.pb.WatchMapRequest(map=m), timeout=600, metadata=md))

    def done(self, calls):
        return [c for c in calls if c.done()]

    def wait_done(self, calls, count, timeout):
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end and len(self.done(calls)) < count:
            time.sleep(0.1)
        return self.done(calls)

    def close(self):
        self.event.set()
        for c in self.streams + self.watchers:
            c.cancel()
        for ch in self.channels:
            ch.close()


def codes(calls):
    out = {}
    for c in calls:
        try:
            name = c.code().name
        except Exception:  # noqa: BLE001
            name = "?"
        out[name] = out.get(name, 0) + 1
    return out


def unary_calls(s, n, tag, md=None):
    """n ordinary calls on a fresh channel (CreateMap, ListMaps, GetStats, Ingest of a small scan), one at a time;
    returns (ok, failures). Stops after two failures (the probes allow at most one in a hundred)."""
    ch = h.channel(s.addr)
    admin, loop = h.rpc.MapAdminStub(ch), h.rpc.LoopClosureStub(ch)
    scan = h.synthetic_scan(1500, seed=31)
    ok, failures = 0, []
    pb = h.pb
    for i in range(n):
        kind = i % 4
        t0 = time.monotonic()
        try:
            if kind == 0:
                admin.CreateMap(pb.CreateMapRequest(name=f"{tag}-{i}"), timeout=DEADLINE, metadata=md)
            elif kind == 1:
                admin.ListMaps(pb.ListMapsRequest(), timeout=DEADLINE, metadata=md)
            elif kind == 2:
                admin.GetStats(pb.GetStatsRequest(map="m"), timeout=DEADLINE, metadata=md)
            else:
                loop.Ingest(pb.IngestRequest(key=h.key(tag, i), scan=scan), timeout=DEADLINE, metadata=md)
            ok += 1
        except h.grpc.RpcError as e:
            h.record(e)
            failures.append(f"{['CreateMap', 'ListMaps', 'GetStats', 'Ingest'][kind]}: {e.code().name} "
                            f"'{h.short(e.details(), 80)}' after {time.monotonic() - t0:.1f} s")
            if len(failures) >= 2:
                break
    ch.close()
    return ok, failures


def many_idle_streams(tmp, extra=("--max-streams-per-client", "1000")):
    pb = h.pb
    s = h.Server(os.path.join(tmp, "crowd.db"), extra)
    crowd = None
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=DEADLINE)
        crowd = Crowd(s.addr, 300, 300, channels=6)
        time.sleep(3)  # let them arrive; nothing below depends on how long they took
        early = crowd.done(crowd.streams + crowd.watchers)
        if early:
            h.note(f"{len(early)} of the 600 idle streams ended early: {codes(early)}")
        ok, failures = unary_calls(s, 100, "u")
        h.note(f"with 300 idle IngestStreams and 300 WatchMap subscribers open: {ok} unary calls OK, "
               f"{len(failures)} failed")
        assert ok >= 99 and len(failures) <= 1, \
            f"expected >= 99 of 100 unary calls OK, got {ok} OK before stopping; failures: {'; '.join(failures)}"
        s.assert_alive()
    finally:
        if crowd:
            crowd.close()
        s.stop()


def default_limit(tmp, tokens=False):
    pb = h.pb
    extra, md, other = [], None, None
    if tokens:
        path = os.path.join(tmp, "tokens.txt")
        with open(path, "w") as f:
            f.write("token-aaaa-1111 *\ntoken-bbbb-2222 *\n")
        extra = ["--tokens", path]
        md = [("authorization", "Bearer token-aaaa-1111")]
        other = [("authorization", "Bearer token-bbbb-2222")]
    s = h.Server(os.path.join(tmp, f"limit{int(tokens)}.db"), extra, token="token-aaaa-1111" if tokens else None)
    crowd = None
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=DEADLINE, metadata=md)
        crowd = Crowd(s.addr, 40, 0, md=md, channels=1)
        done = crowd.wait_done(crowd.streams, 8, 15)
        refused = [c for c in done if c.code() == h.C.RESOURCE_EXHAUSTED]
        for c in done:
            h.record(c)
        still_open = len(crowd.streams) - len(done)
        h.note(f"40 idle IngestStreams from one client{' (one token)' if tokens else ''}: {len(refused)} refused, "
               f"{still_open} open, ended: {codes(done)}")
        problems = []
        if len(refused) != 8 or still_open != 32:
            problems.append(f"expected 8 RESOURCE_EXHAUSTED and 32 open, got {len(refused)} refused and "
                            f"{still_open} open (ended: {codes(done)})")
        for c in refused:
            if "streams" not in (c.details() or "").lower():
                problems.append(f"expected the refusal to mention 'streams', got '{h.short(c.details())}'")
                break
        # Unary calls go on, from a new channel and from the streams' own connection.
        ok, failures = unary_calls(s, 20, "lim", md=md)
        if failures:
            problems.append(f"expected every unary call to succeed while the streams are open, got "
                            f"{'; '.join(failures)}")
        try:
            h.rpc.MapAdminStub(crowd.channels[0]).ListMaps(pb.ListMapsRequest(), timeout=DEADLINE, metadata=md)
        except h.grpc.RpcError as e:
            problems.append(f"expected ListMaps on the streams' channel to succeed, got {h.status_of(e)}")
        if tokens:
            # Another token is another client: its stream is served although token A is at its limit.
            ch = h.channel(s.addr)
            try:
                req = pb.IngestRequest(key=h.key("other-token", 1), scan=h.synthetic_scan(1500, seed=32))
                r = list(h.rpc.LoopClosureStub(ch).IngestStream(iter([req]), timeout=DEADLINE, metadata=other))
                assert len(r) == 1
            except h.grpc.RpcError as e:
                problems.append(f"expected a stream with another token to be served, got {h.status_of(e)}")
            finally:
                ch.close()
        assert not problems, "; ".join(problems)
        s.assert_alive()
    finally:
        if crowd:
            crowd.close()
        s.stop()


def slots_released(tmp):
    """After a client's streams end, it can open new ones (the per-client count goes down again)."""
    pb = h.pb
    s = h.Server(os.path.join(tmp, "release.db"))
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=DEADLINE)
        crowd = Crowd(s.addr, 40, 0, channels=1)
        crowd.wait_done(crowd.streams, 8, 15)
        crowd.close()
        scan = h.synthetic_scan(1500, seed=33)
        t_end = time.monotonic() + 30
        last = None
        seq = 0
        while time.monotonic() < t_end:
            seq += 1
            try:
                r = list(s.loop.IngestStream(iter([pb.IngestRequest(key=h.key("again", seq), scan=scan)]),
                                             timeout=DEADLINE))
                assert len(r) == 1, f"expected one response, got {len(r)}"
                s.assert_alive()
                return
            except h.grpc.RpcError as e:
                h.record(e)
                last = h.status_of(e)
                if e.code() != h.C.RESOURCE_EXHAUSTED:
                    break
                time.sleep(0.5)
        raise AssertionError(f"expected a new stream to be served once the old ones were cancelled, got {last}")
    finally:
        s.stop()


def idle_timeout(tmp):
    pb = h.pb
    state = {}

    try:
        s = state["s"] = h.Server(os.path.join(tmp, "idle.db"), ["--stream-idle-timeout-s", "2"])
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=DEADLINE)
    except (h.ServerStartError, h.grpc.RpcError) as e:
        state["err"] = str(e) if isinstance(e, h.ServerStartError) else f"setup failed: {h.status_of(e)}"

    def idle_ingeststream_ended():
        assert "err" not in state, state["err"]
        s = state["s"]
        ev = threading.Event()
        t0 = time.monotonic()
        silent = s.loop.IngestStream(h.blocking_requests(ev), timeout=120)
        # An IngestChunked that sends nothing is ended the same way (it once made the server Finish twice and
        # abort).
        silent_chunked = s.loop.IngestChunked.future(h.blocking_requests(ev), timeout=120)
        # One that sent a scan and then fell silent is ended too; its scan stays stored.
        req = pb.IngestRequest(key=h.key("idle", 1), scan=h.synthetic_scan(1500, seed=34))
        after_one = s.loop.IngestStream(h.blocking_requests(ev, [req]), timeout=120)
        watch = s.graph.WatchMap(pb.WatchMapRequest(map="m"), timeout=120)
        state["watch"] = watch
        try:
            # Read its answer (a client sees a stream's status only after the responses before it).
            try:
                first = next(after_one)
                assert first.seq == 1, f"expected the answer to seq 1, got seq {first.seq}"
            except h.grpc.RpcError as e:
                h.record(e)
                raise AssertionError(f"expected an answer to the one scan sent, got {h.status_of(e)}")
            t_end = time.monotonic() + 30
            while time.monotonic() < t_end and not (silent.done() and after_one.done() and silent_chunked.done()):
                time.sleep(0.1)
            elapsed = time.monotonic() - t0
            problems = []
            for what, c in (("a silent IngestStream", silent), ("an IngestStream silent after one scan", after_one),
                            ("a silent IngestChunked", silent_chunked)):
                if not c.done():
                    problems.append(f"expected {what} to be ended (UNAVAILABLE, 'idle'), still open after 30 s")
                    continue
                h.record(c)
                if c.code() != h.C.UNAVAILABLE or "idle" not in (c.details() or "").lower():
                    problems.append(f"expected {what} ended with UNAVAILABLE mentioning 'idle', got "
                                    f"{c.code().name}: '{h.short(c.details())}'")
            if not problems:
                h.note(f"idle IngestStreams ended after {elapsed:.1f} s")
                assert elapsed >= 1.0, f"expected the streams to live ~2 s, they ended after {elapsed:.1f} s"
            assert not problems, "; ".join(problems)
            s.assert_alive()
            st = s.admin.GetStats(pb.GetStatsRequest(map="m"), timeout=DEADLINE)
            assert st.scans == 1, f"expected the scan sent before the silence to stay stored, the map has {st.scans}"
        finally:
            ev.set()
            silent_chunked.cancel()
            silent.cancel()
            after_one.cancel()

    def watchmap_not_ended():
        assert "err" not in state, state["err"]
        assert "watch" in state, "no WatchMap subscriber was opened (the probe before failed early)"
        s, watch = state["s"], state["watch"]
        time.sleep(8)  # four idle timeouts (the IngestStream probe before this one already took some)
        if watch.done():
            h.record(watch)
            raise AssertionError(f"expected a WatchMap subscriber to stay open, it ended with "
                                 f"{watch.code().name}: '{h.short(watch.details())}'")
        watch.cancel()
        s.assert_alive()

    try:
        h.probe("C.idle_ingeststream_ended_unavailable", idle_ingeststream_ended)
        h.probe("C.watchmap_not_ended_by_idle_timeout", watchmap_not_ended)
    finally:
        if "s" in state:
            state["s"].stop()


def run(tmp):
    h.probe("C.300_idle_ingeststreams_300_watchers_do_not_starve_unary", many_idle_streams, tmp)
    h.probe("C.default_limit_refuses_streams_beyond_32_per_peer", default_limit, tmp, False)
    h.probe("C.default_limit_is_per_token", default_limit, tmp, True)
    h.probe("C.stream_slots_released_after_cancel", slots_released, tmp)
    idle_timeout(tmp)
