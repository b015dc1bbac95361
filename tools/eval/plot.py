#!/usr/bin/python3
"""Figures of an sglc-eval run: plot.py OUT_DIR.

Reads whichever of pr.csv, trajectory.csv and pose_errors.csv exist in OUT_DIR (and summary.json for the PR
title) and writes pr_curve.png, trajectory.png and pose_errors.png next to them; a figure whose input is absent
is skipped. Exits 1 on a malformed file, 2 on bad usage or a missing OUT_DIR.
"""
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


class Malformed(Exception):
    pass


def read_csv(path, header, types):
    """Rows of `path` as tuples converted by `types`; the header must be exactly `header`."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except (UnicodeDecodeError, csv.Error) as e:
        raise Malformed(f"{path}: {e}") from None
    if not rows or [c.strip() for c in rows[0]] != header:
        found = ",".join(rows[0]) if rows else "an empty file"
        raise Malformed(f"{path}: expected the header '{','.join(header)}', found '{found}'")
    out = []
    for n, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise Malformed(f"{path}: line {n}: {len(row)} fields, expected {len(header)}")
        try:
            out.append(tuple(t(v) for t, v in zip(types, row)))
        except ValueError as e:
            raise Malformed(f"{path}: line {n}: {e}") from None
    return out


def flag(v):
    if v.strip() not in ("0", "1"):
        raise ValueError(f"expected 0 or 1, found '{v}'")
    return v.strip() == "1"


def detection_kind(v):
    if v.strip() not in ("0", "1", "2"):
        raise ValueError(f"detection must be 0, 1 or 2, found '{v}'")
    return int(v)


def finite(v):
    x = float(v)
    if not math.isfinite(x):
        raise ValueError(f"non-finite value '{v}'")
    return x


def read_summary(out_dir):
    path = os.path.join(out_dir, "summary.json")
    if not os.path.exists(path):
        return {}
    try:
        with open(path) as f:
            summary = json.load(f)
    except ValueError as e:  # JSON or UTF-8 decoding
        raise Malformed(f"{path}: {e}") from None
    if not isinstance(summary, dict):
        raise Malformed(f"{path}: expected a JSON object")
    for key in ("f1max", "ep"):
        if key in summary and not isinstance(summary[key], (int, float)):
            raise Malformed(f"{path}: '{key}' is not a number")
    return summary


def plot_pr(out_dir, summary):
    path = os.path.join(out_dir, "pr.csv")
    rows = read_csv(path, ["threshold", "precision", "recall"], [float, finite, finite])
    for n, (_, p, r) in enumerate(rows, start=2):
        if not (0 <= p <= 1 and 0 <= r <= 1):
            raise Malformed(f"{path}: line {n}: precision and recall must lie in [0, 1]")
    fig, ax = plt.subplots(figsize=(6, 5))
    if rows:
        t, p, r = (np.array(c) for c in zip(*rows))
        ax.plot(r, p, color="tab:blue", lw=1.5, label="PR curve")
        f1 = np.divide(2 * p * r, p + r, out=np.zeros_like(p), where=(p + r) > 0)
        b = int(np.argmax(f1))
        ax.plot(r[b], p[b], "o", color="tab:red", label=f"F1max {f1[b]:.3f} (threshold {t[b]:.3g})")
        ax.legend(loc="lower left")
    else:
        ax.text(0.5, 0.5, "no points", ha="center", va="center", transform=ax.transAxes)
    ax.set(xlim=(0, 1.02), ylim=(0, 1.02), xlabel="recall", ylabel="precision")
    ax.grid(alpha=0.3)
    title = [str(summary.get("title", "Precision-recall"))]
    scores = [f"{name}={summary[key]:.3f}" for key, name in (("f1max", "F1max"), ("ep", "EP")) if key in summary]
    if scores:
        title.append(" ".join(scores))
    ax.set_title("\n".join(title), fontsize=10)
    return save(fig, out_dir, "pr_curve.png")


def plot_trajectory(out_dir):
    path = os.path.join(out_dir, "trajectory.csv")
    rows = read_csv(path, ["frame", "x", "y", "has_true_loop", "detection", "match_frame"],
                    [int, finite, finite, flag, detection_kind, int])
    where = {}
    for frame, x, y, *_ in rows:
        if frame in where:
            raise Malformed(f"{path}: frame {frame} appears twice")
        where[frame] = (x, y)
    for frame, _, _, _, kind, match in rows:
        if kind == 2 and match < 0:
            raise Malformed(f"{path}: frame {frame}: a false detection without a match_frame")

    def xy(select):
        pts = [(x, y) for (_, x, y, *rest) in rows if select(*rest)]
        return np.array(pts).reshape(-1, 2)

    true_det = xy(lambda has, kind, match: kind == 1)
    false_det = xy(lambda has, kind, match: kind == 2)
    missed = xy(lambda has, kind, match: has and kind != 1)
    links = [((x, y), where[m]) for (_, x, y, _, kind, m) in rows if kind == 2 and m in where]
    unknown = sum(1 for r in rows if r[4] == 2 and r[5] not in where)
    if unknown:
        print(f"plot.py: {path}: {unknown} false detection(s) matched a frame not in the file; drawn without a line",
              file=sys.stderr)

    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot([r[1] for r in rows], [r[2] for r in rows], color="0.6", lw=0.7, label=f"path ({len(rows)} frames)")
    for a, b in links:
        ax.plot([a[0], b[0]], [a[1], b[1]], color="tab:red", lw=0.6, alpha=0.7)
    ax.scatter(missed[:, 0], missed[:, 1], s=6, color="orange", zorder=3, label=f"missed loops ({len(missed)})")
    ax.scatter(false_det[:, 0], false_det[:, 1], s=14, color="tab:red", zorder=4,
               label=f"false loops ({len(false_det)})")
    ax.scatter(true_det[:, 0], true_det[:, 1], s=14, color="tab:green", zorder=5,
               label=f"true loops ({len(true_det)})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set(xlabel="x (m)", ylabel="y (m)", title="Loop detections")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    return save(fig, out_dir, "trajectory.png")


def plot_pose_errors(out_dir):
    path = os.path.join(out_dir, "pose_errors.csv")
    rows = read_csv(path, ["i", "j", "registered", "verified", "rte_m", "rre_deg"], [int, int, flag, flag, float, float])
    registered = [r for r in rows if r[2]]
    for r in registered:
        if not (math.isfinite(r[4]) and math.isfinite(r[5])):
            raise Malformed(f"{path}: pair {r[0]},{r[1]}: registered with a non-finite error")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for ax, col, name, unit in ((axes[0], 4, "RTE", "m"), (axes[1], 5, "RRE", "deg")):
        values = np.array([r[col] for r in registered])
        ax.set_title(f"{name}: {len(values)} registered of {len(rows)} pairs", fontsize=10)
        ax.set(xlabel=f"{name} ({unit})", ylabel="pairs")
        if len(values) == 0:
            ax.text(0.5, 0.5, "no registered pairs", ha="center", va="center", transform=ax.transAxes)
            continue
        bins = int(np.clip(np.sqrt(len(values)), 10, 60))
        ax.hist(values, bins=bins, color="tab:blue", alpha=0.8)
        med = float(np.median(values))
        ax.axvline(med, color="tab:red", ls="--", label=f"median {med:.3g} {unit}")
        ax.legend()
    fig.tight_layout()
    return save(fig, out_dir, "pose_errors.png")


def plot_slam(out_dir, summary):
    path = os.path.join(out_dir, "slam.csv")
    rows = read_csv(path, ["frame", "robot", "gt_x", "gt_y", "odom_x", "odom_y", "opt_x", "opt_y"],
                    [int, str, float, float, float, float, float, float])
    fig, ax = plt.subplots(figsize=(7.5, 7.5))
    robots = sorted({r[1] for r in rows})
    gt = np.array([[r[2], r[3]] for r in rows]) if rows else np.zeros((0, 2))
    ax.plot(gt[:, 0], gt[:, 1], ".", color="black", ms=2, label="ground truth")
    colours = ["tab:blue", "tab:green", "tab:purple", "tab:brown"]
    for k, robot in enumerate(robots):
        rr = np.array([[r[4], r[5], r[6], r[7]] for r in rows if r[1] == robot])
        c = colours[k % len(colours)]
        ax.plot(rr[:, 0], rr[:, 1], "--", color=c, lw=0.8, alpha=0.6, label=f"{robot} odometry (aligned)")
        ax.plot(rr[:, 2], rr[:, 3], "-", color=c, lw=1.2, label=f"{robot} optimised")
    title = "pose graph"
    if "ate_odometry" in summary and "ate_optimised" in summary:
        title += f": ATE {summary['ate_odometry']:.2f} m -> {summary['ate_optimised']:.2f} m"
    ax.set_title(title)
    ax.set(xlabel="x (m)", ylabel="y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save(fig, out_dir, "slam.png")


def save(fig, out_dir, name):
    path = os.path.join(out_dir, name)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path


def main(argv):
    if len(argv) != 2:
        print("usage: plot.py OUT_DIR", file=sys.stderr)
        return 2
    out_dir = argv[1]
    if not os.path.isdir(out_dir):
        print(f"plot.py: {out_dir}: no such directory", file=sys.stderr)
        return 2
    figures = (("pr.csv", lambda: plot_pr(out_dir, read_summary(out_dir))),
               ("trajectory.csv", lambda: plot_trajectory(out_dir)),
               ("pose_errors.csv", lambda: plot_pose_errors(out_dir)),
               ("slam.csv", lambda: plot_slam(out_dir, read_summary(out_dir))))
    try:
        for source, plot in figures:
            if os.path.exists(os.path.join(out_dir, source)):
                print(f"wrote {plot()}")
    except (Malformed, OSError) as e:
        print(f"plot.py: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
