#!/usr/bin/env bash
# The scaling table of docs/slurm.md: one reference rendered whole, then as 1, 2 and 4 shards, the
# shards one after another on this machine, each standing in for a machine of its own (the
# wall time of N machines is the slowest shard's plus the merge), and `cmp` of every merge
# with the whole render.
#
#   slurm/shard_scaling.sh [STAGELIGHT]      (default target/release/stagelight)
#
# SCENE (scenes/cornell_box.ron), SPP (128), THREADS (2) and COUNTS ("1 2 4") change the runs.
# Time it under the machine's quiet wrapper where other jobs share the cores. Exit status 0
# when every merge is identical to the whole render.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=$(realpath "${1:-$repo/target/release/stagelight}")
SCENE=${SCENE:-$repo/scenes/cornell_box.ron}
SPP=${SPP:-128}
THREADS=${THREADS:-2}
COUNTS=${COUNTS:-1 2 4}
tmp=$(mktemp -d /tmp/stagelight-scaling.XXXXXX)
trap 'rm -rf "$tmp"' EXIT

now() { date +%s.%N; }
seconds() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

t0=$(now)
"$bin" reference "$SCENE" --spp "$SPP" --threads "$THREADS" -o "$tmp/single.exr" --quiet >/dev/null
single=$(seconds "$t0" "$(now)")
echo "whole render: $single s ($SPP spp of $(basename "$SCENE"), $THREADS threads)"
echo
echo "| shards | each shard's wall s | merge s | N machines' wall s | \`cmp\` with the whole render ($single s) |"
echo "|---|---|---|---|---|"
for n in $COUNTS; do
    parts=()
    times=()
    slowest=0
    for i in $(seq "$n"); do
        part=$tmp/$n/part-$i.exr
        t0=$(now)
        "$bin" reference "$SCENE" --spp "$SPP" --threads "$THREADS" --shard "$i/$n" -o "$part" \
            --quiet >/dev/null
        t=$(seconds "$t0" "$(now)")
        times+=("$t")
        slowest=$(awk -v a="$slowest" -v b="$t" 'BEGIN { print (b > a) ? b : a }')
        parts+=("$part")
    done
    t0=$(now)
    "$bin" merge "${parts[@]}" -o "$tmp/$n/merged.exr" >/dev/null
    merge=$(seconds "$t0" "$(now)")
    if cmp "$tmp/single.exr" "$tmp/$n/merged.exr"; then
        same=identical
    else
        same=DIFFERENT
    fi
    list=$(IFS=,; echo "${times[*]}" | sed 's/,/, /g')
    echo "| $n | $list | $merge | $(awk -v a="$slowest" -v b="$merge" 'BEGIN { printf "%.2f", a + b }') | $same |"
    [ "$same" = identical ] || exit 1
done
