# Helpers for the integration tests: a scratch folder removed on exit, and checks that explain failures.
set -euo pipefail
STEREOD=$1
STEREOCTL=$2
WORK=$(mktemp -d /tmp/stereod-it.XXXXXX)
PIDS=()
cleanup() {
	for pid in "${PIDS[@]}"; do kill -9 "$pid" 2>/dev/null || true; done
	[ -n "${STEREOD_KEEP_WORK:-}" ] && echo "kept $WORK" || rm -rf "$WORK"
}
trap cleanup EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
pass() { echo "ok: $*"; }
# Small, fast sim settings for tests that need frames, not pictures.
SMALL_SIM=(--set sim.width=320 --set sim.height=240)
