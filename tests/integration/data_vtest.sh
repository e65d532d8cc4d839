#!/usr/bin/env bash
# Real data: OpenCV's vtest.avi (795 frames, 10 fps) through batch mode. Needs ../shared/data.
set -euo pipefail
STEREOD=$1
DATA=$2
VIDEO=$DATA/opencv_samples/vtest.avi
if [ ! -f "$VIDEO" ]; then
	echo "SKIP: $VIDEO is absent (this test needs ../shared/data beside the checkout)"
	exit 77
fi
WORK=$(mktemp -d /tmp/stereod-it.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
"$STEREOD" process --input "$VIDEO" --format video --output "$WORK/out.ndjson" --no-progress
lines=$(wc -l <"$WORK/out.ndjson")
[ "$lines" -eq 795 ] || { echo "FAIL: $lines frame messages, want 795"; exit 1; }
jq -s -e '[.[].seq] == [range(0; 795)]' "$WORK/out.ndjson" >/dev/null || { echo "FAIL: not in order"; exit 1; }
jq -s -e '[range(1; length) as $i | .[$i].t_capture_ns - .[$i - 1].t_capture_ns] | unique == [100000000]' \
	"$WORK/out.ndjson" >/dev/null || { echo "FAIL: t_capture_ns not spaced by 100 ms"; exit 1; }
echo "ok: vtest.avi: 795 frames in order, t_capture_ns spaced by exactly 100 ms"
