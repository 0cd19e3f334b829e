#!/usr/bin/env bash
# The figures of BENCHMARKS.md "Mixture tuning and --strategy auto (issue 33, item 4)": image- and
# loss-gradient variance of bsdf, diff at q = 0.5, 0.75, 0.9 with balance- and power-heuristic
# placements, and what --strategy auto picks (its pilot's cost in summary.json's "pilot"), on a
# single roughness (the Cornell box's sphere), two roughnesses (the twin scene's metal box drives the
# sampler; the diffuse box's GGX layer measured too) and a blend weight. Usage:
#   benches/mixture_tuning.sh [OUT_DIR]
# RUNS (default 48) and PATHGRAD (default target/release/pathgrad) can be set in the environment.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-mixture-tuning}"
bin="${PATHGRAD:-target/release/pathgrad}"
runs="${RUNS:-48}"
rows=(--strategy bsdf,diff,auto --q 0.5,0.75,0.9 --placement-mis balance,power --runs "$runs" --json)
size=(--width 128 --height 128)
cornell=(scenes/cornell-box/cornell-box.xml --param sphere.bsdf.alpha.value "${size[@]}")
twin=(scenes/twin/twin.xml --diff-param metal_box.bsdf.alpha.value "${size[@]}")
blend=(scenes/blend/blend.xml --param object.weight.value "${size[@]}")
for nee in nee nonee; do
  flag=()
  [ "$nee" = nonee ] && flag=(--no-nee)
  "$bin" variance "${cornell[@]}" -D alpha=0.1 "${rows[@]}" --spp 2 "${flag[@]}" -o "$out/cornell-image-$nee"
  "$bin" variance "${twin[@]}" --param metal_box.bsdf.alpha.value "${rows[@]}" --spp 2 "${flag[@]}" -o "$out/twin-metal-image-$nee"
  "$bin" variance "${twin[@]}" --param diffuse_box.bsdf.bsdf_1.alpha.value "${rows[@]}" --spp 2 "${flag[@]}" \
    -o "$out/twin-diffuse-image-$nee"
  "$bin" variance "${blend[@]}" -D weight=0.4 "${rows[@]}" --spp 2 "${flag[@]}" -o "$out/blend-image-$nee"
done
# Loss gradients with and without adaptive pixel sampling (the Tables 1-2 protocol).
loss=(--adaptive --spp 1 --spp-primal 3)
"$bin" variance "${cornell[@]}" -D alpha=0.3 --target-set sphere.bsdf.alpha.value=0.1 "${rows[@]}" "${loss[@]}" \
  -o "$out/cornell-loss"
"$bin" variance "${twin[@]}" --param metal_box.bsdf.alpha.value --target-set metal_box.bsdf.alpha.value=0.05 \
  "${rows[@]}" "${loss[@]}" -o "$out/twin-loss"
"$bin" variance "${blend[@]}" -D weight=0.9 --target-set object.weight.value=0.4 "${rows[@]}" "${loss[@]}" \
  -o "$out/blend-loss"
# What the pilot costs in an optimisation: 100 plain iterations (spp 3 + 2; as recorded, without the
# adaptive pixels and control variates `optimize` now adds by default), --strategy auto.
"$bin" optimize scenes/cornell-box/cornell-box.xml -D alpha=0.3 --target-set sphere.bsdf.alpha.value=0.1 \
  --param sphere.bsdf.alpha.value "${size[@]}" --iters 100 --strategy auto --adaptive=false --control-variates=false \
  --json -o "$out/opt-cornell-auto"
"$bin" optimize scenes/twin/twin.xml --target-set metal_box.bsdf.alpha.value=0.05 \
  --param metal_box.bsdf.alpha.value "${size[@]}" --iters 100 --strategy auto --adaptive=false --control-variates=false \
  --json -o "$out/opt-twin-auto"
