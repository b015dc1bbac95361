#!/usr/bin/env bash
# Sets up, builds, and checks the real KITTI loop pair (sequence 00, frames 52 and 4501) with sglc-pair.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh
DATA="${SGLC_DATA:-../shared/data}/semantickitti_scans/sequences/00"
if [ ! -d "$DATA" ]; then
  echo "demo: $DATA not found (set SGLC_DATA to the folder holding semantickitti_scans)" >&2
  exit 1
fi
build/bin/sglc-pair --scan-a "$DATA/velodyne/000052.bin" --labels-a "$DATA/labels/000052.label" \
                    --scan-b "$DATA/velodyne/004501.bin" --labels-b "$DATA/labels/004501.label"
