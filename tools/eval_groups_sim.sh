#!/usr/bin/env bash
# A first check of the target groups against the sim's truth (the full `stereoctl eval` of groups is not
# written yet): for each group with a 3D position, the ground-plane distance (x, z) to the nearest true mover
# of that frame; and the dynamic-label precision / recall / F1 with groups.label_points off and on.
#   tools/eval_groups_sim.sh BUILD_DIR [SCENE=default] [FRAMES=150]
set -euo pipefail
BUILD=$1 SCENE=${2:-default} FRAMES=${3:-150}
WORK=$(mktemp -d /tmp/stereod-groups.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
extra=()
[ "$SCENE" = walk ] && extra=(--set sim.depth=true)
printf '| scene | label_points | groups | with 3D | within 1 m of a mover | within 2 m | label precision | recall | F1 | groups ms mean |\n|---|---|---|---|---|---|---|---|---|---|\n'
for lp in false true; do
	"$BUILD/daemon/stereod" process -i sim -f sim -o "$WORK/out.ndjson" --no-progress --set sim.frames="$FRAMES" \
		--set sim.scene="$SCENE" --set groups.label_points=$lp "${extra[@]}" --truth-dir "$WORK/truth" >/dev/null 2>&1
	near=$(jq -s -c --slurpfile t "$WORK/truth/truth.ndjson" '[.[] | . as $f | ($t | map(select(.seq == $f.seq)) | .[0].objects) as $objs
		| .groups[] | select(.position_m) | .position_m as $p
		| ([$objs[] | ((.position_m[0] - $p[0]) * (.position_m[0] - $p[0]) + (.position_m[2] - $p[2]) * (.position_m[2] - $p[2])) | sqrt] | min)]
		| "\(length) | \(map(select(. < 1)) | length) | \(map(select(. < 2)) | length)"' -r "$WORK/out.ndjson")
	total=$(jq -s '[.[].groups | length] | add' "$WORK/out.ndjson")
	ms=$(jq -s '[.[].timing_ms.groups // empty] | if length > 0 then add / length else 0 end | . * 100 | round / 100' "$WORK/out.ndjson")
	labels=$("$BUILD/tools/stereoctl" eval --results "$WORK/out.ndjson" --truth "$WORK/truth" --json |
		jq -r '.all | "\(.precision * 1000 | round / 1000) | \(.recall * 1000 | round / 1000) | \(.f1 * 1000 | round / 1000)"')
	printf '| %s | %s | %s | %s | %s | %s |\n' "$SCENE" "$lp" "$total" "$near" "$labels" "$ms"
done
