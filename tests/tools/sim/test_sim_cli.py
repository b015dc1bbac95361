#!/usr/bin/env python3
"""Contract test of sglc-sim: output layout, same seed same bytes, progress and summary, one-line errors.

Usage: test_sim_cli.py SGLC_SIM_BINARY SHARED_DATA_DIR. The KITTI part is skipped (with a message) when
SHARED_DATA_DIR has no KITTI poses; the rest uses the built-in route.
"""
import filecmp
import json
import os
import subprocess
import sys
import tempfile

binary, data = sys.argv[1], sys.argv[2]
failures = []
SMALL = ["--beams", "16", "--columns", "256"]


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def run(*args):
    return subprocess.run([binary, *args], capture_output=True, text=True, timeout=300)


with tempfile.TemporaryDirectory() as tmp:
    a, b, c = (os.path.join(tmp, x) for x in "abc")
    p = run("--route", "loop", "--frames", "0:3,1905:1911", "--seed", "3", "--out", a, *SMALL)
    check(p.returncode == 0, f"loop route run exits 0 (got {p.returncode}: {p.stderr.strip()})")
    check("wrote 9 frames" in p.stdout, "summary says how many frames were written")
    for word in ("frames/s", "ground truth", "peak memory", "world:"):
        check(word in p.stdout, f"summary mentions '{word}'")
    check("frames (100%)" in p.stderr, "progress lines go to stderr")
    for name in ("poses.txt", "calib.txt", "times.txt", "frames.txt", "pairs_distance.txt", "loop_distance4.txt",
                 "sim_info.json"):
        check(os.path.isfile(os.path.join(a, name)), f"{name} written")
    bins = sorted(os.listdir(os.path.join(a, "velodyne")))
    labels = sorted(os.listdir(os.path.join(a, "labels")))
    check(bins == [f"{k:06d}.bin" for k in range(9)], "velodyne/000000.bin .. 000008.bin")
    check(labels == [f"{k:06d}.label" for k in range(9)], "labels/000000.label .. 000008.label")
    for k in range(9):
        nb = os.path.getsize(os.path.join(a, "velodyne", f"{k:06d}.bin"))
        nl = os.path.getsize(os.path.join(a, "labels", f"{k:06d}.label"))
        check(nb == 4 * nl and nl > 0, f"frame {k}: 16 bytes per point in .bin, 4 in .label")
    with open(os.path.join(a, "poses.txt")) as f:
        check(len(f.read().splitlines()) == 9, "poses.txt has one row per frame")
    with open(os.path.join(a, "frames.txt")) as f:
        check([int(x) for x in f.read().split()] == [0, 1, 2, 1905, 1906, 1907, 1908, 1909, 1910],
              "frames.txt maps output frames to trajectory frames")
    with open(os.path.join(a, "sim_info.json")) as f:
        info = json.load(f)
    check(info["seed"] == 3 and info["sensor"]["beams"] == 16 and info["frames"] == 9, "sim_info.json records the run")
    with open(os.path.join(a, "pairs_distance.txt")) as f:
        rows = [line.split() for line in f if not line.startswith("#")]
    check(any(r[2] == "1" for r in rows), "the end of the route revisits its start (a positive pair)")

    # Same seed, same bytes (whatever the thread count); another seed, another world.
    p = run("--route", "loop", "--frames", "0:3,1905:1911", "--seed", "3", "--out", b, "--threads", "1", *SMALL)
    check(p.returncode == 0, "second run exits 0")
    same = filecmp.cmpfiles(a, b, ["poses.txt", "calib.txt", "pairs_distance.txt", "loop_distance4.txt",
                                   "velodyne/000004.bin", "labels/000004.label"], shallow=False)
    check(not same[1] and not same[2], f"same seed gives the same bytes (differ: {same[1]}, errors: {same[2]})")
    p = run("--route", "loop", "--frames", "0:3", "--seed", "4", "--out", c, *SMALL)
    check(p.returncode == 0, "third run exits 0")
    p = run("--route", "loop", "--frames", "0:2", "--out", c, *SMALL)
    check(p.returncode == 1 and "--overwrite" in p.stderr, "an output folder with scans is refused")
    p = run("--route", "loop", "--frames", "0:3", "--seed", "4", "--out", c, "--overwrite", "--quiet", *SMALL)
    check(p.returncode == 0, "--overwrite replaces an earlier run")
    check(not filecmp.cmp(os.path.join(a, "velodyne", "000001.bin"), os.path.join(c, "velodyne", "000001.bin"),
                          shallow=False), "another seed gives another scan")

    # Label noise and odometry drift options.
    d = os.path.join(tmp, "d")
    p = run("--route", "loop", "--frames", "0:40:10", "--seed", "3", "--out", d, "--label-noise", "0.05",
            "--odom-noise", "0.01", "--quiet", *SMALL)
    check(p.returncode == 0 and p.stderr == "", f"--quiet run is silent on stderr ({p.stderr.strip()})")
    check(os.path.isfile(os.path.join(d, "odometry.txt")), "--odom-noise writes odometry.txt")
    # Output frame 0 is trajectory frame 0 in both runs: same points, noisy labels.
    check(filecmp.cmp(os.path.join(a, "velodyne", "000000.bin"), os.path.join(d, "velodyne", "000000.bin"),
                      shallow=False), "label noise leaves the points alone")
    check(not filecmp.cmp(os.path.join(a, "labels", "000000.label"), os.path.join(d, "labels", "000000.label"),
                          shallow=False), "--label-noise changes labels")

    # Every run reports the IoU of its labels against the true ones; the network model lowers it.
    with open(os.path.join(d, "sim_info.json")) as fh:
        info = json.load(fh)
    check(info["label_noise"]["model"] == "iid" and "road" in info["label_iou"] and
          0 < info["label_miou"] < 1, f"--label-noise run: label_iou and label_miou in sim_info.json ({info['label_miou']})")
    with open(os.path.join(a, "sim_info.json")) as fh:
        info = json.load(fh)
    check(info["label_miou"] == 1 and all(v == 1 for v in info["label_iou"].values()),
          "without label noise every class has IoU 1")
    check("labels:       mIoU" in run("--route", "loop", "--frames", "0:2", "--out", os.path.join(tmp, "i"),
                                      "--quiet", *SMALL).stdout, "the summary has a labels: mIoU line")
    n = os.path.join(tmp, "n")
    p = run("--route", "loop", "--frames", "0:1911:200", "--seed", "3", "--out", n, "--label-noise-model", "network",
            "--quiet")
    check(p.returncode == 0 and "label noise: network" in p.stdout, f"--label-noise-model network runs ({p.stderr})")
    with open(os.path.join(n, "sim_info.json")) as fh:
        info = json.load(fh)
    check(info["label_noise"]["model"] == "network" and 0.4 < info["label_miou"] < 0.8 and
          0.8 < info["label_iou"]["road"] < 0.97, f"network model: mIoU {info['label_miou']:.3f}, per class in "
          f"sim_info.json ({info['label_iou']})")

    # Field of view.
    f = os.path.join(tmp, "f")
    p = run("--route", "loop", "--frames", "0:2", "--out", f, "--beams", "8", "--columns", "64", "--fov-up", "10",
            "--fov-down", "-10", "--quiet")
    with open(os.path.join(f, "sim_info.json")) as fh:
        elevation = json.load(fh)["sensor"]["elevation_deg"]
    check(p.returncode == 0 and len(elevation) == 8 and elevation[0] == 10 and elevation[-1] == -10,
          f"--fov-up/--fov-down spread the beams ({elevation})")

    # Sensor presets and realism options.
    g = os.path.join(tmp, "g")
    p = run("--route", "loop", "--frames", "100:102", "--out", g, "--sensor", "rosette", "--laser-offsets",
            "--mixed-pixels", "0.5", "--motion-distortion", "--quiet")
    with open(os.path.join(g, "sim_info.json")) as fh:
        sensor = json.load(fh)["sensor"]
    check(p.returncode == 0 and sensor["name"] == "rosette" and sensor["rosette"]["rays"] == 24000 and
          sensor["laser_offsets"] and sensor["motion_distortion"] and sensor["mixed_pixel_rate"] == 0.5,
          f"--sensor rosette with the realism options runs ({p.stderr.strip()})")
    check("24000 rays" in p.stdout, "the summary names the rosette's rays")
    p = run("--route", "loop", "--frames", "0:1", "--out", g, "--sensor", "vlp16", "--overwrite", "--quiet")
    with open(os.path.join(g, "sim_info.json")) as fh:
        sensor = json.load(fh)["sensor"]
    check(p.returncode == 0 and sensor["beams"] == 16 and sensor["columns"] == 1800, "--sensor vlp16: 16 x 1800")
    # The realistic preset: network label noise, turnover, laser offsets, mixed pixels (0.5 unless given).
    p = run("--route", "loop", "--frames", "0:1", "--out", g, "--realistic", "--mixed-pixels", "0.25", "--overwrite",
            "--quiet")
    with open(os.path.join(g, "sim_info.json")) as fh:
        info = json.load(fh)
    check(p.returncode == 0 and info["label_noise"]["model"] == "network" and info["world"]["turnover"] and
          info["world"]["epoch"] == 0 and info["sensor"]["laser_offsets"] and
          info["sensor"]["mixed_pixel_rate"] == 0.25 and not info["sensor"]["motion_distortion"],
          f"--realistic sets its parts and keeps a given --mixed-pixels ({p.stderr.strip()})")
    p = run("--route", "loop", "--frames", "0:1", "--out", g, "--realistic", "--sensor", "vlp16", "--epoch", "2",
            "--overwrite", "--quiet")
    with open(os.path.join(g, "sim_info.json")) as fh:
        info = json.load(fh)
    check(p.returncode == 0 and info["sensor"]["mixed_pixel_rate"] == 0.5 and info["world"]["epoch"] == 2 and
          info["sensor"]["beams"] == 16, "--realistic combines with --sensor and --epoch")

    # KITTI trajectory (needs the shared data).
    poses = os.path.join(data, "kitti_odometry_gt_poses", "poses", "00.txt")
    calib = os.path.join(data, "semantickitti_scans", "sequences", "00", "calib.txt")
    if os.path.isfile(poses) and os.path.isfile(calib):
        k = os.path.join(tmp, "k")
        p = run("--poses", poses, "--calib", calib, "--frames", "52,4501", "--seed", "7", "--out", k, *SMALL)
        check(p.returncode == 0, f"KITTI 00 run exits 0 ({p.stderr.strip()})")
        with open(os.path.join(k, "pairs_distance.txt")) as f:
            rows = [line.split() for line in f if not line.startswith("#")]
        check(["000001", "000000", "1"] in rows, "KITTI 00 frames 52 and 4501 are a positive pair")
        p = run("--poses", poses, "--frames", "0:2", "--out", k)
        check(p.returncode == 2 and "--calib" in p.stderr, "--poses without --calib is a usage error")
    else:
        print(f"SKIP (KITTI part): {poses} not found")

    # Time: another epoch moves parked cars (frames differ) but not the ground truth; aliasing 0 is the default.
    frames = ["--route", "loop", "--frames", "0:1911:150", "--seed", "5", *SMALL]
    e0, e1, al = (os.path.join(tmp, x) for x in ("e0", "e1", "al"))
    p0 = run(*frames, "--epoch", "0", "--out", e0)
    p1 = run(*frames, "--epoch", "1", "--out", e1)
    check(p0.returncode == 0 and p1.returncode == 0, f"--epoch runs exit 0 ({p0.stderr.strip()} {p1.stderr.strip()})")
    check("turnover on, day 1" in p1.stdout, "the summary names the epoch")
    for name in ("poses.txt", "pairs_distance.txt", "loop_distance4.txt", "times.txt"):
        check(filecmp.cmp(os.path.join(e0, name), os.path.join(e1, name), shallow=False),
              f"--epoch 1 keeps {name} of --epoch 0")
    differing = sum(not filecmp.cmp(os.path.join(e0, "labels", n), os.path.join(e1, "labels", n), shallow=False)
                    for n in sorted(os.listdir(os.path.join(e0, "labels"))))
    check(differing >= 5, f"--epoch 1 changes the parked cars in most frames (got {differing} of 13 differing)")
    with open(os.path.join(e1, "sim_info.json")) as f:
        world = json.load(f)["world"]
    check(world["epoch"] == 1 and world["turnover"] and world["parking_slots"] > 0, "sim_info.json records the epoch")
    few = ["--route", "loop", "--frames", "0:1911:600", "--seed", "5", *SMALL]
    p = run(*few, "--aliasing", "0", "--out", al)
    dflt = os.path.join(tmp, "dflt")
    q = run(*few, "--out", dflt)
    check(p.returncode == 0 and q.returncode == 0, "--aliasing 0 run exits 0")
    check(all(filecmp.cmp(os.path.join(al, "velodyne", n), os.path.join(dflt, "velodyne", n), shallow=False)
              for n in os.listdir(os.path.join(dflt, "velodyne"))), "--aliasing 0 gives the default's bytes")

    # Errors: one line on stderr, exit 2 for usage, 1 for bad input.
    for args, code, word in [
        (["--route", "loop"], 2, "--out"),
        (["--out", os.path.join(tmp, "e")], 2, "--route"),
        (["--route", "loop", "--poses", "x", "--calib", "y", "--out", os.path.join(tmp, "e")], 2, "either"),
        (["--route", "square", "--out", os.path.join(tmp, "e")], 2, "route"),
        (["--route", "loop", "--frames", "5:3", "--out", os.path.join(tmp, "e")], 1, "frame selection"),
        (["--route", "loop", "--frames", "0:99999", "--out", os.path.join(tmp, "e")], 1, "frame selection"),
        (["--route", "loop", "--beams", "0", "--out", os.path.join(tmp, "e")], 1, "beams"),
        (["--poses", os.path.join(tmp, "missing.txt"), "--calib", calib, "--out", os.path.join(tmp, "e")], 1,
         "missing.txt"),
        (["--route", "loop", "--label-noise", "2", "--out", os.path.join(tmp, "e")], 2, "label-noise"),
        (["--route", "loop", "--label-noise-model", "unet", "--out", os.path.join(tmp, "e")], 2,
         "--label-noise-model"),
        (["--route", "loop", "--label-noise-model", "network", "--label-noise", "0.05", "--out",
          os.path.join(tmp, "e")], 2, "cannot be mixed with --label-noise"),
        (["--route", "loop", "--label-noise-model", "network", "--label-miss", "0.5", "--out",
          os.path.join(tmp, "e")], 2, "--label-miss"),
        (["--route", "loop", "--calib", "c.txt", "--out", os.path.join(tmp, "e")], 2, "--calib"),
        (["--route", "loop", "--fov-up", "3", "--out", os.path.join(tmp, "e")], 2, "--fov-down"),
        (["--route", "loop", "--sensor", "hdl16", "--out", os.path.join(tmp, "e")], 2, "--sensor"),
        (["--route", "loop", "--sensor", "vlp16", "--beams", "32", "--out", os.path.join(tmp, "e")], 2,
         "mutually exclusive"),
        (["--route", "loop", "--sensor", "rosette", "--columns", "64", "--out", os.path.join(tmp, "e")], 2,
         "rosette"),
        (["--route", "loop", "--realistic", "--label-noise", "0.1", "--out", os.path.join(tmp, "e")], 2,
         "--realistic uses the calibrated network label noise and cannot be mixed with --label-noise"),
        (["--route", "loop", "--realistic", "--label-noise-model", "iid", "--out", os.path.join(tmp, "e")], 2,
         "--realistic uses --label-noise-model network"),
        (["--route", "loop", "--mixed-pixels", "1.5", "--out", os.path.join(tmp, "e")], 2, "--mixed-pixels"),
        (["--route", "loop", "--epoch", "-1", "--out", os.path.join(tmp, "e")], 2, "--epoch"),
        (["--route", "loop", "--epoch", "x", "--out", os.path.join(tmp, "e")], 2, "--epoch"),
        (["--route", "loop", "--aliasing", "1.5", "--out", os.path.join(tmp, "e")], 2, "--aliasing"),
        (["--route", "loop", "--aliasing", "nan", "--out", os.path.join(tmp, "e")], 2, "--aliasing"),
        (["--route", "loop", "--mixed-pixels", "nan", "--out", os.path.join(tmp, "e")], 2,
         "--mixed-pixels must be a finite number"),
        (["--route", "loop", "--label-noise", "nan", "--out", os.path.join(tmp, "e")], 2, "--label-noise"),
        (["--route", "loop", "--range", "nan", "--out", os.path.join(tmp, "e")], 2, "--range"),
        (["--route", "loop", "--fov-up", "nan", "--fov-down", "-10", "--out", os.path.join(tmp, "e")], 2, "--fov-up"),
        (["--route", "loop", "--epoch", "-2147483648", "--out", os.path.join(tmp, "e")], 2, "--epoch"),
    ]:
        p = run(*args)
        lines = p.stderr.strip().splitlines()
        check(p.returncode == code, f"{args}: exit {code} (got {p.returncode})")
        check(len(lines) == 1 and lines[0].startswith("sglc-sim: error:") and word in lines[0],
              f"{args}: one error line mentioning '{word}' (got {p.stderr.strip()!r})")
    # Only numbers are refused as NaN: a directory may be called "nan".
    p = run("--route", "loop", "--frames", "0:1", "--out", os.path.join(tmp, "nan"), "--quiet", *SMALL)
    check(p.returncode == 0 and os.path.isdir(os.path.join(tmp, "nan", "velodyne")),
          f"--out nan is a directory name (got {p.returncode}: {p.stderr.strip()})")
    p = run("--help")
    check(p.returncode == 0 and "--poses" in p.stdout and "--frames" in p.stdout, "--help lists the options")

if failures:
    print(f"{len(failures)} check(s) failed")
    sys.exit(1)
print("all sglc-sim CLI checks passed")
