#!/usr/bin/python3
"""tools/eval/at_threshold.py: a field run's figures at a higher loop-probability bar, from its CSV files."""
import json
import os
import subprocess
import sys
import tempfile

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "tools", "eval", "at_threshold.py")


def write(path, text):
    with open(path, "w") as f:
        f.write(text)


def main():
    failures = []
    with tempfile.TemporaryDirectory() as root:
        seq = os.path.join(root, "sequence-07")
        os.makedirs(seq)
        write(os.path.join(seq, "summary.json"), json.dumps({"protocol": "sequence"}))
        # Three verified top-1 answers outside the band: true at 0.95 and 0.6, false at 0.7; one in the band.
        write(os.path.join(seq, "top1.csv"), "frame,match_frame,score,distance_m,outcome\n"
              "1,0,0.95,1.0,true\n2,0,0.6,1.0,true\n3,0,0.7,300,false\n4,0,0.99,9,between\n")
        write(os.path.join(seq, "pr.csv"), "threshold,precision,recall\n0.6,0.667,1.0\n0.7,0.5,0.5\n0.95,1.0,0.5\n")
        rel = os.path.join(root, "sensor-vlp16-09")
        os.makedirs(rel)
        write(os.path.join(rel, "summary.json"), json.dumps({"protocol": "relocalization", "queries_with_true_place": 4}))
        write(os.path.join(rel, "relocalization.csv"), "frame,match_frame,score,distance_m,nearest_map_m,outcome\n"
              "0,1,0.9,1,1,true\n1,2,0.55,1,1,true\n2,3,0.85,400,1,false\n3,-1,0,-1,1,none\n")
        out = subprocess.run([sys.executable, TOOL, "0.8", seq, rel], capture_output=True, text=True)
        lines = out.stdout.split("\n")
        s = next((l for l in lines if l.startswith("| sequence-07")), "")
        r = next((l for l in lines if l.startswith("| sensor-vlp16-09")), "")
        if s != "| sequence-07 | 0.667 | - | 1.000 (1 / 0) |":
            failures.append(f"sequence at 0.8: F1 of the curve's points at or above the bar, one true answer kept: {s!r}")
        if r != "| sensor-vlp16-09 | - | 0.250 | 0.500 (1 / 1) |":
            failures.append(f"relocalization at 0.8: Recall@1 over the 4 queries with a place, 1 true and 1 false: {r!r}")
        bad = subprocess.run([sys.executable, TOOL], capture_output=True, text=True)
        if bad.returncode == 0:
            failures.append("no arguments: a usage error")
    for f in failures:
        print("FAIL:", f)
    print(f"at_threshold: {len(failures)} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
