#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, checks the formatting, builds, runs clang-tidy on the last commit's C++
# files, and runs the whole test suite twice: a Release build and an AddressSanitizer + UndefinedBehaviorSanitizer
# build. Exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/check-format.sh
scripts/build.sh
# clang-tidy (function size, use-after-move, dangling handles) on the C++ files the last commit changed.
if git rev-parse -q --verify HEAD~1 >/dev/null; then scripts/tidy.sh HEAD~1; fi
(cd build && ctest --output-on-failure -j "$(nproc)")

echo "== sanitizer build (ASan + UBSan)"
cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSGLC_SANITIZE=ON -DSGLC_BUILD_BENCHMARKS=OFF >/dev/null
cmake --build build-asan -j "$(nproc)"
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
(cd build-asan && ctest --output-on-failure -j "$(nproc)")
