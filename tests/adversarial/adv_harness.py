"""Shared harness of the adversarial suite: servers on free loopback ports, probes, status bookkeeping, scans.

Every probe prints exactly one line, "PASS <class>.<name>" or "FAIL <class>.<name>: expected X, got Y".
Lines starting with two spaces are notes (measurements, what a probe saw); lines starting with "== " head a
probe class. Nothing here depends on timing to pass except generous limits ("the call ended before its
deadline", "a refused stream was answered within 20 s").
"""
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback

import grpc
import numpy as np

SERVER = STUBS = DATA = CLI = None
pb = rpc = None
SEQ_DIR = None
HAVE_DATA = False
C = grpc.StatusCode

# Every non-OK status any probe saw: (where, code name, message). G checks none of them leaks SQL.
STATUSES = []
_status_lock = threading.Lock()

# Every server process the suite started, so that a class can end its own leftovers (by pid, nothing else).
_PROCS = []

passed = 0
failed = 0
skipped = 0


def setup(server, stubs, data, cli):
    global SERVER, STUBS, DATA, CLI, pb, rpc, SEQ_DIR, HAVE_DATA
    SERVER, STUBS, DATA, CLI = server, stubs, data, cli
    sys.path.insert(0, STUBS)
    from sglc.v1 import sglc_pb2, sglc_pb2_grpc  # noqa: E402
    pb, rpc = sglc_pb2, sglc_pb2_grpc
    SEQ_DIR = os.path.join(DATA, "semantickitti_scans", "sequences", "00")
    HAVE_DATA = all(os.path.exists(os.path.join(SEQ_DIR, "velodyne", f + ".bin")) for f in ("000052", "004501"))


# ------------------------------------------------------------------------------------------------ output

def note(text):
    print("  " + text, flush=True)


def short(msg, n=160):
    msg = (msg or "").replace("\n", " ")
    return msg if len(msg) <= n else msg[:n] + "..."


def record(e, where=""):
    """Remember a failed call's status (for the suite-wide check that no message leaks SQL)."""
    try:
        code, details = e.code(), e.details()
    except Exception:  # noqa: BLE001  (not a finished call)
        return
    with _status_lock:
        STATUSES.append((where, code.name if code else "?", details or ""))


def status_of(e):
    record(e)
    return f"{e.code().name}: '{short(e.details())}'"


def probe(name, fn, *args, **kw):
    """Runs one probe; prints PASS/FAIL; never raises."""
    global passed, failed
    try:
        fn(*args, **kw)
    except AssertionError as e:
        failed += 1
        print(f"FAIL {name}: {e}", flush=True)
    except grpc.RpcError as e:
        failed += 1
        print(f"FAIL {name}: unexpected status {status_of(e)}", flush=True)
    except ServerStartError as e:
        failed += 1
        print(f"FAIL {name}: {e}", flush=True)
    except Exception as e:  # noqa: BLE001
        failed += 1
        tb = traceback.extract_tb(e.__traceback__)
        where = f" (at {os.path.basename(tb[-1].filename)}:{tb[-1].lineno})" if tb else ""
        print(f"FAIL {name}: {type(e).__name__}: {short(str(e), 300)}{where}", flush=True)
    else:
        passed += 1
        print(f"PASS {name}", flush=True)


def skip(name, why):
    global skipped
    skipped += 1
    print(f"SKIP {name}: {why}", flush=True)


# ------------------------------------------------------------------------------------------------ servers

class ServerStartError(Exception):
    pass


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_binary(timeout=600):
    """The other engineer rebuilds build/ now and then: wait until the server binary exists and is settled."""
    t_end = time.monotonic() + timeout
    announced = False
    while True:
        try:
            st = os.stat(SERVER)
            if st.st_mode & 0o111 and time.time() - st.st_mtime > 3:
                return
        except FileNotFoundError:
            pass
        if time.monotonic() > t_end:
            raise ServerStartError(f"{SERVER} missing or still being written after {timeout} s")
        if not announced:
            note(f"waiting for {SERVER} (missing or being rebuilt)")
            announced = True
        time.sleep(2)


CHANNEL_OPTIONS = [("grpc.max_send_message_length", 512 * 1024 * 1024),
                   ("grpc.max_receive_message_length", 512 * 1024 * 1024),
                   ("grpc.initial_reconnect_backoff_ms", 100),
                   ("grpc.min_reconnect_backoff_ms", 100),
                   ("grpc.max_reconnect_backoff_ms", 500)]


def channel(addr):
    return grpc.insecure_channel(addr, options=CHANNEL_OPTIONS)


class Server:
    """One sglc-server process on a free loopback port with its own database and log."""

    def __init__(self, db, extra=(), token=None, port=None, wait=True, sync_normal=True, log_path=None):
        self.db = db
        self.extra = list(extra)
        self.token = token
        self.port = port or free_port()
        self.addr = f"127.0.0.1:{self.port}"
        self.log_path = log_path or db + f".{self.port}.log"  # a PostgreSQL URL needs one given
        cmd = [SERVER, "--db", db, "--listen", self.addr, *(["--sync-normal"] if sync_normal else []), *self.extra]
        for attempt in range(3):
            wait_for_binary()
            self.log = open(self.log_path, "ab")
            try:
                self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT)
                break
            except OSError as e:  # ETXTBSY / ENOEXEC while the binary is being relinked
                self.log.close()
                if attempt == 2:
                    raise ServerStartError(f"cannot run {SERVER}: {e}")
                time.sleep(5)
        _PROCS.append(self.proc)
        if wait:
            self.wait_listening()
        self.channel = channel(self.addr)
        self.admin = rpc.MapAdminStub(self.channel)
        self.loop = rpc.LoopClosureStub(self.channel)
        self.graph = rpc.PoseGraphStub(self.channel)
        if wait:
            self.wait_serving()

    @property
    def md(self):
        return [("authorization", f"Bearer {self.token}")] if self.token else None

    def log_tail(self, n=6):
        try:
            with open(self.log_path, errors="replace") as f:
                lines = [ln.rstrip() for ln in f.readlines() if ln.strip()]
            # The line that says why a process died, if there is one, first.
            why = [ln for ln in lines[:-n] if any(w in ln for w in ("Check failed", "assertion failed", "terminate",
                                                                     "what()", "error:", "Abort"))]
            return " | ".join(short(ln, 200) for ln in why[-1:] + lines[-n:])
        except OSError:
            return ""

    def exit_reason(self):
        rc = self.proc.poll()
        if rc is None:
            return None
        what = f"killed by signal {-rc} ({signal.Signals(-rc).name})" if rc < 0 else f"exit code {rc}"
        return f"server exited ({what}); log: {self.log_tail(1)}"

    def wait_listening(self, timeout=120):
        """Until the port accepts connections (a channel made earlier would sit in reconnect backoff)."""
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end and self.proc.poll() is None:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1):
                    return
            except OSError:
                time.sleep(0.05)

    def wait_serving(self, timeout=120):
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if self.proc.poll() is not None:
                raise ServerStartError(f"server did not start with flags {' '.join(self.extra) or '(none)'}: "
                                       f"{self.exit_reason()}")
            try:
                self.admin.ListMaps(pb.ListMapsRequest(), timeout=2, metadata=self.md)
                return
            except grpc.RpcError as e:
                if e.code() in (C.UNAUTHENTICATED, C.PERMISSION_DENIED):
                    return  # serving: UNAVAILABLE would come before authentication
                if e.code() not in (C.UNAVAILABLE, C.DEADLINE_EXCEEDED):
                    raise ServerStartError(f"server answers ListMaps with {status_of(e)} while starting")
            time.sleep(0.1)
        raise ServerStartError(f"server not serving after {timeout} s; log: {self.log_tail(3)}")

    def health(self, timeout=10):
        """grpc.health.v1.Health/Check of the whole server, without the grpc_health package: b'\\x08\\x01' is SERVING."""
        check = self.channel.unary_unary("/grpc.health.v1.Health/Check", request_serializer=lambda b: b,
                                         response_deserializer=lambda b: b)
        return check(b"", timeout=timeout)

    def alive_problem(self):
        """None when the process runs, health says SERVING and ListMaps answers; else what is wrong."""
        if self.proc.poll() is not None:
            return self.exit_reason()
        try:
            h = self.health()
            if h != b"\x08\x01":
                return f"health check answers {h!r}, not SERVING"
            self.admin.ListMaps(pb.ListMapsRequest(), timeout=15, metadata=self.md)
        except grpc.RpcError as e:
            if self.proc.poll() is not None:
                return self.exit_reason()
            return f"server no longer answers: {status_of(e)}"
        return None

    def assert_alive(self):
        p = self.alive_problem()
        assert p is None, p

    def snapshot(self, m="m"):
        """What a failed call must not change: the number of maps, and the map's scans and index entries."""
        whole = self.admin.GetStats(pb.GetStatsRequest(), timeout=30, metadata=self.md)
        try:
            st = self.admin.GetStats(pb.GetStatsRequest(map=m), timeout=30, metadata=self.md)
            return (whole.maps, st.scans, st.index_entries)
        except grpc.RpcError as e:
            if e.code() == C.NOT_FOUND:
                return (whole.maps, 0, 0)
            raise

    def rss_kb(self):
        out = {}
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith(("VmRSS:", "VmHWM:")):
                    out[line.split(":")[0]] = int(line.split()[1])
        return out

    def stop(self, sig=signal.SIGTERM, timeout=60):
        """Returns the exit code, or None when the process had to be killed after `timeout`."""
        try:
            self.channel.close()
        except Exception:  # noqa: BLE001
            pass
        rc = self.proc.poll()
        if rc is None:
            self.proc.send_signal(sig)
            try:
                rc = self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=30)
                rc = None
        self.log.close()
        return rc

    def kill(self):
        return self.stop(signal.SIGKILL)


def end_leftovers():
    """Ends the server processes this suite started that are still running (each by its own pid)."""
    for p in _PROCS:
        if p.poll() is None:
            p.kill()
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass
    _PROCS.clear()


class Fixture:
    """A class's server; a fresh one (new database) replaces it when a probe left it dead, so that one crash
    does not fail every later probe of the class (the crash itself fails the probe that caused it)."""

    def __init__(self, tmp, name, extra=(), token=None, prepare=None):
        self.tmp, self.name, self.extra, self.token, self.prepare = tmp, name, extra, token, prepare
        self.n = 0
        self.s = None

    def server(self):
        if self.s is not None and self.s.proc.poll() is None:
            return self.s
        if self.s is not None:
            note(f"{self.name}: {self.s.exit_reason()}; starting a fresh server for the next probes")
            self.s.stop()
        self.n += 1
        self.s = Server(os.path.join(self.tmp, f"{self.name}-{self.n}.db"), self.extra, token=self.token)
        if self.prepare:
            self.prepare(self.s)
        return self.s

    def stop(self):
        if self.s is not None:
            rc = self.s.stop()
            self.s = None
            return rc


# ------------------------------------------------------------------------------------------------ assertions

ABS_PATH = re.compile(r"(?:^|[\s'\"(=:,])/(?:tmp|work|home|var|root|usr|etc|proc|dev|opt|srv|mnt)\b")


def expect_error(s, call, code, words=(), any_words=(), forbid=(), deadline=30, m="m", check_stored=True):
    """call(timeout) must fail with `code` and a message that names the problem, within its deadline; the
    server stays up and nothing is stored. Returns the message."""
    before = s.snapshot(m) if check_stored else None
    t0 = time.monotonic()
    try:
        call(deadline)
    except grpc.RpcError as e:
        record(e)
        elapsed = time.monotonic() - t0
        got, msg = e.code(), e.details() or ""
        assert got == code, f"expected {code.name}, got {got.name}: '{short(msg)}'"
        assert msg.strip(), f"expected {code.name} with a message saying what is wrong, got an empty message"
        low = msg.lower()
        for w in words:
            assert w.lower() in low, f"expected {code.name} mentioning '{w}', got {code.name}: '{short(msg)}'"
        if any_words:
            assert any(w.lower() in low for w in any_words), \
                f"expected {code.name} mentioning one of {list(any_words)}, got {code.name}: '{short(msg)}'"
        for w in forbid:
            assert w.lower() not in low, f"expected a message without '{w}', got '{short(msg)}'"
    else:
        elapsed = time.monotonic() - t0
        after = s.snapshot(m) if check_stored else None
        stored = f"; stored: {before} -> {after}" if check_stored and after != before else ""
        raise AssertionError(f"expected {code.name}, got OK{stored}")
    assert elapsed <= deadline + 10, f"the call took {elapsed:.1f} s, past its {deadline} s deadline"
    s.assert_alive()
    if check_stored:
        after = s.snapshot(m)
        assert after == before, f"expected nothing stored, (maps, scans, index entries) went {before} -> {after}"
    return msg


def expect_ok(s, call, deadline=30, stored=None, m="m"):
    """call(timeout) must succeed; with `stored`, the map's scans grow by exactly that many."""
    before = s.snapshot(m) if stored is not None else None
    try:
        r = call(deadline)
    except grpc.RpcError as e:
        record(e)
        raise AssertionError(f"expected OK, got {e.code().name}: '{short(e.details())}'")
    s.assert_alive()
    if stored is not None:
        after = s.snapshot(m)
        assert after[1] == before[1] + stored and after[2] == before[2] + stored, \
            f"expected {stored} scan(s) stored, (maps, scans, index entries) went {before} -> {after}"
    return r


# ------------------------------------------------------------------------------------------------ scans

def load_scan(frame):
    pts = np.fromfile(os.path.join(SEQ_DIR, "velodyne", frame + ".bin"), dtype="<f4").reshape(-1, 4)[:, :3]
    lab = np.fromfile(os.path.join(SEQ_DIR, "labels", frame + ".label"), dtype="<u4")
    return pb.Scan(points=np.ascontiguousarray(pts).tobytes(), labels=lab.tobytes())


def synthetic_arrays(n=3000, seed=0):
    """A street-like labelled cloud: road (40), two building walls (50), car-sized clusters (10), poles (80)."""
    rng = np.random.default_rng(seed)
    n_road, n_wall = int(n * 0.45), int(n * 0.3)
    n_rest = n - n_road - n_wall
    road = np.column_stack([rng.uniform(-30, 30, n_road), rng.uniform(-30, 30, n_road),
                            rng.normal(-1.7, 0.02, n_road)])
    side = rng.integers(0, 2, n_wall)
    wall = np.column_stack([np.where(side == 0, 12.0, -14.0) + rng.normal(0, 0.05, n_wall),
                            rng.uniform(-30, 30, n_wall), rng.uniform(-1.7, 6, n_wall)])
    n_cars = 8
    centres = rng.uniform(-10, 10, (n_cars, 2))
    n_poles = 4
    pole_xy = rng.uniform(-10, 10, (n_poles, 2))
    idx = rng.integers(0, n_cars + n_poles, n_rest)
    rest = np.empty((n_rest, 3))
    lab_rest = np.empty(n_rest, dtype="<u4")
    car = idx < n_cars
    k = idx[car]
    rest[car] = np.column_stack([centres[k, 0] + rng.uniform(-2, 2, car.sum()),
                                 centres[k, 1] + rng.uniform(-0.9, 0.9, car.sum()),
                                 rng.uniform(-1.6, -0.2, car.sum())])
    lab_rest[car] = 10
    p = idx[~car] - n_cars
    rest[~car] = np.column_stack([pole_xy[p, 0] + rng.normal(0, 0.05, (~car).sum()),
                                  pole_xy[p, 1] + rng.normal(0, 0.05, (~car).sum()),
                                  rng.uniform(-1.7, 4, (~car).sum())])
    lab_rest[~car] = 80
    pts = np.vstack([road, wall, rest]).astype("<f4")
    lab = np.concatenate([np.full(n_road, 40, "<u4"), np.full(n_wall, 50, "<u4"), lab_rest])
    return pts, lab


def synthetic_scan(n=3000, seed=0):
    pts, lab = synthetic_arrays(n, seed)
    return pb.Scan(points=pts.tobytes(), labels=lab.tobytes())


def realistic_scan(frame="000052", seed=0):
    """A real scan when the shared data is there, else a synthetic one."""
    return load_scan(frame) if HAVE_DATA else synthetic_scan(4000, seed)


def key(robot, seq, session="run", m="m"):
    return pb.ScanKey(map=m, robot=robot, session=session, seq=seq)


# ------------------------------------------------------------------------------------------------ other clients

class Bystander(threading.Thread):
    """Another client doing ordinary work on its own channel and map while a class probes the server: none of
    its calls may fail."""

    def __init__(self, s, name="bystander"):
        super().__init__(daemon=True)
        self.addr, self.md, self.map = s.addr, s.md, name
        self.ok = 0
        self.failures = []
        self._halt = threading.Event()
        self.channel = channel(self.addr)
        admin = rpc.MapAdminStub(self.channel)
        admin.CreateMap(pb.CreateMapRequest(name=name), timeout=30, metadata=self.md)
        self.start()

    def run(self):
        admin = rpc.MapAdminStub(self.channel)
        loop = rpc.LoopClosureStub(self.channel)
        scan = synthetic_scan(1500, seed=4242)
        seq = 0
        while not self._halt.is_set():
            for call in (lambda: admin.ListMaps(pb.ListMapsRequest(), timeout=30, metadata=self.md),
                         lambda: admin.GetStats(pb.GetStatsRequest(map=self.map), timeout=30, metadata=self.md),
                         lambda: loop.Ingest(pb.IngestRequest(key=key("by", seq, m=self.map), scan=scan),
                                             timeout=30, metadata=self.md)):
                try:
                    call()
                    self.ok += 1
                except grpc.RpcError as e:
                    record(e, "bystander")
                    self.failures.append(f"{e.code().name}: '{short(e.details(), 80)}'")
            seq += 1
            self._halt.wait(0.3)

    def finish(self):
        self._halt.set()
        self.join(timeout=120)
        self.channel.close()
        assert self.ok > 0, "the other client completed no call"
        assert not self.failures, (f"expected every call of another client to succeed, {len(self.failures)} failed "
                                   f"(of {self.ok + len(self.failures)}), first: {self.failures[0]}")


def blocking_requests(event, first=()):
    """A request iterator that yields `first` and then sends nothing until `event` is set."""
    for r in first:
        yield r
    event.wait()


def wire_verdict(data):
    """Top-level protobuf wire-format scan: 'invalid' when the bytes cannot be any message (wire type 6/7, a
    truncated or over-long varint, a length or fixed field past the end), 'unsure' for constructs parsers
    treat differently (field 0, groups), 'valid' otherwise (nested contents unchecked)."""
    i, n = 0, len(data)

    def varint(i):
        v = shift = 0
        for k in range(10):
            if i >= n:
                return None, i
            b = data[i]
            i += 1
            v |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                return v, i
        return None, i  # longer than 10 bytes

    while i < n:
        tag, i = varint(i)
        if tag is None:
            return "invalid"
        wt, field = tag & 7, tag >> 3
        if wt in (6, 7):
            return "invalid"
        if field == 0 or wt in (3, 4):
            return "unsure"
        if wt == 0:
            v, i = varint(i)
            if v is None:
                return "invalid"
        elif wt == 1:
            i += 8
        elif wt == 5:
            i += 4
        elif wt == 2:
            ln, i = varint(i)
            if ln is None:
                return "invalid"
            i += ln
        if i > n:
            return "invalid"
    return "valid"


def garbage_for(msg_cls, count=4, seed=7):
    """b'\\xff'*10 plus random byte strings that are certainly not a valid `msg_cls` (wire-level invalid and
    rejected by the Python parser too)."""
    rng = random.Random(seed)
    out = [b"\xff" * 10]
    tries = 0
    while len(out) < count + 1 and tries < 10000:
        tries += 1
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 48)))
        if wire_verdict(data) != "invalid":
            continue
        try:
            msg_cls.FromString(data)
            continue  # parses after all: another code would be legitimate
        except Exception:  # noqa: BLE001
            out.append(data)
    return out


# PostgreSQL (the test cluster ctest starts; SGLC_TEST_PG names a file holding its URL).
def pg_url():
    """The test cluster's URL, or "" when there is none."""
    url_file = os.environ.get("SGLC_TEST_PG", "")
    return open(url_file).read().strip() if url_file and os.path.exists(url_file) else ""


def psql(url, sql):
    out = subprocess.run(["psql", url, "-XAtqc", sql], capture_output=True, text=True, timeout=60)
    if out.returncode != 0:
        raise RuntimeError(f"psql: {out.stderr.strip()}")
    return out.stdout.strip()


def fresh_database(base_url, db):
    """Creates database `db` anew on the cluster of base_url; its URL."""
    psql(base_url, f"DROP DATABASE IF EXISTS {db}")
    psql(base_url, f"CREATE DATABASE {db}")
    return base_url.rsplit("/", 1)[0] + "/" + db


def drop_database(base_url, db):
    try:
        psql(base_url, f"DROP DATABASE IF EXISTS {db} WITH (FORCE)")
    except Exception as e:  # noqa: BLE001
        note(f"could not drop {db}: {e}")
