#!/usr/bin/env bash
# Does every integrator agree with Mitsuba 3 on a Mitsuba scene file? Two seeds per integrator
# at a time budget, then ../shared/mitsuba/agree.py against the two halves render_xml.py made.
# Usage: xml_agreement.sh SCENE.xml REF_DIR NAME SECONDS [INTEGRATOR ...] [-- EXTRA RENDER ARGS]
#   (REF_DIR/NAME.{a,b}.exr from: render_xml.py SCENE.xml REF_DIR NAME SPP_PER_HALF)
# Prints one line per integrator: excess ratio, block z, pass/FAIL. Renders stay in REF_DIR/ours.
set -u
scene=$1 refs=$2 name=$3 seconds=$4; shift 4
integrators=() extra=()
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then shift; extra=("$@"); break; fi
  integrators+=("$1"); shift
done
[ ${#integrators[@]} -eq 0 ] && integrators=(pt bdpt vcm bpm pm ppm sppm pssmlt mmlt mlt)
here=$(cd "$(dirname "$0")" && pwd)
bin=${STAGELIGHT:-$here/../../../target/release/stagelight}
agree=${AGREE:-$here/../../../../shared/mitsuba/agree.py}
py=${PY:-python3}
mkdir -p "$refs/ours"
for integrator in "${integrators[@]}"; do
  for seed in 1 2; do
    "$bin" render "$scene" --integrator "$integrator" --time "$seconds" --seed "$seed" \
      "${extra[@]}" -o "$refs/ours/$name.$integrator.$seed.exr" > "$refs/ours/$name.$integrator.$seed.log" 2>&1 \
      || { echo "$integrator: render failed: $(tail -1 "$refs/ours/$name.$integrator.$seed.log")"; continue 2; }
  done
  result=$("$py" "$agree" "$refs/ours/$name.$integrator.1.exr" "$refs/ours/$name.$integrator.2.exr" \
    "$refs/$name.a.exr" "$refs/$name.b.exr" 2>&1 | tr '\n' ' ')
  echo "$integrator: $result"
done
