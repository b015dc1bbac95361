#!/usr/bin/env python3
"""Prints the loops found by scripts/demo.sh with their pose error against the simulator's ground truth."""
import json
import math
import os
import sys

work = sys.argv[1]
poses = []
with open(os.path.join(work, "seq", "poses.txt")) as f:
    for line in f:
        v = [float(x) for x in line.split()]
        poses.append([v[0:4], v[4:8], v[8:12], [0.0, 0.0, 0.0, 1.0]])


def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def inv(t):
    r = [[t[j][i] for j in range(3)] for i in range(3)]
    p = [-sum(r[i][k] * t[k][3] for k in range(3)) for i in range(3)]
    return [r[0] + [p[0]], r[1] + [p[1]], r[2] + [p[2]], [0.0, 0.0, 0.0, 1.0]]


frame_of = {}  # scan id -> frame number
rows = []
for robot in ("alpha", "bravo"):
    with open(os.path.join(work, robot + ".jsonl")) as f:
        for line in f:
            r = json.loads(line)
            frame_of[r["scan_id"]] = int(r["frame"])
            rows.append((robot, r))
count = {"intra": 0, "inter": 0}
errors = []
print(f"{'query':>12} {'candidate':>14} {'kind':>5} {'score':>6} {'inliers':>7} {'dist_m':>7} {'RTE_m':>7} {'RRE_deg':>7}")
for robot, r in rows:
    q = int(r["frame"])
    for loop in r["loops"]:
        c = frame_of[loop["scan_id"]]
        T = [loop["T"][4 * i:4 * i + 4] for i in range(4)]
        G = mul(inv(poses[q]), poses[c])  # maps the candidate's points into the query's frame
        rte = math.dist([T[i][3] for i in range(3)], [G[i][3] for i in range(3)])
        tr = sum(T[k][i] * G[k][i] for i in range(3) for k in range(3))
        rre = math.degrees(math.acos(max(-1.0, min(1.0, (tr - 1) / 2))))
        dist = math.dist([poses[q][i][3] for i in range(3)], [poses[c][i][3] for i in range(3)])
        kind = "inter" if loop["robot"] != robot else "intra"
        count[kind] += 1
        errors.append((rte, rre))
        print(f"{robot + ' ' + str(q):>12} {loop['robot'] + ' ' + str(c):>14} {kind:>5} {loop['score']:6.3f} "
              f"{loop['inliers']:7d} {dist:7.2f} {rte:7.3f} {rre:7.3f}")
print(f"loops: {count['intra']} intra-robot, {count['inter']} inter-robot")
if errors:
    errors.sort()
    print(f"median RTE {sorted(e[0] for e in errors)[len(errors) // 2]:.3f} m, "
          f"median RRE {sorted(e[1] for e in errors)[len(errors) // 2]:.3f} deg, "
          f"loops more than 2 m / 5 deg off: {sum(1 for e in errors if e[0] > 2 or e[1] > 5)}")

# The picture: both robots' paths and every loop (needs matplotlib; skipped without it).
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.exit(0)
fig, ax = plt.subplots(figsize=(7, 6), dpi=110)
for robot, colour in (("alpha", "tab:blue"), ("bravo", "tab:orange")):
    frames = sorted(int(r["frame"]) for rb, r in rows if rb == robot)
    ax.plot([poses[f][0][3] for f in frames], [poses[f][1][3] for f in frames], color=colour, lw=1.2,
            label=f"robot {robot} ({len(frames)} scans)")
for kind, colour in (("intra", "tab:green"), ("inter", "tab:red")):
    first = True
    for robot, r in rows:
        q = int(r["frame"])
        for loop in r["loops"]:
            if (loop["robot"] != robot) != (kind == "inter"):
                continue
            c = frame_of[loop["scan_id"]]
            ax.plot([poses[q][0][3], poses[c][0][3]], [poses[q][1][3], poses[c][1][3]], color=colour, lw=0.6,
                    alpha=0.5, label=f"{kind}-robot loops ({count[kind]})" if first else None)
            ax.scatter([poses[q][0][3]], [poses[q][1][3]], s=4, color=colour)
            first = False
ax.set_aspect("equal")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.set_title("scripts/demo.sh: loops the server found between and within two robots")
ax.legend(loc="best", fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(work, "demo.png"))
print(f"picture: {os.path.join(work, 'demo.png')}")
