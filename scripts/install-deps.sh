#!/usr/bin/env bash
# Installs every Debian bookworm package stereod needs to build, test and run.
# One list for the README's two commands and for CI: nothing else is assumed on the machine.
#   install-deps.sh               what building and running need (the README's first command)
#   install-deps.sh --test-beds   also the camera test beds' peers: fake GigE cameras, QEMU and a kernel's
#                                 headers for the V4L2 bed (the second command, and CI)
set -euo pipefail
test_beds=false
[ "${1:-}" = "--test-beds" ] && test_beds=true

packages=(
  # toolchain
  build-essential cmake pkg-config ninja-build clang-format
  # libraries the code links against
  libopencv-dev libeigen3-dev libspdlog-dev libfmt-dev nlohmann-json3-dev libcli11-dev libtoml11-dev
  libsystemd-dev zlib1g-dev libgtest-dev libbenchmark-dev
  # results on DDS as ROS 2 messages (Eclipse Cyclone DDS and its IDL compiler, idlc)
  cyclonedds-dev cyclonedds-tools
  # camera drivers: GigE / USB3 Vision (Aravis), FireWire (libdc1394), MJPG decoding for V4L2 (libjpeg-turbo)
  libaravis-dev libusb-1.0-0-dev libdc1394-dev libturbojpeg0-dev
  # real photographs for the sim scene's textures and the real-data tests (same files as ../shared/data)
  opencv-doc
  # tools the tests and the README use as real clients
  socat jq procps
  # the Debian package (cmake --build build --target package): dpkg-shlibdeps computes its Depends
  dpkg-dev
)

if $test_beds; then
  # camera test beds: fake GigE cameras in a private network namespace; V4L2 drivers in a QEMU-booted kernel
  packages+=(aravis-tools aravis-tools-cli iproute2 util-linux qemu-system-x86 busybox-static cpio kmod v4l-utils)
  # the service's unit checks (systemd-analyze verify / security), and real systemd booting a fresh bookworm
  # root with the package installed (tests/systemd: debootstrap, systemd-nspawn)
  packages+=(systemd debootstrap systemd-container)
  # fuzzing the parsers of outside bytes: clang's libFuzzer (tests/fuzz)
  packages+=(clang libclang-rt-14-dev)
  # an independent MCAP reader for the MCAP tests: Foxglove's @mcap/core from npm (tests/mcap); Debian's
  # Node.js where the machine has none
  if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    packages+=(nodejs npm)
  fi
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "$(id -u)" -ne 0 ]; then
  SUDO=sudo
else
  SUDO=
fi
export DEBIAN_FRONTEND=noninteractive
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  echo "install-deps: installing ${missing[*]}"
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

$test_beds || exit 0
# The MCAP tests' reader, at the version package-lock.json pins (npm is reachable from CI; never the daemon's).
mcap_dir="$(cd "$(dirname "$0")/.." && pwd)/tests/mcap"
if [ ! -d "$mcap_dir/node_modules/@mcap/core" ] || [ "$mcap_dir/package-lock.json" -nt "$mcap_dir/node_modules" ]; then
  echo "install-deps: npm ci in tests/mcap (@mcap/core, the independent MCAP reader)"
  (cd "$mcap_dir" && npm ci --no-audit --no-fund --loglevel=error)
fi
# The V4L2 test bed builds v4l2loopback for the kernel it boots (Debian's current one), so it needs that
# kernel's headers; which version that is, only apt can say.
kver=$(apt-cache depends linux-image-amd64 2>/dev/null | sed -n 's/.*Depends: linux-image-//p' | head -1)
if [ -z "$kver" ]; then
  $SUDO apt-get update -q
  kver=$(apt-cache depends linux-image-amd64 2>/dev/null | sed -n 's/.*Depends: linux-image-//p' | head -1)
fi
if [ -n "$kver" ] && ! dpkg-query -W -f='${Status}' "linux-headers-$kver" 2>/dev/null | grep -q "install ok installed"; then
  echo "install-deps: installing linux-headers-$kver (for the V4L2 test bed's v4l2loopback)"
  $SUDO apt-get install -y -q --no-install-recommends "linux-headers-$kver" || echo "install-deps: no linux-headers-$kver; the V4L2 bed will run without v4l2loopback"
fi
