#!/usr/bin/env bash
# The daemon's live recording (`[record] path`) through faults (issue 17): a full disk (a small tmpfs) stops
# the recording with an error in status while the stream goes on, and the file keeps every complete frame; a
# SIGKILLed daemon leaves a recording whose complete frames all replay; an unwritable path is refused at start
# naming the key; a second run keeps the first run's file. The tmpfs needs root (skipped otherwise).
source "$(dirname "$0")/lib.sh"
count_frames() { # a recording's complete frames, as `stereoctl info` reads them
	"$STEREOCTL" info "$1" | grep -oE '^  [0-9]+ (complete )?frames' | grep -oE '[0-9]+'
}

# 1. An unwritable path: refused at start, naming the key.
if "$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$WORK/x.sock" --set record.path=/proc/stereod.srec \
	>"$WORK/unwritable.log" 2>&1; then
	fail "started with record.path=/proc/stereod.srec"
fi
grep -q "record.path" "$WORK/unwritable.log" || fail "the refusal does not name record.path: $(tail -2 "$WORK/unwritable.log")"
pass "unwritable record.path refused: $(grep -m1 "record.path" "$WORK/unwritable.log" | cut -c1-160)"

# 2. SIGKILL while recording: every complete frame replays.
SOCK=$WORK/kill.sock
"$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$SOCK" --set record.path="$WORK/live.srec" >"$WORK/kill.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
for _ in $(seq 300); do
	[ -f "$WORK/live.srec" ] && [ "$(stat -c %s "$WORK/live.srec")" -gt 11000000 ] && break
	sleep 0.05
done
kill -9 $DAEMON
wait $DAEMON 2>/dev/null || true
recovered=$(count_frames "$WORK/live.srec")
[ "$recovered" -ge 20 ] || fail "only $recovered frames recovered after SIGKILL"
"$STEREOD" process --input "$WORK/live.srec" --format recording --output "$WORK/replay.ndjson" --no-progress 2>/dev/null ||
	fail "the killed daemon's recording does not replay"
[ "$(wc -l <"$WORK/replay.ndjson")" -eq "$recovered" ] || fail "replayed $(wc -l <"$WORK/replay.ndjson") of $recovered frames"
jq -s -e '[.[].seq] as $s | $s == ($s | sort)' "$WORK/replay.ndjson" >/dev/null || fail "recorded frames out of order"
rm -f "$SOCK"
pass "SIGKILL while recording: $recovered complete frames, all replayed in order"

# 3. A second run on the same path keeps the first run's file.
SOCK=$WORK/again.sock
"$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$SOCK" --set record.path="$WORK/live.srec" >"$WORK/again.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
sleep 1
kill -TERM $DAEMON
wait $DAEMON || fail "second run: exit $? after SIGTERM"
[ "$(count_frames "$WORK/live.srec.1")" -eq "$recovered" ] || fail "the first run's recording was not kept as live.srec.1"
second=$(count_frames "$WORK/live.srec")
[ "$second" -gt 0 ] || fail "the second run recorded nothing"
pass "a second run kept the first recording as live.srec.1 and recorded $second frames"

# 4. A full disk: the recording stops with an error in status; the stream goes on; complete frames kept.
if [ "$(id -u)" -ne 0 ]; then
	echo "SKIP (part 4): mounting a small tmpfs needs root"
	exit 0
fi
mkdir -p "$WORK/small"
mount -t tmpfs -o size=6m tmpfs "$WORK/small" || { echo "SKIP (part 4): cannot mount a tmpfs here"; exit 0; }
# The daemon must be gone before the tmpfs can be unmounted (it holds the recording open).
trap 'for pid in "${PIDS[@]}"; do kill -9 "$pid" 2>/dev/null || true; done; sleep 0.3; umount "$WORK/small" 2>/dev/null; cleanup' EXIT
SOCK=$WORK/full.sock
"$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$SOCK" --set output.status_interval_s=0.25 \
	--set record.path="$WORK/small/full.srec" >"$WORK/full.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
timeout 6 socat -u UNIX-CONNECT:"$SOCK" - >"$WORK/full.ndjson" || true
failed_at=$(grep -n '"type":"status"' "$WORK/full.ndjson" | grep '"state":"failed"' | head -1 | cut -d: -f1) || true
[ -n "$failed_at" ] || fail "status never said the recording failed: $(grep '"type":"status"' "$WORK/full.ndjson" | tail -1 | jq -c .recording)"
status=$(sed -n "${failed_at}p" "$WORK/full.ndjson")
echo "$status" | jq -e '.recording.error | test("No space left")' >/dev/null ||
	fail "the error does not say the disk is full: $(echo "$status" | jq -c .recording)"
after=$(tail -n +"$failed_at" "$WORK/full.ndjson" | grep -c '"type":"frame"' || true)
[ "$after" -ge 20 ] || fail "only $after frames streamed after the recording failed"
kill -0 $DAEMON || fail "the daemon died with the disk full"
kill -TERM $DAEMON
wait $DAEMON || fail "exit $? after SIGTERM with a failed recording"
written=$(echo "$status" | jq '.recording.frames')
kept=$(count_frames "$WORK/small/full.srec")
[ "$kept" -eq "$written" ] || fail "status said $written frames were written, the file holds $kept complete ones"
grep -q "recording stopped: .*No space left" "$WORK/full.log" || fail "no log line for the failed recording"
pass "full disk: recording stopped after $kept complete frames ($(echo "$status" | jq -r .recording.error | cut -c1-100)); $after frames streamed after; the file holds exactly the $kept frames status counted"
