#!/usr/bin/env bash
# Runs every libFuzzer target for a bounded time over a scratch copy of its committed corpus
# (tests/fuzz/corpus/<target>; what the run finds is not written back). A crash, leak, timeout or
# out-of-memory stops the run and fails it; the input that did it is kept in the scratch folder and printed.
# Usage: run_fuzz.sh BUILD_FUZZ_DIR [SECONDS_PER_TARGET]
set -euo pipefail
BUILD=$(realpath "$1")
SECONDS_EACH=${2:-30}
HERE=$(cd "$(dirname "$0")" && pwd)
WORK=$(mktemp -d /tmp/stereod-fuzz.XXXXXX)
failed=()
for target in fuzz_config fuzz_recording fuzz_frame_message fuzz_kitti_calib; do
	exe=$BUILD/tests/fuzz/$target
	[ -x "$exe" ] || { echo "FAIL: $exe not built"; exit 1; }
	mkdir -p "$WORK/$target/corpus" "$WORK/$target/artifacts"
	cp "$HERE/corpus/$target"/* "$WORK/$target/corpus/"
	# -rss_limit_mb: an input that makes a reader allocate without bound is a finding, not a host problem.
	if (cd "$WORK/$target" && "$exe" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=1024 \
		-max_len=65536 -print_final_stats=1 -artifact_prefix="$WORK/$target/artifacts/" corpus \
		>"$WORK/$target/log" 2>&1); then
		runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$WORK/$target/log")
		edges=$(grep -o 'cov: [0-9]*' "$WORK/$target/log" | tail -1)
		echo "ok: $target: $runs inputs in ${SECONDS_EACH} s, $edges, corpus $(ls "$WORK/$target/corpus" | wc -l)"
	else
		echo "FAIL: $target"
		grep -E "ERROR|SUMMARY|==[0-9]+==|Test unit written|#[0-9]+ .* in " "$WORK/$target/log" | head -30
		failed+=("$target")
	fi
done
if [ ${#failed[@]} -gt 0 ]; then
	echo "fuzzing found problems in: ${failed[*]} (inputs kept in $WORK)"
	exit 1
fi
rm -rf "$WORK"
