#!/usr/bin/env bash
# The Debian package (CPack): built from this build tree, named stereod_<version>_<arch>.deb, holding the
# binaries, the unit, the config as a conffile and the docs; Depends computed by dpkg-shlibdeps; maintainer
# scripts that make the system user. The unit as packaged: `systemd-analyze verify` clean, and its
# `systemd-analyze security` exposure at most 2.0 (printed).
# Usage: package.sh STEREOD STEREOCTL BUILD_DIR
BUILD=$3
set -- "$1" "$2"
source "$(dirname "$0")/lib.sh"
command -v dpkg-shlibdeps >/dev/null || { echo "SKIP: dpkg-shlibdeps missing (dpkg-dev)"; exit 77; }
(cd "$BUILD" && cpack -G DEB -B "$WORK/pkg" >"$WORK/cpack.log" 2>&1) || fail "cpack: $(tail -5 "$WORK/cpack.log")"
version=$("$STEREOD" --version | awk '{print $2}')
deb="$WORK/pkg/stereod_${version}_$(dpkg --print-architecture).deb"
[ -f "$deb" ] || fail "no $(basename "$deb"): $(ls "$WORK/pkg")"
depends=$(dpkg-deb -f "$deb" Depends)
for lib in libopencv-core libaravis libsystemd0 libspdlog libc6; do
	echo "$depends" | grep -q "$lib" || fail "Depends lacks $lib (shlibdeps): $depends"
done
contents=$(dpkg-deb -c "$deb" | awk '{print $6}')
for f in ./usr/bin/stereod ./usr/bin/stereoctl ./usr/lib/systemd/system/stereod.service ./etc/stereod/stereod.toml \
	./usr/share/doc/stereod/README.md ./usr/share/doc/stereod/docs/service.md; do
	echo "$contents" | grep -qx "$f" || fail "the package lacks $f"
done
dpkg-deb -e "$deb" "$WORK/control"
grep -qx /etc/stereod/stereod.toml "$WORK/control/conffiles" || fail "the config is not a conffile"
grep -q "useradd --system" "$WORK/control/postinst" || fail "postinst makes no system user"
dpkg-deb -x "$deb" "$WORK/root"
# The binaries in the package run (stripped, same libraries).
"$WORK/root/usr/bin/stereod" --version >/dev/null || fail "the packaged stereod does not run"
size=$(du -k "$deb" | cut -f1)
if command -v systemd-analyze >/dev/null; then
	# verify needs ExecStart's binary to exist on this machine: point it at the packaged one.
	sed "s|/usr/bin/stereod|$WORK/root/usr/bin/stereod|" "$WORK/root/usr/lib/systemd/system/stereod.service" \
		>"$WORK/stereod.service"
	systemd-analyze verify "$WORK/stereod.service" >"$WORK/verify.log" 2>&1 || fail "systemd-analyze verify: $(cat "$WORK/verify.log")"
	exposure=$(cd "$WORK" && systemd-analyze security --offline=true "$WORK/stereod.service" 2>&1 |
		sed -n 's/.*Overall exposure level for stereod.service: \([0-9.]*\).*/\1/p')
	[ -n "$exposure" ] || fail "no exposure level from systemd-analyze security"
	awk -v e="$exposure" 'BEGIN { exit !(e <= 2.0) }' || fail "unit exposure $exposure (limit 2.0)"
	unit="unit verified, exposure $exposure"
else
	unit="systemd-analyze missing: unit not checked"
fi
pass "$(basename "$deb") ($size KiB): binaries, unit, conffile, docs; Depends from shlibdeps: $(echo "$depends" | tr ',' '\n' | wc -l) packages; $unit"
