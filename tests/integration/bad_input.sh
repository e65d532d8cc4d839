#!/usr/bin/env bash
# Bad input gets one clear error naming what is wrong, and nothing is lost.
source "$(dirname "$0")/lib.sh"

expect_error() { # name, expected text, command...
	local name=$1 want=$2
	shift 2
	if "$@" >"$WORK/out" 2>"$WORK/err"; then fail "$name: succeeded"; fi
	grep -qF -- "$want" "$WORK/err" || fail "$name: stderr lacks '$want': $(cat "$WORK/err")"
	[ "$(grep -c . "$WORK/err")" -eq 1 ] || fail "$name: more than one line of error: $(cat "$WORK/err")"
	pass "$name: $(cat "$WORK/err")"
}

printf '[sim]\nwidth = 640\nheight 480\n' >"$WORK/malformed.toml"
expect_error "malformed line" "malformed.toml:3: syntax error" "$STEREOD" --config "$WORK/malformed.toml"
printf '[sim]\nwidth = 640\n\n[output]\nsokcet = "/tmp/x"\n' >"$WORK/unknown.toml"
expect_error "unknown key" "unknown.toml:5: unknown key 'output.sokcet'" "$STEREOD" --config "$WORK/unknown.toml"
printf '[pipeline]\nworkers = -1\n' >"$WORK/range.toml"
expect_error "out of range" "range.toml:2: pipeline.workers: must be between 0 and 256 (got -1)" \
	"$STEREOD" --config "$WORK/range.toml"
expect_error "missing config" "cannot read config file" "$STEREOD" --config "$WORK/absent.toml"
expect_error "missing input" "--input $WORK/nope.avi: no such file or directory" \
	"$STEREOD" process --input "$WORK/nope.avi" --output "$WORK/x.ndjson"
echo "not a recording" >"$WORK/fake.srec"
expect_error "not a recording" "not a stereod recording" \
	"$STEREOD" process --input "$WORK/fake.srec" --format recording --output "$WORK/x.ndjson"

# The prior's ONNX model: missing, not a model, or not fitting the configuration, refused at start with the
# reason; a class map that does not parse names file, line and key.
MODELS="$(cd "$(dirname "$0")/../fixtures/onnx" && pwd)"
ONNX=(--set prior.enabled=true --set prior.detector=onnx --set prior.model_width=64 --set prior.model_height=64)
expect_error "missing model" "prior.model: $WORK/absent.onnx: cannot open: No such file or directory" \
	"$STEREOD" process --input sim --format sim --set sim.frames=2 "${ONNX[@]}" --set prior.model="$WORK/absent.onnx" \
	--output "$WORK/x.ndjson"
expect_error "not a model" "prior.model: $WORK/fake.srec: not a model OpenCV's dnn can read" \
	"$STEREOD" process --input sim --format sim --set sim.frames=2 "${ONNX[@]}" --set prior.model="$WORK/fake.srec" \
	--output "$WORK/x.ndjson"
expect_error "unfit model" "class 7 is mapped, but the model has 2 classes (0 to 1)" \
	"$STEREOD" process --input sim --format sim --set sim.frames=2 "${ONNX[@]}" \
	--set prior.model="$MODELS/yolov8_fixed.onnx" --set prior.model_classes=7:dynamic --output "$WORK/x.ndjson"
printf '[prior]\nenabled = true\nmodel_classes = "0:dynamic,56:chair"\n' >"$WORK/classes.toml"
expect_error "bad class map" "classes.toml:3: prior.model_classes: '56:chair': the category must be dynamic or potentially_dynamic" \
	"$STEREOD" --config "$WORK/classes.toml"

# A truncated recording is not an error: its complete frames are processed and the cut is reported once.
"$STEREOCTL" record "${SMALL_SIM[@]}" --frames 5 --output "$WORK/five.srec" 2>/dev/null
truncate -s $(($(stat -c %s "$WORK/five.srec") - 10)) "$WORK/five.srec"
"$STEREOD" process --input "$WORK/five.srec" --output "$WORK/five.ndjson" 2>"$WORK/err" || fail "truncated replay failed"
[ "$(wc -l <"$WORK/five.ndjson")" -eq 4 ] || fail "truncated recording: want the 4 complete frames"
grep -q "4 complete frames recovered; cut at byte" "$WORK/err" || fail "no cut report: $(cat "$WORK/err")"
pass "truncated recording: $(grep -o 'replay: .*' "$WORK/err")"

# A video cut in half: the frames that are there are processed, and the early end is said (it used to exit 0
# with no word, though the container had announced 795 frames).
VIDEO=/usr/share/doc/opencv-doc/examples/data/vtest.avi
if [ -f "$VIDEO" ]; then
	head -c $(($(stat -c %s "$VIDEO") / 2)) "$VIDEO" >"$WORK/half.avi"
	"$STEREOD" process --input "$WORK/half.avi" --output "$WORK/half.ndjson" --set features.enabled=false \
		2>"$WORK/err" || fail "half video: $(tail -3 "$WORK/err")"
	grep -q "the input ended early: video announced 795 frames" "$WORK/err" || fail "no early-end warning: $(tail -3 "$WORK/err")"
	pass "video cut in half: $(grep -o 'the input ended early.*' "$WORK/err")"
fi
