#!/usr/bin/python3
"""Reference poses for nearby scan pairs of a sequence by dense point-to-plane ICP.

Recorded trajectories are not always exact at the scale of a loop pose (nuScenes' ego poses are 0.1-0.4 m off
for scans 4-9 m apart); a dense registration of the full scans, started from the recorded poses, is a better
reference. Writes 'i j T' rows (T: 3x4 row-major, maps scan i into scan j, as sglc-eval --gt-from-pairs reads)
for every pair at the given gaps, and prints how far the recorded poses are from it.

  tools/eval/dense_reference.py SEQUENCE_DIR --gaps 1,2 --out pairs.txt
SEQUENCE_DIR holds velodyne/NNNNNN.bin and poses.txt (LiDAR poses, 12 numbers per line).
"""
import argparse
import os
import sys

import numpy as np
from scipy.spatial import cKDTree


def load_scan(directory, frame, min_range=3.0, max_range=60.0):
    raw = np.fromfile(os.path.join(directory, "velodyne", "%06d.bin" % frame), dtype=np.float32)
    if raw.size % 4:
        sys.exit("%06d.bin: not a multiple of 16 bytes" % frame)
    pts = raw.reshape(-1, 4)[:, :3].astype(np.float64)
    r = np.linalg.norm(pts[:, :2], axis=1)
    return pts[(r > min_range) & (r < max_range)]


def normals(points, tree, k=10):
    _, nn = tree.query(points, k=k)
    nb = points[nn] - points[nn].mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    return vecs[:, :, 0]


def icp(source, target, start, iterations=30):
    """Point-to-plane ICP: the 4x4 transform mapping source into target, and the median residual (m)."""
    tree = cKDTree(target)
    n = normals(target, tree)
    T = start.copy()
    for it in range(iterations):
        moved = source @ T[:3, :3].T + T[:3, 3]
        d, j = tree.query(moved)
        keep = d < (1.0 if it < 10 else 0.3)
        p, q, nq = moved[keep], target[j[keep]], n[j[keep]]
        A = np.hstack([np.cross(p, nq), nq])
        b = np.einsum("ij,ij->i", q - p, nq)
        x = np.linalg.lstsq(A, b, rcond=None)[0]
        a, c, g = x[:3]
        u, _, vt = np.linalg.svd(np.array([[1, -g, c], [g, 1, -a], [-c, a, 1]]))
        step = np.eye(4)
        step[:3, :3] = u @ vt
        step[:3, 3] = x[3:]
        T = step @ T
    d, _ = tree.query(source @ T[:3, :3].T + T[:3, 3])
    return T, float(np.median(d[d < 0.5]))


def pose_error(a, b):
    e = np.linalg.inv(a) @ b
    angle = np.degrees(np.arccos(np.clip((np.trace(e[:3, :3]) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(e[:3, 3])), float(angle)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence")
    ap.add_argument("--gaps", default="1,2", help="frame gaps of the pairs (default 1,2)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    poses_path = os.path.join(args.sequence, "poses.txt")
    if not os.path.isfile(poses_path):
        sys.exit(f"{poses_path}: missing (12 numbers per line: LiDAR poses)")
    rows = np.loadtxt(poses_path, ndmin=2)
    if rows.shape[1] != 12 or not np.isfinite(rows).all():
        sys.exit(f"{poses_path}: need 12 finite numbers per line, got {rows.shape[1]}")
    rows = rows.reshape(-1, 3, 4)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = rows
    try:
        gaps = [int(g) for g in args.gaps.split(",")]
    except ValueError:
        sys.exit(f"--gaps: comma-separated positive integers, got '{args.gaps}'")
    if any(g < 1 for g in gaps):
        sys.exit("--gaps: each gap must be at least 1")
    with open(args.out, "w") as out:
        for gap in gaps:
            errors = []
            for i in range(len(poses) - gap):
                j = i + gap
                recorded = np.linalg.inv(poses[j]) @ poses[i]  # maps i into j
                T, residual = icp(load_scan(args.sequence, i), load_scan(args.sequence, j), recorded)
                errors.append(pose_error(recorded, T))
                out.write("%d %d %s\n" % (i, j, " ".join("%.9f" % v for v in T[:3].ravel())))
                print("%2d %2d  residual %.3f m  recorded vs dense %.3f m %.3f deg" % (i, j, residual, *errors[-1]))
            e = np.array(errors)
            print("gap %d: %d pairs, recorded poses vs dense registration: median %.3f m %.3f deg, max %.3f m %.3f deg"
                  % (gap, len(e), np.median(e[:, 0]), np.median(e[:, 1]), e[:, 0].max(), e[:, 1].max()))


if __name__ == "__main__":
    main()
