#!/usr/bin/env bash
# Configures and builds the project into build/ (executables in build/bin/). Arguments go to the configure step;
# SGLC_BUILD_TARGETS="a b" builds only those targets (scripts/demo.sh: what the demo runs, no tests).
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
targets=()
for t in ${SGLC_BUILD_TARGETS:-}; do targets+=(--target "$t"); done
cmake --build build -j "$(nproc)" "${targets[@]}"
