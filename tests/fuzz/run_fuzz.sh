#!/usr/bin/env bash
# Runs every libFuzzer target over a scratch copy of its committed corpus (tests/fuzz/corpus/<target>; what
# the run finds is not written back). A crash, leak, timeout or out-of-memory stops the run and fails it; the
# input that did it is kept in the scratch folder and printed.
# CI runs a fixed number of inputs from a fixed seed (STEREOD_FUZZ_SEED, default 1), sized to about 30 s each
# on the 2-core CI machine: the same inputs on every run, so a red CI is reproducible and a green one
# means what it says. Exploring further: STEREOD_FUZZ_SEED=0 (random) and a time budget.
# Usage: run_fuzz.sh BUILD_FUZZ_DIR [SECONDS_PER_TARGET]   (with SECONDS given: time-bounded, random seed)
set -euo pipefail
BUILD=$(realpath "$1")
SECONDS_EACH=${2:-30}
HERE=$(cd "$(dirname "$0")" && pwd)
WORK=$(mktemp -d /tmp/stereod-fuzz.XXXXXX)
failed=()
for target in fuzz_config fuzz_recording fuzz_mcap fuzz_frame_message fuzz_kitti_calib; do
	exe=$BUILD/tests/fuzz/$target
	[ -x "$exe" ] || { echo "FAIL: $exe not built"; exit 1; }
	mkdir -p "$WORK/$target/corpus" "$WORK/$target/artifacts"
	cp "$HERE/corpus/$target"/* "$WORK/$target/corpus/"
	# -rss_limit_mb: an input that makes a reader allocate without bound is a finding, not a host problem.
	case $target in
	fuzz_config) runs=8000 ;;
	fuzz_recording) runs=20000 ;;
	fuzz_mcap) runs=60000 ;;
	fuzz_frame_message) runs=400000 ;;
	fuzz_kitti_calib) runs=150000 ;;
	esac
	if [ -n "${2:-}" ]; then
		bound=(-max_total_time="$SECONDS_EACH" -seed=0)
	else
		bound=(-runs="$runs" -seed="${STEREOD_FUZZ_SEED:-1}")
	fi
	if (cd "$WORK/$target" && "$exe" "${bound[@]}" -timeout=10 -rss_limit_mb=1024 \
		-max_len=65536 -print_final_stats=1 -artifact_prefix="$WORK/$target/artifacts/" corpus \
		>"$WORK/$target/log" 2>&1); then
		edges=$(grep -o 'cov: [0-9]*' "$WORK/$target/log" | tail -1)
		done_runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$WORK/$target/log")
		echo "ok: $target: $done_runs inputs (${bound[*]}), $edges, corpus $(ls "$WORK/$target/corpus" | wc -l)"
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
