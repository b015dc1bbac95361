#!/usr/bin/env python3
"""scripts/demo.sh's report: every loop the server found with its pose error against the simulator's ground truth;
then the pose graph's work (the trajectory error of the drifting odometry and of the server's optimised poses,
and the error at the end of the drive); and a picture of the three trajectories with the loops.

Usage: demo_report.py WORK_DIR SERVER_ADDRESS PYTHON_PACKAGE_DIR"""
import json
import math
import os
import sys
import time

work, server, package = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, package)
import numpy as np  # noqa: E402
import sglc  # noqa: E402


def read_poses(name):
    out = []
    with open(os.path.join(work, "seq", name)) as f:
        for line in f:
            v = [float(x) for x in line.split()]
            out.append([v[0:4], v[4:8], v[8:12], [0.0, 0.0, 0.0, 1.0]])
    return out


poses = read_poses("poses.txt")  # the truth (the simulator's calib.txt is the identity: LiDAR poses)
odometry = read_poses("odometry.txt")  # what the robots sent


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


# ---- The pose graph: wait for the server's solve of every scan and loop, then compare with the truth.
robots = ("alpha", "bravo")
with sglc.Client(server, timeout=120) as client:
    n_scans = len(frame_of)
    n_loops = len(client.loops("demo"))
    deadline = time.monotonic() + 300
    with client.watch("demo", timeout=300) as watch:
        for event in watch:  # the last solve of all of it; a global solve follows a local one within 2 s
            if event.nodes == n_scans and event.loops == n_loops and event.converged:
                break
            if time.monotonic() > deadline:
                sys.exit("demo: the pose graph did not solve every scan and loop within 300 s")
    time.sleep(3)  # the global solve (pose_graph.global_interval_s=2 in the demo)
    optimised = {r: client.poses("demo", r) for r in robots}
    _, summary = client.export("demo", out_dir=os.path.join(work, "graph"))


def xyz(T):
    return np.array([T[0][3], T[1][3], T[2][3]])


def ate(est, gt):
    """RMSE of positions after the best rigid alignment of est onto gt (Umeyama, no scale)."""
    a, b = np.array(est), np.array(gt)
    ma, mb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((b - mb).T @ (a - ma))
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return float(np.sqrt(np.mean(np.sum((b - (a - ma) @ R.T - mb) ** 2, axis=1))))


frames = {r: [p.seq for p in optimised[r]] for r in robots}
est = {r: [p.T[:3, 3] for p in optimised[r]] for r in robots}
all_frames = frames["alpha"] + frames["bravo"]
gt_all = [xyz(poses[f]) for f in all_frames]
odo_all = [xyz(odometry[f]) for f in all_frames]
opt_all = est["alpha"] + est["bravo"]
length = sum(np.linalg.norm(xyz(poses[b]) - xyz(poses[a])) for a, b in zip(all_frames, all_frames[1:]))
last = all_frames[-1]
end_odo = float(np.linalg.norm(xyz(odometry[last]) - xyz(poses[last])))
end_opt = float(np.linalg.norm(opt_all[-1] - xyz(poses[last])))
print(f"pose graph: {summary['nodes']} scans, {summary['loop_edges']} loops "
      f"(graph written to {os.path.join(work, 'graph')}/graph.g2o)")
print(f"trajectory error (ATE, both robots, {length / 1000:.2f} km): drifting odometry {ate(odo_all, gt_all):.2f} m "
      f"-> optimised {ate(opt_all, gt_all):.2f} m")
print(f"error at the end of the drive: drifting odometry {end_odo:.2f} m -> optimised {end_opt:.2f} m")

# The picture: the truth, the drifting odometry, the optimised trajectory and the loops (needs matplotlib).
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.exit(0)
fig, ax = plt.subplots(figsize=(7.5, 6.5), dpi=110)
g, o = np.array(gt_all), np.array(odo_all)
for robot, colour in (("alpha", "tab:blue"), ("bravo", "tab:orange")):
    k = [i for i, f in enumerate(all_frames) if (i < len(frames["alpha"])) == (robot == "alpha")]
    ax.plot(o[k, 0], o[k, 1], color=colour, lw=0.9, ls="--", alpha=0.6, label=f"{robot}: drifting odometry")
    e = np.array(est[robot])
    ax.plot(e[:, 0], e[:, 1], color=colour, lw=1.6, label=f"{robot}: optimised by the server")
ax.plot(g[:, 0], g[:, 1], color="black", lw=0.7, label="ground truth")
first = True
for robot, r in rows:
    for loop in r["loops"]:
        if loop["robot"] == robot:
            continue
        q, c = xyz(poses[int(r["frame"])]), xyz(poses[frame_of[loop["scan_id"]]])
        ax.plot([q[0], c[0]], [q[1], c[1]], color="tab:red", lw=0.4, alpha=0.35,
                label=f"inter-robot loops ({count['inter']})" if first else None)
        first = False
ax.set_aspect("equal")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.set_title(f"scripts/demo.sh: ATE {ate(odo_all, gt_all):.2f} m (odometry) -> {ate(opt_all, gt_all):.2f} m "
             f"(pose graph), end error {end_odo:.2f} -> {end_opt:.2f} m", fontsize=9)
ax.legend(loc="best", fontsize=7)
fig.tight_layout()
fig.savefig(os.path.join(work, "demo.png"))
print(f"picture: {os.path.join(work, 'demo.png')}")
