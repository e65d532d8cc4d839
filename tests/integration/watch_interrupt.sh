#!/usr/bin/env bash
# stereoctl watch stops on Ctrl-C (SIGINT) even when no data comes (it used to wait for the next line).
source "$(dirname "$0")/lib.sh"
SOCK=$WORK/quiet.sock
# A socket that accepts and never says anything: socat listening, holding the connection open.
socat UNIX-LISTEN:"$SOCK",fork SYSTEM:'sleep 30' >/dev/null 2>&1 &
PIDS+=($!)
for _ in $(seq 50); do [ -S "$SOCK" ] && break; sleep 0.1; done
"$STEREOCTL" watch --socket "$SOCK" &
WATCH=$!
sleep 1
kill -INT $WATCH
for _ in $(seq 20); do kill -0 $WATCH 2>/dev/null || break; sleep 0.1; done
kill -0 $WATCH 2>/dev/null && { kill -9 $WATCH; fail "stereoctl watch still running 2 s after SIGINT with no data"; }
pass "stereoctl watch stopped on SIGINT while waiting for data"
