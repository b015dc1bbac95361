#!/usr/bin/env python3
"""Realism check of the LiDAR simulator against real labelled KITTI scans (tools/sim/README.md).

Simulates KITTI 00 at the pose of a real SemanticKITTI scan, computes the same statistics for both with
sglc-sim-stats (points per class, ranges, the engine's clustered landmarks, descriptor occupancy), prints
Markdown tables, and draws a bird's-eye view of each, coloured by class.

  /usr/bin/python3 tools/sim/realism.py --bin build/bin --data ../shared/data --out tools/sim/docs

Table 1 compares one simulated frame with the real scan at the same pose. Table 2 compares medians over
several seeds and poses (simulated) with the real scans available (real), so that one lucky or unlucky
frame does not decide the picture.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

import numpy as np

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

# Display colours per SemanticKITTI raw class (our own palette).
CLASSES = {
    0: ("unlabelled", "#404040"), 1: ("outlier", "#404040"), 10: ("car", "#2f6fff"), 11: ("bicycle", "#8a5cff"),
    18: ("truck", "#1c3fa8"), 20: ("other-vehicle", "#5f8fff"), 30: ("person", "#ff4040"),
    40: ("road", "#d050d0"), 44: ("parking", "#ff9cff"), 48: ("sidewalk", "#8a3a8a"), 49: ("other-ground", "#5a1a5a"),
    50: ("building", "#ffc800"), 51: ("fence", "#ff7830"), 52: ("other-structure", "#e09000"),
    60: ("lane-marking", "#ffffff"), 70: ("vegetation", "#00a000"), 71: ("trunk", "#8b4513"),
    72: ("terrain", "#a0d050"), 80: ("pole", "#fff0a0"), 81: ("traffic-sign", "#ff0000"),
    99: ("other-object", "#a0a0a0"),
}
MOVING = ("moving", "#ff00ff")
GROUPS = [
    ("road + parking", [40, 44]), ("sidewalk + other-ground", [48, 49]), ("terrain", [72]), ("building", [50]),
    ("fence", [51]), ("vegetation", [70]), ("trunk", [71]), ("pole", [80]), ("traffic-sign", [81]),
    ("car / truck / other-vehicle", [10, 18, 20]), ("moving (252-259)", list(range(252, 260))),
    ("other (0, 1, 52, 99, ...)", None),
]


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"realism.py: {' '.join(cmd)} failed:\n{p.stderr}")
    return p.stdout


def simulate(args, seed, frames, out):
    run([os.path.join(args.bin, "sglc-sim"), "--poses", args.poses, "--calib", args.calib, "--frames",
         ",".join(str(f) for f in frames), "--seed", str(seed), "--out", out, "--quiet"])
    return [(os.path.join(out, "velodyne", f"{k:06d}.bin"), os.path.join(out, "labels", f"{k:06d}.label"))
            for k in range(len(frames))]


def stats(args, scans):
    """scans: list of (name, bin, label) -> (per-scan dict by name, descriptor distances)."""
    out = json.loads(run([os.path.join(args.bin, "sglc-sim-stats")] + [f"{n}={b}:{l}" for n, b, l in scans]))
    return {s["name"]: s for s in out["scans"]}, out["descriptor_distance"]


def group_counts(s):
    classes = {int(k): v for k, v in s["classes"].items()}
    counted, out = set(), []
    for _, ids in GROUPS:
        if ids is None:
            out.append(sum(v for k, v in classes.items() if k not in counted))
        else:
            out.append(sum(classes.get(i, 0) for i in ids))
            counted.update(ids)
    return out


def rows(s):
    """Named numeric rows of one scan's statistics."""
    r = [("points", s["points"])]
    r += [(f"points: {name}", v) for (name, _), v in zip(GROUPS, group_counts(s))]
    edges = [0, 5, 10, 20, 30, 40, 50, 60, 80]
    for k, v in enumerate(s["range_hist"][:8]):
        r.append((f"range {edges[k]}-{edges[k + 1]} m", v))
    r.append(("median range (m)", round(s["range_median_m"], 1)))
    for cls in ("vehicle", "trunk", "pole"):
        r.append((f"clustered {cls}s (engine nodes)", s["nodes"].get(cls, 0)))
    for cls in ("vehicle", "trunk", "pole"):
        size = s["node_mean_size_lwh"].get(cls)
        r.append((f"mean {cls} box l x w x h (m)", "-" if size is None else " x ".join(f"{x:.1f}" for x in size)))
    r.append(("graph edges (< 60 m)", s["graph_edges"]))
    r.append(("plane features", s["planes"]))
    r.append(("background BEV cells", s["background_cells"]))
    d = s["descriptor"]
    r.append(("scan descriptor: non-zero foreground bins", f"{d['foreground_nonzero']} / {d['foreground_dims']}"))
    r.append(("scan descriptor: non-zero background bins", f"{d['background_nonzero']} / {d['background_dims']}"))
    inten = {int(k): v for k, v in s["intensity_mean_per_class"].items()}
    for cls in (40, 50, 70, 10):
        if cls in inten:
            r.append((f"mean intensity: {CLASSES[cls][0]}", round(inten[cls], 2)))
    return r


def markdown(header, columns):
    names = [n for n, _ in columns[0]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for i, n in enumerate(names):
        lines.append("| " + n + " | " + " | ".join(str(c[i][1]) for c in columns) + " |")
    return "\n".join(lines)


def median_rows(scan_stats):
    per = [rows(s) for s in scan_stats]
    out = []
    for i, (name, _) in enumerate(per[0]):
        vals = [p[i][1] for p in per]
        if all(isinstance(v, (int, float)) for v in vals):
            med = statistics.median(vals)
            if all(isinstance(v, int) for v in vals):
                shown = f"{med:.0f}" if med > 20 else f"{med:g}"
                out.append((name, f"{shown} ({min(vals)}..{max(vals)})"))
            else:
                digits = 1 if max(vals) > 1.5 else 2
                out.append((name, f"{med:.{digits}f} ({min(vals):.{digits}f}..{max(vals):.{digits}f})"))
    return out


def bev(bin_path, label_path, title, png):
    pts = np.fromfile(bin_path, dtype=np.float32).reshape(-1, 4)
    lab = np.fromfile(label_path, dtype=np.uint32) & 0xFFFF
    keep = (np.abs(pts[:, 0]) < 40) & (np.abs(pts[:, 1]) < 40)
    pts, lab = pts[keep], lab[keep]
    colours = np.array([CLASSES.get(int(c), MOVING if c >= 252 else ("?", "#808080"))[1] for c in lab])
    order = np.argsort(pts[:, 2])  # higher points drawn last
    fig, ax = plt.subplots(figsize=(6.2, 6.2), dpi=100)
    ax.set_facecolor("black")
    ax.scatter(pts[order, 0], pts[order, 1], s=0.35, c=colours[order], linewidths=0, rasterized=True)
    ax.set_xlim(-40, 40)
    ax.set_ylim(-40, 40)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, forward)")
    ax.set_ylabel("y (m, left)")
    ax.set_title(title, fontsize=10)
    present = sorted(set(int(c) for c in lab))
    handles, seen = [], set()
    for c in present:
        name, col = CLASSES.get(c, MOVING if c >= 252 else ("other", "#808080"))
        if name in seen:
            continue
        seen.add(name)
        handles.append(Line2D([], [], marker="s", linestyle="", color=col, label=name, markersize=5))
    ax.legend(handles=handles, loc="upper left", fontsize=6, ncol=2, framealpha=0.6)
    fig.tight_layout()
    fig.savefig(png, dpi=100)
    plt.close(fig)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", default=os.path.join(here, "..", "..", "build", "bin"),
                    help="folder with sglc-sim and sglc-sim-stats")
    ap.add_argument("--data", default=os.path.join(here, "..", "..", "..", "shared", "data"),
                    help="shared data folder")
    ap.add_argument("--frame", type=int, default=52,
                    help="KITTI 00 frame with a real labelled scan (52, 88, 850, 4501)")
    ap.add_argument("--seed", type=int, default=3, help="world seed of the single-frame comparison")
    ap.add_argument("--seeds", default="2,3,5,7", help="seeds of the median comparison")
    ap.add_argument("--out", default=os.path.join(here, "docs"), help="where the PNGs go")
    args = ap.parse_args()
    seq = os.path.join(args.data, "semantickitti_scans", "sequences", "00")
    args.poses = os.path.join(args.data, "kitti_odometry_gt_poses", "poses", "00.txt")
    args.calib = os.path.join(seq, "calib.txt")
    for path in (args.poses, args.calib, os.path.join(seq, "velodyne", f"{args.frame:06d}.bin")):
        if not os.path.exists(path):
            sys.exit(f"realism.py: {path} not found (--data points at the shared data)")
    os.makedirs(args.out, exist_ok=True)
    real_frames = [f for f in (52, 88, 850, 4501) if os.path.exists(os.path.join(seq, "velodyne", f"{f:06d}.bin"))]

    with tempfile.TemporaryDirectory() as tmp:
        # 1. One simulated frame against the real scan at the same pose.
        (sim_bin, sim_label), = simulate(args, args.seed, [args.frame], os.path.join(tmp, "one"))
        real_bin = os.path.join(seq, "velodyne", f"{args.frame:06d}.bin")
        real_label = os.path.join(seq, "labels", f"{args.frame:06d}.label")
        one, dist = stats(args, [("sim", sim_bin, sim_label), ("real", real_bin, real_label)])
        print(f"## One frame: KITTI 00 frame {args.frame}, simulated (seed {args.seed}) vs real\n")
        print(markdown(["", f"simulated (seed {args.seed})", f"real 00/{args.frame:06d}"],
                       [rows(one["sim"]), rows(one["real"])]))
        print("\nScan-descriptor L2 distance (the engine's retrieval distance) simulated vs real: "
              f"{dist['sim vs real']:.2f}\n")
        bev(sim_bin, sim_label, f"simulated: KITTI 00 pose {args.frame}, seed {args.seed} (HDL-64 preset)",
            os.path.join(args.out, "bev_sim.png"))
        bev(real_bin, real_label, f"real: KITTI 00 scan {args.frame:06d} (SemanticKITTI labels)",
            os.path.join(args.out, "bev_real.png"))

        # 2. Medians over seeds x real poses against all real scans.
        scans = []
        for seed in [int(s) for s in args.seeds.split(",")]:
            for (b, l), f in zip(simulate(args, seed, real_frames, os.path.join(tmp, f"s{seed}")), real_frames):
                scans.append((f"sim{seed}.{f}", b, l))
        for f in real_frames:
            scans.append((f"real.{f}", os.path.join(seq, "velodyne", f"{f:06d}.bin"),
                          os.path.join(seq, "labels", f"{f:06d}.label")))
        many, dist = stats(args, scans)
        sim_stats = [s for n, s in many.items() if n.startswith("sim")]
        real_stats = [s for n, s in many.items() if n.startswith("real")]
        print(f"## Medians (min..max): {len(sim_stats)} simulated frames (seeds {args.seeds} at KITTI 00 poses "
              f"{', '.join(map(str, real_frames))}) vs {len(real_stats)} real scans\n")
        print(markdown(["", "simulated", "real"], [median_rows(sim_stats), median_rows(real_stats)]))

        def dists(a, b):
            return [v for k, v in dist.items() if (k.startswith(a) and k.split(" vs ")[1].startswith(b)) or
                    (k.startswith(b) and k.split(" vs ")[1].startswith(a))]
        ss, sr, rr = dists("sim", "sim"), dists("sim", "real"), dists("real", "real")
        def summary(v):
            return f"{statistics.median(v):.2f} ({min(v):.2f}..{max(v):.2f})"
        print(f"\nScan-descriptor L2 distance, median (min..max): simulated-simulated {summary(ss)}, "
              f"simulated-real {summary(sr)}, real-real {summary(rr)}")
    for png in ("bev_sim.png", "bev_real.png"):
        print(f"\nwrote {os.path.join(args.out, png)} ({os.path.getsize(os.path.join(args.out, png)) // 1024} KB)",
              file=sys.stderr)


if __name__ == "__main__":
    main()
