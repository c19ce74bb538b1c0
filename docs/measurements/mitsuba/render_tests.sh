#!/usr/bin/env bash
# Mitsuba's own render test (src/render/tests/test_renders.py, as ../shared/mitsuba/ztest.py
# applies it) on the mitsuba-data scenes stagelight reads, under pt: 2e6 samples over the image,
# per-pixel z against the shipped reference and variance images, >= 99.75% of pixel channels
# passing. Prints one line per scene, without and with our own variance image (OWN_VAR, for
# pixels where light selection by power makes our estimator noisier than Mitsuba's).
# Usage: render_tests.sh MITSUBA_DATA_DIR [OUT_DIR]
#   (MITSUBA_DATA_DIR: a checkout of mitsuba-renderer/mitsuba-data; PY: a python with numpy
#    and OpenEXR; ZTEST: ../shared/mitsuba/ztest.py by default)
set -u
data=$1 out=${2:-/tmp/stagelight-render-tests}
here=$(cd "$(dirname "$0")" && pwd)
bin=${STAGELIGHT:-$here/../../../target/release/stagelight}
ztest=${ZTEST:-$here/../../../../shared/mitsuba/ztest.py}
py=${PY:-python3}
mkdir -p "$out"
# scene file, reference stem (refs/STEM_ref_rgb.exr and STEM_ref_rgb_var.exr beside it)
tests=(
  "tests/scenes/infinite_mirrors/scene_path.xml scene"
  "tests/scenes/floating_sphere/test_directional_direct.xml test_directional"
  "tests/scenes/texture_interp/test_texture_interp_direct.xml test_texture_interp"
  "tests/scenes/instancing/test_instancing_path.xml test_instancing"
  "tests/scenes/orthographic_sensor/test_orthographic_path.xml test_orthographic"
  "tests/scenes/spot_light/test_spot_direct.xml test_spot"
  "tests/scenes/projector/test_projector_constant_direct.xml test_projector_constant"
  "tests/scenes/projector/test_projector_textured_direct.xml test_projector_textured"
  "tests/scenes/bsdf_spheres/test_textured_diffuse_path.xml test_textured_diffuse"
  "tests/scenes/bsdf_spheres/test_textured_roughconductor_path.xml test_textured_roughconductor"
  "tests/scenes/bsdf_spheres/test_roughplastic_linear_path.xml test_roughplastic_linear"
  "tests/scenes/bsdf_spheres/test_roughplastic_nonlinear_path.xml test_roughplastic_nonlinear"
  "tests/scenes/bsdf_spheres/test_roughdielectric_path.xml test_roughdielectric"
)
for entry in "${tests[@]}"; do
  read -r xml stem _ <<< "$entry"
  dir=$(dirname "$data/$xml")
  ref=$dir/refs/${stem}_ref_rgb.exr var=$dir/refs/${stem}_ref_rgb_var.exr
  pixels=$("$py" -c "import OpenEXR,sys; f=OpenEXR.File(sys.argv[1]); w,h=f.header()['dataWindow'][1]-f.header()['dataWindow'][0]+1; print(w*h)" "$ref")
  spp=$(( (2000000 + pixels / 2) / pixels ))
  name=$(basename "$xml" .xml)
  if ! (cd "$dir" && "$bin" render "$(basename "$xml")" --spp "$spp" -o "$out/$name.exr" \
        --variance "$out/$name.var.exr" > "$out/$name.log" 2>&1); then
    echo "$name: render failed: $(tail -1 "$out/$name.log")"; continue
  fi
  plain=$("$py" "$ztest" "$out/$name.exr" "$ref" "$var" "$spp")
  own=$("$py" "$ztest" "$out/$name.exr" "$ref" "$var" "$spp" "$out/$name.var.exr")
  echo "$name ($spp spp): $plain | with our variance: $own"
done
