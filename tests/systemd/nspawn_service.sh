#!/usr/bin/env bash
# The service under real systemd (issue 17): a fresh Debian bookworm root (debootstrap, minbase: what a board
# has before stereod) booted with systemd-nspawn, the package built from this tree installed with apt as a user
# would, enabled, and driven by tests/systemd/guest_check.sh inside. Then the package is purged and the root
# checked clean. Recipe: ../shared/testbeds/README.md section F (--register=no --keep-unit where PID 1 is not
# systemd, as on CI). Root only; the bare root is cached (STEREOD_TESTBED_CACHE, default
# /var/cache/stereod-testbeds), and apt's downloads go to the host's apt cache.
# Usage: nspawn_service.sh BUILD_DIR
set -euo pipefail
BUILD=$(realpath "$1")
HERE=$(cd "$(dirname "$0")" && pwd)
CACHE=${STEREOD_TESTBED_CACHE:-/var/cache/stereod-testbeds}
skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "FAIL: $*"; exit 1; }
[ "$(id -u)" -eq 0 ] || skip "needs root (systemd-nspawn, debootstrap)"
command -v systemd-nspawn >/dev/null || skip "systemd-nspawn missing (systemd-container)"
command -v debootstrap >/dev/null || skip "debootstrap missing"
WORK=$(mktemp -d /tmp/stereod-nspawn.XXXXXX)
cleanup() { rm -rf "$WORK"; }
trap cleanup EXIT
t0=$SECONDS
elapsed() { echo $((SECONDS - t0)); }

# The bare root, once: minbase with systemd as PID 1 (and udev, which systemd expects). Nothing of stereod's.
mkdir -p "$CACHE"
exec 9>"$CACHE/.lock"
flock 9
if [ ! -f "$CACHE/bookworm-minbase.tar" ]; then
	echo "debootstrap: a bookworm minbase root into $CACHE (once)"
	rm -rf "$CACHE/rootfs.tmp"
	debootstrap --variant=minbase --include=systemd,systemd-sysv,dbus,udev bookworm "$CACHE/rootfs.tmp" \
		http://deb.debian.org/debian >"$WORK/debootstrap.log" 2>&1 || fail "debootstrap: $(tail -5 "$WORK/debootstrap.log")"
	tar -C "$CACHE/rootfs.tmp" -cf "$CACHE/bookworm-minbase.tar.tmp" .
	mv "$CACHE/bookworm-minbase.tar.tmp" "$CACHE/bookworm-minbase.tar"
	rm -rf "$CACHE/rootfs.tmp"
fi
flock -u 9
ROOT=$WORK/root
mkdir -p "$ROOT"
tar -C "$ROOT" -xf "$CACHE/bookworm-minbase.tar"
echo "root ready at $(elapsed) s"

# The package, from this build tree.
(cd "$BUILD" && cpack -G DEB -B "$WORK/pkg" >"$WORK/cpack.log" 2>&1) || fail "cpack: $(tail -5 "$WORK/cpack.log")"
deb=$(ls "$WORK"/pkg/stereod_*.deb)
cp "$deb" "$ROOT/root/stereod.deb"
echo "package $(basename "$deb") at $(elapsed) s"

in_root() { systemd-nspawn -q -D "$ROOT" --register=no --keep-unit --bind=/var/cache/apt/archives "$@"; }
# Installed as a user installs it: apt resolves the Depends from Debian.
in_root sh -c 'apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends /root/stereod.deb' \
	>"$WORK/install.log" 2>&1 || fail "apt install: $(tail -15 "$WORK/install.log")"
in_root sh -c 'systemctl enable stereod' >>"$WORK/install.log" 2>&1 || fail "systemctl enable: $(tail -5 "$WORK/install.log")"
in_root getent passwd stereod >/dev/null || fail "installing made no stereod user"
echo "installed at $(elapsed) s ($(grep -c '^Setting up' "$WORK/install.log") packages set up)"

install -m 0755 "$HERE/guest_check.sh" "$ROOT/usr/local/bin/stereod-guest-check"
cp "$HERE/stereod-check.service" "$ROOT/etc/systemd/system/"
ln -s /etc/systemd/system/stereod-check.service "$ROOT/etc/systemd/system/multi-user.target.wants/"
mkdir -p "$WORK/out"
boot_start=$SECONDS
timeout 300 systemd-nspawn -q -D "$ROOT" -b --register=no --keep-unit --bind="$WORK/out:/out" --console=pipe \
	>"$WORK/boot.log" 2>&1 || echo "nspawn ended with $? (see below)"
echo "guest ran $((SECONDS - boot_start)) s"
R=$WORK/out/result.txt
[ -f "$R" ] || fail "no findings from the guest: $(tail -30 "$WORK/boot.log")"
echo "--- findings"
cat "$R"
get() { sed -n "s/^$1=//p" "$R" | head -1; }
problems=()
check() { eval "$2" || problems+=("$1 ($(get "$3"))"); }
check "the check did not finish" '[ "$(get done)" = yes ]' done
check "package did not enable the unit" '[ "$(get enabled)" = enabled ]' enabled
check "unit never active (READY)" '[ "$(get active)" = yes ]' active
check "not running as the stereod user" '[ "$(get user)" = stereod ]' user
check "no fps in STATUS=" '[[ "$(get status_text)" == *fps* ]]' status_text
check "reload failed" '[ "$(get reload)" = ok ]' reload
check "client lost over the reload" '[ "$(get client_kept)" = yes ]' client_kept
check "client got no frames after the reload" '[ "$(get frames_after)" -gt 0 ]' frames_after
check "status interval not applied live (1 s -> 0.25 s)" '[ "$(get status_after_per_4s)" -ge $(( $(get status_before_per_4s) * 2 )) ]' status_after_per_4s
check "a live option restarted the service" '[ "$(get main_pid_same)" = yes ]' main_pid_same
check "a hung pipeline was not restarted by the watchdog" '[ "$(get watchdog_restart)" = yes ]' watchdog_restart
check "no watchdog timeout in the journal" '[ "$(get watchdog_logged)" -ge 1 ]' watchdog_logged
check "not active again after the fault" '[ "$(get active_again)" = yes ]' active_again
check "stop took 2 s or more" 'awk -v s="$(get stop_s)" "BEGIN { exit !(s < 2) }"' stop_s
check "stop did not exit 0" '[ "$(get stop_status)" = 0 ] && [ "$(get stop_result)" = success ]' stop_result
if [ ${#problems[@]} -gt 0 ]; then
	echo "--- journal (stereod)"
	tail -60 "$WORK/out/journal.txt" 2>/dev/null || true
	fail "$(IFS=';'; echo "${problems[*]}")"
fi

# Removed as a user removes it: purge leaves no user, no config, no state, no binary.
in_root sh -c 'DEBIAN_FRONTEND=noninteractive apt-get purge -y -q stereod' >"$WORK/purge.log" 2>&1 ||
	fail "apt purge: $(tail -10 "$WORK/purge.log")"
left=()
for f in /usr/bin/stereod /usr/bin/stereoctl /etc/stereod /var/lib/stereod /usr/lib/systemd/system/stereod.service; do
	[ -e "$ROOT$f" ] && left+=("$f")
done
in_root getent passwd stereod >/dev/null && left+=("user stereod")
in_root getent group stereod >/dev/null && left+=("group stereod")
[ ${#left[@]} -eq 0 ] || fail "purge left: ${left[*]}"
echo "ok: under real systemd: active (READY) $(get active_after_s) s after the check started as user $(get user); reload in $(get reload_s) s kept the client (status lines per 4 s $(get status_before_per_4s) -> $(get status_after_per_4s)); hung pipeline restarted by the watchdog after $(get watchdog_restart_after_s) s; stop in $(get stop_s) s, exit $(get stop_status); purge clean; $(elapsed) s in all"
