#!/usr/bin/env python3
"""Writes docs/RESULTS.md (on stdout) from the summaries scripts/results.sh leaves in RESULTS_DIR."""
import csv
import datetime
import os
import platform
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import field_md  # noqa: E402
from field_md import f3, load  # noqa: E402


def pct(x):
    return "-" if x is None else f"{100 * x:.1f} %"


def lowest_precision(run_dir):
    """Precision at the PR curve's lowest threshold (every verified detection), from pr.csv."""
    try:
        with open(os.path.join(run_dir, "pr.csv")) as f:
            rows = list(csv.DictReader(f))
    except FileNotFoundError:
        return None
    return float(rows[0]["precision"]) if rows else None


BEGIN_LABELS = "<!-- label-free results: begin (scripts/results.sh PARTS=\"labels nuscenes\") -->"
END_LABELS = "<!-- label-free results: end -->"


def verified_share(run_dir):
    """Share of the pose protocol's pairs that verification accepted, from pose_errors.csv."""
    try:
        with open(os.path.join(run_dir, "pose_errors.csv")) as f:
            rows = list(csv.DictReader(f))
    except FileNotFoundError:
        return None
    return sum(r["verified"] == "1" for r in rows) / len(rows) if rows else None


def labels_section(root):
    """The label-free sections: simulated runs with labels given / computed / completed, other sensors, and
    nuScenes scene 1072. Empty when none of their runs is present."""
    out = []
    w = out.append
    modes = [("given", "given (ground truth)"), ("computed", "none sent: computed by the labeller"),
             ("completed", "without pole and trunk ids: completed by the labeller")]
    runs = []
    for seq in ("00", "05", "08"):
        for mode, what in modes:
            runs.append((f"labels-{seq}-{mode}", seq, "64", what))
        for beams in ("32", "128"):
            runs.append((f"labels-{seq}-computed-beams{beams}", seq, beams, modes[1][1]))
    runs = [r for r in runs if os.path.isdir(os.path.join(root, r[0]))]
    nus = os.path.join(root, "nuscenes")
    if not runs and not os.path.isdir(nus):
        return out
    w(BEGIN_LABELS)
    if runs:
        w("## Without labels: given, computed and completed labels side by side (simulated, all protocols)")
        w("")
        w("The same simulated sequences (seed 7, no label noise) with their ground-truth labels sent (given), with "
          "points only (the engine's labeller computes every label: `sglc-eval --no-labels`), and with a label set "
          "that has no pole or trunk ids (poles inside buildings, trunks inside vegetation, as nuScenes-lidarseg "
          "labels them; the labeller completes those roles, `labeller.mode: auto`). Sequence protocol as above "
          "(F1max, Recall@1, precision of every verified top-1 whatever its score, pose errors of the true top-1); "
          "pair protocol on the SSC neg_1 lists; pose protocol on the loop_distance4 pairs. Targets for labels "
          "computed (issue): F1max >= 0.93, precision of every verified top-1 >= 0.98, pose RR 100 % with RTE <= "
          "0.05 m.")
        w("")
        w("| sequence | beams | labels | seq. F1max | Recall@1 | precision, all verified | seq. RR / RTE | "
          "pair F1max | pair EP | pose RR | pose verified | pose RTE / RRE mean | fingerprint median |")
        w("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for name, seq, beams, what in runs:
            d = os.path.join(root, name)
            q = load(os.path.join(d, "sequence", "summary.json")) or {}
            p = load(os.path.join(d, "pairs", "summary.json")) or {}
            r = load(os.path.join(d, "pose", "summary.json")) or {}
            fp = q.get("timings", {}).get("fingerprint", {}).get("median_ms")
            w(f"| {seq} | {beams} | {what} | {f3(q.get('f1max'))} | {f3(q.get('recall_at_1'))} | "
              f"{f3(lowest_precision(os.path.join(d, 'sequence')))} | {pct(q.get('rr'))} / {f3(q.get('rte_mean'))} m | "
              f"{f3(p.get('f1max'))} | {f3(p.get('ep'))} | {pct(r.get('rr'))} | "
              f"{pct(verified_share(os.path.join(d, 'pose')))} | {f3(r.get('rte_mean'))} m / {f3(r.get('rre_mean'))} "
              f"deg | {'-' if fp is None else f'{fp:.1f} ms'} |")
        w("")
        w("\"pose verified\": share of the listed loop pairs verification accepts (each is registered either way).")
        w("")
    if os.path.isdir(nus):
        w("## nuScenes scene 1072 (real HDL-32E, nuScenes-lidarseg labels): consecutive and next-but-one scans")
        w("")
        w("All 39 consecutive and 38 next-but-one pairs (3-9 m apart), registered as known loops by the pose "
          "protocol. Reference: a dense point-to-plane registration of the two full scans "
          "(`tools/eval/dense_reference.py`); the recorded poses (poses.txt) are themselves off from it (below), "
          "so they are a coarser reference. Labels: the scene's own (preset `nuscenes`, labeller off: vehicles "
          "are its only landmarks), completed (preset `nuscenes`, labeller auto: poles and trunks added), none "
          "(labeller computes all).")
        w("")
        ref = os.path.join(nus, "dense_reference.txt")
        if os.path.exists(ref):
            for line in open(ref):
                if line.startswith("gap"):
                    w(f"- {line.strip()}")
            w("")
        w("| labels | verified | RR vs dense | RTE / RRE median vs dense | RTE / RRE mean vs dense | "
          "RR vs poses.txt | RTE / RRE median vs poses.txt |")
        w("|---|---|---|---|---|---|---|")
        for mode in ("own", "completed", "computed"):
            a = load(os.path.join(nus, f"{mode}-dense", "summary.json"))
            b = load(os.path.join(nus, f"{mode}-recorded", "summary.json")) or {}
            if not a:
                continue
            w(f"| {mode} | {pct(verified_share(os.path.join(nus, f'{mode}-dense')))} | {pct(a['rr'])} | "
              f"{f3(a['rte_median'])} m / {f3(a['rre_median'])} deg | {f3(a['rte_mean'])} m / {f3(a['rre_mean'])} deg | "
              f"{pct(b.get('rr'))} | {f3(b.get('rte_median'))} m / {f3(b.get('rre_median'))} deg |")
        w("")
    w(END_LABELS)
    w("")
    return out


def splice(path, root):
    """RESULTS.md at path with its label-free sections replaced by the ones of root (or added before the
    figures)."""
    def before_figures(text):
        return text.index("## Figures") if "## Figures" in text else len(text)
    return field_md.replace_section(path, labels_section(root), BEGIN_LABELS, END_LABELS, before_figures)


def main():
    if len(sys.argv) == 4 and sys.argv[1] == "--splice":
        sys.stdout.write(splice(sys.argv[2], sys.argv[3]))
        return
    if len(sys.argv) != 2 or not os.path.isdir(sys.argv[1]):
        sys.exit("usage: results_md.py RESULTS_DIR | results_md.py --splice RESULTS.md RESULTS_DIR")
    root = sys.argv[1]
    rel = os.path.relpath(root, "docs") if os.path.isdir("docs") else root
    runs = sorted(d for d in os.listdir(root) if d.startswith("sim-"))
    out = []
    w = out.append
    w("# Results")
    w("")
    w(f"Generated by `scripts/results.sh` ({datetime.date.today().isoformat()}, {platform.machine()}, "
      f"{os.cpu_count()} cores) with `build/bin/sglc-eval`; every number below was measured by that run. "
      f"Summaries, CSV files and figures are in `docs/results/` after running it (not committed). Engine "
      f"configuration: the defaults of this commit (`build/bin/sglc-pair --dump-config`). Only the runs present "
      f"in `docs/results/` are listed (`SEQS=... NOISES=...` select them; the default is every sequence at 5, 0 "
      f"and 15 % noise). Times come from whatever else the machine was running; the benchmarks in docs/PERFORMANCE.md "
      f"are the reference for speed.")
    w("")
    w("Data: the simulator (`tools/sim`) following the KITTI ground-truth trajectories 00, 05 and 08 (HDL-64, "
      "seed 7; label noise applied as `LabelNoise::fromRate`), with the published pair lists of KITTI frame "
      "numbers: SSC `neg_1` lists for the pair protocol and LCR-Net `loop_distance4` for the pose protocol. "
      "00's camera poses are converted with the Tr of the shared `calib.txt`, 05's and 08's with KITTI's "
      "04-10 Tr (`tools/sim/calib`); the simulated world is built along the converted path and the sensor "
      "rides 1.73 m over its ground (KITTI's recorded heights disagree by up to 4 m between passes of 08). "
      "Ground truth is the pose each frame was rendered from. Simulated worlds are not KITTI: these numbers "
      "show the method and its regressions, they are not a substitute for a run on the real sequences.")
    w("")
    if os.path.isdir(os.path.join(root, "field")):  # scripts/field.sh's runs come first: the headline
        out.extend(field_md.section(os.path.join(root, "field")))
    w("## The paper's numbers (real KITTI, as reported; do not mix protocols)")
    w("")
    w("| protocol | paper (SGLC, RA-L 2024) | our comparable table |")
    w("|---|---|---|")
    w("| distance protocol, SSC pair lists (positive < 3 m, negative > 20 m) | mean F1max 0.972, EP 0.964 | "
      "pair protocol (neg_1 lists, simulated) |")
    w("| overlap protocol, KITTI 00 (overlap > 0.3) | AUC 0.949, F1max 0.931, Recall@1 0.950, Recall@1% 0.986 | "
      "none: our sequence protocol uses distance (positive < 3 m), not overlap |")
    w("| loop pose, pairs < 4 m (loop_distance4) | 00: RR 100 %, RTE 0.04 m, RRE 0.21 deg; 08: RR 100 %, 0.08 m, "
      "0.41 deg | pose protocol (simulated) and the real pair |")
    w("| time (AMD 3960X) | 10.2 ms per scan (descriptor + loop decision), 20.8 ms pose estimation | "
      "timings table |")
    w("")

    w("## Pair protocol (SSC neg_1 lists: every positive and as many negatives)")
    w("")
    w("Score of a pair: the verification score if the pair is verified, else 0 (never a detection).")
    w("")
    w("| sequence | label noise | pairs used | positives | F1max | EP | AUC |")
    w("|---|---|---|---|---|---|---|")
    for r in runs:
        s = load(os.path.join(root, r, "pairs", "summary.json"))
        if s:
            seq, noise = r[4:6], r.split("noise")[1]
            w(f"| {seq} | {pct(float(noise))} | {s['pairs_used']} | {s['positives']} | {f3(s['f1max'])} | "
              f"{f3(s['ep'])} | {f3(s['auc'])} |")
    w("")

    w("## Sequence protocol (every frame queries all earlier frames but the last 100)")
    w("")
    w("Retrieval of 10 descriptor neighbours (at least 1 % of the frames), verification, top-1 threshold sweep. "
      "A true loop is a frame closer than 3 m; a top-1 candidate between 3 and 20 m counts as no detection. "
      "RR/RTE/RRE: refined poses of the true top-1 detections against ground truth.")
    w("")
    w("\"Precision, all verified\": the precision of every verified top-1 detection whatever its score (the "
      "PR curve's lowest threshold), i.e. how often a loop the service reports as verified is a true loop.")
    w("")
    w("| sequence | noise | queries with a loop | F1max | EP | AUC | Recall@1 | Recall@1% | false loops at F1max "
      "| precision, all verified | RR | RTE mean | RRE mean |")
    w("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        s = load(os.path.join(root, r, "sequence", "summary.json"))
        if s:
            seq, noise = r[4:6], r.split("noise")[1]
            w(f"| {seq} | {pct(float(noise))} | {s['queries_with_true_loop']} / {s['queries']} | {f3(s['f1max'])} | "
              f"{f3(s['ep'])} | {f3(s['auc'])} | {f3(s['recall_at_1'])} | {f3(s['recall_at_1pct'])} | "
              f"{s['at_f1max']['false_loops']} | {f3(lowest_precision(os.path.join(root, r, 'sequence')))} | "
              f"{pct(s['rr'])} | {f3(s['rte_mean'])} m | {f3(s['rre_mean'])} deg |")
    w("")

    w("## Pose protocol (LCR-Net loop_distance4 pairs, ground truth from the simulated trajectory)")
    w("")
    w("The listed pairs are known loops: each is registered whether or not verification accepts it, as the paper "
      "(following LCDNet) registers every listed pair. RR: share of pairs with RTE < 2 m and RRE < 5 deg; "
      "RR verified: of those, the ones verification also accepted (share of all pairs).")
    w("")
    w("| sequence | noise | pairs | RR | RR verified | RTE mean / median | RRE mean / median |")
    w("|---|---|---|---|---|---|---|")
    for r in runs:
        s = load(os.path.join(root, r, "pose", "summary.json"))
        if s:
            seq, noise = r[4:6], r.split("noise")[1]
            rv = pct(s['rr_verified']) if 'rr_verified' in s else "-"
            w(f"| {seq} | {pct(float(noise))} | {s['pose_pairs']} | {pct(s['rr'])} | {rv} | {f3(s['rte_mean'])} / "
              f"{f3(s['rte_median'])} m | {f3(s['rre_mean'])} / {f3(s['rre_median'])} deg |")
    w("")

    w("## Targets at 5 % label noise (issue: F1max >= 0.97, EP >= 0.95, RR 100 % with RTE <= 0.05 m, "
      "RRE <= 0.3 deg)")
    w("")
    w("| sequence | pair F1max | pair EP | pose RR | pose RTE mean | pose RRE mean | met |")
    w("|---|---|---|---|---|---|---|")
    for r in runs:
        if not r.endswith("noise0.05"):
            continue
        p = load(os.path.join(root, r, "pairs", "summary.json")) or {}
        q = load(os.path.join(root, r, "pose", "summary.json")) or {}
        missed = [name for name, ok in [("F1max", p.get("f1max", 0) >= 0.97), ("EP", p.get("ep", 0) >= 0.95),
                                        ("RR", q.get("rr", 0) == 1.0), ("RTE", q.get("rte_mean", 9) <= 0.05),
                                        ("RRE", q.get("rre_mean", 9) <= 0.3)] if not ok]
        w(f"| {r[4:6]} | {f3(p.get('f1max'))} | {f3(p.get('ep'))} | {pct(q.get('rr'))} | {f3(q.get('rte_mean'))} m | "
          f"{f3(q.get('rre_mean'))} deg | {'yes' if not missed else '**no**: ' + ', '.join(missed)} |")
    w("")
    w("Pairs verification rejects (places whose noisy labels leave too few consistent landmarks or too little "
      "background agreement) are registered from the landmarks' coarse pose or, where that fails, from the "
      "background views alone (docs/ENGINE.md, \"known loops\").")
    w("")

    w("## Time per frame (sequence protocol, in-process, medians / p90 in ms)")
    w("")
    w("| run | fingerprint | search | verify (10 candidates) | refine | store | total |")
    w("|---|---|---|---|---|---|---|")
    for r in runs:
        s = load(os.path.join(root, r, "sequence", "summary.json"))
        if s:
            t = s["timings"]
            cells = " | ".join(f"{t[k]['median_ms']:.2f} / {t[k]['p90_ms']:.2f}"
                               for k in ("fingerprint", "search", "verify", "refine", "store", "total"))
            w(f"| {r[4:]} | {cells} |")
    w("")

    w("## Real SemanticKITTI scans (../shared/data/semantickitti_scans)")
    w("")
    p = load(os.path.join(root, "real", "pairs", "summary.json"))
    q = load(os.path.join(root, "real", "pose", "summary.json"))
    if p:
        w(f"Pair protocol over the {p['pairs_used']} listed pairs ({p['positives']} loop, {p['negatives']} "
          f"non-loops): F1max {f3(p['f1max'])}, EP {f3(p['ep'])}.")
    if q:
        w(f"Pose of the loop (4501 querying 52) against pairs.txt's reference: RR {pct(q['rr'])}, RTE {q['rte_mean']:.3f} m, "
          f"RRE {q['rre_mean']:.3f} deg (paper, KITTI 00 mean: 0.04 m, 0.21 deg). pairs.txt's pose comes from "
          f"SemanticKITTI's trajectory and is itself 36 mm / 0.12 deg from a dense point-to-plane registration "
          f"of the two full scans; against that registration the engine's pose of 52 querying 4501 is "
          f"6 mm / 0.10 deg off "
          f"(`RealPipeline.LoopPairAgreesWithDenseRegistration`).")
    w("")

    w("## Ablations (built-in route, every 3rd frame, sequence protocol, no label noise)")
    w("")
    w("| configuration | F1max | EP | Recall@1 | RR | RTE mean | RRE mean | verify median | refine p90 |")
    w("|---|---|---|---|---|---|---|---|---|")
    for name, what in [("default", "defaults (prune with >= 15 matches, fine ICP, plane refine)"),
                       ("prune-always", "triangle pruning always (the paper)"),
                       ("no-pruning", "no triangle pruning"),
                       ("no-fine-icp", "no instance ICP"),
                       ("no-plane-refine", "no plane refinement"),
                       ("coarse-only", "coarse RANSAC pose only")]:
        s = load(os.path.join(root, "ablation", name, "summary.json"))
        if s:
            t = s["timings"]
            w(f"| {what} | {f3(s['f1max'])} | {f3(s['ep'])} | {f3(s['recall_at_1'])} | {pct(s['rr'])} | "
              f"{f3(s['rte_mean'])} m | {f3(s['rre_mean'])} deg | {t['verify']['median_ms']:.2f} ms | "
              f"{t['refine']['p90_ms']:.2f} ms |")
    w("")
    w("The node descriptor's global part cannot be switched off by configuration (`descriptor.k_eigen` >= 1), "
      "so that ablation of the paper's table is not run.")
    w("")
    noisy = [(name, what) for name, what in [
        ("default", "defaults"),
        ("no-prune-fallback", "no fallback when pruning keeps too few matches (`match.prune_min_kept: 0`)"),
        ("no-plane-fit", "no plane fit of the pose hypotheses (`verify.fit_max_shift_m: 0`)"),
        ("keep-fragments", "fragments kept as nodes (`graph.min_extent_m: 0`)"),
        ("no-background-sources", "no pose hypotheses from the background (`verify.background_max_nodes: 0`)"),
        ("anchor-everywhere", "instance pairs anchor every direction (`refine.min_information: 1e9`)")]
        if load(os.path.join(root, "ablation-noise", name, "summary.json"))]
    if noisy:
        w("## Ablations of this engine's own changes (built-in route, every 3rd frame, 5 % label noise)")
        w("")
        w("\"Precision, all verified\" as in the sequence table.")
        w("")
        w("| configuration | F1max | EP | Recall@1 | precision, all verified | RR | RTE mean | RRE mean |")
        w("|---|---|---|---|---|---|---|---|")
        for name, what in noisy:
            d = os.path.join(root, "ablation-noise", name)
            s = load(os.path.join(d, "summary.json"))
            w(f"| {what} | {f3(s['f1max'])} | {f3(s['ep'])} | {f3(s['recall_at_1'])} | {f3(lowest_precision(d))} | "
              f"{pct(s['rr'])} | {f3(s['rte_mean'])} m | {f3(s['rre_mean'])} deg |")
        w("")
    w("## Pose graph (SLAM protocol through a server: KITTI 00's path, 1 % odometry drift)")
    w("")
    w("ATE after SE(3) alignment; odometry aligned per robot, optimised poses of all robots with one alignment. "
      "Target (issue): ATE reduced at least 5x; the two robots' frames aligned within 0.3 m / 0.5 deg.")
    w("")
    w("| robots | scans | loops reported | ATE odometry | ATE optimised | reduction | second robot's frame |")
    w("|---|---|---|---|---|---|---|")
    for robots in (1, 2):
        s = load(os.path.join(root, f"slam-00-robots{robots}", "summary.json"))
        if s:
            fa = s.get("frame_alignment_error")
            frame = f"{fa['m']:.3f} m / {fa['deg']:.3f} deg" if fa else "-"
            w(f"| {robots} | {s['frames'] if robots == 1 else sum(r['frames'] for r in s['per_robot'])} | "
              f"{s['loops_reported']} | {s['ate_odometry']:.3f} m | {s['ate_optimised']:.3f} m | "
              f"{s['ate_odometry'] / max(s['ate_optimised'], 1e-9):.1f}x | {frame} |")
    w("")
    out.extend(labels_section(root))
    w("## Figures")
    w("")
    for robots in (1, 2):
        w(f"- slam-00-robots{robots}: `{rel}/slam-00-robots{robots}/slam.png`")
    for r in runs:
        w(f"- {r}: `{rel}/{r}/sequence/pr_curve.png`, `{rel}/{r}/sequence/trajectory.png`, "
          f"`{rel}/{r}/pairs/pr_curve.png`, `{rel}/{r}/pose/pose_errors.png`")
    print("\n".join(out))


if __name__ == "__main__":
    main()
