"""K. Crash safety: SIGKILL during concurrent ingestion by 4 clients (three times over one database); every scan
acknowledged before the kill is there after the restart, and the index matches the scans."""
import os
import threading
import time

import adv_harness as h

CLASS = "K"
TITLE = "SIGKILL during concurrent ingestion"

ROUNDS = 3
CLIENTS = 4


class Writers:
    """CLIENTS clients ingesting small scans until stopped or refused (unary Ingest; with_stream: the first
    client sends on one IngestStream instead)."""

    def __init__(self, s, tag, with_stream=False):
        self.acked = {}  # scan_id -> (robot, session, seq)
        self.errors = []
        self.lock = threading.Lock()
        self.halt = threading.Event()
        self.threads = [threading.Thread(target=self.stream if with_stream and i == 0 else self.unary, args=(s.addr, tag, i), daemon=True)
                        for i in range(CLIENTS)]
        for t in self.threads:
            t.start()

    def ack(self, r, robot, session):
        with self.lock:
            self.acked[r.scan_id] = (robot, session, r.seq)

    def unary(self, addr, tag, i):
        ch = h.channel(addr)
        stub = h.rpc.LoopClosureStub(ch)
        robot, session = f"k{i}", tag
        seq = 0
        try:
            while not self.halt.is_set():
                req = h.pb.IngestRequest(key=h.key(robot, seq, session=session),
                                         scan=h.synthetic_scan(2000, seed=1000 * i + seq), query=seq % 2 == 1)
                r = stub.Ingest(req, timeout=30)
                self.ack(r, robot, session)
                seq += 1
        except h.grpc.RpcError as e:
            h.record(e, "K writer")
            self.errors.append(f"{e.code().name}: {h.short(e.details(), 100)}")
        finally:
            ch.close()

    def stream(self, addr, tag, i):
        ch = h.channel(addr)
        robot, session = f"k{i}", tag

        def requests():
            seq = 0
            while not self.halt.is_set():
                yield h.pb.IngestRequest(key=h.key(robot, seq, session=session),
                                         scan=h.synthetic_scan(2000, seed=1000 * i + seq))
                seq += 1
        try:
            for r in h.rpc.LoopClosureStub(ch).IngestStream(requests(), timeout=120):
                self.ack(r, robot, session)
        except h.grpc.RpcError as e:
            h.record(e, "K writer")
            self.errors.append(f"{e.code().name}: {h.short(e.details(), 100)}")
        finally:
            ch.close()

    def count(self):
        with self.lock:
            return len(self.acked)

    def stop(self):
        self.halt.set()
        for t in self.threads:
            t.join(timeout=60)


def check_present(s, acked, early_errors=()):
    assert not early_errors, f"expected the writers to run until the kill, got {h.short('; '.join(early_errors), 400)}"
    missing, wrong = [], []
    for sid, (robot, session, seq) in sorted(acked.items()):
        try:
            info = s.admin.GetScan(h.pb.GetScanRequest(scan_id=sid), timeout=30)
            if (info.key.robot, info.key.session, info.key.seq) != (robot, session, seq):
                wrong.append(f"{sid}: {info.key.robot}/{info.key.session}/{info.key.seq}")
        except h.grpc.RpcError as e:
            h.record(e)
            if e.code() != h.C.NOT_FOUND:
                raise
            missing.append(sid)
    assert not missing and not wrong, (f"expected all {len(acked)} acknowledged scans after the restart, "
                                       f"missing {len(missing)} (e.g. {missing[:5]}), wrong key {wrong[:3]}")
    st = s.admin.GetStats(h.pb.GetStatsRequest(map="m"), timeout=30)
    assert st.index_entries == st.scans, f"expected index_entries == scans, got {st.index_entries} != {st.scans}"
    assert st.scans >= len(acked), f"expected at least {len(acked)} scans, got {st.scans}"


def run(tmp):
    db = os.path.join(tmp, "crash.db")
    acked = {}
    s = h.Server(db)
    try:
        s.admin.CreateMap(h.pb.CreateMapRequest(name="m"), timeout=30)
        for rnd in range(1, ROUNDS + 1):
            w = Writers(s, f"round{rnd}")
            t_end = time.monotonic() + 60
            # Kill in the middle of the ingestion: once some scans are acknowledged, all writers still going.
            while time.monotonic() < t_end and w.count() < 10 * rnd and not w.errors:
                time.sleep(0.05)
            early = list(w.errors)
            if s.proc.poll() is not None:
                early.insert(0, f"the server died on its own before the SIGKILL: {s.exit_reason()}")
            s.kill()
            w.stop()
            acked.update(w.acked)
            h.note(f"round {rnd}: {len(w.acked)} scans acknowledged before SIGKILL; writers ended with "
                   f"{sorted(set(w.errors)) or 'no error'}")
            s = h.Server(db)
            h.probe(f"K.acknowledged_scans_survive_sigkill_round{rnd}", check_present, s, dict(acked), early)
        h.probe("K.server_serves_after_crashes", lambda: h.expect_ok(
            s, lambda t: s.loop.Ingest(h.pb.IngestRequest(key=h.key("after", 1), scan=h.synthetic_scan(2000, seed=9)),
                                       timeout=t), stored=1))
    finally:
        rc = s.stop()

    def clean_exit():
        assert rc == 0, f"expected exit code 0 after SIGTERM, got {rc}"
    h.probe("K.clean_shutdown_after_crashes", clean_exit)
