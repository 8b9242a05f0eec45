#!/usr/bin/env bash
# Installs every Debian 12 package nerfar needs (idempotent, as root) and builds
# the project in build/ (Release). Usage: scripts/setup.sh [--no-build]
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake ninja-build pkg-config git
  clang-14 libclang-rt-14-dev clang-format
  libgtest-dev libgmock-dev libbenchmark-dev
  libopencv-dev libopencv-contrib-dev opencv-data
  libopenexr-dev libapriltag-dev libembree-dev libeigen3-dev libtbb-dev
  nlohmann-json3-dev libassimp-dev zlib1g-dev
  libv4l-dev libcamera-dev
  libglfw3-dev libgl-dev libimgui-dev
  xvfb xauth xdotool libgl1-mesa-dri ffmpeg
  poppler-utils python3-opencv python3-numpy
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${#missing[@]} packages: ${missing[*]}"
  sudo_cmd=""
  [ "$(id -u)" = 0 ] || sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all ${#packages[@]} packages present"
fi

if [ "${1:-}" != "--no-build" ]; then
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release
  cmake --build build --parallel "$(nproc)"
fi
