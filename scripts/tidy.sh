#!/usr/bin/env bash
# clang-tidy (.clang-tidy: function size <= 80 lines, a few bug checks) on the C++ sources a branch changed:
# those added, modified or renamed since its merge base with BASE (default: HEAD~1), using
# build/compile_commands.json. `scripts/tidy.sh main` before sending a branch.
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-HEAD~1}
git rev-parse --verify --quiet "$base^{commit}" >/dev/null || { echo "tidy: '$base' is not a commit" >&2; exit 2; }
[ -f build/compile_commands.json ] || { echo "tidy: build/compile_commands.json missing: run scripts/build.sh" >&2; exit 2; }
from=$(git merge-base "$base" HEAD)
changed=$(git diff --name-only --diff-filter=d "$from" -- '*.cpp')
files=()
while IFS= read -r f; do
  [ -n "$f" ] && grep -qF "\"file\": \"$PWD/$f\"" build/compile_commands.json && files+=("$f")
done <<< "$changed"
if [ ${#files[@]} -eq 0 ]; then
  echo "tidy: no changed C++ sources since $(git rev-parse --short "$from")"
  exit 0
fi
echo "tidy: ${#files[@]} file(s) changed since $(git rev-parse --short "$from")"
clang-tidy -p build --quiet "${files[@]}"
