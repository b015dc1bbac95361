#!/usr/bin/env bash
# clang-tidy (.clang-tidy: function size <= 80 lines, a few bug checks) on the C++ sources changed since BASE
# (default: HEAD~1), using build/compile_commands.json. `scripts/tidy.sh main` before sending a branch.
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-HEAD~1}
[ -f build/compile_commands.json ] || { echo "build/compile_commands.json missing: run scripts/build.sh" >&2; exit 2; }
mapfile -t files < <(git diff --name-only --diff-filter=AM "$base" -- '*.cpp' | while read -r f; do
  grep -q "\"file\": \"$(pwd)/$f\"" build/compile_commands.json && echo "$f"; done)
if [ ${#files[@]} -eq 0 ]; then
  echo "tidy: no changed C++ sources since $base"
  exit 0
fi
echo "tidy: ${#files[@]} file(s) changed since $base"
clang-tidy -p build --quiet "${files[@]}"
