#!/usr/bin/env bash
# Installs every Debian bookworm package stereod needs to build, test and run.
# One list for the README's two commands and for CI: nothing else is assumed on the machine.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake pkg-config ninja-build clang-format
  # libraries the code links against
  libopencv-dev libeigen3-dev libspdlog-dev libfmt-dev nlohmann-json3-dev libcli11-dev libtoml11-dev
  libsystemd-dev zlib1g-dev libgtest-dev libbenchmark-dev
  # real photographs for the sim scene's textures and the real-data tests (same files as ../shared/data)
  opencv-doc
  # tools the tests and the README use as real clients
  socat jq procps
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
  SUDO=sudo
else
  SUDO=
fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
