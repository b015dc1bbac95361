#!/usr/bin/env bash
# Installs the Debian 12 packages this project builds and tests with, skipping what is already there.
# Run as root (or with sudo available). Safe to run repeatedly.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  # engine
  libeigen3-dev libyaml-cpp-dev nlohmann-json3-dev libcli11-dev zlib1g-dev
  # map database: SQLite + FAISS (OpenBLAS makes FAISS's BLAS calls far faster than the reference BLAS)
  libsqlite3-dev libfaiss-dev libopenblas0-pthread
  # the PostgreSQL map store: libpq to build; the server and its client programs (pg_dump) to test and back up
  libpq-dev postgresql-15 postgresql-client-15
  # the gRPC balancer of scripts/cluster-demo.sh (deploy/nginx/sglc-grpc.conf)
  nginx
  # PCD and PLY scans (sglc_io links PCL's io and common modules only)
  libpcl-dev
  # service
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler libspdlog-dev
  # the metrics endpoint: Boost.Beast over Asio (header-only); Prometheus' promtool checks its exposition (the
  # Prometheus server the package brings is disabled below)
  libboost-dev prometheus
  # pose-graph optimisation
  libceres-dev
  # tests, benchmarks, Python clients and plots
  libgtest-dev libgmock-dev libbenchmark-dev
  # the format check of scripts/test.sh, and scripts/tidy.sh
  clang-format clang-tidy
  python3 python3-numpy python3-grpcio python3-protobuf python3-matplotlib
  # the Python package: its engine module (pybind11), offline `pip install` into a venv, its pytest suite
  pybind11-dev python3-dev python3-venv python3-pip python3-pytest
  # the deployment-file test (tests/deploy) parses compose.yaml
  python3-yaml
  # dense ICP reference poses (tools/eval/dense_reference.py, results.sh part nuscenes)
  python3-scipy
  # bags: MCAP chunks (zstd, lz4), ROS 1 chunks (lz4, bz2); the lz4 tool compresses the test bags' chunks
  # (tests/interop/write_bag.mjs); Debian's ROS 1 bag writer for the ROS 1 test bags (write_ros1_bag.py)
  libzstd-dev liblz4-dev libbz2-dev lz4
  python3-rosbag python3-roslz4 python3-sensor-msgs python3-nav-msgs python3-tf2-msgs
  # the live view's page is tested in a real browser: Debian's Chromium, driven by playwright-core
  # (tests/interop; playwright downloads no browser of its own)
  chromium
)

# Node.js and npm run the test bags' writers (tests/interop). A machine with its own Node.js keeps it; without
# one, Debian's is installed.
command -v node >/dev/null || PACKAGES+=(nodejs)
command -v npm >/dev/null || PACKAGES+=(npm)

# The npm packages of tests/interop (pinned by its package-lock.json), installed again when the lockfile changed.
npm_packages() {
  local dir=tests/interop stamp=tests/interop/node_modules/.sglc-lock.sha256
  local want
  want=$(sha256sum "$dir/package-lock.json" | cut -d' ' -f1)
  if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "install-deps: npm ci in $dir"
    (cd "$dir" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error)
    echo "$want" >"$stamp"
  fi
}

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  cd "$(dirname "$0")/.." && npm_packages
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root to install: ${missing[*]}" >&2; exit 1; }
  SUDO="sudo"
fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
# The prometheus package is here for its promtool only: where systemd runs, the server it enables is stopped
# (only when this script installed it).
if [[ " ${missing[*]} " == *" prometheus "* ]] && [ -d /run/systemd/system ]; then
  $SUDO systemctl disable --now prometheus.service >/dev/null 2>&1 || true
fi
cd "$(dirname "$0")/.." && npm_packages
