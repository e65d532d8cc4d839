#!/usr/bin/env bash
# Who may read the stream: with output.allow_groups set, a client whose user is in the group gets `hello` and
# frames; a client whose user is not gets an `error` line naming why, is disconnected, and is counted
# (drops.clients_denied) while the allowed client keeps streaming. The users are real (made here, removed on
# exit), the clients are real processes run as them (setpriv), the check is the kernel's SO_PEERCRED /
# SO_PEERGROUPS.
source "$(dirname "$0")/lib.sh"
[ "$(id -u)" = 0 ] || { echo "SKIP: needs root to make the test users"; exit 77; }
for tool in useradd groupadd setpriv socat; do
	command -v $tool >/dev/null || { echo "SKIP: $tool missing"; exit 77; }
done
tag=$$
GROUP=stereodrd$tag OK=stereodok$tag BAD=stereodno$tag
remove_users() {
	userdel "$OK" 2>/dev/null || true
	userdel "$BAD" 2>/dev/null || true
	groupdel "$GROUP" 2>/dev/null || true
	rm -rf "$SOCKDIR"
	cleanup
}
SOCKDIR=$(mktemp -d /tmp/stereod-access.XXXXXX)
chmod 0755 "$SOCKDIR" # the test users must reach the socket (mode 438 = 0o666 below): the allow list decides
trap remove_users EXIT
groupadd --system "$GROUP"
useradd --system --no-create-home --shell /usr/sbin/nologin -G "$GROUP" "$OK"
useradd --system --no-create-home --shell /usr/sbin/nologin "$BAD"
SOCK=$SOCKDIR/stereod.sock
"$STEREOD" "${SMALL_SIM[@]}" --set sim.fps=20 --set output.socket="$SOCK" --set output.socket_mode=438 \
	--set output.status_interval_s=0.3 --set "output.allow_groups=[\"$GROUP\"]" >"$WORK/daemon.log" 2>&1 &
DAEMON=$!
PIDS+=($DAEMON)
for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
[ -S "$SOCK" ] || fail "no socket: $(tail -3 "$WORK/daemon.log")"
as() { # user command...
	local user=$1
	shift
	setpriv --reuid="$user" --regid="$user" --init-groups "$@"
}
# Refused: one error line, then the connection closes.
timeout 5 bash -c "$(declare -f as); as $BAD socat -u UNIX-CONNECT:$SOCK -" >"$WORK/bad.out" 2>&1 || true
[ "$(wc -l <"$WORK/bad.out")" -eq 1 ] || fail "the refused client got more than one line: $(head -3 "$WORK/bad.out")"
jq -e '.type == "error" and (.error | test("not allowed: uid [0-9]+"))' "$WORK/bad.out" >/dev/null ||
	fail "the refused client did not get the error line: $(cat "$WORK/bad.out")"
# Allowed through the group: hello, frames, and a status that counts the refusal.
timeout 10 bash -c "$(declare -f as); as $OK socat -u UNIX-CONNECT:$SOCK -" 2>/dev/null | tee "$WORK/ok.raw" |
	jq -c --unbuffered 'select(.type == "hello" or .type == "status" or .type == "frame") | {type, denied: .drops.clients_denied}' |
	head -40 >"$WORK/ok.out" || true
head -1 "$WORK/ok.out" | grep -q '"type":"hello"' || fail "the allowed client got no hello: $(head -2 "$WORK/ok.out")"
frames=$(grep -c '"type":"frame"' "$WORK/ok.out" || true)
[ "$frames" -ge 10 ] || fail "the allowed client got only $frames frames"
denied=$(grep '"type":"status"' "$WORK/ok.out" | tail -1 | jq .denied)
[ "$denied" = 1 ] || fail "status counts $denied denied clients, want 1"
grep -q "refused 1 client(s) not allowed to read (last: uid $(id -u "$BAD")" "$WORK/daemon.log" ||
	fail "the refusal was not logged: $(grep socket "$WORK/daemon.log" | tail -3)"
kill -TERM $DAEMON
wait $DAEMON || fail "daemon exit code after SIGTERM"
pass "allow_groups: uid $(id -u "$BAD") refused with an error line and counted (drops.clients_denied = $denied), uid $(id -u "$OK") (in $GROUP) streamed $frames frames"
