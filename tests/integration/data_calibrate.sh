#!/usr/bin/env bash
# Stereo calibration on real chessboard pairs (OpenCV's samples, 9x6 inner corners; needs ../shared/data or
# opencv-doc): `stereoctl calibrate` writes the YAML with an RMS re-projection error under 0.5 px; stereod
# rectifies the same pairs with it and finds their stereo matches on one row; calibrations that do not fit
# (another image size, the eyes swapped) are refused at start with a message saying why.
# Usage: data_calibrate.sh STEREOD STEREOCTL DATA_DIR
DATA=$3
set -- "$1" "$2"
source "$(dirname "$0")/lib.sh"
SAMPLES=""
for dir in "$DATA/opencv_samples" /usr/share/doc/opencv-doc/examples/data; do
	[ -f "$dir/left01.jpg" ] && SAMPLES=$dir && break
done
[ -n "$SAMPLES" ] || { echo "SKIP: no left01.jpg..right14.jpg (../shared/data/opencv_samples or opencv-doc)"; exit 77; }

"$STEREOCTL" calibrate "$SAMPLES" --board 9x6 --square-mm 25 -o "$WORK/stereo.yml" --json >"$WORK/cal.json" ||
	fail "stereoctl calibrate failed: $(cat "$WORK/cal.json")"
rms=$(jq .rms_px "$WORK/cal.json")
pairs=$(jq '.pairs | length' "$WORK/cal.json")
[ "$pairs" -eq 13 ] || fail "the board was used in $pairs pairs, the samples have 13: $(jq -c .rejected "$WORK/cal.json")"
awk -v r="$rms" 'BEGIN { exit !(r < 0.5) }' || fail "RMS re-projection error $rms px (limit 0.5)"
[ "$(jq '.problems | length' "$WORK/cal.json")" = 0 ] || fail "problems: $(jq -c .problems "$WORK/cal.json")"
pass "calibrate: $pairs pairs, RMS $rms px (left alone $(jq .left_rms_px "$WORK/cal.json"), right alone $(jq .right_rms_px "$WORK/cal.json")), baseline $(jq .baseline_m "$WORK/cal.json") m in 25 mm squares"

# The pairs as a `folder` source, rectified with the calibration: stereo matches sit on one row.
mkdir -p "$WORK/pairs/left" "$WORK/pairs/right" "$WORK/swapped/left" "$WORK/swapped/right"
for f in "$SAMPLES"/left*.jpg; do
	n=$(basename "$f" | sed 's/^left//')
	ln -s "$f" "$WORK/pairs/left/$n"
	ln -s "${f%/*}/right$n" "$WORK/pairs/right/$n"
	ln -s "$f" "$WORK/swapped/right/$n"
	ln -s "${f%/*}/right$n" "$WORK/swapped/left/$n"
done
"$STEREOD" process --input "$WORK/pairs" --format folder --output "$WORK/out.ndjson" --no-progress \
	--set source.fps=1 --set calibration.file="$WORK/stereo.yml" 2>"$WORK/process.log" ||
	fail "stereod process with the calibration: $(tail -3 "$WORK/process.log")"
grep -q "calibration: $WORK/stereo.yml" "$WORK/process.log" || fail "the calibration was not announced: $(cat "$WORK/process.log")"
matched=$(jq -s '[.[].stereo.matched] | add' "$WORK/out.ndjson")
row=$(jq -s '[.[].stereo.median_row_diff_px | fabs] | max' "$WORK/out.ndjson")
xyz=$(jq -s '[.[].points[] | select(.xyz_m)] | length' "$WORK/out.ndjson")
[ "$matched" -gt 1000 ] || fail "only $matched stereo matches over 13 rectified pairs"
awk -v r="$row" 'BEGIN { exit !(r < 0.3) }' || fail "rectified pairs: a frame's matches differ by $row px in rows (limit 0.3)"
[ "$xyz" -gt 100 ] || fail "only $xyz points with xyz_m"
pass "rectified: $matched stereo matches over 13 pairs, every frame's median row difference within $row px, $xyz points with xyz_m"

# Refusals: the right calibration for other images, and a calibration of swapped eyes.
sed 's/^image_width: 640/image_width: 1280/' "$WORK/stereo.yml" >"$WORK/wrong_size.yml"
if "$STEREOD" process --input "$WORK/pairs" --format folder --output "$WORK/x.ndjson" --no-progress \
	--set source.fps=1 --set calibration.file="$WORK/wrong_size.yml" 2>"$WORK/refused.log"; then
	fail "a calibration for 1280x480 images was accepted for 640x480 ones"
fi
grep -q "wrong_size.yml does not fit" "$WORK/refused.log" && grep -q "1280x480" "$WORK/refused.log" ||
	fail "the refusal does not say why: $(cat "$WORK/refused.log")"
if "$STEREOCTL" calibrate "$WORK/swapped" -o "$WORK/swapped.yml" >"$WORK/swapped.out" 2>&1; then
	fail "calibrating swapped eyes reported no problem: $(tail -3 "$WORK/swapped.out")"
fi
grep -q "swapped" "$WORK/swapped.out" || fail "swapped eyes: $(tail -3 "$WORK/swapped.out")"
if "$STEREOD" process --input "$WORK/pairs" --format folder --output "$WORK/x.ndjson" --no-progress \
	--set source.fps=1 --set calibration.file="$WORK/swapped.yml" 2>"$WORK/refused2.log"; then
	fail "a calibration of swapped eyes was accepted"
fi
grep -q "swapped" "$WORK/refused2.log" || fail "the refusal does not say the eyes are swapped: $(cat "$WORK/refused2.log")"
pass "refused at start: a calibration for 1280x480 images ($(grep -o 'it was made for[^"]*' "$WORK/refused.log" | head -1)), and one of swapped eyes"
