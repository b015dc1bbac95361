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
    # The graph is optimised in the background while scans arrive, so two runs may stop at another iteration:
    # agreement to a millimetre (translations) and 1e-3 (quaternions), not to the last bit.
    worst = max(max(abs(x - y) for x, y in zip(p, q)) for p, q in zip(t_dir, t_bag))
    assert worst < 1e-3, worst


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


def loop_errors(rows, poses):
    """Translation error (m) of each reported loop's T against the simulator's poses (T: query in candidate)."""
    import numpy as np
    errors = []
    for r in rows:
        for loop in r["loops"]:
            q, c = poses[int(r["frame"])], poses[loop["seq"]]
            truth = np.linalg.inv(c) @ q
            T = np.array(loop["T"], dtype=float).reshape(4, 4)
            errors.append(float(np.linalg.norm(T[:3, 3] - truth[:3, 3])))
    return errors


def test_motion_distorted_drive_is_deskewed(server, tmp_path):
    """The simulator's motion-distorted drive (9 m/s: the last column of a sweep is 0.9 m on) with its per-point
    times: de-skewed by `sglc ingest`, from a directory and from a bag (Ouster's t field), its loops' poses are
    right; sent as they are, they are off by about the distortion."""
    import numpy as np
    sim, node = _binary("SGLC_SIM_BIN", "sglc-sim"), shutil.which("node")
    cli = _binary("SGLC_CLI_BIN", "sglc")
    run([sim, "--route", "loop", "--frames", SIM_FRAMES, "--motion-distortion", "--out", str(tmp_path / "sim")])
    assert len(os.listdir(tmp_path / "sim" / "point_times")) == 80
    poses = [np.vstack([np.array(line.split(), dtype=float).reshape(3, 4), [0, 0, 0, 1]])
             for line in open(tmp_path / "sim" / "poses.txt")]
    fixed, note = ingest(cli, server, "deskewed", tmp_path / "sim")
    assert "de-skewed" in note, note
    raw, _ = ingest(cli, server, "raw", tmp_path / "sim", "--no-deskew")
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"from_sequence": str(tmp_path / "sim"), "points_topic": "/points",
                                "odom_topic": "/odom", "storage": "mcap", "compression": "lz4"}))
    run([node, os.path.join(REPO, "tests", "interop", "write_bag.mjs"), str(spec), str(tmp_path / "d.mcap")])
    from_bag, _ = ingest(cli, server, "bag", tmp_path / "d.mcap", "--points-topic", "/points", "--odom-topic",
                         "/odom", "--keyframe-m", "0", "--keyframe-deg", "0")
    e_fixed, e_raw, e_bag = loop_errors(fixed, poses), loop_errors(raw, poses), loop_errors(from_bag, poses)
    assert len(e_fixed) >= 10 and len(e_bag) >= 10, (len(e_fixed), len(e_bag))
    assert np.median(e_fixed) < 0.1, np.median(e_fixed)
    assert np.median(e_bag) < 0.1, np.median(e_bag)
    assert not e_raw or np.median(e_raw) > 3 * np.median(e_fixed), (np.median(e_raw), np.median(e_fixed))


def test_python_readers_give_the_drive(drive):
    """sglc.read_bag on the MCAP, .db3 and ROS 1 forms of the drive gives the directory's scans and poses;
    sglc.read_scan reads the directory's .bin files."""
    import numpy as np
    import sglc
    from sglc import engine
    if engine._engine is None:
        pytest.skip("no engine module in this build (sanitizer builds have none): sglc.read_bag is not there")
    seq, mcap, db3 = drive
    poses = [np.vstack([np.array(line.split(), dtype=float).reshape(3, 4), [0, 0, 0, 1]])
             for line in open(seq / "poses.txt")]
    bins = sorted(os.listdir(seq / "velodyne"))
    for path in (mcap, db3):
        bag = sglc.read_bag(path, "/points", odom_topic="/odom", keyframe_m=0, keyframe_deg=0)
        assert len(bag) == bag.clouds == 80 and bag.warnings == []
        for k in (0, 37, 79):
            scan = bag[k]
            points, labels = sglc.read_scan(seq / "velodyne" / bins[k])
            assert labels is None
            assert scan.index == k and scan.points.dtype == np.float32
            assert np.array_equal(scan.points, points)
            assert np.allclose(scan.pose, poses[k], atol=1e-6)
            assert scan.intensities is not None and scan.times is None and not scan.deskewed
    # Keyframes every 50 m, iterated.
    sparse = list(sglc.read_bag(mcap, "/points", odom_topic="/odom", keyframe_m=50, keyframe_deg=360))
    assert 20 <= len(sparse) <= 30 and sparse[0].index == 0
    with pytest.raises(ValueError, match="no topic /nope"):
        sglc.read_bag(mcap, "/nope")
    with pytest.raises(IndexError):
        sglc.read_bag(mcap, "/points")[80]
    with pytest.raises(ValueError, match="not a bag"):
        sglc.read_bag(seq / "poses.txt", "/points")


def test_sglc_pair_reads_a_bag(drive):
    """sglc-pair takes a bag's cloud by index or stamp and answers as it does for the same scans as files."""
    pair = _binary("SGLC_PAIR_BIN", "sglc-pair")
    seq, mcap, _ = drive
    bins = sorted(os.listdir(seq / "velodyne"))
    files = json.loads(run([pair, "--scan-a", str(seq / "velodyne" / bins[6]), "--scan-b",
                            str(seq / "velodyne" / bins[5])]).stdout)
    from_bag = json.loads(run([pair, "--scan-a", str(mcap), "--scan-b", str(mcap), "--points-topic", "/points",
                               "--index-a", "6", "--index-b", "5"]).stdout)
    stamps = [float(x) for x in open(seq / "times.txt") if x.strip()]
    by_stamp = json.loads(run([pair, "--scan-a", str(mcap), "--scan-b", str(mcap), "--points-topic", "/points",
                               "--stamp-a", str(1700000000 + stamps[6] + 0.01), "--index-b", "5"]).stdout)
    for key in ("is_loop", "T_a_b", "probability", "inliers"):
        assert files[key] == from_bag[key] == by_stamp[key], key
    r = subprocess.run([pair, "--scan-a", str(mcap), "--scan-b", str(mcap), "--points-topic", "/points",
                        "--index-a", "600", "--index-b", "5"], capture_output=True, text=True)
    assert r.returncode != 0 and "has no cloud 600" in r.stderr, r.stderr


def test_sglc_eval_reads_a_bag(drive, tmp_path):
    """The sequence protocol on the MCAP form of the drive (poses from its odometry) gives the figures of the
    same drive as a directory."""
    evaluate = _binary("SGLC_EVAL_BIN", "sglc-eval")
    seq, mcap, _ = drive
    summaries = []
    for name, args in (("dir", ["--data", str(seq)]),
                       ("bag", ["--data", str(mcap), "--points-topic", "/points", "--odom-topic", "/odom"])):
        # Frames here are 24 trajectory frames apart: 10 of them span what the default 100 do.
        run([evaluate, "--protocol", "sequence", *args, "--exclude-recent", "10", "--out", str(tmp_path / name),
             "--no-plots"], timeout=1800)
        summaries.append(json.load(open(tmp_path / name / "summary.json")))
    a, b = summaries
    for key in ("f1max", "recall_at_1", "verified_true", "verified_false", "queries_with_true_loop"):
        assert a[key] == b[key], (key, a[key], b[key])
    # The poses went through a quaternion in the bag: the same to about 1e-9 m.
    assert abs(a["rte_median"] - b["rte_median"]) < 1e-6
    assert a["queries_with_true_loop"] > 0
