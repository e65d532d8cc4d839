#!/usr/bin/env bash
# The Aravis driver against real GigE Vision peers: Aravis's fake cameras speaking GVCP/GVSP over UDP,
# inside a network namespace this test makes (discovery broadcasts never leave it).
#   1. two cameras, 1024x768 Mono8 at 30 fps, 20 s to a socket client: every frame in order, no gap, no drop,
#      |lr_skew| < 2 ms, the 16-bit block-id wrap crossed (the fake starts at 65000), SIGTERM exits 0;
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
start_camera 127.0.0.1 CAM-L
start_camera 127.0.0.2 CAM-R
RIGHT_PID=$CAM_PID
wait_cameras 2
SOCK=$WORK/pair.sock
# Capture alone (features off): the fake camera's moving ramp is a worst case for the classifier (46 ms per
# frame), which would make this a test of processing speed on two cores, not of the camera path.
"$STEREOD" "${PAIR[@]}" --set output.socket="$SOCK" --set output.status_interval_s=0.5 --set features.enabled=false \
	>"$WORK/daemon.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
wait_socket "$SOCK"
watch_stamped "$SOCK" "$WORK/pair.out" &
WATCH=$!
sleep 20
stop_daemon $DAEMON
wait $WATCH 2>/dev/null || true
frames_of "$WORK/pair.out" >"$WORK/pair.frames"
n=$(wc -l <"$WORK/pair.frames")
[ "$n" -ge 480 ] || fail "only $n frames in 20 s at 30 fps (the fake cameras stall, but not this much); $(last_status "$WORK/pair.out")"
jq -s -e '[.[].seq] as $s | all(range(1; $s|length); $s[.] == $s[. - 1] + 1)' "$WORK/pair.frames" >/dev/null ||
	fail "frame sequence has a gap or is out of order"
skew=$(jq -s '[.[].lr_skew_ns | fabs] | max' "$WORK/pair.frames")
skew_mean=$(jq -s '[.[].lr_skew_ns | fabs] | add / length | floor' "$WORK/pair.frames")
status=$(last_status "$WORK/pair.out")
# The fake cameras' sender thread stalls now and then on a busy 2-core machine (testbeds FINDINGS 1.3) and
# skips frame periods without a frame-id gap: the partner's frames of those periods cannot be paired. Those
# are counted as unpaired and must be explained, one for one at most, by the periods a camera skipped. Any
# other drop is a failure.
drops=$(echo "$status" | jq -c '.drops | with_entries(select(.value > 0 and .key != "unpaired"))')
[ "$drops" = "{}" ] || fail "drops counted: $drops; $status"
unpaired=$(echo "$status" | jq '.drops.unpaired')
skipped=$(echo "$status" | jq '.device | .left_skipped_periods + .right_skipped_periods + .left_irregular_intervals + .right_irregular_intervals')
# (a fault costs at most two frames, its own and its partner's: a skipped period costs the partner's frame, a
# late frame itself and the partner it missed; the +3 covers the cameras settling just after the first pair)
[ "$unpaired" -le $((2 * skipped + 3)) ] || fail "$unpaired unpaired frames, but the cameras skipped or were irregular only $skipped: $status"
[ "$(echo "$status" | jq '.frames.captured == .frames.published')" = true ] || fail "captured != published: $status"
[ "$skew" -lt 2000000 ] || fail "|lr_skew| up to $skew ns (limit 2 ms)"
[ "$(echo "$status" | jq '.device.left_missing_frames + .device.right_missing_frames')" = 0 ] ||
	fail "frame ids missing: $(echo "$status" | jq -c .device)"
[ "$(echo "$status" | jq '.device.left_completed > 536')" = true ] || fail "block-id wrap not reached"
grep -q '"ok"' "$WORK/pair.frames" || fail "no frame has status ok"
latency=$(echo "$status" | jq -c '.latency_ms.capture_to_publish | {p50, p99, max}')
pass "pair: $n frames in 20 s, seq contiguous across the block-id wrap, no drop by stereod ($unpaired unpaired for $skipped skipped periods and irregular intervals of the fake cameras), |lr_skew| max $skew ns mean $skew_mean ns, latency $latency ms, startup unpaired $(echo "$status" | jq .device.startup_unpaired)"

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
[ "$outage" -gt 0 ] || fail "the outage cost no counted frame: $status"
pass "right camera killed and restarted after 4 s: streaming resumed $resume_s s after it came back, client kept, outage counted as $outage frames"

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
	local frames=0
	for f in "$WORK/$1"/left/*.png; do
		"$IMAGE_EQUAL" "$f" "$WORK/aloeL.png" >/dev/null || fail "$1: $(basename "$f") left differs: $("$IMAGE_EQUAL" "$f" "$WORK/aloeL.png")"
		"$IMAGE_EQUAL" "${f/left/right}" "$WORK/aloeR.png" >/dev/null || fail "$1: right $(basename "$f") differs"
		frames=$((frames + 1))
	done
	[ $frames -ge 10 ] || fail "$1: only $frames frames recorded"
	echo $frames
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
