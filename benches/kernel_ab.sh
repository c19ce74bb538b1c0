#!/usr/bin/env bash
# kernel_ab.sh BINARY THREADS ROUNDS SCENE:SPP...: PT's wavefront (default 2^18, 2^16 and 2^14 paths
# in flight) against its megakernel, renders interleaved round by round so that drift in the
# machine falls on all of them alike; prints each render's samples/s, then the medians. Run it
# under /work/tools/quiet.sh (or on an otherwise idle machine).
#   benches/kernel_ab.sh target/release/stagelight 2 5 scenes/cornell_box.ron:32 scenes/door_ajar.ron:16
set -euo pipefail
bin=$1 threads=$2 rounds=$3
shift 3
out=$(mktemp -d)
configs=("wavefront-262144:--kernel wavefront" "wavefront-65536:--kernel wavefront --wavefront 65536"
  "wavefront-16384:--kernel wavefront --wavefront 16384" "megakernel:--kernel megakernel")
for round in $(seq "$rounds"); do
  for scene_spp in "$@"; do
    scene=${scene_spp%:*} spp=${scene_spp##*:}
    for c in "${configs[@]}"; do
      name=${c%%:*} args=${c#*:}
      # shellcheck disable=SC2086
      rate=$("$bin" render "$scene" --spp "$spp" --threads "$threads" --quiet -o "$out/x.exr" $args |
        awk '/samples\/s/ { v = $2; if ($3 == "M") v *= 1e6; else if ($3 == "k") v *= 1e3; print v }')
      echo "$(basename "$scene") $name $rate" | tee -a "$out/rates"
    done
  done
done
echo "medians of $rounds renders, $threads threads:"
sort "$out/rates" | awk '{ k = $1 " " $2; v[k] = v[k] " " $3 } END { for (k in v) print k, v[k] }' |
  while read -r scene name values; do
    median=$(tr ' ' '\n' <<<"$values" | sort -g | awk '{ a[NR] = $1 } END { print a[int((NR + 1) / 2)] }')
    printf "%-18s %-18s %.3f M samples/s\n" "$scene" "$name" "$(awk "BEGIN { print $median / 1e6 }")"
  done | sort
rm -rf "$out"
