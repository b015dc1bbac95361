#!/usr/bin/env python3
"""sglc-eval end to end on a short simulated sequence (the built-in route, every 6th frame).

Usage: test_eval_cli.py SGLC_EVAL SGLC_SERVER
Checks floors on the metrics (so an engine regression fails CI), that the in-process and the server back-ends
give identical numbers, the pair and pose protocols on pairs taken from the run, the figures, and bad input.
"""
import csv
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

EVAL, SERVER = sys.argv[1], sys.argv[2]
SANITIZED = os.environ.get("SGLC_SANITIZED") == "1"
FRAMES = "::6"
METRICS = ["f1max", "f1max_threshold", "ep", "auc", "recall_at_1", "recall_at_1pct", "queries_with_true_loop",
           "top1_in_band", "rr", "registered", "rte_mean", "rre_mean", "at_f1max", "verified_true", "verified_false",
           "precision_all_verified"]


def run(args, expect=0):
    p = subprocess.run([EVAL, *args], capture_output=True, text=True, timeout=600)
    assert p.returncode == expect, f"sglc-eval {' '.join(args)} exited {p.returncode}:\n{p.stderr[-2000:]}"
    return p


def logged_port(server, log_path):
    """The port `server` logged it listens on; fails with the log's tail if it exits first."""
    for _ in range(600):
        with open(log_path, errors="replace") as f:
            for line in f:
                if '"event":"listening"' in line:
                    return json.loads(line)["port"]
        assert server.poll() is None, f"sglc-server exited {server.returncode} before listening:\n{tail(log_path)}"
        time.sleep(0.1)
    raise AssertionError(f"sglc-server logged no port in 60 s:\n{tail(log_path)}")


def tail(path, lines=30):
    """The log's last lines, or, when a sanitizer reported, the report's first lines (its stacks)."""
    try:
        with open(path, errors="replace") as f:
            text = f.readlines()
    except OSError as e:
        return f"(no log: {e})"
    report = next((i for i, line in enumerate(text) if "Sanitizer" in line and "ERROR" in line), None)
    return "".join(text[report:report + 60] if report is not None else text[-lines:])


def have_matplotlib():
    return subprocess.run(["/usr/bin/python3", "-c", "import matplotlib, numpy"], capture_output=True).returncode == 0


def run_other_protocols(tmp, local, s, port, plots):
    """Relocalization across sensors, pose and pair protocols, and "all", each against the sequence run `s`."""
    # 2c. Relocalization across sensors: a map of HDL-64-like scans, queried by a 32-beam sensor driving the
    # same route at other frames; in-process and through the server with identical numbers.
    sim = os.path.join(os.path.dirname(EVAL), "sglc-sim")
    for name, args in (("map", ["--frames", "0:1911:6"]), ("q32", ["--frames", "3:1911:24", "--beams", "32"])):
        subprocess.run([sim, "--route", "loop", "--seed", "7", "--quiet", "--out", os.path.join(tmp, name)] + args,
                       check=True, stdout=subprocess.DEVNULL, timeout=600)
    reloc = {}
    for backend, extra in (("in-process", []), ("server", ["--server", f"127.0.0.1:{port}"])):
        out = os.path.join(tmp, "reloc-" + backend)
        run(["--protocol", "relocalization", "--map-data", os.path.join(tmp, "map"), "--data",
             os.path.join(tmp, "q32"), "--out", out, "--no-plots"] + extra)
        reloc[backend] = json.load(open(os.path.join(out, "summary.json")))
    rl = reloc["in-process"]
    print(f"relocalization (64 -> 32 beams): Recall@1 {rl['recall_at_1']:.3f}, precision of every verified top-1 "
          f"{rl['precision_all_verified']:.3f}, RTE median {rl['rte_median']:.3f} m over {rl['queries']} queries")
    assert rl["map_frames"] == 319 and rl["queries"] == 80 and rl["queries_with_true_place"] == 80, rl
    # Today: Recall@1 0.93, precision 1.0, RTE median 0.003 m.
    assert rl["recall_at_1"] >= 0.8 and rl["precision_all_verified"] >= 0.98 and rl["rte_median"] < 0.05, rl
    for k in ("recall_at_1", "precision", "precision_all_verified", "rr", "rte_median", "verified_true"):
        assert reloc["server"][k] == rl[k], f"relocalization {k}: server {reloc['server'][k]} != {rl[k]}"
    rows = list(csv.DictReader(open(os.path.join(tmp, "reloc-in-process", "relocalization.csv"))))
    assert len(rows) == 80 and sum(r["outcome"] == "true" for r in rows) == rl["verified_true"], rows[:3]

    # 3. Pose and pair protocols on pairs taken from the run: its true detections, and far-apart frames.
    rows = list(csv.DictReader(open(os.path.join(local, "trajectory.csv"))))
    pos = {int(x["frame"]): (float(x["x"]), float(x["y"])) for x in rows}
    loops = [(int(x["frame"]), int(x["match_frame"])) for x in rows if x["detection"] == "1"]
    frames = sorted(pos)
    far = [(a, b) for a, b in zip(frames, frames[len(frames) // 2:]) if math.dist(pos[a], pos[b]) > 20][:len(loops)]
    pairs = os.path.join(tmp, "pairs.txt")
    with open(pairs, "w") as f:
        f.write("# i j label\n")
        f.writelines(f"{a} {b} 1\n" for a, b in loops)
        f.writelines(f"{a} {b} 0\n" for a, b in far)
    spec = ",".join(str(x) for x in sorted({x for p in loops + far for x in p}))
    out = os.path.join(tmp, "pose")
    run(["--protocol", "pose", "--sim", "--frames", spec, "--pairs", pairs, "--out", out] +
        ([] if plots else ["--no-plots"]))
    ps = json.load(open(os.path.join(out, "summary.json")))
    print(f"pose: RR {ps['rr']:.3f} over {ps['pose_pairs']} pairs, RTE {ps['rte_mean']:.3f} m, "
          f"RRE {ps['rre_mean']:.3f} deg")
    assert ps["pose_pairs"] == len(loops) and ps["rr"] == 1.0 and ps["rte_mean"] < 0.05, ps
    assert 0.9 <= ps["rr_verified"] <= ps["rr"], ps
    with open(os.path.join(out, "pose_errors.csv")) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(loops) and set(rows[0]) == {"i", "j", "registered", "verified", "rte_m", "rre_deg"}
    assert sum(r["verified"] == "1" for r in rows) / len(rows) >= ps["rr_verified"] - 1e-9
    if plots:
        assert os.path.getsize(os.path.join(out, "pose_errors.png")) > 1000
    out = os.path.join(tmp, "pairs")
    run(["--protocol", "pairs", "--sim", "--frames", spec, "--pairs", pairs, "--out", out, "--no-plots"])
    pr = json.load(open(os.path.join(out, "summary.json")))
    print(f"pairs: F1max {pr['f1max']:.3f} EP {pr['ep']:.3f} ({pr['positives']} + {pr['negatives']} pairs)")
    assert pr["positives"] == len(loops) and pr["negatives"] == len(far) and len(far) > 20, pr
    assert pr["f1max"] >= 0.97 and pr["ep"] >= 0.95, pr

    # 3b. "all": the three protocols over one set of stored frames give the same numbers as separate runs.
    out = os.path.join(tmp, "all")
    run(["--protocol", "all", "--sim", "--frames", FRAMES, "--pairs", pairs, "--pose-pairs", pairs, "--out", out,
         "--no-plots"])
    combined = json.load(open(os.path.join(out, "summary.json")))
    for k in METRICS:
        assert combined["sequence"][k] == s[k], f"all/sequence {k}"
    for k in ("f1max", "ep", "auc", "positives", "negatives"):
        assert combined["pairs"][k] == pr[k], f"all/pairs {k}"
    for k in ("rr", "rte_mean", "rre_mean", "pose_pairs"):
        assert combined["pose"][k] == ps[k], f"all/pose {k}"

    # 3c. "all --sim" without pair files: the pair and pose lists come from the simulator's ground truth, as
    # sglc-sim writes them (loops: horizontal distance < 3 m, frames more than 50 apart).
    out = os.path.join(tmp, "derived")
    run(["--protocol", "all", "--sim", "--frames", FRAMES, "--out", out, "--no-plots"])
    derived = json.load(open(os.path.join(out, "summary.json")))
    for k in METRICS:
        assert derived["sequence"][k] == s[k], f"derived/sequence {k}"
    dp, dq = derived["pairs"], derived["pose"]
    assert dp["pairs_file"].startswith("simulator ground truth") and dq["pairs_file"].startswith("simulator"), dp
    expected = sum(1 for i, a in enumerate(frames) for b in frames[:i]
                   if a - b > 50 and math.dist(pos[a], pos[b]) < 3.0)
    assert dp["positives"] == expected and dp["negatives"] >= expected, (dp, expected)
    print(f"derived pairs: F1max {dp['f1max']:.3f} ({dp['positives']} + {dp['negatives']} pairs); pose: RR "
          f"{dq['rr']:.3f} over {dq['pose_pairs']} pairs, RTE median {dq['rte_median']:.3f} m")
    assert dp["f1max"] >= 0.9 and dq["pose_pairs"] >= expected // 2 and dq["rr"] >= 0.9, (dp, dq)


def main():
    tmp = tempfile.mkdtemp(prefix="sglc-eval-test-")
    server = None
    try:
        # 1. Sequence protocol in-process, with figures when matplotlib is there.
        local = os.path.join(tmp, "local")
        plots = have_matplotlib()
        run(["--protocol", "sequence", "--sim", "--frames", FRAMES, "--out", local] + ([] if plots else ["--no-plots"]))
        s = json.load(open(os.path.join(local, "summary.json")))
        print(f"sequence: F1max {s['f1max']:.3f} EP {s['ep']:.3f} R@1 {s['recall_at_1']:.3f} RR {s['rr']:.3f} "
              f"RTE {s['rte_mean']:.3f} m RRE {s['rre_mean']:.3f} deg ({s['registered']} poses)")
        assert s["queries"] == 319 and s["queries_with_true_loop"] > 100, s
        # Floors below today's figures: 0.996 / 0.997 F1max / EP with the loop model of 2026-11-28, whose loops
        # rank by probability to a thousandth and then the nearer pose (by probability alone, candidates 3.7 m
        # away that the model was as sure of ranked first, and F1max was 0.81).
        assert s["f1max"] >= 0.95 and s["ep"] >= 0.95, s
        assert s["precision_all_verified"] >= 0.99, s
        assert s["at_f1max"]["false_loops"] == 0, s
        # Every verified top-1 detection, whatever its score, is a true loop (today: precision 1.0 at the lowest
        # threshold): "verified" must mean right, not just "above the F1max threshold".
        lowest = next(csv.DictReader(open(os.path.join(local, "pr.csv"))))
        assert float(lowest["precision"]) >= 0.98, lowest
        assert s["precision_all_verified"] >= 0.98, s
        rows = list(csv.DictReader(open(os.path.join(local, "top1.csv"))))
        assert sum(r["outcome"] == "true" for r in rows) == s["verified_true"] > 100, (s, rows[:3])
        assert sum(r["outcome"] == "false" for r in rows) == s["verified_false"], s
        assert s["rr"] == 1.0 and s["registered"] >= 100, s
        assert s["rte_mean"] < 0.01 and s["rre_mean"] < 0.05, s
        for stage in ("fingerprint", "search", "verify", "refine", "total"):
            assert s["timings"][stage]["n"] == 319 and s["timings"][stage]["median_ms"] >= 0, stage
        if plots:
            for png in ("pr_curve.png", "trajectory.png"):
                assert os.path.getsize(os.path.join(local, png)) > 1000, png
        else:
            print("  figures not checked: /usr/bin/python3 has no matplotlib")

        # 2. The same through a real server: identical numbers and files.
        # Port 0: the server picks a free port and logs it, so no other test's server can take it in between.
        server_log = os.path.join(tmp, "server.log")
        log = open(server_log, "wb")
        server = subprocess.Popen([SERVER, "--db", os.path.join(tmp, "s.db"), "--listen", "127.0.0.1:0",
                                   "--sync-normal"], stdout=log, stderr=subprocess.STDOUT)
        port = logged_port(server, server_log)
        remote = os.path.join(tmp, "remote")
        for attempt in range(100):
            p = subprocess.run([EVAL, "--protocol", "sequence", "--sim", "--frames", FRAMES, "--out", remote,
                                "--no-plots", "--server", f"127.0.0.1:{port}"], capture_output=True, text=True,
                               timeout=600)
            if p.returncode == 0 or "UNAVAILABLE" not in p.stderr:
                break
            time.sleep(0.1)  # the server is still starting
        assert p.returncode == 0, p.stderr[-2000:]
        r = json.load(open(os.path.join(remote, "summary.json")))
        assert r["backend"] == "server" and s["backend"] == "in-process"
        for k in METRICS:
            assert r[k] == s[k], f"{k}: server {r[k]} != in-process {s[k]}"
        for f in ("pr.csv", "trajectory.csv"):
            assert open(os.path.join(remote, f)).read() == open(os.path.join(local, f)).read(), f

        # 2b. SLAM through the server's pose graph: two robots with 2 % drift, the second in an unrelated frame.
        slam = os.path.join(tmp, "slam")
        run(["--protocol", "slam", "--sim", "--frames", "::8", "--odom-noise", "0.02", "--robots", "2",
             "--server", f"127.0.0.1:{port}", "--out", slam] + ([] if plots else ["--no-plots"]))
        sl = json.load(open(os.path.join(slam, "summary.json")))
        fa = sl["frame_alignment_error"]
        print(f"slam: ATE {sl['ate_odometry']:.3f} -> {sl['ate_optimised']:.3f} m, second robot's frame "
              f"{fa['m']:.3f} m / {fa['deg']:.3f} deg")
        # Today: 1.39 -> 0.22 m, the second robot's frame 0.23 m / 0.10 deg off.
        assert sl["ate_optimised"] < sl["ate_odometry"] / 4 and fa["connected"] and fa["m"] < 0.6 and fa["deg"] < 1.0, sl
        if plots:
            assert os.path.getsize(os.path.join(slam, "slam.png")) > 1000
        run(["--protocol", "slam", "--sim", "--out", slam], expect=1)  # needs --server

        # The maps the sequence and slam runs created on the server were deleted at their end (no --keep-maps).
        assert r["server_map_kept"] is False and sl["server_map_kept"] is False

        if SANITIZED:
            # Under ASan + UBSan every run is several times slower; the runs below repeat the engine paths
            # above through other protocols (their metrics are checked by the Release run), so only the
            # sequence protocol, its server twin, the pose graph and the bad input run there.
            print("  relocalization, pose, pairs and all protocols: not run under the sanitizers")
        else:
            run_other_protocols(tmp, local, s, port, plots)
        cli = os.path.join(os.path.dirname(SERVER), "sglc")
        if os.access(cli, os.X_OK):  # and none of the runs' maps is left on the server
            listed = subprocess.run([cli, "maps", "--json", "--server", f"127.0.0.1:{port}"], capture_output=True,
                                    text=True, timeout=60)
            assert listed.returncode == 0 and "eval-" not in listed.stdout, listed.stdout + listed.stderr

        # 4. Bad input: a clear message and exit 1 (CLI misuse: 106 from CLI11 for a missing required flag).
        bad = os.path.join(tmp, "bad.txt")
        with open(bad, "w") as f:
            f.write("1 2 1\n3 x 0\n")
        cases = [
            (["--protocol", "pairs", "--data", tmp, "--out", tmp], "needs --pairs"),
            (["--protocol", "all", "--data", tmp, "--pairs", bad, "--out", tmp], "needs --pose-pairs"),
            (["--protocol", "sequence", "--sim", "--data", tmp, "--out", tmp], "exactly one of --data"),
            (["--protocol", "pairs", "--sim", "--pairs", bad, "--out", tmp], "bad.txt:2"),
            (["--protocol", "pairs", "--sim", "--pairs", os.path.join(tmp, "none.txt"), "--out", tmp], "cannot read"),
            (["--protocol", "sequence", "--data", os.path.join(tmp, "nodir"), "--out", tmp], "nodir"),
            (["--protocol", "sequence", "--sim", "--frames", "5:1", "--out", tmp], "5:1"),
            (["--protocol", "relocalization", "--data", tmp, "--out", tmp], "--map-data DIR go together"),
            (["--protocol", "sequence", "--sim", "--positive-m", "-1", "--out", tmp], "positive distance"),
            (["--protocol", "sequence", "--map-data", tmp, "--data", tmp, "--out", tmp], "go together"),
        ]
        for args, words in cases:
            p = run(args, expect=1)
            assert words in p.stderr, f"{args}: '{words}' not in: {p.stderr}"
        # NaN and infinity pass CLI11's range checks: every option refuses them by name (exit 2, nothing run).
        for option, value in (("--positive-m", "nan"), ("--label-noise", "nan"), ("--negative-m", "inf")):
            p = run(["--protocol", "sequence", "--sim", option, value, "--out", os.path.join(tmp, "nan")], expect=2)
            assert f"{option} must be a finite number" in p.stderr, p.stderr
            assert not os.path.exists(os.path.join(tmp, "nan")), option
        print("ok")
        return 0
    except BaseException:
        if server:  # the server's side of a failure: whether it still runs, and what it logged last
            print(f"sglc-server: {'running' if server.poll() is None else f'exited {server.returncode}'}; its log "
                  f"ends:\n{tail(server_log)}", file=sys.stderr)
        raise
    finally:
        if server:
            server.terminate()
            server.wait(timeout=30)
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
