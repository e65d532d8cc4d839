#!/usr/bin/env bash
# SIGTERM while clients connect and disconnect: the daemon used to crash (SIGSEGV in ~SocketServer, 2 of 22
# runs) and leave its socket file. Five rounds of a fast sim, clients churning, SIGTERM: exit 0, socket gone.
source "$(dirname "$0")/lib.sh"
for round in 1 2 3 4 5; do
	SOCK=$WORK/churn$round.sock
	"$STEREOD" "${SMALL_SIM[@]}" --set sim.fps=1000 --set features.enabled=false --set output.socket="$SOCK" \
		--set output.client_queue=4 >"$WORK/daemon$round.log" 2>&1 &
	DAEMON=$!
	PIDS+=($DAEMON)
	for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
	[ -S "$SOCK" ] || fail "no socket: $(tail -3 "$WORK/daemon$round.log")"
	churners=()
	for c in $(seq 8); do
		(for _ in $(seq 400); do timeout 0.05 socat -u UNIX-CONNECT:"$SOCK" /dev/null 2>/dev/null || true; done) &
		churners+=($!)
	done
	sleep 1.5
	kill -TERM $DAEMON
	rc=0
	wait $DAEMON || rc=$?
	kill "${churners[@]}" 2>/dev/null || true
	wait "${churners[@]}" 2>/dev/null || true
	[ $rc -eq 0 ] || fail "round $round: exit code $rc after SIGTERM under connection churn: $(tail -3 "$WORK/daemon$round.log")"
	[ -e "$SOCK" ] && fail "round $round: socket file left behind"
	grep -q "socket: client .* connected" "$WORK/daemon$round.log" && fail "per-client lines logged at info"
done
pass "5 rounds of SIGTERM under connection churn: exit 0, socket removed, no per-client log lines"
