#!/bin/bash
# Fits the loop model (docs/METHOD.md, section 8) from simulated training worlds and writes it to
# core/models/loop_model.txt. Fitting uses only the simulator's KITTI paths 00, 05 and 08 with seeds below 100;
# validation (scripts/field.sh on paths 07, 09 and 10, seeds below 100) is run separately; every other path
# and seed is reserved for checks of the product and never run here.
#   scripts/calibrate.sh              # collect (about 40 minutes on 2 cores), then fit
#   FIT_ONLY=1 scripts/calibrate.sh   # refit from the evidence already collected in $OUT
# The worlds (seed 11): the sequence protocol (realistic preset) on 00, 05 and 08, every 2nd frame; the same
# without labels (the engine's labeller) on 05, every 3rd frame; relocalization one day and 30 days later and
# with VLP-16, HDL-32E, OS1-128 and rosette queries (every 24th frame from frame 2, 30 candidates each) against
# an HDL-64 map of every 4th frame of 00. Every candidate's hypotheses are collected with
# verify.min_probability 1, so that every source runs where it applies.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-docs/results/calibrate}
VERSION=${VERSION:-$(date -u +%Y-%m-%d)-$(git rev-parse --short HEAD)}
mkdir -p "$OUT"
if [ -z "${FIT_ONLY:-}" ]; then
  CONFIG=$(mktemp /tmp/sglc-calibrate.XXXXXX.yaml)
  trap 'rm -f "$CONFIG"' EXIT
  echo "verify: {min_probability: 1}" > "$CONFIG"
  export CONFIG SPLICE=0 SEED=11
  OUT="$OUT/seed11" STEP=2 PARTS=sequence scripts/field.sh
  OUT="$OUT/seed11" RELOC_STEP=24 RELOC_CANDIDATES=30 PARTS="reloc sensors" RELOC_SEQ=00 scripts/field.sh
  OUT="$OUT/seed11-nolabels" STEP=3 SEQS=05 PARTS=sequence NO_LABELS=1 scripts/field.sh
fi
/usr/bin/python3 tools/calibrate/fit.py --version "$VERSION" --out core/models/loop_model.txt \
  $(find "$OUT" -name evidence.csv | sort)
