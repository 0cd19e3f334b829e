#!/usr/bin/env bash
# The variance figures of BENCHMARKS.md ("Gradient variance"): image-gradient variance of `diff`
# against `bsdf` with and without NEE with q sweeps (the paper's Figures 5-6), a roughness sweep
# (Figure 7), and loss-gradient variance with and without adaptive pixel sampling (Tables 1-2), on
# the Cornell box's rough Beckmann sphere and the blend scene. Usage:
#   cargo build --release && benches/variance_figures.sh [OUT_DIR]
# Each command prints its table; OUT_DIR/*/summary.json has the rows. RUNS (default 100) and
# PATHGRAD (default target/release/pathgrad) can be set in the environment.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-variance-figures}"
bin="${PATHGRAD:-target/release/pathgrad}"
runs="${RUNS:-100}"
cornell=(scenes/cornell-box/cornell-box.xml --param sphere.bsdf.alpha.value --width 64)
blend=(scenes/blend/blend.xml --param object.weight.value --width 64)
sweep=(--strategy bsdf,diff --q 0.1,0.3,0.5,0.7,0.9 --runs "$runs" --spp 2)
for nee in nee nonee; do
  flag=()
  [ "$nee" = nonee ] && flag=(--no-nee)
  "$bin" variance "${cornell[@]}" -D alpha=0.1 "${sweep[@]}" "${flag[@]}" -o "$out/cornell-image-$nee"
  # w = 0.4 as the paper's Dragon; at w = 0.5 the differential density equals the mixture's.
  "$bin" variance "${blend[@]}" -D weight=0.4 "${sweep[@]}" "${flag[@]}" -o "$out/blend-image-$nee"
  for alpha in 0.05 0.2 0.4; do
    "$bin" variance "${cornell[@]}" -D alpha=$alpha --strategy bsdf,diff --runs "$runs" --spp 2 "${flag[@]}" \
      -o "$out/cornell-alpha$alpha-$nee"
  done
done
# Loss gradients (Tables 1-2 protocol): the target at the scene value, the parameter perturbed.
"$bin" variance "${cornell[@]}" -D alpha=0.3 --target-set sphere.bsdf.alpha.value=0.1 \
  --strategy bsdf,diff --adaptive --runs "$runs" --spp 1 --spp-primal 3 -o "$out/cornell-loss"
"$bin" variance "${blend[@]}" -D weight=0.9 --target-set object.weight.value=0.4 \
  --strategy bsdf,diff --adaptive --runs "$runs" --spp 1 --spp-primal 3 -o "$out/blend-loss"
