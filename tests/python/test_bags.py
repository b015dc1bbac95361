"""A simulated drive written as a bag by writers nobody here wrote (@mcap/core and Foxglove's CDR serialiser,
tests/interop/write_bag.mjs) gives, through `sglc ingest BAG`, the same loops and the same trajectory as the same
drive ingested as a sequence directory."""
import json
import os
import shutil
import subprocess

import pytest

from conftest import REPO, _binary

SIM_FRAMES = "0:1911:24"  # the built-in route, every 24th frame: 80 scans, 21.6 m apart, with revisits


def run(args, **kw):
    r = subprocess.run(args, capture_output=True, text=True, **kw)
    assert r.returncode == 0, f"{args}\n{r.stdout}\n{r.stderr}"
    return r


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """(sequence directory without labels, MCAP bag of it, db3 bag directory of it)."""
    sim, node = _binary("SGLC_SIM_BIN", "sglc-sim"), shutil.which("node")
    if sim is None:
        pytest.skip("sglc-sim is not built")
    assert node, "node is missing: run scripts/install-deps.sh"
    assert os.path.isdir(os.path.join(REPO, "tests", "interop", "node_modules", "@mcap", "core")), \
        "npm packages missing in tests/interop: run scripts/install-deps.sh"
    tmp = tmp_path_factory.mktemp("drive")
    run([sim, "--route", "loop", "--frames", SIM_FRAMES, "--out", str(tmp / "sim")])
    # Unlabelled (a bag's clouds carry no labels): velodyne/, poses.txt, times.txt.
    seq = tmp / "seq"
    seq.mkdir()
    (seq / "velodyne").symlink_to(tmp / "sim" / "velodyne")
    for name in ("poses.txt", "times.txt"):
        shutil.copy(tmp / "sim" / name, seq / name)
    bags = []
    for storage, compression, out in (("mcap", "zstd", tmp / "drive.mcap"), ("db3", "", tmp / "drive_db3")):
        spec = tmp / f"{storage}.json"
        spec.write_text(json.dumps({"from_sequence": str(tmp / "sim"), "points_topic": "/points", "odom_topic": "/odom",
                                    "storage": storage, "compression": compression}))
        run([node, os.path.join(REPO, "tests", "interop", "write_bag.mjs"), str(spec), str(out)])
        bags.append(out)
    return seq, bags[0], bags[1]


def ingest(cli, address, map_name, path, *extra):
    r = run([cli, "ingest", "--server", address, "--map", map_name, "--robot", "r", "--session", "s", "--query",
             "--json", *extra, str(path)], timeout=1800)
    return [json.loads(line) for line in r.stdout.splitlines()], r.stderr


def trajectory(cli, address, map_name, out):
    run([cli, "trajectory", "--server", address, "--map", map_name, "--robot", "r", "--format", "tum", "--out", str(out)])
    return [list(map(float, line.split()[1:])) for line in open(out) if line.strip() and not line.startswith("#")]


def test_bag_gives_the_loops_and_trajectory_of_the_sequence(server, drive, tmp_path):
    cli = _binary("SGLC_CLI_BIN", "sglc")
    seq, mcap, db3 = drive
    from_dir, _ = ingest(cli, server, "dir", seq)
    every = ("--points-topic", "/points", "--odom-topic", "/odom", "--keyframe-m", "0", "--keyframe-deg", "0")
    from_mcap, note = ingest(cli, server, "mcap", mcap, *every)
    assert "80 keyframes of 80 clouds on /points" in note, note
    from_db3, _ = ingest(cli, server, "db3", db3, *every)
    assert len(from_dir) == len(from_mcap) == len(from_db3) == 80
    loops = sum(1 for r in from_dir if r["loops"])
    assert loops >= 10, f"the drive should revisit places: {loops} scans with loops"
    for a, b, c in zip(from_dir, from_mcap, from_db3):
        assert a["frame"] == str(int(a["frame"])).zfill(6) and int(a["frame"]) == int(b["frame"])
        for other in (b, c):
            assert [(l["seq"], l["T"], l["probability"]) for l in a["loops"]] == \
                   [(l["seq"], l["T"], l["probability"]) for l in other["loops"]], a["frame"]
    # The odometry reached the pose graph the same way: the optimised trajectories agree.
    t_dir = trajectory(cli, server, "dir", tmp_path / "dir.tum")
    t_bag = trajectory(cli, server, "mcap", tmp_path / "mcap.tum")
    assert len(t_dir) == len(t_bag) == 80
    worst = max(max(abs(x - y) for x, y in zip(p, q)) for p, q in zip(t_dir, t_bag))
    assert worst < 1e-5, worst


def test_keyframes_by_distance(server, drive):
    cli = _binary("SGLC_CLI_BIN", "sglc")
    _, mcap, _ = drive
    # Scans 21.6 m apart: with keyframes every 50 m, about every third scan is sent.
    rows, note = ingest(cli, server, "sparse", mcap, "--points-topic", "/points", "--odom-topic", "/odom",
                        "--keyframe-m", "50", "--keyframe-deg", "360")
    assert "keyframes of 80 clouds" in note
    assert 20 <= len(rows) <= 30, len(rows)
    numbers = [int(r["frame"]) for r in rows]
    assert numbers == sorted(numbers) and numbers[0] == 0
    assert all(b - a >= 2 for a, b in zip(numbers, numbers[1:])), numbers


def test_bag_errors_name_the_topic(server, drive):
    cli = _binary("SGLC_CLI_BIN", "sglc")
    _, mcap, _ = drive
    r = subprocess.run([cli, "ingest", "--server", server, "--map", "m", "--robot", "r", "--points-topic", "/lidar",
                        str(mcap)], capture_output=True, text=True)
    assert r.returncode != 0
    assert "no topic /lidar" in r.stderr and "/points (sensor_msgs/msg/PointCloud2, 80 messages)" in r.stderr, r.stderr
    r = subprocess.run([cli, "ingest", "--server", server, "--map", "m", "--robot", "r", str(mcap)],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "--points-topic" in r.stderr, r.stderr
