"""What the end-to-end server tests share: a real sglc-server on a free loopback port, status checks, and the
runner that gives each test a temporary directory and shows its servers' logs when it fails.

pb, rpc = configure(SERVER_BINARY, PYTHON_STUB_DIR) first: it imports the generated sglc.v1 stubs."""
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import traceback

import grpc

_binary = pb = rpc = None


def configure(binary, stubs):
    """The server binary the tests start, and the stubs' directory; returns the modules (sglc_pb2, sglc_pb2_grpc)."""
    global _binary, pb, rpc
    sys.path.insert(0, stubs)
    from sglc.v1 import sglc_pb2, sglc_pb2_grpc
    _binary, pb, rpc = binary, sglc_pb2, sglc_pb2_grpc
    return pb, rpc


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    def __init__(self, db, extra=()):
        self.log_path = db + ".log"
        self.log = open(self.log_path, "ab")
        start = self.log.tell()  # the log is appended to across restarts: read this run's lines only
        # Port 0: the server takes a free port and logs it, so another test's server cannot take it in between.
        self.proc = subprocess.Popen([_binary, "--db", db, "--listen", "127.0.0.1:0", "--sync-normal", *extra],
                                     stdout=self.log, stderr=subprocess.STDOUT)
        self._start = start
        self.port = self._listening_port(start)
        self.addr = f"127.0.0.1:{self.port}"
        self.channel = grpc.insecure_channel(self.addr)
        grpc.channel_ready_future(self.channel).result(timeout=30)
        self.admin = rpc.MapAdminStub(self.channel)
        self.loop = rpc.LoopClosureStub(self.channel)
        self.graph = rpc.PoseGraphStub(self.channel)
        # Serving once the database is loaded.
        for _ in range(300):
            try:
                self.admin.ListMaps(pb.ListMapsRequest(), timeout=5)
                break
            except grpc.RpcError as e:
                if e.code() not in (grpc.StatusCode.UNAVAILABLE,):
                    break
                time.sleep(0.05)

    def _listening_port(self, start):
        import json
        for _ in range(600):
            with open(self.log_path, errors="replace") as f:
                f.seek(start)
                for line in f:
                    if '"event":"listening"' in line:
                        return json.loads(line)["port"]
            assert self.proc.poll() is None, f"sglc-server exited {self.proc.returncode} before it listened"
            time.sleep(0.1)
        raise AssertionError("sglc-server logged no port in 60 s")

    def logged_port(self, event):
        """The port the server logged for `event` (e.g. "viz", "metrics": their addresses may say port 0)."""
        import json
        with open(self.log_path, errors="replace") as f:
            f.seek(self._start)
            for line in f:
                if f'"event":"{event}"' in line:
                    return json.loads(line)["port"]
        raise AssertionError(f"the server logged no '{event}' line")

    def stop(self, sig=signal.SIGTERM):
        self.channel.close()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            self.proc.wait(timeout=60)
        self.log.close()
        return self.proc.returncode


def expect_code(code, fn, what):
    try:
        fn()
    except grpc.RpcError as e:
        assert e.code() == code, f"{what}: expected {code}, got {e.code()}: {e.details()}"
        assert e.details(), f"{what}: the status has no message"
        return e.details()
    raise AssertionError(f"{what}: expected {code}, the call succeeded")


def run(tests, prefix):
    """Runs each test with a fresh temporary directory; exits 1 when any failed."""
    passed = failed = 0
    for t in tests:
        tmp = tempfile.mkdtemp(prefix=prefix)
        try:
            print(f"{t.__name__}:")
            t(tmp)
            passed += 1
            print("  ok")
        except Exception:  # noqa: BLE001
            failed += 1
            traceback.print_exc()
            for log in [f for f in os.listdir(tmp) if f.endswith(".log")]:
                print(f"--- {log} (last lines)")
                print("".join(open(os.path.join(tmp, log), errors="replace").readlines()[-15:]))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)
