#!/usr/bin/env python3
"""A field run's figures at a higher verify.min_probability than it ran with, from its CSV files.

    at_threshold.py THRESHOLD RUN_DIR...

A candidate is verified when its probability (the score) reaches the bar and answers are ordered verified first,
then by probability: so at a higher bar a query's top-1 answer is the one it had, when that reaches the new bar,
and none otherwise. That makes the precision of every verified top-1 and relocalization's Recall@1 exact from
top1.csv / relocalization.csv, and the sequence protocol's F1max the best F1 of pr.csv's points at or above the
bar. Prints one markdown row per run.
"""
import csv
import json
import os
import sys


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    bar = float(sys.argv[1])
    print(f"| run | F1max | Recall@1 | precision, every verified top-1 (true / false) |")
    print("|---|---|---|---|")
    for run in sys.argv[2:]:
        name = os.path.basename(os.path.normpath(run))
        s = json.load(open(os.path.join(run, "summary.json")))
        if s.get("protocol") == "relocalization" or os.path.exists(os.path.join(run, "relocalization.csv")):
            answers = [r for r in rows(os.path.join(run, "relocalization.csv")) if r["outcome"] in ("true", "false")]
            f1 = "-"
            with_place = s["queries_with_true_place"]
        else:
            answers = [r for r in rows(os.path.join(run, "top1.csv")) if r["outcome"] in ("true", "false")]
            curve = [r for r in rows(os.path.join(run, "pr.csv")) if float(r["threshold"]) >= bar]
            best = max((2 * float(r["precision"]) * float(r["recall"]) / (float(r["precision"]) + float(r["recall"]))
                        for r in curve if float(r["precision"]) + float(r["recall"]) > 0), default=0.0)
            f1 = f"{best:.3f}"
            with_place = None
        kept = [r for r in answers if float(r["score"]) >= bar]
        true = sum(r["outcome"] == "true" for r in kept)
        false = len(kept) - true
        precision = f"{true / len(kept):.3f}" if kept else "-"
        recall = f"{true / with_place:.3f}" if with_place else "-"
        print(f"| {name} | {f1} | {recall} | {precision} ({true} / {false}) |")


if __name__ == "__main__":
    main()
