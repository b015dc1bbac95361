#!/usr/bin/python3
"""Fits the loop model (core/include/sglc/loop_model.hpp) to evidence.csv files written by sglc-eval.

Each row of an evidence.csv is one pose hypothesis verification judged, with its model features (columns
x+NAME, x-NAME, x~NAME: the sign says the weight must be >= 0, <= 0, or either) and whether its pose is true
(column `true`). The fit is a logistic regression by Newton's method with a small L2 penalty (not on the bias);
a weight whose sign breaks its feature's monotonicity is held at 0 and the rest refitted, until none does
(an active set). Deterministic: the same files give the same model.

    tools/calibrate/fit.py --version NAME --out core/models/loop_model.txt RUN_DIR/*/evidence.csv

It also prints, over each query's top-1 answer (the hypothesis of highest probability), the precision and
recall at a list of thresholds, pooled and per file, and the smallest listed threshold at which every file's
precision is at least --precision: the default of verify.min_probability.
"""
import argparse
import csv
import sys

import numpy as np


def read(paths):
    names, signs, rows, labels, groups, chosen = None, None, [], [], [], []
    for k, path in enumerate(paths):
        with open(path, newline="") as f:
            reader = csv.reader(f)
            header = next(reader)
            cols = [i for i, h in enumerate(header) if h.startswith("x")]
            these = [header[i][2:] for i in cols]
            if names is None:
                names = these
                signs = [{"+": 1, "-": -1, "~": 0}[header[i][1]] for i in cols]
            elif these != names:
                sys.exit(f"{path}: its features {these} are not those of {paths[0]}")
            ti, qi, ci, pi = header.index("true"), header.index("query"), header.index("chosen"), header.index("probability")
            for r in reader:
                rows.append([float(r[i]) for i in cols])
                labels.append(int(r[ti]))
                groups.append((k, int(r[qi])))
                chosen.append(int(r[ci]))
    if not rows:
        sys.exit("no rows")
    return names, np.array(signs), np.array(rows), np.array(labels, dtype=float), groups, np.array(chosen)


def fit(X, y, signs, l2):
    n, d = X.shape
    A = np.hstack([np.ones((n, 1)), X])
    free = np.ones(d + 1, dtype=bool)
    while True:
        w = np.zeros(d + 1)
        idx = np.flatnonzero(free)
        for _ in range(100):
            z = A[:, idx] @ w[idx]
            p = 1.0 / (1.0 + np.exp(-z))
            g = A[:, idx].T @ (p - y)
            reg = np.full(len(idx), l2)
            reg[idx == 0] = 0.0
            g += reg * w[idx]
            H = (A[:, idx] * (p * (1 - p))[:, None]).T @ A[:, idx] + np.diag(reg + 1e-9)
            step = np.linalg.solve(H, g)
            w[idx] -= step
            if np.max(np.abs(step)) < 1e-10:
                break
        bad = [j for j in range(1, d + 1) if free[j] and signs[j - 1] * w[j] < 0]
        if not bad:
            return w
        # Hold the most wrongly signed weight at 0 and refit.
        worst = max(bad, key=lambda j: abs(w[j]))
        free[worst] = False


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("evidence", nargs="+")
    ap.add_argument("--version", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--l2", type=float, default=1.0)
    ap.add_argument("--precision", type=float, default=0.99)
    a = ap.parse_args()
    names, signs, X, y, groups, chosen = read(a.evidence)
    w = fit(X, y, signs, a.l2)
    p = 1.0 / (1.0 + np.exp(-(w[0] + X @ w[1:])))
    loss = -np.mean(y * np.log(np.maximum(p, 1e-12)) + (1 - y) * np.log(np.maximum(1 - p, 1e-12)))
    print(f"{len(y)} hypotheses, {int(y.sum())} true; log loss {loss:.4f}")
    # Each query's top-1 answer under the fitted model: the hypothesis of highest probability.
    best = {}
    for i, g in enumerate(groups):
        if g not in best or p[i] > p[best[g]]:
            best[g] = i
    top = np.array(sorted(best.values()))
    queries_true = {g for i, g in enumerate(groups) if y[i] > 0}
    print(f"{len(best)} queries with a hypothesis, {len(queries_true)} with a true one")
    files = sorted({g[0] for g in best})
    top_file = np.array([groups[i][0] for i in top])
    true_per_file = {k: len({g for g in queries_true if g[0] == k}) for k in files}
    print("threshold  answered  precision  recall  | worst file's precision (file)")
    chosen_thr = None
    for t in [0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.97, 0.98, 0.99]:
        keep = p[top] >= t
        sel = top[keep]
        prec = y[sel].mean() if len(sel) else 1.0
        rec = y[sel].sum() / max(1, len(queries_true))
        worst, worst_k = 1.0, None
        for k in files:
            s = top[keep & (top_file == k)]
            if len(s) and y[s].mean() < worst:
                worst, worst_k = y[s].mean(), k
        print(f"{t:9.2f}  {len(sel):8d}  {prec:9.4f}  {rec:6.4f}  | {worst:.4f} ({a.evidence[worst_k] if worst_k is not None else '-'})")
        if chosen_thr is None and worst >= a.precision:
            chosen_thr = t
    print(f"smallest listed threshold with every file's top-1 precision >= {a.precision}: {chosen_thr}")
    for k in files:
        s = top[top_file == k]
        print(f"  {a.evidence[k]}: {len(s)} queries with a hypothesis, {true_per_file[k]} with a true one")
    with open(a.out, "w") as f:
        f.write("# The loop model (sglc/loop_model.hpp): p(true loop) = 1 / (1 + exp(-(bias + sum of weight x feature))).\n")
        f.write("# Fitted by tools/calibrate/fit.py (logistic regression, L2 %.3g, monotone signs) from %d hypotheses\n"
                % (a.l2, len(y)))
        f.write("# (%d with a true pose) in %d evidence.csv files: scripts/calibrate.sh.\n" % (int(y.sum()), len(a.evidence)))
        f.write("sglc-loop-model 1\n")
        f.write(f"version {a.version}\n")
        f.write(f"bias {w[0]:.6g}\n")
        for name, wj in zip(names, w[1:]):
            f.write(f"{name} {0.0 if wj == 0 else wj:.6g}\n")


if __name__ == "__main__":
    main()
