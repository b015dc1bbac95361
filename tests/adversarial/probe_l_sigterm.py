"""L. SIGTERM under load: calls in flight finish or fail cleanly (UNAVAILABLE / CANCELLED, never INTERNAL or
UNKNOWN), WatchMap subscribers are ended, the process exits 0, and every acknowledged scan is there afterwards."""
import os
import time

import adv_harness as h
from probe_k_crash import Writers, check_present

CLASS = "L"
TITLE = "SIGTERM under load"

CLEAN = ("UNAVAILABLE", "CANCELLED", "ABORTED")


def run(tmp):
    pb = h.pb
    db = os.path.join(tmp, "term.db")
    s = h.Server(db)
    state = {}
    try:
        s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
        watch = s.graph.WatchMap(pb.WatchMapRequest(map="m"), timeout=120)
        # A chunked upload that never sent its first chunk is ended by the shutdown too (it once made the server
        # Finish it twice and abort instead of exiting 0).
        silence = h.threading.Event()
        silent_chunked = s.loop.IngestChunked.future(h.blocking_requests(silence), timeout=120)
        w = Writers(s, "term", with_stream=True)
        t_end = time.monotonic() + 60
        while time.monotonic() < t_end and w.count() < 20 and not w.errors:
            time.sleep(0.05)
        early = list(w.errors)
        if s.proc.poll() is not None:
            early.insert(0, f"the server died on its own before the SIGTERM: {s.exit_reason()}")
        t0 = time.monotonic()
        rc = s.stop()  # SIGTERM, wait up to 60 s
        took = time.monotonic() - t0
        w.stop()
        state.update(rc=rc, took=took, acked=dict(w.acked), errors=list(w.errors), early=early)
        t_w = time.monotonic() + 30
        while time.monotonic() < t_w and not watch.done():
            time.sleep(0.1)
        state["watch"] = (watch.code().name, watch.details() or "") if watch.done() else None
        if watch.done() and watch.code() != h.C.OK:
            h.record(watch)
        watch.cancel()
        silence.set()
        silent_chunked.cancel()
        h.note(f"SIGTERM with {len(w.acked)} scans acknowledged: exit code {rc} after {took:.1f} s; writers ended "
               f"with {sorted(set(e.split(':')[0] for e in w.errors)) or 'no error'}; WatchMap: "
               f"{state['watch'][0] if state['watch'] else 'still open'}")
    except (h.ServerStartError, h.grpc.RpcError) as e:
        state["err"] = str(e) if isinstance(e, h.ServerStartError) else f"setup failed: {h.status_of(e)}"
        s.stop()

    def exit_zero():
        assert "err" not in state, state["err"]
        assert not state["early"], \
            f"expected the load to run until the SIGTERM, got {h.short('; '.join(state['early']), 400)}"
        assert state["rc"] == 0, (f"expected exit code 0 after SIGTERM, got "
                                  f"{'no exit within 60 s' if state['rc'] is None else state['rc']}")

    def clean_errors():
        assert "err" not in state, state["err"]
        bad = [e for e in state["errors"] if e.split(":")[0] not in CLEAN]
        assert not bad, f"expected in-flight calls to end OK, UNAVAILABLE or CANCELLED, got {bad[:3]}"
        wst = state["watch"]
        assert wst is not None, "expected the WatchMap subscriber to be ended by the shutdown, still open after 30 s"
        assert wst[0] in ("OK",) + CLEAN, f"expected WatchMap to end OK or UNAVAILABLE, got {wst[0]}: '{wst[1]}'"

    def acked_present():
        assert "err" not in state, state["err"]
        s2 = h.Server(db)
        try:
            check_present(s2, state["acked"])
        finally:
            s2.stop()

    h.probe("L.sigterm_under_load_exits_0", exit_zero)
    h.probe("L.inflight_calls_end_cleanly", clean_errors)
    h.probe("L.acknowledged_scans_present_after_sigterm", acked_present)
