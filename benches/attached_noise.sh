#!/usr/bin/env bash
# Attached sampling (issue 34): the η gradient of the loss of each attached test scene against a
# target rendered at η = 1.3, over independent seeds, for several amplitudes of the noise added
# to the ray Jacobians (--jacobian-noise; 0 is the exact completion alone). Prints per amplitude
# the mean ± its standard error, the variance across seeds, and how many runs failed. The mean
# must not move with the amplitude (the noise is zero-mean); the variance says what it costs.
#   benches/attached_noise.sh [PATHGRAD] [SEEDS] [SPP]
set -euo pipefail
bin=${1:-target/release/pathgrad}
seeds=${2:-32}
spp=${3:-8}
for scene in sphere slab pane; do
  for a in 0 0.05 0.2 0.5; do
    values=()
    for ((s = 0; s < seeds; s++)); do
      values+=("$("$bin" grad "tests/data/scenes/attached_$scene.xml" --param glass.bsdf.eta \
        --target-set glass.bsdf.eta=1.3 --sampling attached --jacobian-noise "$a" --seed "$s" \
        --spp "$spp" --width 48 --height 48 --json 2>/dev/null \
        | python3 -c 'import json,sys; print(json.load(sys.stdin)["gradients"]["glass.bsdf.eta"][0])')")
    done
    printf '%s\n' "${values[@]}" | python3 -c "
import sys, statistics as st
v = [float(x) for x in sys.stdin.read().split()]
m, var = st.mean(v), st.variance(v)
print(f'$scene  noise $a: mean {m:.5g} ± {(var / len(v)) ** 0.5:.2g}, variance {var:.3g} over {len(v)} seeds')
"
  done
done
