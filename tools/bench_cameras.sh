#!/usr/bin/env bash
# Capture cost and latency against two fake GigE cameras (Aravis's own, in a private network namespace), and
# the soak: frames lost and resident memory over a long run.
#   tools/bench_cameras.sh BUILD_DIR [SECONDS=20] [FPS list="30 60"] [FAKE=stock|exposure]
# FAKE: stock = Aravis's arv-fake-gv-camera-0.8 (stamps its sender's wake time, skips periods when it stalls);
# exposure = the project's build/tests/stereod_fakecam --ramp (stamps the exposure slot, sends a late frame
# from its frame memory; see tests/fakecam/stereod_fakecam.cpp).
# Prints one table row per frame rate: frames, drops, |skew|, capture-to-publish latency, daemon CPU per frame
# (classification off: this is the capture path, the cameras' receive threads and the socket), RSS at start
# and end. The fake cameras run on the same two cores; their own CPU is reported apart.
if [ -z "${STEREOD_BENCH_NETNS:-}" ]; then
	STEREOD_BENCH_NETNS=1 exec unshare -rn bash "$0" "$@"
fi
set -euo pipefail
BUILD=$(realpath "$1")
SECONDS_RUN=${2:-20}
RATES=${3:-30 60}
FAKE=${4:-stock}
fake_camera() { # address serial
	if [ "$FAKE" = exposure ]; then
		"$BUILD/tests/stereod_fakecam" "$1" "$2" --ramp >/dev/null 2>&1 &
	else
		arv-fake-gv-camera-0.8 -i "$1" -s "$2" >/dev/null 2>&1 &
	fi
}
WORK=$(mktemp -d /tmp/stereod-bench.XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null; rm -rf "$WORK"' EXIT
ip link set lo up
ip addr add 127.0.0.2/8 dev lo
cpu_s() { awk '{ printf "%.3f", ($14 + $15) / 100 }' "/proc/$1/stat"; }
rss_mb() { awk '/VmRSS/ { printf "%.1f", $2 / 1024 }' "/proc/$1/status"; }
printf '| fps | seconds | frames | drops (stereod) | unpaired (fake stalls) | max abs skew ms | latency p50 / p99 / max ms | stereod CPU ms/frame | fake cameras CPU ms/frame | RSS start -> end MB |\n'
printf '|---|---|---|---|---|---|---|---|---|---|\n'
for fps in $RATES; do
	fake_camera 127.0.0.1 B-L
	L=$!
	fake_camera 127.0.0.2 B-R
	R=$!
	sleep 1.5
	SOCK=$WORK/b.sock
	"$BUILD/daemon/stereod" --set source.driver=aravis --set aravis.left=127.0.0.1 --set aravis.right=127.0.0.2 \
		--set aravis.width=1024 --set aravis.height=768 --set aravis.pixel_format=Mono8 --set aravis.packet_size=8192 \
		--set aravis.frame_rate="$fps" --set aravis.clock=shared --set aravis.max_skew_ms=2 --set features.enabled=false \
		--set output.socket="$SOCK" >"$WORK/daemon.log" 2>&1 &
	D=$!
	for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
	"$BUILD/tools/stereoctl" watch --socket "$SOCK" --raw >"$WORK/out.ndjson" &
	W=$!
	sleep 2
	cpu0=$(cpu_s $D); fake0=$(awk -v a="$(cpu_s $L)" -v b="$(cpu_s $R)" 'BEGIN { print a + b }'); rss0=$(rss_mb $D)
	n0=$(grep -c '"type":"frame"' "$WORK/out.ndjson" || true)
	sleep "$SECONDS_RUN"
	cpu1=$(cpu_s $D); fake1=$(awk -v a="$(cpu_s $L)" -v b="$(cpu_s $R)" 'BEGIN { print a + b }'); rss1=$(rss_mb $D)
	n1=$(grep -c '"type":"frame"' "$WORK/out.ndjson" || true)
	kill -TERM $D; wait $D || true
	kill $W $L $R 2>/dev/null || true
	wait $W $L $R 2>/dev/null || true
	status=$(grep '"type":"status"' "$WORK/out.ndjson" | tail -1)
	frames=$((n1 - n0))
	drops=$(echo "$status" | jq '[.drops | to_entries[] | select(.key != "unpaired") | .value] | add')
	unpaired=$(echo "$status" | jq '.drops.unpaired')
	skew=$(grep '"type":"frame"' "$WORK/out.ndjson" | jq -s '[.[].lr_skew_ns | fabs] | max / 1e6')
	latency=$(echo "$status" | jq -r '.latency_ms.capture_to_publish | "\(.p50) / \(.p99) / \(.max)"')
	printf '| %s | %s | %s | %s | %s | %.2f | %s | %s | %s | %s -> %s |\n' "$fps" "$SECONDS_RUN" "$frames" "$drops" "$unpaired" "$skew" \
		"$latency" "$(awk -v a="$cpu0" -v b="$cpu1" -v n="$frames" 'BEGIN { printf "%.2f", (b - a) * 1000 / n }')" \
		"$(awk -v a="$fake0" -v b="$fake1" -v n="$frames" 'BEGIN { printf "%.2f", (b - a) * 1000 / n }')" "$rss0" "$rss1"
done
