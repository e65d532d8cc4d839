#!/usr/bin/env bash
# Batch mode over the sim: every frame, in order, with its ground truth written for the evaluation tool.
source "$(dirname "$0")/lib.sh"
"$STEREOD" process --input sim --format sim "${SMALL_SIM[@]}" --set sim.frames=30 --set sim.scene=static_far \
	--output "$WORK/sim.ndjson" --truth-dir "$WORK/truth" 2>"$WORK/log" || fail "$(cat "$WORK/log")"
[ "$(wc -l <"$WORK/sim.ndjson")" -eq 30 ] || fail "want 30 messages"
jq -s -e '[.[].seq] == [range(0; 30)]' "$WORK/sim.ndjson" >/dev/null || fail "out of order"
jq -s -e '[.[1:][] | (.t_capture_ns)] | . == (sort)' "$WORK/sim.ndjson" >/dev/null || fail "timestamps go back"
[ "$(wc -l <"$WORK/truth/truth.ndjson")" -eq 30 ] || fail "want 30 truth lines"
[ "$(ls "$WORK/truth/masks" | wc -l)" -eq 30 ] || fail "want 30 masks"
head -1 "$WORK/truth/truth.ndjson" | jq -e '.camera_pose | length == 12' >/dev/null || fail "truth pose"
"$STEREOCTL" eval --results "$WORK/sim.ndjson" --truth "$WORK/truth" --json >"$WORK/eval.json" || fail "eval failed"
jq -e '.all.frames == 29' "$WORK/eval.json" >/dev/null || fail "eval scored $(jq .all.frames "$WORK/eval.json") frames"
pass "batch sim: 30 frames in order, truth and eval: $(cat "$WORK/eval.json")"
