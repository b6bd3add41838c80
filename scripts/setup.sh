#!/usr/bin/env bash
# Installs every system package lex3d needs (Debian 12 / apt-get) and builds it in
# Release. The one place where packages are installed. Usage: scripts/setup.sh [BUILD_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build}"

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

PACKAGES=(
  build-essential cmake pkg-config
  libeigen3-dev libpcl-dev libflann-dev liboctomap-dev zlib1g-dev liblzf-dev
  libcli11-dev libgtest-dev libgmock-dev
  clang libclang-rt-14-dev
  python3 python3-numpy python3-scipy
  draco time python3-matplotlib
  libpcap-dev nlohmann-json3-dev
  python3-dev pybind11-dev python3-pytest
  python3-distributed python3-dask
  librosbag-storage-dev libsensor-msgs-dev libbz2-dev liblz4-dev
)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release
cmake --build "$BUILD_DIR" -j2
echo "setup: built $BUILD_DIR/lex3d"
# Install the library, headers, CMake package, pkg-config file, the command and the Python
# module under /usr/local: Debian's own place for locally built software, searched by the
# compiler, the linker (after ldconfig), CMake's find_package and /usr/bin/python3
# (/usr/local/lib/python3.X/dist-packages), without touching the packaged /usr tree or pip.
$SUDO cmake --install "$BUILD_DIR" > /dev/null
$SUDO ldconfig
echo "setup: installed lex3d $(/usr/bin/python3 -c 'import lex3d; print(lex3d.__version__)') into /usr/local (import lex3d works)"
