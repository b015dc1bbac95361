"""Fixtures of the sglc Python package tests (pytest).

Environment (set by tests/python/CMakeLists.txt for ctest):
  SGLC_BUILD_DIR   the build tree whose python/ holds the assembled package (default: <repo>/build)
  SGLC_SERVER_BIN  sglc-server to start for the service tests (default: <build dir>/bin/sglc-server)
  SGLC_PAIR_BIN    sglc-pair, the C++ reference for the engine tests (default: <build dir>/bin/sglc-pair)
  SGLC_DATA        ../shared/data (tests needing real scans skip when it is absent)
"""
import os
import socket
import subprocess
import sys
import time

import pytest

REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
BUILD = os.path.abspath(os.environ.get("SGLC_BUILD_DIR") or os.path.join(REPO, "build"))
DATA = os.environ.get("SGLC_DATA") or os.path.normpath(os.path.join(REPO, "..", "shared", "data"))
sys.path.insert(0, os.path.join(BUILD, "python"))

import sglc  # noqa: E402


def _binary(env, name):
    path = os.environ.get(env) or os.path.join(BUILD, "bin", name)
    return path if os.access(path, os.X_OK) else None


@pytest.fixture(scope="session")
def kitti_dir():
    seq = os.path.join(DATA, "semantickitti_scans", "sequences", "00")
    if not os.path.isfile(os.path.join(seq, "velodyne", "000052.bin")):
        pytest.skip(f"{seq} not found: the real SemanticKITTI scans are needed")
    return seq


@pytest.fixture(scope="session")
def kitti(kitti_dir):
    """read(frame) -> (points (N, 3) float32, labels (N,) uint32) of KITTI 00."""
    def read(frame):
        return sglc.read_kitti_scan(os.path.join(kitti_dir, "velodyne", frame + ".bin"),
                                    os.path.join(kitti_dir, "labels", frame + ".label"))
    return read


@pytest.fixture(scope="session")
def reference_pose():
    """T_a_b of the real pair 000052-004501 (maps 4501 into 52), from pairs.txt."""
    import numpy as np
    path = os.path.join(DATA, "semantickitti_scans", "pairs.txt")
    if not os.path.isfile(path):
        pytest.skip(f"{path} not found")
    with open(path) as f:
        for line in f:
            c = line.split()
            if c and not c[0].startswith("#") and c[:3] == ["00", "000052", "004501"]:
                return np.vstack([np.float64(c[7:19]).reshape(3, 4), [0, 0, 0, 1]])
    pytest.fail("pairs.txt has no 000052-004501 row")


def pose_error(T, R):
    import numpy as np
    dt = float(np.linalg.norm(T[:3, 3] - R[:3, 3]))
    c = (np.trace(T[:3, :3].T @ R[:3, :3]) - 1) / 2
    return dt, float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(tmp, extra=()):
    """Starts this build's sglc-server on a free loopback port with a fresh database in `tmp` (retrying when
    the port was taken in between); returns (process, address, extra with "{port}" replaced) once it answers
    SERVING. "{port}" in `extra` becomes another free port (e.g. for --metrics-listen)."""
    binary = _binary("SGLC_SERVER_BIN", "sglc-server")
    if binary is None:
        pytest.skip("sglc-server is not built")
    for attempt in range(3):
        address = f"127.0.0.1:{_free_port()}"
        args = [x.replace("{port}", str(_free_port())) for x in extra]
        log = open(tmp / f"server{attempt}.log", "wb")
        proc = subprocess.Popen([binary, "--db", str(tmp / "map.db"), "--listen", address, *args],
                                stdout=log, stderr=subprocess.STDOUT)
        up = False
        deadline = time.monotonic() + 120
        while not up and proc.poll() is None and time.monotonic() < deadline:
            with sglc.Client(address, timeout=2.0) as probe:
                up = probe.serving(timeout=2.0)
            if not up:
                time.sleep(0.05)
        if up:
            return proc, address, args
        proc.kill()
        proc.wait()
    pytest.fail(f"sglc-server did not start; see {tmp}")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A fresh sglc-server on a free loopback port; yields its address."""
    proc, address, _ = start_server(tmp_path_factory.mktemp("server"))
    yield address
    proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@pytest.fixture
def client(server):
    with sglc.Client(server, timeout=120) as c:
        yield c
