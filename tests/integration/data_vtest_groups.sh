#!/usr/bin/env bash
# Real data: issue 16's vtest acceptance, with the default (sparse) flow, against the reference of our own
# (stereoctl reference: the per-pixel median background; docs/classification.md): each walking person inside
# a group box in at least 90 % of the views where they walk, under 10 % of the boxes on the background, and a
# dynamic-label F1 on the walking people of at least 0.9. Also that the label rule of stop 47
# (groups.new_in_box_frames) is what lifts the F1: with it off the figure is lower. Needs ../shared/data.
# Usage: data_vtest_groups.sh STEREOD STEREOCTL DATA_DIR
VIDEO=$3/opencv_samples/vtest.avi
set -- "$1" "$2"
source "$(dirname "$0")/lib.sh"
[ -f "$VIDEO" ] || { echo "SKIP: $VIDEO is absent (this test needs ../shared/data beside the checkout)"; exit 77; }

"$STEREOCTL" reference --input "$VIDEO" --format video -o "$WORK/ref" >/dev/null 2>&1
run() { # name, extra --set ...
	local name=$1
	shift
	"$STEREOD" process --input "$VIDEO" --format video --output "$WORK/$name.ndjson" --no-progress "$@" 2>/dev/null
	"$STEREOCTL" eval --results "$WORK/$name.ndjson" --truth "$WORK/ref" --groups --json >"$WORK/$name.json"
}
run default
run no_new --set groups.new_in_box_frames=0
get() { jq -r ".$2" "$WORK/$1.json"; }
covered=$(get default walking_covered)
on_movers=$(get default groups_on_movers)
f1=$(get default walking_label_f1)
f1_off=$(get no_new walking_label_f1)
echo "walking views covered $covered, boxes on movers $on_movers, walking-label F1 $f1 (precision" \
	"$(get default walking_label_precision), recall $(get default walking_label_recall)); without" \
	"groups.new_in_box_frames $f1_off"
awk -v a="$covered" 'BEGIN { exit !(a >= 0.9) }' || fail "walkers inside a box in $covered of their walking views, want >= 0.9"
awk -v a="$on_movers" 'BEGIN { exit !(a > 0.9) }' || fail "$on_movers of the boxes on a mover: over 10 % on the background"
awk -v a="$f1" 'BEGIN { exit !(a >= 0.9) }' || fail "walking-label F1 $f1, want >= 0.9"
awk -v a="$f1" -v b="$f1_off" 'BEGIN { exit !(a > b + 0.01) }' || fail "new_in_box_frames lifts the F1 from $f1_off to $f1 only"
pass "issue 16's vtest acceptance holds"
