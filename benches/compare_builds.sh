#!/usr/bin/env bash
# Interleaved timings of several pathgrad builds on one scene: for each round, every build renders
# (primal) and takes a gradient step (`grad --target`), in turn, so a noisy shared machine slows
# them alike. Prints one line per build and round; nothing is asserted. A tool for BENCHMARKS.md.
#
#   benches/compare_builds.sh LABEL=BINARY ...        e.g. base=/tmp/base/release/pathgrad head=target/release/pathgrad
#
# Build an older commit beside the checkout with
#   git worktree add /tmp/wt COMMIT && (cd /tmp/wt && CARGO_TARGET_DIR=/tmp/wt-target cargo build --release)
# Environment: SCENE (default the sphere scene), PARAM, ROUNDS (3), SIZE (256), SPP (16), DEPTH (6).
set -euo pipefail
SCENE=${SCENE:-benches/scenes/sphere/sphere.xml}
PARAM=${PARAM:-diff_bsdf.alpha.value}
ROUNDS=${ROUNDS:-3}
SIZE=${SIZE:-256}
SPP=${SPP:-16}
DEPTH=${DEPTH:-6}
ARGS=(--width "$SIZE" --height "$SIZE" --max-depth "$DEPTH")
for icd in /usr/share/vulkan/icd.d/lvp_icd.json /usr/share/vulkan/icd.d/lvp_icd.x86_64.json; do
  if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$icd" ]; then export VK_DRIVER_FILES="$icd"; fi
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
first=${1#*=}
# The target: the scene at a changed parameter value, rendered once by the first build.
"$first" render "$SCENE" "${ARGS[@]}" -D alpha=0.3 --spp 64 -o "$tmp/target.exr" >/dev/null 2>&1 ||
  "$first" render "$SCENE" "${ARGS[@]}" --spp 64 --seed 77 -o "$tmp/target.exr" >/dev/null
time_s() { python3 -c 'import json,sys; print(round(json.load(sys.stdin)["time_s"], 3))'; }
# Warm-up: compile (or load) every build's kernels before timing.
for pair in "$@"; do
  bin=${pair#*=}
  "$bin" render "$SCENE" "${ARGS[@]}" --spp 1 -o "$tmp/w.exr" >/dev/null 2>&1
  "$bin" grad "$SCENE" "${ARGS[@]}" --spp 1 --target "$tmp/target.exr" --param "$PARAM" >/dev/null 2>&1
done
for round in $(seq "$ROUNDS"); do
  for pair in "$@"; do
    label=${pair%%=*}
    bin=${pair#*=}
    p=$("$bin" render "$SCENE" "${ARGS[@]}" --spp "$SPP" -o "$tmp/w.exr" --json 2>/dev/null | time_s)
    g=$("$bin" grad "$SCENE" "${ARGS[@]}" --spp "$SPP" --target "$tmp/target.exr" --param "$PARAM" --json 2>/dev/null | time_s)
    echo "round $round  $label  primal ${p} s  gradient step ${g} s"
  done
done
