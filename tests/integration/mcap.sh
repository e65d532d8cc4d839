#!/usr/bin/env bash
# MCAP (issue 18), checked by an independent reader: Foxglove's @mcap/core from npm (tests/mcap/check_mcap.mjs).
#  1. `stereoctl record --output X.mcap --images`: every frame there, indexes and CRCs valid, schemas parse; the
#     MCAP replays to exactly the results its .srec twin gives.
#  2. `stereod process --output X.mcap --images`: the results channel holds the NDJSON stream's messages.
#  3. A live MCAP recording SIGKILLed mid-run: every complete chunk is read, by us and by @mcap/core alike, and
#     replays; a live recording stopped cleanly has a valid summary.
source "$(dirname "$0")/lib.sh"
CHECK_DIR=$3
if ! command -v node >/dev/null || [ ! -d "$CHECK_DIR/node_modules/@mcap/core" ]; then
	echo "SKIP: the independent reader is not installed (scripts/install-deps.sh --test-beds runs npm ci in $CHECK_DIR)"
	exit 77
fi
check() { node "$CHECK_DIR/check_mcap.mjs" "$@"; }
# The results minus what depends on the machine's clock and load.
comparable() { jq -c 'del(.timing_ms, .t_host_ns, .t_publish_ns)' "$1"; }

# ---- 1. stereoctl record
"$STEREOCTL" record "${SMALL_SIM[@]}" -f sim -n 40 --output "$WORK/rec.mcap" --images 2>"$WORK/rec.log" ||
	fail "record failed: $(cat "$WORK/rec.log")"
"$STEREOCTL" record "${SMALL_SIM[@]}" -f sim -n 40 --output "$WORK/rec.srec" 2>/dev/null
check indexed "$WORK/rec.mcap" >"$WORK/rec.json" || fail "@mcap/core: $(cat "$WORK/rec.json")"
jq -e '.topics["/stereod/raw"] == 40 and .topics["/stereod/left/compressed"] == 40 and
	.topics["/stereod/right/compressed"] == 40 and .schemas["foxglove.CompressedImage"] == "jsonschema" and
	.messages == .statistics_messages' "$WORK/rec.json" >/dev/null || fail "recorded MCAP: $(cat "$WORK/rec.json")"
"$STEREOCTL" info "$WORK/rec.mcap" >"$WORK/info.txt" || fail "stereoctl info: $(cat "$WORK/info.txt")"
grep -q "clean end (data CRC ok)" "$WORK/info.txt" || fail "info: $(cat "$WORK/info.txt")"
grep -q "summary: .* valid" "$WORK/info.txt" || fail "info: $(cat "$WORK/info.txt")"
"$STEREOD" process --input "$WORK/rec.mcap" --output "$WORK/from_mcap.ndjson" --no-progress 2>/dev/null
"$STEREOD" process --input "$WORK/rec.srec" --output "$WORK/from_srec.ndjson" --no-progress 2>/dev/null
[ "$(wc -l <"$WORK/from_mcap.ndjson")" -eq 40 ] || fail "replayed $(wc -l <"$WORK/from_mcap.ndjson") frames of 40"
cmp -s <(comparable "$WORK/from_mcap.ndjson") <(comparable "$WORK/from_srec.ndjson") ||
	fail "the MCAP replays to other results than the .srec of the same frames"
pass "stereoctl record: 40 frames + 80 JPEG images, read by @mcap/core through the index; replay = .srec's"

# ---- 2. stereod process --output X.mcap
"$STEREOD" process --input "$WORK/rec.srec" --output "$WORK/out.mcap" --images --no-progress 2>"$WORK/process.log" ||
	fail "process to MCAP: $(cat "$WORK/process.log")"
check indexed "$WORK/out.mcap" --dump "$WORK/out_frames.ndjson" >"$WORK/out.json" ||
	fail "@mcap/core: $(cat "$WORK/out.json")"
jq -e '.topics["/stereod/frames"] == 40 and .topics["/stereod/left/compressed"] == 40 and
	.schemas["stereod.Frame"] == "jsonschema" and .frames_seq == [range(0; 40)]' "$WORK/out.json" >/dev/null ||
	fail "process MCAP: $(cat "$WORK/out.json")"
cmp -s <(comparable "$WORK/out_frames.ndjson") <(comparable "$WORK/from_srec.ndjson") ||
	fail "the MCAP's results differ from the NDJSON stream's"
# Every results reader (eval, map, trajectory) takes the MCAP as it takes the NDJSON.
"$STEREOD" process --input sim --format sim "${SMALL_SIM[@]}" --set sim.frames=30 --output "$WORK/sim.mcap" \
	--truth-dir "$WORK/truth" --no-progress 2>/dev/null
"$STEREOD" process --input sim --format sim "${SMALL_SIM[@]}" --set sim.frames=30 --output "$WORK/sim.ndjson" \
	--no-progress 2>/dev/null
"$STEREOCTL" eval --results "$WORK/sim.mcap" --truth "$WORK/truth" --json >"$WORK/eval_mcap.json" ||
	fail "eval on MCAP: $(cat "$WORK/eval_mcap.json")"
"$STEREOCTL" eval --results "$WORK/sim.ndjson" --truth "$WORK/truth" --json >"$WORK/eval_ndjson.json"
cmp -s "$WORK/eval_mcap.json" "$WORK/eval_ndjson.json" ||
	fail "eval differs between MCAP and NDJSON results: $(head -c 300 "$WORK/eval_mcap.json")"
pass "process --output X.mcap: 40 results equal to the NDJSON stream, images beside; eval reads it alike"

# ---- 3. live recording, SIGKILLed, then stopped cleanly
SOCK=$WORK/s.sock
"$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$SOCK" --set record.path="$WORK/live.mcap" \
	--set record.images=true 2>"$WORK/live.log" &
DAEMON=$!
PIDS+=($DAEMON)
# ~540 kB a frame raw (+ two small JPEGs): chunks close every 4 MB. Kill once several are on disk.
for _ in $(seq 400); do
	[ -f "$WORK/live.mcap" ] && [ "$(stat -c %s "$WORK/live.mcap")" -gt 20000000 ] && break
	sleep 0.05
done
kill -9 $DAEMON
wait $DAEMON 2>/dev/null || true
"$STEREOCTL" info "$WORK/live.mcap" >"$WORK/live_info.txt" || true
cat "$WORK/live_info.txt"
grep -q "recovered; cut at byte" "$WORK/live_info.txt" || fail "no cut reported: $(cat "$WORK/live_info.txt")"
ours=$(sed -n 's/^  \([0-9]*\) messages in \([0-9]*\) chunks recovered.*/\1 \2/p' "$WORK/live_info.txt")
raw=$(sed -n 's|^  /stereod/raw: \([0-9]*\) messages.*|\1|p' "$WORK/live_info.txt")
check stream "$WORK/live.mcap" >"$WORK/live.json" || fail "@mcap/core: $(cat "$WORK/live.json")"
theirs=$(jq -r '"\(.messages) \(.chunks)"' "$WORK/live.json")
[ "$ours" = "$theirs" ] || fail "stereoctl info recovered '$ours' (messages chunks), @mcap/core '$theirs'"
[ "${raw:-0}" -ge 15 ] || fail "only ${raw:-0} raw frames kept"
jq -e '.topics["/stereod/frames"] > 0' "$WORK/live.json" >/dev/null || fail "no results in the live MCAP"
"$STEREOD" process --input "$WORK/live.mcap" --output "$WORK/live.ndjson" --no-progress 2>/dev/null
[ "$(wc -l <"$WORK/live.ndjson")" -eq "$raw" ] || fail "replayed $(wc -l <"$WORK/live.ndjson") of $raw frames"
pass "SIGKILLed live MCAP: $ours (messages, chunks) kept, @mcap/core reads the same; $raw frames replay"

"$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$SOCK" --set record.path="$WORK/clean.mcap" 2>"$WORK/clean.log" &
DAEMON=$!
PIDS+=($DAEMON)
for _ in $(seq 400); do
	[ -f "$WORK/clean.mcap" ] && [ "$(stat -c %s "$WORK/clean.mcap")" -gt 6000000 ] && break
	sleep 0.05
done
kill -TERM $DAEMON
wait $DAEMON || fail "the daemon exited with $? on SIGTERM: $(tail -5 "$WORK/clean.log")"
check indexed "$WORK/clean.mcap" >"$WORK/clean.json" || fail "@mcap/core: $(cat "$WORK/clean.json")"
jq -e '.topics["/stereod/raw"] > 0 and .topics["/stereod/frames"] > 0 and .topics["/stereod/frames"] <= .topics["/stereod/raw"]' \
	"$WORK/clean.json" >/dev/null || fail "clean live MCAP: $(cat "$WORK/clean.json")"
pass "live MCAP stopped by SIGTERM: summary and indexes valid ($(jq -c .topics "$WORK/clean.json"))"
