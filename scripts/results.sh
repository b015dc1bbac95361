#!/bin/bash
# Regenerates docs/RESULTS.md with build/bin/sglc-eval: simulated sequences along KITTI 00, 05 and 08 at 0, 5
# and 15 % label noise (sequence, pair and pose protocols), the real pairs of ../shared/data, and ablations.
# Summaries, CSV files and figures go to docs/results/ (generated, not committed).
#   scripts/results.sh                    # everything (about three hours on 2 cores)
#   SEQS=00 NOISES=0.05 scripts/results.sh   # a subset
#   PARTS="real ablation" scripts/results.sh # only some parts: real, ablation, sim, labels, nuscenes, slam
#                                            # (default: all)
#   PROTOCOLS=pose PARTS=sim scripts/results.sh  # simulated runs of one protocol only (pairs, sequence, pose)
# RESULTS.md is written from every run present in docs/results, so parts can be re-run one at a time.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${DATA:-../shared/data}
EVAL=${EVAL:-build/bin/sglc-eval}
OUT=docs/results
SEQS=${SEQS-"00 05 08"}
NOISES=${NOISES-"0.05 0 0.15"}  # the target noise first
[ -x "$EVAL" ] || { echo "results.sh: $EVAL missing: run scripts/build.sh first" >&2; exit 1; }
[ -d "$DATA/kitti_odometry_gt_poses" ] || { echo "results.sh: $DATA (KITTI poses, pair lists) is absent" >&2; exit 1; }
mkdir -p "$OUT"
# Sequences 00-02 share the Tr of the shared data's calib.txt; 04-10 share KITTI's other published Tr, kept in
# tools/sim/calib (the simulated world is built along the converted path, so either keeps the data consistent).
CALIB=$DATA/semantickitti_scans/sequences/00/calib.txt
calibFor() { if [[ "$1" > "03" ]]; then echo tools/sim/calib/kitti-04-10-calib.txt; else echo "$CALIB"; fi; }

PARTS=${PARTS:-"real ablation sim labels nuscenes slam"}
[ "${SIM_ONLY:-0}" = 1 ] && PARTS="sim slam"  # older spelling: skip the quick parts
want() { [[ " $PARTS " == *" $1 "* ]]; }
[ "${SLAM:-1}" = 1 ] || PARTS=${PARTS/slam/}

if want real; then
# The real SemanticKITTI scans: every listed pair scored, and the loop's pose against its reference.
real=$OUT/real
mkdir -p "$real"
grep -v '^#' "$DATA/semantickitti_scans/pairs.txt" | awk '{print $2+0, $3+0, $4}' > "$real/pairs.txt"
# pairs.txt's T_a_b maps b into a; sglc-eval's pose rows "i j T" map i into j, so the loop is written "b a T".
grep -v '^#' "$DATA/semantickitti_scans/pairs.txt" | awk '$4 == 1 {printf "%d %d", $3, $2; for (k = 8; k <= 19; k++) printf " %s", $k; print ""}' > "$real/loops.txt"
"$EVAL" --protocol pairs --data "$DATA/semantickitti_scans/sequences/00" --pairs "$real/pairs.txt" \
  --out "$real/pairs" --no-plots > /dev/null
"$EVAL" --protocol pose --data "$DATA/semantickitti_scans/sequences/00" --pairs "$real/loops.txt" --gt-from-pairs \
  --out "$real/pose" --no-plots > /dev/null

fi

if want ablation; then
# Ablations on the built-in route (every 3rd frame), sequence protocol.
abl=$OUT/ablation
mkdir -p "$abl"
declare -A CONFIGS=(
  [default]=""
  [prune-always]="match: {prune_min_matches: 0}"
  [no-pruning]="match: {prune_min_matches: 1000000}"
  [no-fine-icp]="fine: {enabled: false}"
  [no-plane-refine]="refine: {enabled: false}"
  [coarse-only]=$'fine: {enabled: false}\nrefine: {enabled: false}'
)
for name in default prune-always no-pruning no-fine-icp no-plane-refine coarse-only; do
  echo "== ablation $name" >&2
  printf '%s\n' "${CONFIGS[$name]}" > "$abl/$name.yaml"
  "$EVAL" --protocol sequence --sim --frames ::3 --config "$abl/$name.yaml" --title "ablation: $name" \
    --out "$abl/$name" --no-plots > /dev/null
done
# This engine's own changes, each switched off, at 5 % label noise.
abl=$OUT/ablation-noise
mkdir -p "$abl"
declare -A NOISY=(
  [default]=""
  [no-prune-fallback]="match: {prune_min_kept: 0}"
  [no-plane-fit]="verify: {fit_max_shift_m: 0}"
  [keep-fragments]="graph: {min_extent_m: 0}"
  [no-background-sources]="verify: {background_max_nodes: 0}"
  [anchor-everywhere]="refine: {min_information: 1000000000}"
)
for name in default no-prune-fallback no-plane-fit keep-fragments no-background-sources anchor-everywhere; do
  echo "== ablation at 5 % noise: $name" >&2
  printf '%s\n' "${NOISY[$name]}" > "$abl/$name.yaml"
  "$EVAL" --protocol sequence --sim --frames ::3 --label-noise 0.05 --config "$abl/$name.yaml" \
    --title "ablation at 5 % noise: $name" --out "$abl/$name" --no-plots > /dev/null
done
fi

if want sim; then

PROTOCOLS=${PROTOCOLS:-all}
for seq in $SEQS; do
  for noise in $NOISES; do
    dir=$OUT/sim-$seq-noise$noise
    if [ "$PROTOCOLS" != all ]; then
      for p in $PROTOCOLS; do
        echo "== simulated $seq, label noise $noise, $p protocol -> $dir/$p" >&2
        case $p in
          pose) pairs=(--pairs "$DATA/loop_gt_lcrnet/loop_distance4/$seq.txt") ;;
          pairs) pairs=(--pairs "$DATA/ssc_pairs/neg_1/$seq.txt") ;;
          *) pairs=() ;;
        esac
        "$EVAL" --protocol "$p" --sim --poses "$DATA/kitti_odometry_gt_poses/poses/$seq.txt" --calib "$(calibFor "$seq")" \
          --label-noise "$noise" "${pairs[@]}" --title "simulated KITTI $seq, label noise $noise - $p" \
          --out "$dir/$p" > /dev/null
      done
      # The combined summary of an earlier --protocol all run would keep the old numbers: rebuild it.
      /usr/bin/python3 -c 'import json, os, sys
d = sys.argv[1]
parts = {p: json.load(open(os.path.join(d, p, "summary.json"))) for p in ("sequence", "pairs", "pose")
         if os.path.exists(os.path.join(d, p, "summary.json"))}
json.dump(parts, open(os.path.join(d, "summary.json"), "w"), indent=2)' "$dir"
      continue
    fi
    echo "== simulated $seq, label noise $noise -> $dir" >&2
    "$EVAL" --protocol all --sim --poses "$DATA/kitti_odometry_gt_poses/poses/$seq.txt" --calib "$(calibFor "$seq")" \
      --label-noise "$noise" --pairs "$DATA/ssc_pairs/neg_1/$seq.txt" \
      --pose-pairs "$DATA/loop_gt_lcrnet/loop_distance4/$seq.txt" \
      --title "simulated KITTI $seq, label noise $noise" --out "$dir" > /dev/null
  done
done
fi

# The label-free path (issue: raw LiDAR): the same simulated sequences with their labels given (ground truth),
# removed (the engine's labeller computes them) and lacking pole and trunk ids (poles inside buildings, trunks
# inside vegetation, as nuScenes-lidarseg labels them: the labeller completes them); then without labels on
# 32- and 128-beam sensors (first sequence of SEQS).
if want labels; then
  LABEL_MODES=${LABEL_MODES-"computed completed given"}
  BEAMS=${BEAMS-"32 128"}
  mkdir -p "$OUT/labels-config"
  completed=$OUT/labels-config/completed.yaml
  cat > "$completed" <<'YAML'
labels:
  node_classes:
    - {name: vehicle, ids: [10, 18, 20]}
    - {name: trunk, ids: []}
    - {name: pole, ids: []}
  building: [50, 80, 81]
  vegetation: [70, 71]
YAML
  labelRun() {  # sequence, mode, beams, output directory
    local args=()
    case $2 in
      computed) args=(--no-labels) ;;
      completed) args=(--config "$completed") ;;
    esac
    echo "== labels $2, simulated $1, $3 beams -> $4" >&2
    "$EVAL" --protocol all --sim --poses "$DATA/kitti_odometry_gt_poses/poses/$1.txt" --calib "$(calibFor "$1")" \
      --beams "$3" "${args[@]}" --pairs "$DATA/ssc_pairs/neg_1/$1.txt" \
      --pose-pairs "$DATA/loop_gt_lcrnet/loop_distance4/$1.txt" --no-plots \
      --title "simulated KITTI $1, $3 beams, labels $2" --out "$4" > /dev/null
  }
  for seq in $SEQS; do
    for mode in $LABEL_MODES; do labelRun "$seq" "$mode" 64 "$OUT/labels-$seq-$mode"; done
  done
  first=${SEQS%% *}
  for beams in $BEAMS; do labelRun "$first" computed "$beams" "$OUT/labels-$first-computed-beams$beams"; done
fi

# nuScenes scene 1072 (real HDL-32E, nuScenes-lidarseg labels): consecutive and next-but-one scans, with the
# scene's own labels (preset nuscenes, labeller off), completed by the labeller, and without labels; poses
# against a dense registration of the full scans and against the recorded poses.
if want nuscenes; then
  nus=$OUT/nuscenes
  scene=$DATA/nuscenes_scene1072
  mkdir -p "$nus"
  if [ -d "$scene" ]; then
    /usr/bin/python3 tools/eval/dense_reference.py "$scene" --gaps 1,2 --out "$nus/dense_pairs.txt" > "$nus/dense_reference.txt"
    awk '{print $1, $2}' "$nus/dense_pairs.txt" > "$nus/pairs.txt"
    printf 'labels: {preset: nuscenes}\nlabeller: {mode: "off"}\n' > "$nus/own.yaml"
    printf 'labels: {preset: nuscenes}\n' > "$nus/completed.yaml"
    for mode in own completed computed; do
      cfg=$nus/completed.yaml extra=()
      [ $mode = own ] && cfg=$nus/own.yaml
      [ $mode = computed ] && extra=(--no-labels)
      echo "== nuScenes 1072, labels $mode" >&2
      "$EVAL" --protocol pose --data "$scene" --pairs "$nus/dense_pairs.txt" --gt-from-pairs --config "$cfg" \
        "${extra[@]}" --no-plots --out "$nus/$mode-dense" > /dev/null
      "$EVAL" --protocol pose --data "$scene" --pairs "$nus/pairs.txt" --config "$cfg" "${extra[@]}" --no-plots \
        --out "$nus/$mode-recorded" > /dev/null
    done
  else
    echo "results.sh: $scene absent: nuScenes part skipped" >&2
  fi
fi

# Pose graph (SLAM protocol) through a server: KITTI 00's path with 1 % odometry drift, one and two robots.
if want slam; then
  srv=$OUT/slam-server
  rm -rf "$srv" && mkdir -p "$srv"
  port=$((50000 + RANDOM % 10000))
  build/bin/sglc-server --db "$srv/map.db" --listen "127.0.0.1:$port" --sync-normal > "$srv/server.log" 2>&1 &
  server_pid=$!
  trap 'kill $server_pid 2>/dev/null || true' EXIT
  sleep 2
  for robots in 1 2; do
    echo "== slam, KITTI 00 path, $robots robot(s)" >&2
    "$EVAL" --protocol slam --sim --poses "$DATA/kitti_odometry_gt_poses/poses/00.txt" --calib "$CALIB" \
      --odom-noise 0.01 --robots "$robots" --server "127.0.0.1:$port" \
      --title "KITTI 00 path, 1 % drift, $robots robot(s)" --out "$OUT/slam-00-robots$robots" > /dev/null
  done
  kill $server_pid
  wait $server_pid || true
  trap - EXIT
fi

[ "${NO_REPORT:-0}" = 1 ] && exit 0
only_label_parts=1
for p in $PARTS; do [ "$p" = labels ] || [ "$p" = nuscenes ] || only_label_parts=0; done
if [ "$only_label_parts" = 0 ]; then
  /usr/bin/python3 tools/eval/results_md.py "$OUT" > docs/RESULTS.md
  echo "wrote docs/RESULTS.md" >&2
else
  # Only the label-free parts ran: their sections replace the old ones; the rest of RESULTS.md stays.
  /usr/bin/python3 tools/eval/results_md.py --splice docs/RESULTS.md "$OUT" > docs/RESULTS.md.new
  mv docs/RESULTS.md.new docs/RESULTS.md
  echo "updated the sections of docs/RESULTS.md that these parts produce" >&2
fi
