#!/usr/bin/env bash
# The variance figures of BENCHMARKS.md ("Gradient variance"): image-gradient variance of `diff`
# against `bsdf` with and without NEE and the q sweep (the paper's Figures 5-6), and loss-gradient
# variance with and without adaptive pixel sampling (Tables 1-2), on the Cornell box's rough
# Beckmann sphere (alpha 0.1) and the blend scene. Usage: benches/variance_figures.sh [OUT_DIR]
# (needs a release build: cargo build --release). Each command prints its table; --json rows land
# in OUT_DIR/*/summary.json.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-variance-figures}"
bin="${PATHGRAD:-target/release/pathgrad}"
runs="${RUNS:-100}"
cornell=(scenes/cornell-box/cornell-box.xml --param sphere.bsdf.alpha.value --width 64)
blend=(scenes/blend/blend.xml --param object.weight.value --width 64)
for name in cornell blend; do
  declare -n scene="$name"
  extra=()
  [ "$name" = cornell ] && extra=(-D alpha=0.1)
  "$bin" variance "${scene[@]}" "${extra[@]}" --strategy bsdf,diff --q 0.1,0.3,0.5,0.7,0.9 \
    --runs "$runs" --spp 2 -o "$out/$name-image-nee"
  "$bin" variance "${scene[@]}" "${extra[@]}" --strategy bsdf,diff --no-nee \
    --runs "$runs" --spp 2 -o "$out/$name-image-nonee"
done
# Loss gradients (Tables 1-2 protocol): the target at the scene value, the parameter perturbed.
"$bin" variance "${cornell[@]}" -D alpha=0.3 --target-set sphere.bsdf.alpha.value=0.1 \
  --strategy bsdf,diff --adaptive --runs "$runs" --spp 1 --spp-primal 3 -o "$out/cornell-loss"
"$bin" variance "${blend[@]}" -D weight=0.9 --target-set object.weight.value=0.4 \
  --strategy bsdf,diff --adaptive --runs "$runs" --spp 1 --spp-primal 3 -o "$out/blend-loss"
