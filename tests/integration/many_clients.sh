#!/usr/bin/env bash
# 100 clients at once, a third of them never reading (issue 17): the pipeline keeps its frame rate, every
# reading client gets the stream, the slow ones cost only their own queues (counted), and the daemon still
# stops cleanly. Figures are printed; the bound on the frame rate is loose (timing label: run alone).
source "$(dirname "$0")/lib.sh"
SOCK=$WORK/stereod.sock
READERS=66
SILENT=34
"$STEREOD" "${SMALL_SIM[@]}" --set output.socket="$SOCK" --set output.status_interval_s=1 \
	--set output.max_clients=200 >"$WORK/daemon.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
[ -S "$SOCK" ] || fail "no socket after 10 s: $(cat "$WORK/daemon.log")"
last_status() { grep '"type":"status"' "$1" | tail -1; }
# The publish rate over all the statuses a client got (frames published between the first and the last, over
# the host time between them): a status's own fps covers one second and swings by 10 % on a loaded machine.
mean_rate() {
	grep '"type":"status"' "$1" | jq -s 'if length < 2 then empty else
		(.[-1].frames.published - .[0].frames.published) / ((.[-1].t_host_ns - .[0].t_host_ns) / 1e9) end'
}

# The frame rate with one client.
timeout 6 socat -u UNIX-CONNECT:"$SOCK" - >"$WORK/alone.ndjson" || true
alone_fps=$(mean_rate "$WORK/alone.ndjson")
[ -n "$alone_fps" ] || fail "fewer than two statuses with one client"

# 66 clients reading everything, 34 that connect and never read (socat hands the stream to `sleep`, which
# never reads its input: once the pipe and the socket buffers fill, the daemon sees a client that is stuck).
for i in $(seq $READERS); do
	socat -u UNIX-CONNECT:"$SOCK" OPEN:"$WORK/reader$i.ndjson",creat,trunc 2>/dev/null &
	PIDS+=($!)
done
SILENT_PIDS=()
for i in $(seq $SILENT); do
	socat -u UNIX-CONNECT:"$SOCK" EXEC:"sleep 30" 2>/dev/null &
	SILENT_PIDS+=($!)
	PIDS+=($!)
done
stop_silent() { # socat's `sleep` outlives a killed socat and would hold ctest's output open
	for pid in "${SILENT_PIDS[@]}"; do pkill -9 -P "$pid" 2>/dev/null || true; done
}
trap 'stop_silent; cleanup' EXIT
sleep 12
status=$(last_status "$WORK/reader1.ndjson")
[ -n "$status" ] || fail "reader 1 got no status"
clients=$(echo "$status" | jq '.clients')
fps=$(mean_rate "$WORK/reader1.ndjson")
ring=$(echo "$status" | jq '.drops.ring_overflow')
queue=$(echo "$status" | jq '.drops.client_queue')
p99=$(echo "$status" | jq '.latency_ms.capture_to_publish.p99')
[ "$clients" -ge $((READERS + SILENT)) ] || fail "status says $clients clients, want $((READERS + SILENT))"
# The pipeline kept its rate: within 20 % of the rate with one client, both over several seconds.
awk -v a="$fps" -v b="$alone_fps" 'BEGIN { exit !(a >= 0.8 * b) }' || fail "publish rate $fps fps with 100 clients, $alone_fps alone"
[ "$queue" -gt 0 ] || fail "the silent clients' queues never overflowed (client_queue = 0): were they reading?"
# What the readers have now (they keep writing: each is read up to its size at this moment).
declare -A size
for i in $(seq $READERS); do size[$i]=$(stat -c %s "$WORK/reader$i.ndjson"); done
# SIGTERM with all 100 clients still connected.
kill -0 $DAEMON || fail "the daemon died: $(tail -5 "$WORK/daemon.log")"
kill -TERM $DAEMON
for _ in $(seq 100); do kill -0 $DAEMON 2>/dev/null || break; sleep 0.1; done
wait $DAEMON && rc=0 || rc=$?
[ $rc -eq 0 ] || fail "exit code $rc after SIGTERM with 100 clients; log: $(tail -5 "$WORK/daemon.log")"
stop_silent

# Each reader's frames within the window of sequence numbers every reader has reached (they start a moment
# apart and stand at different points of their queues), against every frame any reader got there (frames the
# pipeline itself skipped are nobody's): a reader's share is what its queue did not have to discard. Only
# frame messages carry "seq".
for i in $(seq $READERS); do
	head -c "${size[$i]}" "$WORK/reader$i.ndjson" | LC_ALL=C grep -o '"seq":[0-9]*' | cut -c7- >"$WORK/seq$i.txt"
done
lo=0
hi=1000000000
for i in $(seq $READERS); do
	read -r first last < <(awk 'NR == 1 { f = $1 } { l = $1 } END { print f, l }' "$WORK/seq$i.txt")
	[ -n "$first" ] || fail "reader $i got no frame"
	if [ "$first" -gt "$lo" ]; then lo=$first; fi
	if [ "$last" -lt "$hi" ]; then hi=$last; fi
done
published=$(cat "$WORK"/seq*.txt | awk -v lo="$lo" -v hi="$hi" '$1 >= lo && $1 <= hi' | sort -un | wc -l)
[ "$published" -ge 60 ] || fail "the readers share only $published frames (seq $lo..$hi)"
shares=$(for i in $(seq $READERS); do awk -v lo="$lo" -v hi="$hi" '$1 >= lo && $1 <= hi' "$WORK/seq$i.txt" | sort -un | wc -l; done | sort -n)
min=$(echo "$shares" | head -1)
max=$(echo "$shares" | tail -1)
[ "$min" -ge $((published * 9 / 10)) ] || fail "a reading client got only $min of the $published frames published in seq $lo..$hi"
pass "100 clients ($READERS reading, $SILENT never reading): publish $fps fps (alone $alone_fps), ring drops $ring, p99 ${p99} ms; each reader got $min-$max of the $published frames published in seq $lo..$hi; silent clients' messages discarded: $queue; SIGTERM with all connected: exit 0"
