#!/usr/bin/env python3
"""tools/eval/field_md.py: the "Field conditions" section of docs/RESULTS.md from scripts/field.sh's runs.

Builds a small runs directory by hand and checks the rows, the marking of missed targets, a relocalization
run that verified nothing, and the splice into a results file (replaced in place, the rest untouched).
"""
import json
import os
import subprocess
import sys
import tempfile

FIELD_MD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "tools", "eval", "field_md.py")


def write_run(root, name, summary, info):
    os.makedirs(os.path.join(root, name))
    with open(os.path.join(root, name, "summary.json"), "w") as f:
        json.dump(summary, f)
    with open(os.path.join(root, name, "sim_info.json"), "w") as f:
        json.dump(info, f)


def sequence_summary(f1, precision, true, false):
    return {"queries": 100, "f1max": f1, "ep": 0.9, "recall_at_1": 0.8, "precision_all_verified": precision,
            "verified_true": true, "verified_false": false, "rr": 1.0, "rte_median": 0.004, "rre_median": 0.03}


def reloc_summary(recall, true, false, candidates):
    answered = true + false > 0
    return {"queries": 50, "queries_with_true_place": 48, "recall_at_1": recall, "precision": 1.0 if answered else 0.0,
            "precision_all_verified": true / (true + false) if answered else None, "verified_true": true,
            "verified_false": false, "registered": true, "rte_median": 0.005, "rre_median": 0.04,
            "candidates": candidates}


def run(*args):
    out = subprocess.run([sys.executable, FIELD_MD, *args], capture_output=True, text=True)
    if out.returncode != 0:
        raise AssertionError(f"field_md.py {args} exited {out.returncode}: {out.stderr}")
    return out.stdout


def main():
    failures = []

    def check(cond, what):
        if not cond:
            failures.append(what)

    with tempfile.TemporaryDirectory() as root:
        info = {"seed": 11, "label_miou": 0.621}
        write_run(root, "sequence-00", sequence_summary(0.951, 0.997, 674, 2), info)
        write_run(root, "sequence-05", sequence_summary(0.912, 0.975, 300, 8), info)
        write_run(root, "reloc-epoch1-00", reloc_summary(0.794, 451, 0, 100), info)
        write_run(root, "sensor-rosette-00", reloc_summary(0.0, 0, 0, 100), {"seed": 11})
        os.makedirs(os.path.join(root, "not-a-run"))  # no summary.json: ignored

        section = run(root)
        lines = section.split("\n")
        row00 = next((l for l in lines if l.startswith("| 00 | realistic |")), "")
        row05 = next((l for l in lines if l.startswith("| 05 | realistic |")), "")
        check("| 0.951 |" in row00 and "**" not in row00, f"a met target is not bold: {row00!r}")
        check("| **0.912** |" in row05, f"F1max under 0.95 is bold: {row05!r}")
        check("**0.975** (300 / 8)" in row05, f"precision under 0.99 is bold, with its counts: {row05!r}")
        check(row00.rstrip().endswith("| - |"), f"no calibration in the summary: no ECE: {row00!r}")
        check("| 11 | 100 | 0.621 |" in row00, f"seed, queries and label mIoU: {row00!r}")
        day = next((l for l in lines if l.startswith("| one day later")), "")
        check("| 100 | **0.794** |" in day, f"candidates, then Recall@1 under 0.92 in bold: {day!r}")
        check(day.startswith("| one day later, HDL-64 | 00 | 11 |"), f"the map's path and the seed: {day!r}")
        check("1.000 (451 / 0)" in day, f"precision of every verified top-1 with counts: {day!r}")
        rosette = next((l for l in lines if l.startswith("| rosette")), "")
        check("nothing verified" in rosette and rosette.rstrip().endswith("| - | - | - |"),
              f"a run that verified nothing has no precision or pose figures: {rosette!r}")
        check(lines[0].startswith("<!-- field results: begin") and "<!-- field results: end -->" in lines,
              "the section is between its markers")
        check(not any(l.startswith("| 30 days") for l in lines), "absent runs give no rows")

        results = os.path.join(root, "RESULTS.md")
        head, tail = "# Results\n\nIntro.\n", "## Pair protocol\n\ntable\n"
        with open(results, "w") as f:
            f.write(head + "\n" + tail)
        first = run("--splice", results, root)
        check(first.startswith(head) and first.endswith(tail), "put before the first section, the rest kept")
        check(first.index("## Field conditions") < first.index("## Pair protocol"), "the section comes first")
        with open(results, "w") as f:
            f.write(first)
        check(run("--splice", results, root) == first, "splicing the same runs again changes nothing")
        write_run(root, "reloc-epoch30-00", reloc_summary(0.604, 343, 0, 100), info)
        second = run("--splice", results, root)
        check(second.count("## Field conditions") == 1 and "| 30 days later" in second,
              "a new run replaces the section in place")
        check(second.startswith(head) and second.endswith(tail), "replacing keeps the rest byte for byte")
        with open(results, "w") as f:
            f.write(first.replace("<!-- field results: end -->\n", ""))
        broken = subprocess.run([sys.executable, FIELD_MD, "--splice", results, root], capture_output=True, text=True)
        check(broken.returncode != 0 and "missing" in broken.stderr, "a file with one marker is refused")

    # The reliability table pools the runs' calibration bins: 10 answers at 0.05 with 1 true and 30 at 0.95 with
    # 27 true in one run, 10 more at 0.95 with 10 true in another.
    def calibrated(bins):
        c = [{"low": k / 10, "answers": 0, "mean_predicted": 0.0, "observed_true": 0.0} for k in range(10)]
        for k, n, pred, obs in bins:
            c[k] = {"low": k / 10, "answers": n, "mean_predicted": pred, "observed_true": obs}
        return {"calibration": {"answers": sum(b[1] for b in bins), "ece": 0.0, "bins": c}}

    with tempfile.TemporaryDirectory() as root:
        write_run(root, "sequence-07", calibrated([(0, 10, 0.05, 0.1), (9, 30, 0.95, 0.9)]), {})
        write_run(root, "sequence-09", calibrated([(9, 10, 0.95, 1.0)]), {})
        write_run(root, "no-calibration", {"queries": 1}, {})
        table = run("--reliability", root)
        check("Pooled over 2 runs" in table and "50 answers" in table, f"pools the runs with a calibration: {table!r}")
        check("| 0.9-1.0 | 40 | 0.950 | 0.925 |" in table, f"pooled bin: {table!r}")
        # ECE = 10/50 x |0.05 - 0.1| + 40/50 x |0.95 - 0.925| = 0.01 + 0.02
        check("ECE 0.0300." in table, f"pooled ECE: {table!r}")

    for f in failures:
        print("FAIL:", f)
    print(f"field_md: {len(failures)} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
