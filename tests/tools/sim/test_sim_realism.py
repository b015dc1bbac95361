#!/usr/bin/env python3
"""Quick test of tools/sim/realism.py: per-sensor tables with finite, plausible numbers.

Usage: test_sim_realism.py BIN_DIR SHARED_DATA_DIR REALISM_PY. Runs the script with --quick (2-3 frames per
sensor, one seed). A sensor whose real data is absent from SHARED_DATA_DIR must be skipped with a message;
the checks of its numbers are then skipped too (said on stdout).
"""
import json
import math
import os
import subprocess
import sys
import tempfile

bin_dir, data, script = sys.argv[1], sys.argv[2], sys.argv[3]
failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def realism(*args):
    return subprocess.run(["/usr/bin/python3", script, "--bin", bin_dir, *args], capture_output=True, text=True,
                          timeout=300)


# Plausible medians per sensor: (statistic, low, high) for the simulated columns and the real one.
# The class shares also catch a broken label mapping (e.g. road read as unlabelled).
SHARES = {"% ground / road": (10, 70), "% building / manmade": (5, 60), "% other (unlabelled, other-object)": (0, 15)}
PLAUSIBLE = {
    "hdl64": {"points per frame": (90000, 135000), "range median (m)": (4, 15), "range p90 (m)": (12, 40), **SHARES},
    "hdl32": {"points per frame": (20000, 60000), "range median (m)": (4, 15), "range p90 (m)": (12, 45), **SHARES},
}
HAVE = {
    "hdl64": os.path.exists(os.path.join(data, "semantickitti_scans", "sequences", "00", "velodyne", "000052.bin"))
    and os.path.exists(os.path.join(data, "kitti_odometry_gt_poses", "poses", "00.txt")),
    "hdl32": os.path.exists(os.path.join(data, "nuscenes_scene1072", "labels", "000039.label")),
}


def check_sensor(sensor, res, stdout):
    if not HAVE[sensor]:
        check("skipped" in res, f"{sensor}: skipped without its real data")
        print(f"SKIP: {sensor} numbers (no real data in {data})")
        return
    check("skipped" not in res, f"{sensor}: not skipped ({res.get('skipped')})")
    if "skipped" in res:
        return
    columns = {"real": res["real"], **res["simulated"]}
    for title, med in columns.items():
        for name, v in med.items():
            check(v is None or math.isfinite(v), f"{sensor} {title} {name} finite (got {v})")
        for name, (lo, hi) in PLAUSIBLE[sensor].items():
            check(lo <= med[name] <= hi, f"{sensor} {title} {name} in [{lo}, {hi}] (got {med[name]})")
        shares = sum(v for k, v in med.items() if k.startswith("% ") and k[2:] in COARSE_NAMES)
        check(abs(shares - 100) < 12, f"{sensor} {title}: median coarse-group shares add up to ~100 (got {shares})")
    for title, miou in res["label_miou"].items():
        want = (0.3, 0.85) if "realistic" in title else (0.999, 1.001)
        check(want[0] <= miou <= want[1], f"{sensor} {title}: label mIoU in {want} (got {miou})")
    check(res["simulated"]["simulated"]["engine nodes per frame"] >= 5, f"{sensor}: simulated frames have nodes")
    check(stdout.count("| points per frame |") >= 1 and "| label mIoU vs true labels |" in stdout,
          f"{sensor}: Markdown table printed")


COARSE_NAMES = ["ground / road", "sidewalk", "vegetation (incl. trunk)", "building / manmade",
                "pole-like (pole, sign)", "vehicle (incl. moving)", "person (incl. moving)",
                "other (unlabelled, other-object)"]

with tempfile.TemporaryDirectory() as tmp:
    out = os.path.join(tmp, "r.json")
    p = realism("--data", data, "--quick", "--sensors", "hdl64,hdl32", "--json", out)
    check(p.returncode == 0, f"--quick run exits 0 (got {p.returncode}: {p.stderr.strip()[-400:]})")
    if p.returncode == 0:
        with open(out) as f:
            res = json.load(f)
        check(sorted(res) == ["hdl32", "hdl64"], f"both sensors reported (got {sorted(res)})")
        for sensor in ("hdl64", "hdl32"):
            check_sensor(sensor, res.get(sensor, {"skipped": "missing"}), p.stdout)
        check(p.stdout.count("| points per frame |") == sum(HAVE.values()), "one median table per sensor with data")

    # Without real data: a clear message per sensor, exit 0, no table.
    p = realism("--data", os.path.join(tmp, "nothing"), "--quick", "--sensors", "hdl32,hdl64")
    check(p.returncode == 0, f"absent data: exit 0 (got {p.returncode})")
    check(p.stderr.count("skipped:") == 2 and "nothing" in p.stderr,
          f"absent data: one skip message per sensor naming the path (got {p.stderr.strip()!r})")
    check("| points per frame |" not in p.stdout, "absent data: no table")

    # Bad options are refused with exit 2 and name the option.
    for args, word in ((["--sensors", "hdl16"], "--sensors"), (["--sensors", ""], "--sensors"),
                       (["--seeds", "2,x"], "--seeds")):
        p = realism("--data", data, "--quick", *args)
        check(p.returncode == 2 and word in p.stderr, f"{args}: exit 2 naming {word} (got {p.returncode}, "
              f"{p.stderr.strip()[-200:]!r})")

if failures:
    print(f"{len(failures)} check(s) failed")
    sys.exit(1)
print("all realism.py checks passed")
