#!/bin/sh
# Runs inside the nspawn guest as stereod-check.service (After=multi-user.target), with the stereod package
# installed and enabled as a user would: writes one `key=value` line per finding to /out/result.txt, the
# journal to /out/journal.txt, and powers the guest off. tests/systemd/nspawn_service.sh judges the findings.
# Only what a minimal bookworm root has: sh, coreutils, grep, sed, systemctl, journalctl and the package.
OUT=/out/result.txt
: >"$OUT"
say() { echo "$1=$2" >>"$OUT"; }
now() { cut -d' ' -f1 /proc/uptime; }
wait_for() { # seconds, command...: polls every 0.1 s
	limit=$1
	shift
	i=0
	while [ "$i" -lt $((limit * 10)) ]; do
		"$@" && return 0
		sleep 0.1
		i=$((i + 1))
	done
	return 1
}
prop() { systemctl show -p "$1" --value stereod; }
active() { [ "$(systemctl is-active stereod)" = active ]; }
status_lines() { grep -c '"type":"status"' /tmp/watch.out 2>/dev/null || echo 0; }
frame_lines() { grep -c '"type":"frame"' /tmp/watch.out 2>/dev/null || echo 0; }

boot=$(now) # the host's uptime in nspawn: only differences mean anything
since_boot() { echo "$(now) $boot" | awk '{print $1 - $2}'; }
say enabled "$(systemctl is-enabled stereod)"
# 1. The unit reaches active (Type=notify: only after READY=1, sent once the first frame is published).
if wait_for 90 active; then say active yes; else say active no; fi
say active_after_s "$(since_boot)"
say user "$(stat -c %U /proc/"$(prop MainPID)")"
sleep 3 # STATUS= carries fps once a second's frames are counted
say status_text "$(prop StatusText)"
say socket "$(stat -c '%U:%G %a' /run/stereod/stereod.sock 2>/dev/null || echo missing)"

# 2. A client connected across a reload that changes a live option (status every 1 s -> every 0.25 s).
stereoctl watch --socket /run/stereod/stereod.sock --raw >/tmp/watch.out 2>/tmp/watch.err &
watch_pid=$!
sleep 4
before_status=$(status_lines)
before_frames=$(frame_lines)
sed -i 's/^status_interval_s = .*/status_interval_s = 0.25/' /etc/stereod/stereod.toml
reload_start=$(now)
if systemctl reload stereod; then say reload ok; else say reload failed; fi
say reload_s "$(echo "$(now) $reload_start" | awk '{print $1 - $2}')"
sleep 0.2
mid_status=$(status_lines)
sleep 4
after_status=$(status_lines)
after_frames=$(frame_lines)
say status_before_per_4s "$before_status"
say status_after_per_4s "$((after_status - mid_status))"
say frames_before "$before_frames"
say frames_after "$((after_frames - before_frames))"
if kill -0 "$watch_pid" 2>/dev/null; then say client_kept yes; else say client_kept no; fi
say hellos "$(grep -c '"type":"hello"' /tmp/watch.out)"
say main_pid_same "$([ "$(prop NRestarts)" = 0 ] && echo yes || echo no)"
kill "$watch_pid" 2>/dev/null

# 3. A hung pipeline (the test-only fault switch) is restarted by the watchdog.
mkdir -p /etc/systemd/system/stereod.service.d
printf '[Service]\nEnvironment=STEREOD_TEST_FAULT=hang_publish_after=40\nWatchdogSec=3\n' \
	>/etc/systemd/system/stereod.service.d/fault.conf
systemctl daemon-reload
restarts_before=$(prop NRestarts)
systemctl restart stereod
hang_start=$(now)
if wait_for 60 sh -c '[ "$(systemctl show -p NRestarts --value stereod)" -gt '"$restarts_before"' ]'; then
	say watchdog_restart yes
else
	say watchdog_restart no
fi
say watchdog_restart_after_s "$(echo "$(now) $hang_start" | awk '{print $1 - $2}')"
say watchdog_logged "$(journalctl -b --no-pager -u stereod | grep -c 'Watchdog timeout')"
rm /etc/systemd/system/stereod.service.d/fault.conf
systemctl daemon-reload
systemctl restart stereod
if wait_for 60 active; then say active_again yes; else say active_again no; fi

# 4. systemctl stop: SIGTERM, drain, exit 0, within 2 s.
sleep 2
stop_start=$(now)
systemctl stop stereod
say stop_s "$(echo "$(now) $stop_start" | awk '{print $1 - $2}')"
say stop_result "$(prop Result)"
say stop_status "$(prop ExecMainStatus)"
say socket_after_stop "$([ -e /run/stereod/stereod.sock ] && echo present || echo gone)"

journalctl -b --no-pager -o short-monotonic -u stereod >/out/journal.txt 2>&1
say done yes
systemctl poweroff
