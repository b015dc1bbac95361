#!/bin/bash
# Field conditions: the engine on the simulator's realistic preset (network-like label noise, parked cars that
# come and go within the drive, per-laser calibration offsets, mixed pixels), then one day later, with other
# sensors and on look-alike streets. Writes docs/results/field/*/summary.json and splices the "Field
# conditions" section at the top of docs/RESULTS.md (tools/eval/field_md.py).
#   scripts/field.sh                         # everything (about 25 minutes on 2 cores)
#   PARTS="reloc sensors" scripts/field.sh   # some parts: sequence, iid, reloc, sensors, aliasing
#   SEED=12 SEQS=05 scripts/field.sh         # another world, one path
#   RELOC_SEQ=09 scripts/field.sh            # the relocalization map and queries on another path (default 00)
#   CONFIG=engine.yaml SPLICE=0 scripts/field.sh  # another engine configuration; leave docs/RESULTS.md alone
#   NO_LABELS=1                              # the sequence parts without labels (the engine's labeller)
#   SEQ_SENSOR=hdl32                         # the sequence parts with another sensor preset (default hdl64)
# Simulated scans go to a fresh directory under $WORK (default /tmp), deleted after each run and at exit; about
# 2 MB per frame while it lasts. A part that runs replaces its own results in $OUT; the others stay, and the
# tables name each run's seed.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${DATA:-../shared/data}
SIM=${SIM:-build/bin/sglc-sim}
EVAL=${EVAL:-build/bin/sglc-eval}
OUT=${OUT:-docs/results/field}
mkdir -p "${WORK:=/tmp}"
WORK=$(mktemp -d "$WORK/sglc-field.XXXXXX")  # only this directory is ever deleted
SEED=${SEED:-11}
SEQS=${SEQS-"00 05 08"}
STEP=${STEP:-1}  # the sequence protocol takes every STEP-th frame of the path (1: all, as the paper)
PARTS=${PARTS:-"sequence iid reloc sensors aliasing"}
RELOC_SEQ=${RELOC_SEQ:-00}
RELOC_STEP=${RELOC_STEP:-8}  # queries: every RELOC_STEP-th frame from frame 2
SPLICE=${SPLICE:-1}
EVAL_ARGS=()
[ -n "${CONFIG:-}" ] && EVAL_ARGS+=(--config "$CONFIG")
[ -n "${NO_LABELS:-}" ] && NO_LABELS_ARGS=(--no-labels) || NO_LABELS_ARGS=()
for tool in "$SIM" "$EVAL"; do [ -x "$tool" ] || { echo "field.sh: $tool missing: run scripts/build.sh" >&2; exit 1; }; done
[ -d "$DATA/kitti_odometry_gt_poses" ] || { echo "field.sh: $DATA (KITTI poses) is absent" >&2; exit 1; }
mkdir -p "$OUT"
trap 'rm -rf "$WORK"' EXIT
want() { [[ " $PARTS " == *" $1 "* ]]; }
poses() { echo "$DATA/kitti_odometry_gt_poses/poses/$1.txt"; }
calib() { if [[ "$1" > "03" ]]; then echo tools/sim/calib/kitti-04-10-calib.txt; else echo "$DATA/semantickitti_scans/sequences/00/calib.txt"; fi; }

# simulate NAME SEQ FRAMES [sglc-sim flags...]: renders into $WORK/NAME.
simulate() {
  local name=$1 seq=$2 frames=$3
  shift 3
  echo "== sglc-sim $name: KITTI $seq's path, frames $frames, $*" >&2
  "$SIM" --poses "$(poses "$seq")" --calib "$(calib "$seq")" --seed "$SEED" --frames "$frames" --quiet \
    --overwrite --out "$WORK/$name" "$@" > "$WORK/$name.sim.txt"
}
# sequence NAME: the sequence protocol on $WORK/NAME, into $OUT/NAME.
sequence() {
  rm -rf "${OUT:?}/$1"
  "$EVAL" --protocol sequence --data "$WORK/$1" --out "$OUT/$1" --title "field: $1" --no-plots \
    ${EVAL_ARGS[@]+"${EVAL_ARGS[@]}"} ${NO_LABELS_ARGS[@]+"${NO_LABELS_ARGS[@]}"} > /dev/null
  cp "$WORK/$1/sim_info.json" "$OUT/$1/sim_info.json"
  rm -rf "${WORK:?}/$1"
}
# relocalize MAP NAME: the queries of $WORK/NAME against the map $WORK/MAP, into $OUT/NAME. A relocalizing
# robot asks once, not at its keyframe rate, so each query verifies RELOC_CANDIDATES descriptor neighbours
# (QueryOptions.candidates; the service allows up to 200).
RELOC_CANDIDATES=${RELOC_CANDIDATES:-100}
relocalize() {
  rm -rf "${OUT:?}/$2"
  "$EVAL" --protocol relocalization --map-data "$WORK/$1" --data "$WORK/$2" --out "$OUT/$2" \
    --candidates "$RELOC_CANDIDATES" ${EVAL_ARGS[@]+"${EVAL_ARGS[@]}"} \
    --title "field: $2 against $1" --no-plots > /dev/null
  cp "$WORK/$2/sim_info.json" "$OUT/$2/sim_info.json"
  rm -rf "${WORK:?}/$2"
}

if want sequence; then
  for seq in $SEQS; do
    name=sequence-$seq
    [ -n "${SEQ_SENSOR:-}" ] && name=sequence-$seq-$SEQ_SENSOR
    simulate "$name" "$seq" "::$STEP" --realistic ${SEQ_SENSOR:+--sensor "$SEQ_SENSOR"}
    sequence "$name"
  done
fi
if want iid; then  # the ablation: yesterday's independent label noise, static world, ideal sensor
  seq=${SEQS%% *}
  simulate "iid-$seq" "$seq" "::$STEP" --label-noise 0.1
  sequence "iid-$seq"
fi
if want aliasing; then
  seq=${SEQS%% *}
  for rate in 0.5 1; do
    simulate "aliasing$rate-$seq" "$seq" "::$STEP" --realistic --aliasing "$rate"
    sequence "aliasing$rate-$seq"
  done
fi
if want reloc || want sensors; then
  # The map: every 4th frame of KITTI 00's path, HDL-64, today. Queries: every 8th frame from frame 2, so each
  # lies between two map frames (about 2 m from the nearest at KITTI's speeds).
  r=$RELOC_SEQ
  simulate "map-$r" "$r" ::4 --realistic
  if want reloc; then
    simulate "reloc-epoch1-$r" "$r" "2::$RELOC_STEP" --realistic --epoch 1
    relocalize "map-$r" "reloc-epoch1-$r"
    simulate "reloc-epoch30-$r" "$r" "2::$RELOC_STEP" --realistic --epoch 30
    relocalize "map-$r" "reloc-epoch30-$r"
  fi
  if want sensors; then
    for sensor in vlp16 hdl32 os1-128 rosette; do
      simulate "sensor-$sensor-$r" "$r" "2::$RELOC_STEP" --realistic --sensor "$sensor"
      relocalize "map-$r" "sensor-$sensor-$r"
    done
  fi
  rm -rf "${WORK:?}/map-$r"
fi

[ "$SPLICE" = 1 ] || exit 0
/usr/bin/python3 tools/eval/field_md.py --splice docs/RESULTS.md "$OUT" > docs/RESULTS.md.new
mv docs/RESULTS.md.new docs/RESULTS.md
echo "field.sh: updated the field section of docs/RESULTS.md from $OUT" >&2
