#!/usr/bin/env bash
# Regenerates docs/CONFIGURATION.md (every key of sglc-server, sglc-pair and sglc-eval: default, valid values,
# meaning) from the settings registry. Run after adding or changing a setting; a test fails while they differ.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/bin/sglc-server ] || { echo "gen-config-doc: build/bin/sglc-server missing: run scripts/build.sh" >&2; exit 2; }
build/bin/sglc-server --config-reference > docs/CONFIGURATION.md
echo "wrote docs/CONFIGURATION.md"
