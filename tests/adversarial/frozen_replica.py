#!/usr/bin/env python3
"""A frozen replica (issue 36, item 2): three sglc-server replicas on one PostgreSQL database, one client writing
through each; one replica is stopped with SIGSTOP while it holds the database-wide write lock (its TCP
connections stay up) and continued after FREEZE_S seconds.

Required: the other replicas acknowledge scans again within 10 s of the freeze (no gap of more than 10 s
between their acknowledgements while it lasts); after SIGCONT the frozen replica acknowledges scans again (it
finds its transaction gone and reconnects); every acknowledged scan is stored exactly once, nothing else is
stored, and every replica's index holds them all.

Usage: frozen_replica.py SERVER_BINARY PYTHON_STUB_DIR [FREEZE_S]; SGLC_TEST_PG names a file holding the
test cluster's URL (CTest's pg_cluster fixture). Extra server flags in SGLC_FROZEN_FLAGS (e.g.
"--set storage.stall_timeout_ms=0" shows the bug). Exit 0 pass, 1 fail, 77 skipped (no grpc/numpy or no cluster).
"""
import collections
import os
import random
import shlex
import signal
import sys
import tempfile
import threading
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

REPLICAS = 3
BOUND_S = 10.0         # the limit for the others to acknowledge again
CALL_DEADLINE_S = 8.0  # a client's wait for one call (longer than the lock wait, storage.busy_timeout_ms 5 s)
LOCK_HOLDER = ("SELECT a.application_name FROM pg_locks l JOIN pg_stat_activity a ON a.pid = l.pid "
               "WHERE l.locktype = 'advisory' AND l.classid = 1397181507 AND l.objid = 1 AND l.objsubid = 2 "
               "AND l.granted AND l.database = (SELECT oid FROM pg_database WHERE datname = current_database())")




class Client(threading.Thread):
    """Ingests scans of robot c<i> through one replica, each seq retried (UNAVAILABLE, deadline) until
    acknowledged; on halt it finishes the seq it started, so every seq it sent is acknowledged."""

    def __init__(self, i, server, scans):
        super().__init__(daemon=True)
        self.i, self.robot, self.scans = i, f"c{i}", scans
        self.stub = h.rpc.LoopClosureStub(h.channel(server.addr))
        self.acks = []  # (monotonic time of the answer, seq, scan_id)
        self.errors = collections.Counter()
        self.fatal = None
        self.halt = threading.Event()
        self.start()

    def run(self):
        seq = 0
        while not self.halt.is_set():
            req = h.pb.IngestRequest(key=h.key(self.robot, seq), scan=self.scans[seq % len(self.scans)])
            give_up = time.monotonic() + 180
            while True:
                try:
                    r = self.stub.Ingest(req, timeout=CALL_DEADLINE_S)
                    self.acks.append((time.monotonic(), seq, r.scan_id))
                    break
                except grpc.RpcError as e:
                    self.errors[e.code().name] += 1
                    if e.code() not in (h.C.UNAVAILABLE, h.C.DEADLINE_EXCEEDED) or time.monotonic() > give_up:
                        self.fatal = f"seq {seq}: {e.code().name}: {h.short(e.details())}"
                        return
                    time.sleep(0.1)
            seq += 1

    def acked_after(self, t):
        return [a for a in self.acks if a[0] > t]


def max_gap(times, start, end):
    """The longest stretch in [start, end] without one of `times`."""
    points = [start] + sorted(t for t in times if start < t < end) + [end]
    return max(b - a for a, b in zip(points, points[1:]))


def freeze_holder(victim, url, app):
    """SIGSTOPs the victim until it is caught holding the write lock (mid-write); returns the time of the stop."""
    for attempt in range(300):
        t = time.monotonic()
        os.kill(victim.proc.pid, signal.SIGSTOP)
        if h.psql(url, LOCK_HOLDER) == app:
            h.note(f"replica 0 stopped holding the write lock (attempt {attempt + 1})")
            return t
        os.kill(victim.proc.pid, signal.SIGCONT)
        time.sleep(random.uniform(0.02, 0.3))
    raise AssertionError("replica 0 was never caught holding the write lock in 300 tries")


def run(freeze_s, tmp, base_url):
    db = f"sglc_frozen_{os.getpid()}"
    admin_url = base_url
    url = h.fresh_database(admin_url, db)
    flags = shlex.split(os.environ.get("SGLC_FROZEN_FLAGS", ""))
    servers, clients, victim = [], [], None
    try:
        for i in range(REPLICAS):
            servers.append(h.Server(f"{url}?application_name=sglc-r{i}", flags,
                                    log_path=os.path.join(tmp, f"replica{i}.log")))
        victim = servers[0]
        servers[0].admin.CreateMap(h.pb.CreateMapRequest(name="m"), timeout=30)
        for s in servers:  # the others learn of the map from the journal, within a second or so
            t_end = time.monotonic() + 60
            while not any(m.name == "m" for m in s.admin.ListMaps(h.pb.ListMapsRequest(), timeout=30).maps):
                assert time.monotonic() < t_end, "a replica never saw the map another created"
                time.sleep(0.1)
        scans = [h.synthetic_scan(1500, seed=s) for s in range(8)]
        clients = [Client(i, servers[i], scans) for i in range(REPLICAS)]
        t_end = time.monotonic() + 60
        while min(len(c.acks) for c in clients) < 5 and time.monotonic() < t_end:
            time.sleep(0.1)
        assert all(c.acks for c in clients), "the clients did not get going: " + str([c.fatal for c in clients])

        t_stop = freeze_holder(victim, url, "sglc-r0")
        try:
            time.sleep(max(0.0, t_stop + freeze_s - time.monotonic()))
        finally:
            os.kill(victim.proc.pid, signal.SIGCONT)
        t_cont = time.monotonic()
        others = [a[0] for c in clients[1:] for a in c.acks]
        gap = max_gap(others, t_stop, t_cont)
        first = min((t for t in others if t > t_stop), default=None)
        during = sum(1 for t in others if t_stop < t < t_cont)
        h.note(f"freeze {t_cont - t_stop:.1f} s: the others acknowledged {during} scans during it; first "
               f"{'none' if first is None else f'{first - t_stop:.2f} s'} after the stop; longest gap {gap:.2f} s")

        t_end = t_cont + 30
        while not clients[0].acked_after(t_cont) and time.monotonic() < t_end and clients[0].fatal is None:
            time.sleep(0.1)
        back = clients[0].acked_after(t_cont)
        h.note("replica 0 acknowledged again " +
               (f"{back[0][0] - t_cont:.2f} s after SIGCONT" if back else "never (30 s)"))
        time.sleep(3)
        for c in clients:
            c.halt.set()
        for c in clients:
            c.join(timeout=240)

        # Every acknowledged (robot, seq) stored exactly once, under the id it was acknowledged with, nothing else.
        acked = {(c.robot, seq): sid for c in clients for _, seq, sid in c.acks}
        rows = h.psql(url, "SELECT rb.name || ' ' || s.seq || ' ' || s.id FROM scans s JOIN robots rb ON "
                         "rb.id = s.robot_id").splitlines()
        stored = collections.Counter()
        ids = {}
        for line in rows:
            robot, seq, sid = line.split()
            stored[(robot, int(seq))] += 1
            ids[(robot, int(seq))] = int(sid)
        twice = [k for k, n in stored.items() if n > 1]
        lost = [k for k in acked if k not in stored]
        unacked = [k for k in stored if k not in acked]
        moved = [k for k in acked if k in ids and ids[k] != acked[k]]
        h.note(f"acknowledged {len(acked)}, stored {sum(stored.values())} rows ({len(stored)} distinct); "
               f"errors seen by the clients: {dict(sum((c.errors for c in clients), collections.Counter()))}")
        indexed = []
        for s in servers:
            t_end = time.monotonic() + 60
            while True:
                n = s.admin.GetStats(h.pb.GetStatsRequest(map="m"), timeout=30).index_entries
                if n == len(acked) or time.monotonic() > t_end:
                    break
                time.sleep(0.2)
            indexed.append(n)
        h.note(f"index entries on the replicas: {indexed}")

        problems = [f"client {c.i} gave up: {c.fatal}" for c in clients if c.fatal]
        if gap > BOUND_S:
            problems.append(f"the other replicas acknowledged nothing for {gap:.1f} s (limit {BOUND_S:.0f} s)")
        if not back:
            problems.append("the frozen replica acknowledged nothing within 30 s of SIGCONT")
        for what, keys in (("stored twice", twice), ("acknowledged but not stored", lost),
                           ("stored but never acknowledged", unacked), ("stored under another id", moved)):
            if keys:
                problems.append(f"{len(keys)} scans {what}, e.g. {sorted(keys)[:3]}")
        if any(n != len(acked) for n in indexed):
            problems.append(f"index entries {indexed}, expected {len(acked)} on every replica")
        for i, s in enumerate(servers):
            if s.proc.poll() is not None:
                problems.append(f"replica {i}: {s.exit_reason()}")
        return problems
    finally:
        if victim is not None and victim.proc.poll() is None:
            os.kill(victim.proc.pid, signal.SIGCONT)
        for c in clients:
            c.halt.set()
        for s in servers:
            s.stop()
        h.drop_database(admin_url, db)


def main():
    if len(sys.argv) < 3:
        print(__doc__)
        sys.exit(2)
    h.setup(sys.argv[1], sys.argv[2], "", "")
    freeze_s = float(sys.argv[3]) if len(sys.argv) > 3 else 20.0
    base_url = h.pg_url()
    if not base_url:
        print("SKIP: no PostgreSQL test cluster (run through ctest, or set SGLC_TEST_PG to a file holding a URL)")
        sys.exit(77)
    with tempfile.TemporaryDirectory(prefix="sglc-frozen-") as tmp:
        problems = run(freeze_s, tmp, base_url)
        if problems:
            for i in range(REPLICAS):
                with open(os.path.join(tmp, f"replica{i}.log"), errors="replace") as f:
                    tail = [ln.rstrip() for ln in f.readlines()[-3:]]
                h.note(f"replica {i} log: " + " | ".join(h.short(ln, 200) for ln in tail))
    name = f"frozen_replica.sigstop_{freeze_s:g}s"
    if problems:
        print(f"FAIL {name}: " + "; ".join(problems), flush=True)
        sys.exit(1)
    print(f"PASS {name}", flush=True)


if __name__ == "__main__":
    main()
