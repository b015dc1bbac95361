"""O. Scan files from a hostile disk, through the real tools: a FIFO given as a scan (or inside a sequence
directory) is refused at once, not waited on; 2 GB sparse .bin/.npy/.pcd/.ply files and files declaring more points
than the cap are refused from their size or header before their data is read; ASCII PCD/PLY values that do not fit
their declared type are refused naming the file, line and value; a scan without points is refused by sglc-pair as
the server refuses it. Every tool run is bounded by a timeout, so that a regression fails instead of hanging."""
import os
import subprocess

import numpy as np

import adv_harness as h

CLASS = "O"
TITLE = "FIFOs, sparse giants, ASCII values out of range, empty scans (sglc-pair, sglc ingest)"

CAP = 2_000_000  # kMaxScanPoints: the readers' cap and the server's default max_points
GIANT = 2 << 30  # 2 GiB, sparse
RUN_TIMEOUT = 60  # a hang guard only: each refusal takes well under a second


def pair_binary():
    return os.environ.get("SGLC_PAIR") or os.path.join(os.path.dirname(h.CLI), "sglc-pair")


def run_tool(args, timeout=RUN_TIMEOUT):
    try:
        return subprocess.run(args, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"expected a prompt refusal, {os.path.basename(args[0])} still ran after {timeout} s "
                             f"({' '.join(args[1:])[:200]})") from None


def expect_refused(args, *words):
    """The tool exits 1 with one error line on stderr that holds every one of `words`; nothing on stdout."""
    p = run_tool(args)
    err = p.stderr.strip()
    assert p.returncode == 1, f"expected exit 1, got {p.returncode}: '{h.short(err)}'"
    assert len(err.splitlines()) == 1 and "error" in err, f"expected a one-line error, got '{h.short(err, 300)}'"
    for w in words:
        assert w in err, f"expected the error to mention '{w}', got '{h.short(err, 300)}'"
    assert p.stdout == "", f"expected nothing on stdout, got '{h.short(p.stdout)}'"
    return err


def valid_bin(path, n=2000, seed=5):
    pts, _ = h.synthetic_arrays(n, seed)
    np.hstack([pts, np.zeros((n, 1), "<f4")]).astype("<f4").tofile(path)
    return path


def pair(a, b):
    return [pair_binary(), "--scan-a", a, "--scan-b", b]


def fifo_scan(tmp):
    fifo = os.path.join(tmp, "fifo.bin")
    os.mkfifo(fifo)
    expect_refused(pair(fifo, valid_bin(os.path.join(tmp, "ok.bin"))), fifo, "FIFO")


def fifo_in_sequence(tmp):
    seq = os.path.join(tmp, "seq")
    os.makedirs(os.path.join(seq, "velodyne"))
    valid_bin(os.path.join(seq, "velodyne", "000000.bin"))
    fifo = os.path.join(seq, "velodyne", "000001.bin")
    os.mkfifo(fifo)
    s = h.Server(os.path.join(tmp, "fifo.db"))
    try:
        err = expect_refused([h.CLI, "ingest", "--server", s.addr, "--map", "m", "--robot", "r", "--no-progress",
                              seq], fifo, "FIFO")
        assert "after 1 of 2 scans were stored" in err, f"expected 'after 1 of 2 scans were stored', got '{err}'"
        s.assert_alive()
    finally:
        s.stop()


def sparse(path, header=b"", size=GIANT):
    with open(path, "wb") as f:
        f.write(header)
        f.truncate(size)
    return path


def npy_header(shape, descr="<f4"):
    d = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}".encode()
    d += b" " * ((64 - (10 + len(d) + 1) % 64) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(d).to_bytes(2, "little") + d


def sparse_giants(tmp):
    ok = valid_bin(os.path.join(tmp, "ok.bin"))
    n = GIANT // 16
    giants = {
        "giant.bin": (b"", [f"{n} points"]),
        "giant.npy": (npy_header(f"({n}, 4)"), ["bytes, larger than"]),
        "giant.pcd": (f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
                      f"POINTS {n}\nDATA binary\n".encode(), ["bytes, larger than"]),
        "giant.ply": (f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
                      f"property float y\nproperty float z\nend_header\n".encode(), ["bytes, larger than"]),
    }
    problems = []
    for name, (header, words) in giants.items():
        path = sparse(os.path.join(tmp, name), header)
        try:
            expect_refused(pair(path, ok), path, *words)
        except AssertionError as e:
            problems.append(f"{name}: {e}")
        os.remove(path)
    assert not problems, "; ".join(problems)


def over_the_cap(tmp):
    """Files within the byte limit whose size or header declares more points than the cap."""
    ok = valid_bin(os.path.join(tmp, "ok.bin"))
    n = CAP + 1
    files = {
        "many.bin": (b"", n * 16),
        "many.npy": (npy_header(f"({n}, 3)"), None),
        "many.pcd": (f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
                     f"POINTS {n}\nDATA binary\n".encode(), None),
        "many.ply": (f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
                     f"property float y\nproperty float z\nend_header\n".encode(), None),
    }
    problems = []
    for name, (header, size) in files.items():
        path = sparse(os.path.join(tmp, name), header, size or len(header) + n * 12)
        try:
            expect_refused(pair(path, ok), path, f"{n} points", f"more than the {CAP}")
        except AssertionError as e:
            problems.append(f"{name}: {e}")
        os.remove(path)
    assert not problems, "; ".join(problems)


PCD_HEAD = ("VERSION .7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\n"
            "POINTS 2\nDATA ascii\n1 2 3 40\n")
PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n1 2 3 10 20 30\n")


def ascii_values(tmp):
    ok = valid_bin(os.path.join(tmp, "ok.bin"))
    cases = [("neg.pcd", PCD_HEAD + "4 5 6 -10\n", ["line 11", "'label'", "'-10'", "out of range for U4"]),
             ("frac.pcd", PCD_HEAD + "4 5 6 10.5\n", ["line 11", "'10.5'", "not an integer"]),
             ("huge.pcd", PCD_HEAD + "4 5 6 99999999999\n", ["line 11", "'99999999999'", "out of range for U4"]),
             ("float.pcd", PCD_HEAD.replace("1 2 3 40", "1e39 2 3 40") + "4 5 6 1\n", ["line 10", "'1e39'", "F4"]),
             ("wrap.ply", PLY_HEAD + "4 5 6 300 0 0\n", ["vertex 1", "line 12", "'red'", "'300'", "U1 (0..255)"])]
    problems = []
    for name, text, words in cases:
        path = os.path.join(tmp, name)
        with open(path, "w") as f:
            f.write(text)
        try:
            expect_refused(pair(path, ok), path, *words)
        except AssertionError as e:
            problems.append(f"{name}: {e}")
    assert not problems, "; ".join(problems)


def empty_scans(tmp):
    ok = valid_bin(os.path.join(tmp, "ok.bin"))
    path = os.path.join(tmp, "empty.bin")
    open(path, "wb").close()
    expect_refused(pair(path, ok), f"{path}: scan is empty")
    expect_refused(pair(ok, path), f"{path}: scan is empty")


def run(tmp):
    for name, fn in (("O.fifo_scan_refused_not_waited_on", fifo_scan),
                     ("O.fifo_in_sequence_ingest_refused_counting_stored", fifo_in_sequence),
                     ("O.sparse_2gb_scans_refused_from_size_or_header", sparse_giants),
                     ("O.scans_over_the_point_cap_refused_from_size_or_header", over_the_cap),
                     ("O.ascii_values_out_of_their_type_refused", ascii_values),
                     ("O.empty_scan_refused_by_sglc_pair", empty_scans)):
        sub = os.path.join(tmp, name.split(".")[1])
        os.makedirs(sub)
        h.probe(name, fn, sub)
