#!/usr/bin/env bash
# A sim recording killed with SIGKILL mid-run replays every complete frame, and the reader says what it cut.
source "$(dirname "$0")/lib.sh"
REC=$WORK/run.srec
"$STEREOCTL" record "${SMALL_SIM[@]}" --output "$REC" 2>"$WORK/record.log" &
RECORDER=$!
PIDS+=($RECORDER)
# Kill it mid-run once about 20 frames (of ~538 kB each at 320x240 stereo + truth) are on disk.
for _ in $(seq 300); do
	[ -f "$REC" ] && [ "$(stat -c %s "$REC")" -gt 11000000 ] && break
	sleep 0.05
done
kill -9 $RECORDER
wait $RECORDER 2>/dev/null || true

"$STEREOCTL" info "$REC" >"$WORK/info.out" || fail "info failed: $(cat "$WORK/info.out")"
cat "$WORK/info.out"
recovered=$(grep -oE '^  [0-9]+ (complete )?frames' "$WORK/info.out" | grep -oE '[0-9]+')
[ "$recovered" -ge 20 ] || fail "only $recovered frames recovered"

"$STEREOD" process --input "$REC" --format recording --output "$WORK/out.ndjson" 2>"$WORK/process.log" ||
	fail "replay failed: $(cat "$WORK/process.log")"
lines=$(wc -l <"$WORK/out.ndjson")
[ "$lines" -eq "$recovered" ] || fail "replayed $lines frames, the reader recovered $recovered"
jq -s -e '[.[].seq] == [range(0; length)]' "$WORK/out.ndjson" >/dev/null || fail "replayed frames out of order"
grep -q "replay: $recovered" "$WORK/process.log" || fail "replay did not report what it recovered"
pass "SIGKILLed recording: $recovered frames replayed in order"

# Cut the last record short on purpose: the reader must report the cut and keep the rest.
size=$(stat -c %s "$REC")
truncate -s $((size - 1000)) "$REC"
"$STEREOCTL" info "$REC" >"$WORK/info2.out"
grep -q "complete frames recovered; cut at byte" "$WORK/info2.out" || fail "no cut report: $(cat "$WORK/info2.out")"
now=$(grep -oE '^  [0-9]+ complete frames' "$WORK/info2.out" | grep -oE '[0-9]+')
[ "$now" -eq $((recovered - 1)) ] || fail "after cutting into the last record: $now frames, want $((recovered - 1))"
pass "truncated recording: $(sed -n 3p "$WORK/info2.out")"
