#!/usr/bin/python3
"""Fits the loop model (core/include/sglc/loop_model.hpp) to evidence.csv files written by sglc-eval.

Each row of an evidence.csv is one pose hypothesis verification judged, with its model features (columns
x+NAME, x-NAME, x~NAME: the sign says the weight must be >= 0, <= 0, or either) and whether its pose is true
(column `true`). The model is additive: each monotone feature's term is a piecewise-linear curve through knots
at quantiles of its values (--knots segments over the true rows, plus the median, 90th and 99th percentile of
all rows), written as a sum of ramps (0 below a segment, 1 above it) whose weights take the feature's sign, so
the curve is monotone; a feature of either sign, or one with two values, keeps one weight. The fit is a
logistic regression by Newton's method with a small L2 penalty (not on the bias); a weight whose sign breaks
its feature's monotonicity is held at 0 and the rest refitted, until none does (an active set). Deterministic:
the same files give the same model.

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


def knots_of(X, y, signs, segments):
    """Each feature's knots (None: one linear weight)."""
    knots = []
    for j in range(X.shape[1]):
        v = X[:, j]
        if segments == 0 or signs[j] == 0 or len(np.unique(v)) <= 2:
            knots.append(None)
            continue
        qs = np.concatenate([np.percentile(v[y > 0], np.linspace(0, 100, segments + 1)), np.percentile(v, [50, 90, 99])])
        k = np.unique(np.round(qs, 4))
        knots.append(k if len(k) >= 2 else None)
    return knots


def expand(X, knots):
    """The basis: a feature's value where it is linear, else one ramp per segment between its knots."""
    cols, owner = [], []
    for j, k in enumerate(knots):
        if k is None:
            cols.append(X[:, j])
            owner.append(j)
            continue
        for a, b in zip(k[:-1], k[1:]):
            cols.append(np.clip((X[:, j] - a) / (b - a), 0.0, 1.0))
            owner.append(j)
    return np.array(cols).T, np.array(owner)


def curve_text(name, knots, w):
    """A feature's model line: its weight, or its curve's knots X:T (T: the term at X)."""
    if knots is None:
        return f"{name} {0.0 if w[0] == 0 else w[0]:.6g}"
    terms = np.concatenate([[0.0], np.cumsum(w)])
    # Knots inside a flat stretch say nothing: keep the ends of every stretch.
    keep = [i for i in range(len(knots)) if i in (0, len(knots) - 1) or not (terms[i - 1] == terms[i] == terms[i + 1])]
    return name + " " + " ".join(f"{knots[i]:.6g}:{0.0 if terms[i] == 0 else terms[i]:.6g}" for i in keep)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("evidence", nargs="+")
    ap.add_argument("--version", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--l2", type=float, default=1.0)
    ap.add_argument("--precision", type=float, default=0.99)
    ap.add_argument("--knots", type=int, default=0, help="segments per monotone feature's curve (0: one weight)")
    a = ap.parse_args()
    names, signs, X, y, groups, chosen = read(a.evidence)
    knots = knots_of(X, y, signs, a.knots)
    B, owner = expand(X, knots)
    w = fit(B, y, signs[owner], a.l2)
    p = 1.0 / (1.0 + np.exp(-(w[0] + B @ w[1:])))
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
        f.write("# The loop model (sglc/loop_model.hpp): p(true loop) = 1 / (1 + exp(-(bias + sum of each feature's\n")
        f.write("# term))); a term is weight x value, or linear between knots X:T and constant beyond them.\n")
        shape = f"{a.knots} segments per curve" if a.knots else "one weight per feature"
        f.write("# Fitted by tools/calibrate/fit.py (logistic, %s, L2 %.3g, monotone) from %d hypotheses\n"
                % (shape, a.l2, len(y)))
        f.write("# (%d with a true pose) in %d evidence.csv files: scripts/calibrate.sh.\n" % (int(y.sum()), len(a.evidence)))
        f.write("sglc-loop-model 2\n")
        f.write(f"version {a.version}\n")
        f.write(f"bias {w[0]:.6g}\n")
        for j, name in enumerate(names):
            f.write(curve_text(name, knots[j], w[1:][owner == j]) + "\n")


if __name__ == "__main__":
    main()
