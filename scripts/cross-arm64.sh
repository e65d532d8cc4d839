#!/usr/bin/env bash
# arm64 boards (issue 17): builds stereod for arm64 with Debian's cross toolchain and multiarch libraries,
# writes the arm64 .deb, and runs the unit tests under qemu-user. Everything happens in a throwaway Debian
# bookworm root (debootstrap, cached): on bookworm libopencv-dev:arm64 and libopencv-dev:amd64 cannot be
# installed together, so the build machine's own packages are never touched.
# Root only (debootstrap, systemd-nspawn); about 8 GB of disk. CI runs it once as `cross.arm64` (label
# cross;slow); docs/service.md has its measured time. Exit 77 (skipped) without root, the tools or the disk.
# Usage: scripts/cross-arm64.sh [OUT_DIR]   (default: build-arm64-out; the .deb and the logs land there)
set -euo pipefail
SRC=$(cd "$(dirname "$0")/.." && pwd)
OUT=$(realpath -m "${1:-$SRC/build-arm64-out}")
CACHE=${STEREOD_TESTBED_CACHE:-/var/cache/stereod-testbeds}
fail() { echo "cross-arm64: $*" >&2; exit 1; }
skip() { echo "SKIP: cross-arm64: $*"; exit 77; }
[ "$(id -u)" -eq 0 ] || skip "needs root (debootstrap, systemd-nspawn)"
for tool in debootstrap systemd-nspawn; do
	command -v $tool >/dev/null || skip "$tool missing: bash scripts/install-deps.sh --test-beds"
done
mkdir -p "$OUT" "$CACHE"
# The cached root (2.4 GB), its copy, the build and apt's downloads: about 8 GB when nothing is cached yet.
need_gb=$([ -f "$CACHE/bookworm-cross-arm64.tar" ] && echo 4 || echo 8)
for dir in "$CACHE" /tmp; do
	free_gb=$(($(df --output=avail -k "$dir" | tail -1) / 1024 / 1024))
	[ "$free_gb" -ge "$need_gb" ] || skip "$free_gb GB free on $dir, $need_gb GB needed"
done
WORK=$(mktemp -d /tmp/stereod-cross.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
t0=$SECONDS
say() { echo "[$((SECONDS - t0)) s] $*"; }

# The packages the cross build needs inside the root: the cross compiler, the build machine's tools (cmake,
# idlc), the target's libraries (:arm64), the header-only ones (any architecture) and qemu-user.
target_libs=(libopencv-dev libspdlog-dev libfmt-dev libsystemd-dev zlib1g-dev libgtest-dev cyclonedds-dev
	libaravis-dev libusb-1.0-0-dev libdc1394-dev libturbojpeg0-dev)
packages=(crossbuild-essential-arm64 cmake ninja-build pkg-config dpkg-dev file qemu-user cyclonedds-tools
	libeigen3-dev nlohmann-json3-dev libcli11-dev libtoml11-dev opencv-doc "${target_libs[@]/%/:arm64}")

exec 9>"$CACHE/.lock"
flock 9
if [ ! -f "$CACHE/bookworm-cross-arm64.tar" ]; then
	say "a bookworm root with the arm64 cross toolchain and libraries into $CACHE (once)"
	rm -rf "$CACHE/cross.tmp"
	debootstrap --variant=minbase bookworm "$CACHE/cross.tmp" http://deb.debian.org/debian \
		>"$OUT/debootstrap.log" 2>&1 || fail "debootstrap: $(tail -5 "$OUT/debootstrap.log")"
	systemd-nspawn -q -D "$CACHE/cross.tmp" --register=no --keep-unit --bind=/var/cache/apt/archives sh -c "
		dpkg --add-architecture arm64 && apt-get update -q &&
		DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends ${packages[*]} &&
		apt-get clean" >"$OUT/install.log" 2>&1 || fail "apt: $(tail -15 "$OUT/install.log")"
	tar -C "$CACHE/cross.tmp" -cf "$CACHE/bookworm-cross-arm64.tar.tmp" .
	mv "$CACHE/bookworm-cross-arm64.tar.tmp" "$CACHE/bookworm-cross-arm64.tar"
	rm -rf "$CACHE/cross.tmp"
fi
flock -u 9
mkdir -p "$WORK/root"
tar -C "$WORK/root" -xf "$CACHE/bookworm-cross-arm64.tar"
say "root ready"

# The tree as committed (git ls-files), so that a local build folder does not leak in.
mkdir -p "$WORK/root/src"
(cd "$SRC" && git ls-files -z | xargs -0 tar -cf - ) | tar -C "$WORK/root/src" -xf -
in_root() { systemd-nspawn -q -D "$WORK/root" --register=no --keep-unit --bind="$OUT:/out" "$@"; }

# Only what the package holds and the unit tests (97 build steps of 130): the benchmarks and test helpers are
# built natively by the plain tier already. -O2 without debug information: -g added 30 % to a test file's
# compile (test_dense_motion.cpp natively, 9.8 s against 7.6 s); -O3 trips GCC 12's false -Wrestrict in
# std::string. CMAKE_SKIP_INSTALL_ALL_DEPENDENCY keeps cpack from building `all` after all.
in_root sh -c 'cmake -S /src -B /build -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O2 -DNDEBUG" \
		-DSTEREOD_WERROR=ON \
		-DCMAKE_SKIP_INSTALL_ALL_DEPENDENCY=ON -DCMAKE_TOOLCHAIN_FILE=/src/cmake/aarch64-linux-gnu.cmake &&
		cmake --build /build --target stereod stereoctl unit_tests' \
	>"$OUT/build.log" 2>&1 || fail "build: $(grep -m5 -E 'error|Error' "$OUT/build.log"; tail -5 "$OUT/build.log")"
in_root file /build/daemon/stereod /build/tools/stereoctl | tee "$OUT/file.txt"
grep -q "ARM aarch64" "$OUT/file.txt" || fail "the binaries are not arm64"
say "built"

in_root sh -c 'cd /build && cpack -G DEB -B /out/pkg' >"$OUT/cpack.log" 2>&1 || fail "cpack: $(tail -8 "$OUT/cpack.log")"
deb=$(ls "$OUT"/pkg/stereod_*_arm64.deb) || fail "no stereod_*_arm64.deb in $OUT/pkg"
in_root dpkg-deb -f "/out/pkg/$(basename "$deb")" Architecture Depends | tee "$OUT/control.txt"
say "packaged $(basename "$deb")"

# The unit tests, every one, under qemu-user (ctest runs them through CMAKE_CROSSCOMPILING_EMULATOR).
if in_root sh -c 'cd /build && ctest -L unit -j2 --output-on-failure' >"$OUT/unit.log" 2>&1; then
	say "unit tests under qemu-aarch64: $(grep -E 'tests passed' "$OUT/unit.log")"
else
	tail -30 "$OUT/unit.log"
	fail "unit tests failed under qemu-aarch64 (log: $OUT/unit.log)"
fi
say "done"
