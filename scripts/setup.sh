#!/usr/bin/env bash
# The one entry point behind the README's first two commands and CI.
#   scripts/setup.sh run    install what is needed, build, start stereod on the sim and watch it stream
#   scripts/setup.sh test   install what is needed, build (warnings as errors), run every test tier,
#                           the ASan/UBSan and TSan builds, and the format check
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
JOBS=$(nproc)

build() { # dir, extra cmake args...
	local dir=$1
	shift
	cmake -S "$ROOT" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "$@" >/dev/null
	cmake --build "$dir" -j "$JOBS"
}
# Sanitizer builds: -O1 and line tables only, which compiles several times faster than -O2 -g and still
# gives usable stacks.
SANITIZER_FLAGS=(-DCMAKE_BUILD_TYPE=Debug "-DCMAKE_CXX_FLAGS_DEBUG=-O1 -g1")

# Each heading carries the seconds since the script started, so a slow CI run shows which phase grew.
section() { printf '\n== %s == [%d s]\n' "$*" "$SECONDS"; }

case "${1:-}" in
run)
	section "installing dependencies"
	bash scripts/install-deps.sh
	section "building"
	build build
	SOCK=${STEREOD_SOCKET:-/tmp/stereod.sock}
	section "starting stereod on the sim scene; socket $SOCK (Ctrl-C stops)"
	./build/daemon/stereod --set output.socket="$SOCK" "${@:2}" &
	DAEMON=$!
	trap 'kill -TERM $DAEMON 2>/dev/null; wait $DAEMON 2>/dev/null' EXIT INT TERM
	for _ in $(seq 100); do [ -S "$SOCK" ] && break; sleep 0.1; done
	echo "watching (another terminal: ./build/tools/stereoctl watch --socket $SOCK, or socat - UNIX-CONNECT:$SOCK)"
	./build/tools/stereoctl watch --socket "$SOCK"
	;;
test)
	START=$(date +%s)
	section "installing dependencies (with the camera test beds)"
	bash scripts/install-deps.sh --test-beds

	section "format check (clang-format)"
	mapfile -t sources < <(git ls-files '*.cpp' '*.hpp' 2>/dev/null || find core drivers daemon tools tests -name '*.[ch]pp')
	clang-format --dry-run --Werror "${sources[@]}"
	echo "clang-format: ${#sources[@]} files clean"

	section "build, warnings as errors"
	build build -DSTEREOD_WERROR=ON
	section "tests: unit, integration on sim, integration on real data (../shared/data)"
	(cd build && ctest -j "$JOBS" --output-on-failure --timeout 600)

	section "ASan + UBSan build: unit and integration tests"
	build build-asan "${SANITIZER_FLAGS[@]}" -DSTEREOD_WERROR=ON -DSTEREOD_SANITIZE=address -DSTEREOD_BENCHMARKS=OFF
	(cd build-asan && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
		ctest -j "$JOBS" --output-on-failure --timeout 900 -LE 'data|camera|slow|timing')

	section "TSan build: the concurrent parts (ring, pool, pipeline, socket)"
	build build-tsan "${SANITIZER_FLAGS[@]}" -DSTEREOD_WERROR=ON -DSTEREOD_SANITIZE=thread -DSTEREOD_TOOLS=OFF
	(cd build-tsan && TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$ROOT/tests/tsan.supp" \
		ctest -j "$JOBS" --output-on-failure --timeout 900 -R 'SpscRing|FramePool|Pipeline|SocketServer|LiveRecorder|DdsPublisher')

	section "fuzzing: the parsers of outside bytes (libFuzzer, clang, ASan + UBSan), fixed inputs from seed ${STEREOD_FUZZ_SEED:-1}"
	CC=clang CXX=clang++ build build-fuzz "${SANITIZER_FLAGS[@]}" -DSTEREOD_WERROR=ON -DSTEREOD_FUZZ=ON \
		-DSTEREOD_TESTS=OFF -DSTEREOD_TOOLS=OFF
	bash tests/fuzz/run_fuzz.sh build-fuzz ${STEREOD_FUZZ_SECONDS:+"$STEREOD_FUZZ_SECONDS"}

	section "done in $(($(date +%s) - START)) s"
	;;
*)
	echo "usage: $0 run|test" >&2
	exit 2
	;;
esac
