#!/usr/bin/env bash
# Stereo geometry end to end on the sim's walk (a rig carried forward down a street, walkers crossing, one
# walking at it, one keeping pace): the frames carry metric 3D and the camera's pose; against the sim's truth
# (its depth images and poses.tum) depth and trajectory are within the issue's limits. The figures are
# printed; docs/geometry.md has the longer runs.
source "$(dirname "$0")/lib.sh"
"$STEREOD" process --input sim --format sim --set sim.scene=walk --set sim.depth=true --set sim.frames=120 \
	--output "$WORK/walk.ndjson" --truth-dir "$WORK/truth" 2>"$WORK/log" || fail "$(cat "$WORK/log")"
[ -s "$WORK/truth/poses.tum" ] || fail "the sim wrote no poses.tum"
[ "$(ls "$WORK/truth/depth" | wc -l)" -eq 120 ] || fail "want 120 true depth images"
head -1 "$WORK/walk.ndjson" | jq -e '.ego.T_world_curr | length == 16' >/dev/null || fail "no world pose on frame 0"
valid=$(jq -s '[.[1:][] | select(.ego.valid == true)] | length' "$WORK/walk.ndjson")
[ "$valid" -ge 115 ] || fail "pose estimated on only $valid of 119 frames: $(jq -c -s '[.[] | .ego.reason] | unique' "$WORK/walk.ndjson")"
"$STEREOCTL" eval --results "$WORK/walk.ndjson" --truth "$WORK/truth" --poses "$WORK/truth" --json >"$WORK/eval.json" ||
	fail "eval failed"
labels=$(sed -n 1p "$WORK/eval.json")
trajectory=$(sed -n 2p "$WORK/eval.json")
echo "$labels" | jq -e '.depth.with_depth >= 0.3 * .depth.points' >/dev/null ||
	fail "fewer than 30 % of points carry xyz_m: $(echo "$labels" | jq -c .depth)"
echo "$labels" | jq -e '.depth.median_relative_error < 0.01' >/dev/null ||
	fail "median relative depth error not under 1 %: $(echo "$labels" | jq -c .depth)"
echo "$trajectory" | jq -e '.drift_translation_percent < 1.0 and .drift_windows > 100' >/dev/null ||
	fail "drift over 10-frame windows not under 1 %: $trajectory"
pass "walk, 120 frames: pose on $valid/119; depth $(echo "$labels" | jq -c .depth); trajectory $(echo "$trajectory" | jq -c '{ate_rmse_m: .ate_m.rmse, rpe_median_m: .rpe_translation_m.median, drift_percent: .drift_translation_percent}'); labels F1 $(echo "$labels" | jq .all.f1)"

# The static map of the walk: written, as many vertices as announced, all finite, and the colour path runs.
"$STEREOCTL" map --results "$WORK/walk.ndjson" -o "$WORK/walk.ply" --colour --input sim --format sim \
	--set sim.scene=walk --set sim.depth=true --set sim.frames=120 2>"$WORK/map.log" || fail "map: $(cat "$WORK/map.log")"
announced=$(grep -m1 '^element vertex' "$WORK/walk.ply" | awk '{print $3}')
written=$(sed '1,/^end_header/d' "$WORK/walk.ply" | awk 'NF == 7 && $1 == $1 + 0 && $3 > 0' | wc -l)
[ "$announced" -ge 1000 ] || fail "static map of only $announced points: $(cat "$WORK/map.log")"
[ "$written" -eq "$announced" ] || fail "static map: $announced vertices announced, $written finite ones written"
pass "static map: $(cat "$WORK/map.log")"
"$STEREOCTL" eval --groups --results "$WORK/walk.ndjson" --truth "$WORK/truth" --name walk | tail -1 |
	sed 's/^/groups (figures, not asserted): /'
