#!/usr/bin/env bash
# The target groups against the sim's truth, through `stereoctl eval --groups`: groups against movers in view
# (count exact in frames whose movers are apart, groups on a mover, movers covered), centroid, speed and
# heading errors, id switches; then the dynamic-label precision / recall / F1 with groups.label_points off and
# on. One table row per scene.
#   tools/eval_groups_sim.sh BUILD_DIR [FRAMES=150] [SCENE...]   (scenes: default moving_many walk)
# Further settings for every run in EXTRA, e.g. EXTRA="--set groups.flow=lk". SEEDS="1 2 3" runs each scene
# with each of the sim's seeds (the movers' photographs, sizes and speeds vary with it; default 1), a row each.
set -euo pipefail
BUILD=$1 FRAMES=${2:-150}
shift $(($# > 2 ? 2 : $#))
SCENES=("$@")
[ ${#SCENES[@]} -gt 0 ] || SCENES=(default moving_many walk)
WORK=$(mktemp -d /tmp/stereod-groups.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
groups_table=""
labels_table="| scene | label_points | label precision | recall | F1 | groups ms mean |
|---|---|---|---|---|---|"
read -r -a SEEDS <<<"${SEEDS:-1}"
for scene in "${SCENES[@]}"; do
	for seed in "${SEEDS[@]}"; do
		name=$scene
		[ ${#SEEDS[@]} -gt 1 ] && name="$scene seed $seed"
		for lp in false true; do
			"$BUILD/daemon/stereod" process -i sim -f sim -o "$WORK/out.ndjson" --no-progress --set sim.frames="$FRAMES" \
				--set sim.scene="$scene" --set sim.seed="$seed" --set sim.depth=true --set groups.label_points=$lp \
				${EXTRA:-} --truth-dir "$WORK/truth" >/dev/null 2>&1
			if [ $lp = false ]; then
				table=$("$BUILD/tools/stereoctl" eval --groups --results "$WORK/out.ndjson" --truth "$WORK/truth" --name "$name")
				[ -n "$groups_table" ] && groups_table+=$'\n'$(echo "$table" | tail -1) || groups_table=$(echo "$table" | sed '/^$/d')
			fi
			ms=$(jq -s '[.[].timing_ms.groups // empty] | if length > 0 then add / length else 0 end | . * 100 | round / 100' "$WORK/out.ndjson")
			labels=$("$BUILD/tools/stereoctl" eval --results "$WORK/out.ndjson" --truth "$WORK/truth" --json |
				jq -r '.all | "\(.precision * 1000 | round / 1000) | \(.recall * 1000 | round / 1000) | \(.f1 * 1000 | round / 1000)"')
			labels_table+=$'\n'"| $name | $lp | $labels | $ms |"
		done
	done
done
echo "sim, $FRAMES frames per scene, 1024x768, seeds ${SEEDS[*]}, stereo with depth, groups.label_points off:"
echo
echo "$groups_table"
echo
echo "$labels_table"
