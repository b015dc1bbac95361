#!/usr/bin/env python3
"""Contract test of build/bin/sglc-pair: JSON fields, the real loop pair, and one-line errors on bad input.

Usage: test_pair_cli.py SGLC_PAIR_BINARY SHARED_DATA_DIR. Exits 77 (skipped) when the real data is absent.
"""
import json
import math
import os
import subprocess
import sys
import tempfile

binary, data = sys.argv[1], sys.argv[2]
seq = os.path.join(data, "semantickitti_scans", "sequences", "00")
if not os.path.isdir(seq):
    print(f"SKIP: {seq} not found (real SemanticKITTI scans are needed)")
    sys.exit(77)

failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def scan(frame):
    return [os.path.join(seq, "velodyne", frame + ".bin"), os.path.join(seq, "labels", frame + ".label")]


def run(a, b, extra=()):
    args = [binary, "--scan-a", a[0], "--labels-a", a[1], "--scan-b", b[0], "--labels-b", b[1], *extra]
    return subprocess.run(args, capture_output=True, text=True, timeout=120)


# Reference pose of the loop pair from pairs.txt (maps B into A).
ref = None
with open(os.path.join(data, "semantickitti_scans", "pairs.txt")) as f:
    for line in f:
        cols = line.split()
        if cols and not cols[0].startswith("#") and cols[1] == "000052" and cols[2] == "004501":
            ref = [float(v) for v in cols[7:19]]
check(ref is not None, "pairs.txt has the 000052-004501 row")

p = run(scan("000052"), scan("004501"))
check(p.returncode == 0, f"loop pair exits 0 (got {p.returncode}: {p.stderr.strip()})")
out = json.loads(p.stdout)
for key, kind in [("is_loop", bool), ("score", float), ("inliers", int), ("T_a_b", list), ("timings_ms", dict)]:
    check(isinstance(out.get(key), kind), f"field {key} is a {kind.__name__}")
check(len(out["T_a_b"]) == 16 and out["T_a_b"][12:] == [0, 0, 0, 1], "T_a_b is a row-major 4x4 rigid transform")
check(set(out["timings_ms"]) == {"fingerprint_a", "fingerprint_b", "verify", "refine"}, "timings_ms has the four stages")
check(out["is_loop"] is True, "52-4501 is a loop")
check(isinstance(out.get("probability"), float) and out["probability"] == out["score"], "the score is the probability")
check(out.get("evidence", {}).get("source") == "landmarks" and out["evidence"]["landmarks"] >= 3,
      f"the evidence names its source and landmarks: {out.get('evidence')}")
out_loop = out
if ref:
    T = out["T_a_b"]
    t_err = math.dist([T[3], T[7], T[11]], [ref[3], ref[7], ref[11]])
    R = [[T[4 * r + c] for c in range(3)] for r in range(3)]
    G = [[ref[4 * r + c] for c in range(3)] for r in range(3)]
    trace = sum(R[k][i] * G[k][i] for i in range(3) for k in range(3))  # trace(R^T G)
    r_err = math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1) / 2))))
    print(f"loop pair: RTE {t_err:.4f} m, RRE {r_err:.4f} deg, score {out['score']:.3f}")
    check(t_err < 0.10 and r_err < 0.5, f"pose within 0.10 m / 0.5 deg (got {t_err:.3f} m, {r_err:.3f} deg)")

p = run(scan("000052"), scan("000850"))
check(p.returncode == 0 and json.loads(p.stdout)["is_loop"] is False, "52-850 (337 m apart) is not a loop")
check(json.loads(p.stdout)["refined"] is False, "a rejected pair gets no refined pose")
# Told it is a loop, sglc-pair estimates a pose for a pair verification rejects, and keeps the decision.
p = run(scan("000052"), scan("000850"), ["--known-loop"])
out = json.loads(p.stdout)
check(p.returncode == 0 and out["is_loop"] is False and out["refined"] is True and out.get("reason"),
      "--known-loop: a pose for the rejected pair, is_loop and reason kept")
p = run(scan("000052"), scan("004501"), ["--known-loop"])
check(p.returncode == 0 and json.loads(p.stdout)["T_a_b"] == out_loop["T_a_b"],
      "--known-loop leaves a verified loop's pose as it is")

with tempfile.TemporaryDirectory() as tmp:
    truncated = os.path.join(tmp, "t.bin")
    with open(scan("000052")[0], "rb") as f:
        blob = f.read()
    with open(truncated, "wb") as f:
        f.write(blob[:-6])
    cases = {
        "truncated bin": ([truncated, scan("000052")[1]], scan("004501"), ()),
        "label count mismatch": ([scan("000052")[0], scan("004501")[1]], scan("004501"), ()),
        "missing file": ([os.path.join(tmp, "none.bin"), scan("000052")[1]], scan("004501"), ()),
    }
    bad_config = os.path.join(tmp, "bad.yaml")
    with open(bad_config, "w") as f:
        f.write("verify:\n  t_b: 3\n")
    cases["invalid config"] = (scan("000052"), scan("004501"), ("--config", bad_config))
    for name, (a, b, extra) in cases.items():
        p = run(a, b, extra)
        lines = p.stderr.strip().splitlines()
        check(p.returncode != 0, f"{name}: non-zero exit")
        check(len(lines) == 1 and "error" in lines[0], f"{name}: one-line error (got {p.stderr!r})")
        check(p.stdout == "", f"{name}: nothing on stdout")

# A scan file without points is refused with the server's words, whatever its format, not fingerprinted.
with tempfile.TemporaryDirectory() as tmp:
    empty = {".bin": b"", ".pcd": b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\n"
                                b"HEIGHT 1\nPOINTS 0\nDATA ascii\n"}
    for ext, blob in empty.items():
        path = os.path.join(tmp, "empty" + ext)
        with open(path, "wb") as f:
            f.write(blob)
        p = subprocess.run([binary, "--scan-a", path, "--scan-b", scan("004501")[0]], capture_output=True, text=True,
                           timeout=120)
        check(p.returncode == 1 and f"{path}: scan is empty" in p.stderr and p.stdout == "",
              f"empty {ext} scan: exit 1 with '{path}: scan is empty' (got {p.returncode}: {p.stderr.strip()!r})")

# A FIFO given as a scan is refused at once, not waited on (the timeout turns a hang into a failure).
with tempfile.TemporaryDirectory() as tmp:
    fifo = os.path.join(tmp, "fifo.bin")
    os.mkfifo(fifo)
    try:
        p = subprocess.run([binary, "--scan-a", fifo, "--scan-b", scan("004501")[0]], capture_output=True, text=True,
                           timeout=30)
        check(p.returncode == 1 and "is a FIFO" in p.stderr and fifo in p.stderr,
              f"FIFO scan: exit 1 naming the file as a FIFO (got {p.returncode}: {p.stderr.strip()!r})")
    except subprocess.TimeoutExpired:
        check(False, "FIFO scan: sglc-pair still blocked after 30 s")

print(f"{0 if failures else 1} passed, {len(failures)} failed")
sys.exit(1 if failures else 0)
