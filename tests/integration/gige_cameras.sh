#!/usr/bin/env bash
# The Aravis driver against real GigE Vision peers: Aravis's fake cameras speaking GVCP/GVSP over UDP,
# inside a network namespace this test makes (discovery broadcasts never leave it).
#   1. two cameras, 1024x768 Mono8 at 30 fps, 20 s to a socket client: every frame in order, no gap, no drop,
#      |lr_skew| < 2 ms, the 16-bit block-id wrap crossed (the fake starts at 65400), SIGTERM exits 0. The
#      cameras are the project's fake (Aravis's fake camera stack, stamping the exposure slot as a camera's
#      own clock does, see tests/fakecam/stereod_fakecam.cpp); then the same 20 s against Aravis's stock
#      arv-fake-gv-camera, which stamps its sending thread's wake time: its stalls are counted, not hidden;
#   2. a camera losing 1% of its packets: losses counted, frames flagged incomplete;
#   3. the right camera killed and restarted: the client stays connected, streaming resumes within 10 s;
#   4. exact pixels: real stereo photographs served as two cameras and as one interleaved16 camera,
#      recorded by stereoctl and exported: byte for byte the originals.
# Usage: gige_cameras.sh STEREOD STEREOCTL FAKECAM IMAGE_EQUAL
if [ -z "${STEREOD_GIGE_NETNS:-}" ]; then
	command -v unshare >/dev/null || { echo "SKIP: unshare not found"; exit 77; }
	STEREOD_GIGE_NETNS=1 exec unshare -rn bash "$0" "$@"
fi
STEREOD=$1 STEREOCTL=$2 FAKECAM=$3 IMAGE_EQUAL=$4
set -- "$STEREOD" "$STEREOCTL"
source "$(dirname "$0")/lib.sh"
command -v arv-fake-gv-camera-0.8 >/dev/null || {
	echo "SKIP: arv-fake-gv-camera-0.8 missing (bash scripts/install-deps.sh --test-beds installs aravis-tools)"
	exit 77
}
ip link set lo up
for i in 2 3 4 5; do ip addr add 127.0.0.$i/8 dev lo; done

start_camera() { # address serial [fake camera options...]
	local address=$1 serial=$2
	shift 2
	arv-fake-gv-camera-0.8 -i "$address" -s "$serial" "$@" >"$WORK/cam-$serial.log" 2>&1 &
	CAM_PID=$!
	PIDS+=($CAM_PID)
}
wait_cameras() { # count
	for _ in $(seq 50); do
		[ "$("$STEREOCTL" devices --aravis 2>/dev/null | grep -c 'GigEVision at')" -ge "$1" ] && return 0
		sleep 0.1
	done
	fail "fewer than $1 cameras answered discovery in 5 s"
}
# Reads the socket with each line stamped with the host's real time, until killed.
watch_stamped() { # socket out
	"$STEREOCTL" watch --socket "$1" --raw | while IFS= read -r line; do echo "$EPOCHREALTIME $line"; done >"$2"
}
wait_socket() {
	for _ in $(seq 100); do [ -S "$1" ] && return 0; sleep 0.1; done
	fail "no socket after 10 s: $(tail -5 "$WORK/daemon.log")"
}
stop_daemon() { # pid
	kill -TERM "$1"
	local rc=0
	wait "$1" || rc=$?
	[ $rc -eq 0 ] || fail "daemon exit code $rc after SIGTERM: $(tail -5 "$WORK/daemon.log")"
}
frames_of() { sed 's/^[0-9.]* //' "$1" | grep '"type":"frame"'; }
last_status() { sed 's/^[0-9.]* //' "$1" | grep '"type":"status"' | tail -1; }

PAIR=(--set source.driver=aravis --set aravis.left=127.0.0.1 --set aravis.right=127.0.0.2 --set aravis.width=1024
	--set aravis.height=768 --set aravis.pixel_format=Mono8 --set aravis.frame_rate=30 --set aravis.packet_size=8192
	--set aravis.max_skew_ms=2 --set aravis.clock=shared)
# clock=shared: both fake cameras stamp frames with this host's real-time clock, as two PTP-synchronised
# cameras share one clock; skew is then measured on the cameras' own stamps.

# ---------------------------------------------------------------------------------- 1. a synchronized pair
"$FAKECAM" 127.0.0.1 CAM-L --ramp >"$WORK/cam-l.log" 2>&1 &
EXPOSURE_PIDS=($!)
"$FAKECAM" 127.0.0.2 CAM-R --ramp >"$WORK/cam-r.log" 2>&1 &
EXPOSURE_PIDS+=($!)
PIDS+=("${EXPOSURE_PIDS[@]}")
wait_cameras 2
# Streams 20 s from the pair at 127.0.0.1/2 to a socket client; leaves the frames in $WORK/NAME.frames and the
# last status in STATUS, and checks what holds for any fake camera: seq contiguous, no drop but `unpaired`,
# captured == published, skew under 2 ms, the block-id wrap crossed, SIGTERM exit 0.
stream_pair() { # name
	local sock=$WORK/$1.sock
	# Capture alone (features off): a moving ramp is a worst case for the classifier (46 ms per frame), which
	# would make this a test of processing speed on two cores, not of the camera path.
	"$STEREOD" "${PAIR[@]}" --set output.socket="$sock" --set output.status_interval_s=0.5 --set features.enabled=false \
		>"$WORK/daemon.log" 2>&1 &
	local daemon=$!
	PIDS+=($daemon)
	wait_socket "$sock"
	watch_stamped "$sock" "$WORK/$1.out" &
	local watch=$!
	sleep 20
	stop_daemon $daemon
	wait $watch 2>/dev/null || true
	frames_of "$WORK/$1.out" >"$WORK/$1.frames"
	N=$(wc -l <"$WORK/$1.frames")
	STATUS=$(last_status "$WORK/$1.out")
	[ "$N" -gt 0 ] || fail "$1: no frame in 20 s; $STATUS"
	# Each camera delivered its 20 s at 30 fps to the driver, whatever became of the pairs.
	[ "$(echo "$STATUS" | jq '[.device.left_completed, .device.right_completed] | min >= 480')" = true ] ||
		fail "$1: a camera completed fewer than 480 frames in 20 s at 30 fps: $STATUS"
	jq -s -e '[.[].seq] as $s | all(range(1; $s|length); $s[.] == $s[. - 1] + 1)' "$WORK/$1.frames" >/dev/null ||
		fail "$1: frame sequence has a gap or is out of order"
	SKEW=$(jq -s '[.[].lr_skew_ns | fabs] | max' "$WORK/$1.frames")
	SKEW_MEAN=$(jq -s '[.[].lr_skew_ns | fabs] | add / length | floor' "$WORK/$1.frames")
	local drops
	drops=$(echo "$STATUS" | jq -c '.drops | with_entries(select(.value > 0 and .key != "unpaired"))')
	[ "$drops" = "{}" ] || fail "$1: drops counted: $drops; $STATUS"
	[ "$(echo "$STATUS" | jq '.frames.captured == .frames.published')" = true ] || fail "$1: captured != published: $STATUS"
	# Never beyond the pairing window (aravis.max_skew_ms = 2, inclusive): a wider skew would be a wrong pair.
	[ "$SKEW" -le 2000000 ] || fail "$1: |lr_skew| up to $SKEW ns (pairing window 2 ms)"
	[ "$(echo "$STATUS" | jq '.device.left_completed > 536')" = true ] || fail "$1: block-id wrap not reached"
	grep -q '"ok"' "$WORK/$1.frames" || fail "$1: no frame has status ok"
	UNPAIRED=$(echo "$STATUS" | jq '.drops.unpaired')
	LATENCY=$(echo "$STATUS" | jq -c '.latency_ms.capture_to_publish | {p50, p99, max}')
}

# A camera that stamps its exposures: nothing may be lost at all, not even a frame without its partner.
stream_pair exposure
[ "$N" -ge 480 ] || fail "exposure: only $N frames in 20 s at 30 fps; $STATUS"
[ "$SKEW" -lt 2000000 ] || fail "exposure-stamped cameras: |lr_skew| up to $SKEW ns (limit: under 2 ms)"
missing=$(echo "$STATUS" | jq '.device.left_missing_frames + .device.right_missing_frames')
[ "$UNPAIRED" = 0 ] && [ "$missing" = 0 ] ||
	fail "exposure-stamped cameras: $UNPAIRED unpaired, $missing frame ids missing (slots the fake's sender missed): $(echo "$STATUS" | jq -c '{drops, device}')"
pass "pair: $N frames in 20 s, seq contiguous across the block-id wrap, no drop counted (unpaired 0, frame ids missing 0), |lr_skew| max $SKEW ns mean $SKEW_MEAN ns, latency $LATENCY ms, startup unpaired $(echo "$STATUS" | jq .device.startup_unpaired)"
kill "${EXPOSURE_PIDS[@]}" 2>/dev/null || true
wait "${EXPOSURE_PIDS[@]}" 2>/dev/null || true

# Aravis's stock fake stamps the moment its sender thread runs. That thread stalls now and then on a busy
# 2-core machine (testbeds FINDINGS 1.3) and skips frame periods without a frame-id gap, and its stamps jitter
# by a millisecond or two: the partner's frames of those periods, and frames whose stamps landed further
# apart than max_skew_ms, cannot be paired, and are counted as unpaired. How many depends on how busy the
# machine is (on CI's two cores beside the daemon, 266 of 596 pairs once; 138 unpaired another time, where
# the cameras' skipped periods and late frames were 46: two stamps can each stay within the tolerance of
# their own cadence and still be further than it from each other, so the cadence counts cannot bound the
# unpaired). So neither the pairs nor the unpaired are held to a figure here; every frame the cameras
# completed must be accounted for. Exact pairing is the exposure-stamped cameras' test above.
start_camera 127.0.0.1 CAM-L
start_camera 127.0.0.2 CAM-R
RIGHT_PID=$CAM_PID
wait_cameras 2
stream_pair stock
skipped=$(echo "$STATUS" | jq '.device | .left_skipped_periods + .right_skipped_periods + .left_irregular_intervals + .right_irregular_intervals')
# Every completed frame is in a pair, counted unpaired (at start-up or later) or discarded while settling; at
# most a frame per camera may still be waiting for its partner when the last status was written.
unaccounted=$(echo "$STATUS" | jq '(.device | .left_completed + .right_completed - .startup_unpaired - .settling_discarded)
	- .drops.unpaired - 2 * .frames.captured')
[ "$unaccounted" -ge 0 ] && [ "$unaccounted" -le 2 ] ||
	fail "stock: $unaccounted completed frames neither paired nor counted: $STATUS"
pass "pair, Aravis's stock fake: $N frames, every completed frame paired or counted, $UNPAIRED unpaired for $skipped skipped periods and late frames of the fake cameras, |lr_skew| max $SKEW ns, latency $LATENCY ms"

# ---------------------------------------------------------------------------------- 2. packet loss
start_camera 127.0.0.3 CAM-LOSSY -r 10
wait_cameras 3
SOCK=$WORK/lossy.sock
"$STEREOD" --set source.driver=aravis --set aravis.left=127.0.0.3 --set aravis.layout=side_by_side \
	--set aravis.width=1024 --set aravis.height=768 --set aravis.pixel_format=Mono8 --set aravis.packet_size=8192 \
	--set output.socket="$SOCK" --set output.status_interval_s=0.5 --set features.enabled=false >"$WORK/daemon.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
wait_socket "$SOCK"
watch_stamped "$SOCK" "$WORK/lossy.out" &
WATCH=$!
sleep 6
stop_daemon $DAEMON
wait $WATCH 2>/dev/null || true
status=$(last_status "$WORK/lossy.out")
incomplete=$(frames_of "$WORK/lossy.out" | grep -c '"status":"incomplete"' || true)
missing=$(echo "$status" | jq '.device.left_missing_packets')
counted=$(echo "$status" | jq '.device.left_incomplete + .drops.camera_failed + .drops.source_gap')
[ "$missing" -gt 0 ] || fail "1% packet loss, but no missing packets counted: $(echo "$status" | jq -c .device)"
[ "$counted" -gt 0 ] || fail "no lost or incomplete frame counted: $status"
[ "$incomplete" -gt 0 ] || [ "$(echo "$status" | jq '.drops.camera_failed + .drops.source_gap')" -gt 0 ] ||
	fail "no frame flagged incomplete"
pass "1% packet loss: $missing packets missing, $incomplete frames flagged incomplete, $(echo "$status" | jq -c '{gap: .drops.source_gap, failed: .drops.camera_failed, completed: .device.left_completed}')"
kill "$CAM_PID" 2>/dev/null || true

# ---------------------------------------------------------------------------------- 3. kill and restart
SOCK=$WORK/reconnect.sock
"$STEREOD" "${PAIR[@]}" --set output.socket="$SOCK" --set output.status_interval_s=0.5 --set features.enabled=false \
	--set aravis.no_frame_timeout_s=2 >"$WORK/daemon.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
wait_socket "$SOCK"
watch_stamped "$SOCK" "$WORK/reconnect.out" &
WATCH=$!
sleep 4
kill -9 $RIGHT_PID

sleep 4
start_camera 127.0.0.2 CAM-R
back_time=$EPOCHREALTIME
resumed=""
for _ in $(seq 150); do
	sleep 0.1
	resumed=$(awk -v t="$back_time" '$1 > t && /"type":"frame"/ { print $1; exit }' "$WORK/reconnect.out")
	[ -n "$resumed" ] && break
done
[ -n "$resumed" ] || fail "no frame within 15 s of the camera's return: $(tail -5 "$WORK/daemon.log")"
sleep 2
kill -0 $WATCH 2>/dev/null || fail "the client was disconnected"
stop_daemon $DAEMON
wait $WATCH 2>/dev/null || true
resume_s=$(awk -v a="$resumed" -v b="$back_time" 'BEGIN { printf "%.2f", a - b }')
awk -v s="$resume_s" 'BEGIN { exit !(s < 10) }' || fail "streaming resumed $resume_s s after the camera came back (limit 10 s)"
grep -q '"source_state":"reconnecting"' "$WORK/reconnect.out" || fail "status never said reconnecting: $(grep -E "warn|reconnect" "$WORK/daemon.log" | tail -5)"
status=$(last_status "$WORK/reconnect.out")
outage=$(echo "$status" | jq '.drops.outage')
# The outage is the periods between the last pair before the kill and the first after the return, less one:
# at least the 4 s the camera was away (119 frames at 30 fps), and what the frames' own arrival stamps show.
gap_s=$(grep '"type":"frame"' "$WORK/reconnect.out" | cut -d' ' -f2- | jq -r '.t_host_ns' |
	awk 'NR > 1 && $1 - prev > max { max = $1 - prev } { prev = $1 } END { printf "%.3f", max / 1e9 }')
expected=$(awk -v g="$gap_s" 'BEGIN { printf "%d", g * 30 + 0.5 - 1 }')
[ "$outage" -ge 119 ] || fail "the outage counted $outage frames; the camera was away for over 4 s (119 frames): $status"
[ $((outage - expected)) -le 2 ] && [ $((expected - outage)) -le 2 ] ||
	fail "the outage counted $outage frames; the frames' arrival stamps show a gap of $gap_s s ($expected frames)"
pass "right camera killed and restarted after 4 s: streaming resumed $resume_s s after it came back, client kept, outage counted as $outage frames (the stamps' gap $gap_s s: $expected)"

# ---------------------------------------------------------------------------------- 4. exact pixels
IMAGES=""
for dir in "$(dirname "$0")/../../../shared/data/opencv_samples" /usr/share/doc/opencv-doc/examples/data; do
	[ -f "$dir/aloeL.jpg" ] && IMAGES=$dir && break
done
[ -n "$IMAGES" ] || fail "no aloeL.jpg/aloeR.jpg (../shared/data or opencv-doc)"
"$FAKECAM" 127.0.0.4 PIX-L --image "$IMAGES/aloeL.jpg" >"$WORK/pix-l.log" 2>&1 &
PIDS+=($!)
"$FAKECAM" 127.0.0.5 PIX-R --image "$IMAGES/aloeR.jpg" >"$WORK/pix-r.log" 2>&1 &
PIDS+=($!)
"$FAKECAM" 127.0.0.3 PIX-BB --interleave "$IMAGES/aloeL.jpg" "$IMAGES/aloeR.jpg" --first right >"$WORK/pix-bb.log" 2>&1 &
PIDS+=($!)
wait_cameras 5
# The originals, grey, as the cameras serve them (the fake camera reads them with the same decoder).
check_export() { # name recording
	"$STEREOCTL" export "$2" --output "$WORK/$1" >/dev/null 2>&1 || fail "$1: export failed"
	# A frame the camera delivered with packets missing is recorded as "incomplete" (its lost packets are
	# counted by the daemon); it cannot equal the original, so it is skipped and reported, never compared.
	local frames=0 skipped=0 line=0 status
	[ -f "$WORK/$1/status.txt" ] || fail "$1: export wrote no status.txt"
	for f in "$WORK/$1"/left/*.png; do
		line=$((line + 1))
		status=$(sed -n "${line}p" "$WORK/$1/status.txt")
		if [ "$status" != ok ]; then
			skipped=$((skipped + 1))
			continue
		fi
		"$IMAGE_EQUAL" "$f" "$WORK/aloeL.png" >/dev/null || fail "$1: $(basename "$f") left differs: $("$IMAGE_EQUAL" "$f" "$WORK/aloeL.png")"
		"$IMAGE_EQUAL" "${f/left/right}" "$WORK/aloeR.png" >/dev/null || fail "$1: right $(basename "$f") differs: $("$IMAGE_EQUAL" "${f/left/right}" "$WORK/aloeR.png")"
		frames=$((frames + 1))
	done
	[ $((frames + skipped)) -ge 10 ] || fail "$1: only $((frames + skipped)) frames recorded"
	[ $frames -ge 7 ] || fail "$1: only $frames of $((frames + skipped)) frames arrived whole"
	echo "$frames whole$([ $skipped -gt 0 ] && echo ", $skipped incomplete skipped")"
}
"$STEREOCTL" record --set source.driver=aravis --set aravis.left=127.0.0.4 --set aravis.right=127.0.0.5 \
	--set aravis.width=1282 --set aravis.height=1110 --set aravis.pixel_format=Mono8 --set aravis.packet_size=8192 \
	--output "$WORK/pair.srec" --frames 10 >"$WORK/record.log" 2>&1 || fail "record (pair): $(tail -3 "$WORK/record.log")"
# Reference images: the recording of the pair path is checked against a decode of the originals made the same
# way the fake camera makes them (OpenCV, IMREAD_GRAYSCALE) -- written by the fake camera's decoder below.
"$FAKECAM" --write-grey "$IMAGES/aloeL.jpg" "$WORK/aloeL.png"
"$FAKECAM" --write-grey "$IMAGES/aloeR.jpg" "$WORK/aloeR.png"
n_pair=$(check_export pair "$WORK/pair.srec")
"$STEREOCTL" record --set source.driver=aravis --set aravis.left=127.0.0.3 --set aravis.layout=interleaved16 \
	--set aravis.first_byte=right --set aravis.width=1282 --set aravis.height=1110 --set aravis.pixel_format=Mono16 \
	--set aravis.packet_size=8192 --output "$WORK/bb.srec" --frames 10 >"$WORK/record.log" 2>&1 ||
	fail "record (interleaved16): $(tail -3 "$WORK/record.log")"
n_bb=$(check_export interleaved16 "$WORK/bb.srec")
pass "exact pixels: aloe pair 1282x1110 as two cameras ($n_pair frames) and as one interleaved16 camera ($n_bb frames) equal the originals byte for byte"
