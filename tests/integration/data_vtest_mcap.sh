#!/usr/bin/env bash
# Real data in MCAP (issue 18's acceptance): `stereod process` over OpenCV's vtest.avi (795 frames) into an MCAP
# with the results and the images, read by an independent reader (Foxglove's @mcap/core, through the summary
# and indexes, every chunk CRC checked): every message present, statistics agree, schemas parse, and the
# results equal the NDJSON stream of the same run settings. Needs ../shared/data and the npm reader.
set -euo pipefail
STEREOD=$1
DATA=$2
CHECK_DIR=$3
VIDEO=$DATA/opencv_samples/vtest.avi
if [ ! -f "$VIDEO" ]; then
	echo "SKIP: $VIDEO is absent (this test needs ../shared/data beside the checkout)"
	exit 77
fi
if ! command -v node >/dev/null || [ ! -d "$CHECK_DIR/node_modules/@mcap/core" ]; then
	echo "SKIP: the independent reader is not installed (scripts/install-deps.sh --test-beds runs npm ci in $CHECK_DIR)"
	exit 77
fi
WORK=$(mktemp -d /tmp/stereod-it.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
comparable() { jq -c 'del(.timing_ms, .t_host_ns, .t_publish_ns)' "$1"; }

"$STEREOD" process --input "$VIDEO" --output "$WORK/vtest.mcap" --images --no-progress 2>"$WORK/mcap.log" ||
	fail "process to MCAP: $(cat "$WORK/mcap.log")"
"$STEREOD" process --input "$VIDEO" --output "$WORK/vtest.ndjson" --no-progress 2>/dev/null
node "$CHECK_DIR/check_mcap.mjs" indexed "$WORK/vtest.mcap" --dump "$WORK/frames.ndjson" >"$WORK/check.json" ||
	fail "@mcap/core: $(cut -c1-600 "$WORK/check.json")"
jq -c '{topics, schemas, messages, statistics_messages, chunks}' "$WORK/check.json"
jq -e '.topics["/stereod/frames"] == 795 and .topics["/stereod/left/compressed"] == 795 and
	.messages == 1590 and .statistics_messages == 1590 and .frames_seq == [range(0; 795)] and
	.schemas["stereod.Frame"] == "jsonschema" and .schemas["foxglove.CompressedImage"] == "jsonschema"' \
	"$WORK/check.json" >/dev/null || fail "vtest MCAP: $(jq -c 'del(.frames_seq)' "$WORK/check.json")"
cmp -s <(comparable "$WORK/frames.ndjson") <(comparable "$WORK/vtest.ndjson") ||
	fail "the MCAP's results differ from the NDJSON stream's"
echo "ok: vtest.avi -> MCAP: 795 results + 795 JPEG frames, read by @mcap/core through its index; results = NDJSON"
