#!/usr/bin/python3
"""tools/calibrate/fit.py: a monotone additive loop model from evidence.csv rows, in a file the engine loads.

Synthetic rows: a hypothesis is true with a probability that rises steeply with agreement (a step near 0.5)
and falls with translation; the other features are noise. The fitted curves must follow the features' signs,
separate the two sides of the step, be deterministic, and parse in the engine (sglc-pair --config with
verify.model), which refuses a curve that breaks monotonicity.
"""
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
FIT = os.path.join(HERE, "..", "..", "..", "tools", "calibrate", "fit.py")
NAMES = [("+", "landmarks"), ("+", "landmark_similarity"), ("+", "agreement"), ("+", "wide_agreement"), ("+", "pin"),
         ("+", "plane_overlap"), ("+", "plane_tightness"), ("+", "constraint"), ("+", "landmarks_x_agreement"),
         ("-", "translation"), ("~", "narrow"), ("+", "narrow_x_context"), ("~", "narrow_x_wide_agreement"),
         ("~", "overlay"), ("~", "consensus")]


def write_evidence(path, seed, n=3000):
    rng = np.random.default_rng(seed)
    with open(path, "w") as f:
        f.write("query,candidate,source,chosen,probability,true," + ",".join(f"x{s}{n}" for s, n in NAMES) + "\n")
        for i in range(n):
            x = {name: rng.uniform(0, 1) for _, name in NAMES}
            x["narrow"] = x["overlay"] = x["consensus"] = float(rng.integers(0, 2))
            z = 30 * (x["agreement"] - 0.5) - 2 * x["translation"]
            y = int(rng.uniform() < 1 / (1 + np.exp(-z)))
            f.write(f"{i},{i + 1},landmarks,1,0.5,{y}," + ",".join(f"{x[name]:.6f}" for _, name in NAMES) + "\n")


def curves(model):
    out = {}
    for line in open(model):
        w = line.split()
        if len(w) >= 2 and w[0] in {n for _, n in NAMES}:
            out[w[0]] = [tuple(map(float, k.split(":"))) for k in w[1:]] if ":" in w[1] else float(w[1])
    return out


def term(c, x):
    if isinstance(c, float):
        return c * x
    xs, ts = zip(*c)
    return float(np.interp(x, xs, ts))


def main():
    pair = sys.argv[1] if len(sys.argv) > 1 else None
    failures = []
    with tempfile.TemporaryDirectory() as root:
        ev = os.path.join(root, "evidence.csv")
        write_evidence(ev, 1)
        models = []
        for k in range(2):
            model = os.path.join(root, f"m{k}.txt")
            out = subprocess.run([sys.executable, FIT, "--version", "test-1", "--knots", "3", "--out", model, ev],
                                 capture_output=True, text=True)
            if out.returncode != 0:
                failures.append(f"fit.py failed: {out.stderr}")
                break
            models.append(open(model).read())
        if len(models) == 2:
            if models[0] != models[1]:
                failures.append("two fits of the same rows differ")
            c = curves(os.path.join(root, "m0.txt"))
            if sorted(c) != sorted(n for _, n in NAMES):
                failures.append(f"the model does not give every feature: {sorted(c)}")
            for sign, name in NAMES:
                if name not in c or sign == "~":
                    continue
                xs = np.linspace(-0.5, 1.5, 41)
                t = np.array([term(c[name], x) for x in xs])
                steps = np.diff(t) * (1 if sign == "+" else -1)
                if (steps < -1e-12).any():
                    failures.append(f"{name}'s curve is not monotone in its sign's direction: {c[name]}")
            a = c.get("agreement")
            if a is not None and not term(a, 0.6) - term(a, 0.4) > 4:
                failures.append(f"agreement's curve does not capture the step at 0.5: {a}")
            if isinstance(a, float):
                failures.append("agreement is fitted with one weight, not a curve")
            if "version test-1" not in models[0] or not models[0].count("sglc-loop-model 2"):
                failures.append("the model file lacks its header or version")
            if pair:
                cfg = os.path.join(root, "engine.yaml")
                with open(cfg, "w") as f:
                    f.write(f"verify: {{model: {os.path.join(root, 'm0.txt')}}}\n")
                out = subprocess.run([pair, "--config", cfg, "--dump-config"], capture_output=True, text=True)
                if out.returncode != 0:
                    failures.append(f"the engine refuses the fitted model: {out.stderr}")
                broken = re.sub(r"^agreement .*$", "agreement 0.9:5 1:0", models[0], flags=re.M)
                with open(os.path.join(root, "m0.txt"), "w") as f:
                    f.write(broken)
                out = subprocess.run([pair, "--config", cfg, "--dump-config"], capture_output=True, text=True)
                if out.returncode == 0 or "agreement" not in out.stderr:
                    failures.append(f"the engine accepted a falling agreement curve: {out.stderr}")
        bad = subprocess.run([sys.executable, FIT, "--version", "v", "--out", os.path.join(root, "x.txt"),
                              os.path.join(root, "missing.csv")], capture_output=True, text=True)
        if bad.returncode == 0:
            failures.append("a missing evidence file was not refused")
    for f in failures:
        print("FAIL:", f)
    if not failures:
        print("fit.py: ok")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
