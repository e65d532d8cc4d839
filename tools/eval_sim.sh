#!/usr/bin/env bash
# Scores the seed-000 classifier on the sim's scenes (the seed's four experiments, the walker heading at the
# camera, the default mix and the walk down a street) against the sim's ground truth, and prints one markdown table.
# Usage: tools/eval_sim.sh [build dir] [frames per scene] [extra stereod --set ...]
set -euo pipefail
BUILD=${1:-build}
FRAMES=${2:-150}
shift $(($# > 2 ? 2 : $#))
WORK=$(mktemp -d /tmp/stereod-eval.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
echo "sim scenes, $FRAMES frames each, 1024x768, seed 1; extra settings: ${*:-none}"
echo
first=1
for scene in static_near static_far moving_one moving_many toward default walk; do
	"$BUILD/daemon/stereod" process --input sim --format sim --set sim.scene=$scene --set sim.frames="$FRAMES" \
		"$@" --output "$WORK/$scene.ndjson" --truth-dir "$WORK/$scene" --no-progress 2>/dev/null
	# Rows: every frame; frames whose movers cover >= 2% of the image; the same with points within 3 px of a
	# mover's outline left out (there the feature straddles mover and background, so its pixel is ambiguous).
	table=$("$BUILD/tools/stereoctl" eval --results "$WORK/$scene.ndjson" --truth "$WORK/$scene" --name "$scene")
	bordered=$("$BUILD/tools/stereoctl" eval --results "$WORK/$scene.ndjson" --truth "$WORK/$scene" \
		--name "$scene, outline 3 px excluded" --border 3)
	if [ $first = 1 ]; then
		echo "$table" | head -2
		first=0
	fi
	echo "$table" | tail -2
	echo "$bordered" | tail -1
done
