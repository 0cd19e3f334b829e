#!/usr/bin/env bash
# `optimize` of a near-specular roughness (issue 34): a scene with one isotropic `alpha` (by default
# the gold ball of tests/data/scenes/attached_rough.xml; the rough glass sphere is
# tests/data/scenes/attached_rough_sphere.xml with glass.bsdf.alpha.value) from α = 0.05 towards a
# target rendered at α = 0.01, with detached and with attached sampling, interleaved, each for the
# same wall-time budget. Prints per run when α first came within 0.005 of 0.01, the mean
# |α − 0.01| after the first SETTLE seconds and the share of those iterations within 0.01. A run
# stops at ITERS iterations or SECONDS, whichever comes first: make ITERS large for a race at
# equal time.
#   benches/attached_roughness_optimize.sh [PATHGRAD] [ROUNDS] [SECONDS] [SCENE] [PARAM] [ITERS] [SETTLE]
set -euo pipefail
bin=${1:-target/release/pathgrad}
rounds=${2:-2}
budget=${3:-45}
scene=${4:-tests/data/scenes/attached_rough.xml}
param=${5:-ball.bsdf.alpha.value}
iters=${6:-400}
settle=${7:-5}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
for ((round = 1; round <= rounds; round++)); do
  for mode in detached attached; do
    "$bin" optimize "$scene" --param "$param=0.05" \
      --target-set "$param=0.01" --sampling "$mode" --adaptive=false --control-variates=false --iters "$iters" --time-budget "$budget" --lr 0.004 \
      --width 32 --height 32 --seed "$round" -o "$dir/$mode-$round" --json >/dev/null 2>&1
    python3 - "$dir/$mode-$round/history.csv" "$mode" "$round" "$param" "$settle" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
a = [(float(r["time_s"]), float(r[sys.argv[4]])) for r in rows]
first = next((t for t, x in a if abs(x - 0.01) < 0.005), None)
settle = float(sys.argv[5])
late = [abs(x - 0.01) for t, x in a if t > settle]
share = sum(1 for d in late if d < 0.01) / max(1, len(late))
when = f"{first:.1f} s" if first is not None else "never"
print(f"{sys.argv[2]:8} round {sys.argv[3]}: first within 0.005 at {when}, mean |α − 0.01| after {settle:g} s "
      f"{sum(late) / max(1, len(late)):.4f}, within 0.01 {share:.2f} ({len(late)} iterations), {len(a)} iterations in {a[-1][0]:.1f} s")
PY
  done
done
