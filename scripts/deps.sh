#!/usr/bin/env bash
# Installs the Debian packages ScanAtlas builds and tests with. Idempotent: when every
# package is already present it only runs dpkg-query and returns in well under a second.
set -euo pipefail
pkgs=(
  build-essential cmake ninja-build ccache pkg-config
  libeigen3-dev libflann-dev liblz4-dev libtbb-dev zlib1g-dev libpng-dev libopenmesh-dev
  libegl-dev libgl-dev libegl-mesa0 libgl1-mesa-dri
  libglfw3-dev libimgui-dev libstb-dev xvfb xauth
  libgtest-dev libgmock-dev libbenchmark-dev nlohmann-json3-dev libxxhash-dev libzstd-dev
  libpcl-dev libdraco-dev libopenmpi-dev openmpi-bin
)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "deps.sh: installing ${missing[*]}" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
