#!/bin/sh
# Usage: check_version.sh BINARY "NAME VERSION"
# The binary answers --version with exactly one line "NAME VERSION", exit status 0, and --help with exit 0.
out=$("$1" --version) || { echo "$1 --version exited $?"; exit 1; }
[ "$out" = "$2" ] || { echo "$1 --version printed '$out', expected '$2'"; exit 1; }
"$1" --help >/dev/null 2>&1 || { echo "$1 --help exited $?"; exit 1; }
echo "ok: $out"
