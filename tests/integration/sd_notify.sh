#!/usr/bin/env bash
# What the daemon tells systemd (sd_notify), read by tests/notify/notify_recv.cpp standing in for systemd's
# side (NOTIFY_SOCKET, SO_PASSCRED, WATCHDOG_USEC/WATCHDOG_PID as WatchdogSec= sets them):
#   1. READY=1 comes from the daemon's own pid once the first frame is published, after a STATUS saying it
#      waits for one; STATUS lines carry fps, drops and clients; WATCHDOG=1 comes at least every
#      WATCHDOG_USEC while frames flow; SIGTERM gives STOPPING=1 and exit 0;
#   2. a hung pipeline (the test-only fault STEREOD_TEST_FAULT=hang_publish_after=N) stops the pings, so
#      systemd's watchdog would restart the service; the log says why.
# Usage: sd_notify.sh STEREOD STEREOCTL NOTIFY_RECV
NOTIFY_RECV=$3
set -- "$1" "$2"
source "$(dirname "$0")/lib.sh"
SIM=("${SMALL_SIM[@]}" --set sim.fps=30 --set output.status_interval_s=0.5)

# ---------------------------------------------------------------------------- 1. a healthy daemon
"$NOTIFY_RECV" --watchdog-usec 400000 --term-after 4 --kill-after 12 -- \
	"$STEREOD" "${SIM[@]}" --set output.socket="$WORK/ok.sock" >"$WORK/ok.out" 2>"$WORK/ok.log" ||
	fail "daemon under notify_recv: $(tail -3 "$WORK/ok.out") $(tail -3 "$WORK/ok.log")"
child=$(awk '$3 == "started" {print $2}' "$WORK/ok.out")
ready=$(awk -v p="$child" '$2 == p && $3 ~ /^READY=1/ {print $1; exit}' "$WORK/ok.out")
[ -n "$ready" ] || fail "no READY=1 from the daemon's pid $child: $(head -5 "$WORK/ok.out")"
waiting=$(awk '/ STATUS=starting: waiting for the first frame/ {print $1; exit}' "$WORK/ok.out")
[ -n "$waiting" ] && awk -v a="$waiting" -v b="$ready" 'BEGIN { exit !(a <= b) }' ||
	fail "READY=1 was not preceded by the waiting STATUS: $(head -4 "$WORK/ok.out")"
grep -q "first frame published: ready" "$WORK/ok.log" || fail "the log does not say when it became ready"
grep -Eq 'STATUS=streaming sim: [0-9.]+ fps, [0-9]+ frames dropped, [0-9]+ clients' "$WORK/ok.out" ||
	fail "no STATUS with fps, drops and clients: $(grep STATUS "$WORK/ok.out" | tail -2)"
term=$(awk '$3 == "SIGTERM" {print $1}' "$WORK/ok.out")
# Pings between READY and SIGTERM: how many, and the longest gap (systemd restarts past WATCHDOG_USEC).
read -r pings gap < <(awk -v r="$ready" -v t="$term" '$3 == "WATCHDOG=1" && $1 >= r && $1 <= t {
	if (last != "") { g = $1 - last; if (g > max) max = g } last = $1; n++ } END { printf "%d %.3f\n", n, max }' "$WORK/ok.out")
[ "$pings" -ge 10 ] || fail "only $pings WATCHDOG=1 pings in $(awk -v a="$ready" -v b="$term" 'BEGIN{print b-a}') s"
awk -v g="$gap" 'BEGIN { exit !(g < 0.4) }' || fail "a gap of $gap s between pings (WATCHDOG_USEC 0.4 s)"
grep -q "STOPPING=1" "$WORK/ok.out" || fail "no STOPPING=1 after SIGTERM"
grep -q "^exit 0$" "$WORK/ok.out" || fail "exit after SIGTERM: $(tail -1 "$WORK/ok.out")"
pass "healthy: READY=1 at $ready s from pid $child (after the first frame), $pings pings, longest gap $gap s, $(grep -o 'STATUS=streaming[^|]*' "$WORK/ok.out" | tail -1), STOPPING=1, exit 0"

# ---------------------------------------------------------------------------- 2. a hung pipeline
STEREOD_TEST_FAULT=hang_publish_after=20 "$NOTIFY_RECV" --watchdog-usec 400000 --kill-after 5 -- \
	"$STEREOD" "${SIM[@]}" --set output.socket="$WORK/hung.sock" >"$WORK/hung.out" 2>"$WORK/hung.log" || true
grep -q "^signal 9$" "$WORK/hung.out" || fail "the hung daemon was not still running at 5 s: $(tail -2 "$WORK/hung.out")"
grep -q "READY=1" "$WORK/hung.out" || fail "the hung daemon never became ready"
last_ping=$(awk '$3 == "WATCHDOG=1" {t = $1} END {print t + 0}' "$WORK/hung.out")
awk -v t="$last_ping" 'BEGIN { exit !(t < 3.5) }' ||
	fail "pings went on until $last_ping s although the publisher hung after 20 frames"
grep -q "watchdog: frames come in but none are published" "$WORK/hung.log" ||
	fail "the log does not say why the pings stopped: $(grep -i watchdog "$WORK/hung.log" | head -3)"
pass "hung publisher (after 20 frames): last WATCHDOG=1 at $last_ping s, none in the $(awk -v t="$last_ping" 'BEGIN{printf "%.1f", 5 - t}') s before SIGKILL; systemd would restart it"

# ---------------------------------------------------------------------------- 3. reload on SIGHUP
# A pipeline option and a live option change (the source and pipeline are rebuilt in place, the client stays);
# then a config with an unknown key is refused with its file, line and key, and the running one stays.
cat >"$WORK/stereod.toml" <<TOML
[sim]
width = 320
height = 240
fps = 30
[output]
socket = "$WORK/reload.sock"
status_interval_s = 0.5
TOML
"$NOTIFY_RECV" --watchdog-usec 2000000 --term-after 9 --kill-after 20 -- \
	"$STEREOD" --config "$WORK/stereod.toml" >"$WORK/reload.out" 2>"$WORK/reload.log" &
RECV=$!
PIDS+=($RECV)
for _ in $(seq 100); do [ -S "$WORK/reload.sock" ] && break; sleep 0.1; done
[ -S "$WORK/reload.sock" ] || fail "no socket: $(tail -3 "$WORK/reload.log")"
daemon_pid=$(awk '$3 == "started" {print $2}' "$WORK/reload.out")
"$STEREOCTL" watch --socket "$WORK/reload.sock" --raw >"$WORK/client.out" 2>/dev/null &
CLIENT=$!
PIDS+=($CLIENT)
sleep 2
printf '[classifier]\ntexture_threshold = 14.0\n' >>"$WORK/stereod.toml"
sed -i 's/status_interval_s = 0.5/status_interval_s = 0.5\nmax_clients = 10/' "$WORK/stereod.toml"
kill -HUP "$daemon_pid"
sleep 2.5
frames_before_bad=$(grep -c '"type":"frame"' "$WORK/client.out" || true)
cp "$WORK/stereod.toml" "$WORK/good.toml"
printf '[output]\nsokcet = "/tmp/elsewhere.sock"\n' >"$WORK/stereod.toml"
kill -HUP "$daemon_pid"
sleep 2
kill -0 "$CLIENT" 2>/dev/null || fail "the client was disconnected by the reloads"
wait "$RECV" || fail "daemon exit after the reloads: $(tail -3 "$WORK/reload.out") $(tail -3 "$WORK/reload.log")"
wait "$CLIENT" 2>/dev/null || true
grep -q "reload: applied classifier.texture_threshold, output.max_clients" "$WORK/reload.log" ||
	fail "the first reload did not apply both options: $(grep reload "$WORK/reload.log")"
grep -q "reload: rebuilding the source and the pipeline" "$WORK/reload.log" || fail "the pipeline was not rebuilt"
grep -q "reload refused, the running configuration stays: $WORK/stereod.toml:2: unknown key 'output.sokcet'" \
	"$WORK/reload.log" || fail "the bad config was not refused by file, line and key: $(grep -i reload "$WORK/reload.log")"
reloading=$(grep -c 'RELOADING=1|MONOTONIC_USEC=[0-9]*' "$WORK/reload.out" || true)
[ "$reloading" -eq 2 ] || fail "want 2 RELOADING=1 with MONOTONIC_USEC, got $reloading"
# Each RELOADING=1 is followed by READY=1.
awk '/RELOADING=1/ {open = 1} /READY=1/ {if (open) {done++; open = 0}} END {exit !(done == 2)}' "$WORK/reload.out" ||
	fail "RELOADING=1 not followed by READY=1 each time: $(grep -E 'RELOADING|READY' "$WORK/reload.out")"
frames_after=$(grep -c '"type":"frame"' "$WORK/client.out" || true)
[ "$frames_after" -gt "$frames_before_bad" ] || fail "the client received no frame after the refused reload"
[ "$frames_before_bad" -gt 60 ] || fail "the client received only $frames_before_bad frames across the first reload"
[ -S "$WORK/elsewhere.sock" ] && fail "the refused config moved the socket"
[ "$(grep -c '"type":"hello"' "$WORK/client.out")" -eq 2 ] ||
	fail "the client was not told of the rebuilt source by a second hello"
# What the rebuild cost the live sim, in status drops.reload: the 30 fps periods between the last frame before
# the second hello and the first after it, less one, from their t_host_ns (when each was complete on the host).
paused=$(jq -s '[.[] | select(.type == "hello" or .type == "frame")] as $m
	| ([range(0; $m | length) | select($m[.].type == "hello")][1]) as $h
	| {frames: ((($m[$h + 1].t_host_ns - $m[$h - 1].t_host_ns) * 30 / 1e9 | round) - 1),
	   ms: (($m[$h + 1].t_host_ns - $m[$h - 1].t_host_ns) / 1e6 | round)}' "$WORK/client.out")
counted=$(jq -s '[.[] | select(.type == "status")] | last | .drops.reload' "$WORK/client.out")
expected=$(jq .frames <<<"$paused")
[ "$expected" -gt 0 ] || fail "no pause seen across the rebuild: $paused"
[ "$counted" = "$expected" ] ||
	fail "drops.reload is $counted, the client saw a pause of $(jq .ms <<<"$paused") ms: $expected frames at 30 fps"
grep -q "reload: capture paused [0-9]* ms, $counted frames of the live source not captured" "$WORK/reload.log" ||
	fail "the pause was not logged: $(grep 'reload:' "$WORK/reload.log")"
echo "reload: paused $(jq .ms <<<"$paused") ms, drops.reload $counted"
pass "reload: classifier.texture_threshold (pipeline rebuilt in place) and output.max_clients (live) applied with the client connected ($frames_before_bad frames by then, $frames_after in all); a config with an unknown key refused by file:line:key, the running one kept; RELOADING=1 + MONOTONIC_USEC then READY=1 each time"
