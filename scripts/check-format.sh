#!/usr/bin/env bash
# Fails (listing the files) when a C++ file (tracked, or new and not ignored) differs from what .clang-format
# makes of it.
# `scripts/check-format.sh --fix` rewrites them instead. The tree is formatted with clang-format 14 (Debian 12).
set -euo pipefail
cd "$(dirname "$0")/.."
command -v clang-format >/dev/null || { echo "clang-format is not installed (scripts/install-deps.sh)" >&2; exit 2; }
version=$(clang-format --version | grep -oE '[0-9]+\.[0-9]+' | head -1)
[ "${version%%.*}" = 14 ] || echo "warning: clang-format $version; the tree is formatted with 14" >&2
files=()
while IFS= read -r -d '' f; do files+=("$f"); done < <(git ls-files -z --cached --others --exclude-standard '*.cpp' '*.hpp' '*.h' '*.cc')
if [ "${1:-}" = "--fix" ]; then
  clang-format -i "${files[@]}"
  exit 0
fi
bad=()
for f in "${files[@]}"; do
  out=$(clang-format --dry-run --Werror "$f" 2>&1) && continue
  # A file that is not formatted gives "code should be clang-formatted" warnings; anything else is a failure.
  grep -q "clang-format-violations" <<< "$out" || { echo "clang-format failed on $f: $out" >&2; exit 2; }
  bad+=("$f")
done
if [ ${#bad[@]} -gt 0 ]; then
  echo "these files are not formatted (.clang-format); run scripts/check-format.sh --fix:" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "format: ${#files[@]} C++ files follow .clang-format"
