#!/usr/bin/env bash
# `optimize` of a rough glass sphere's index of refraction under attached sampling (issue 34): the
# GGX sphere of tests/data/scenes/attached_rough_sphere.xml (α 0.2) from η = 1.3 towards a target
# rendered at η = 1.5. Shows first that detached sampling refuses `glass.bsdf.eta` by name, then
# prints per seed the iteration and time when η first came within 0.01 of 1.5, the mean of η and of
# |η − 1.5| over the last quarter of the iterations, and the curve (iteration, seconds, η) every STRIDE
# iterations.
#   benches/attached_eta_optimize.sh [PATHGRAD] [SEEDS] [ITERS] [LR] [STRIDE] [SPP_GRAD]
set -euo pipefail
bin=${1:-target/release/pathgrad}
seeds=${2:-2}
iters=${3:-100}
lr=${4:-0.01}
stride=${5:-10}
spp_grad=${6:-2}
scene=tests/data/scenes/attached_rough_sphere.xml
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
# Plain PRB steps, as BENCHMARKS.md recorded them (`optimize` now adds adaptive pixels and control
# variates by default).
plain=(--adaptive=false --control-variates=false)
echo "detached:"
"$bin" optimize "$scene" --param glass.bsdf.eta=1.3 --target-set glass.bsdf.eta=1.5 --sampling detached "${plain[@]}" \
  --iters 1 --width 32 --height 32 -o "$dir/detached" 2>&1 | sed 's/^/  /' || true
for ((seed = 1; seed <= seeds; seed++)); do
  "$bin" optimize "$scene" --param glass.bsdf.eta=1.3 --target-set glass.bsdf.eta=1.5 --sampling attached "${plain[@]}" \
    --iters "$iters" --lr "$lr" --spp-grad "$spp_grad" --width 32 --height 32 --seed "$seed" -o "$dir/attached-$seed" --json >/dev/null 2>&1
  python3 - "$dir/attached-$seed/history.csv" "$seed" "$stride" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
a = [(int(r["iteration"]), float(r["time_s"]), float(r["glass.bsdf.eta"])) for r in rows]
first = next(((i, t) for i, t, x in a if abs(x - 1.5) < 0.01), None)
tail = a[len(a) * 3 // 4:]
when = f"iteration {first[0]} ({first[1]:.1f} s)" if first else "never"
print(f"attached seed {sys.argv[2]}: first within 0.01 of 1.5 at {when}, mean |η − 1.5| over the last "
      f"{len(tail)} iterations {sum(abs(x - 1.5) for _, _, x in tail) / len(tail):.4f} (mean η "
      f"{sum(x for _, _, x in tail) / len(tail):.4f}), final η {a[-1][2]:.4f}, "
      f"{len(a)} iterations in {a[-1][1]:.1f} s")
stride = int(sys.argv[3])
print("  curve (iteration, s, η): " + "; ".join(f"{i}, {t:.1f}, {x:.4f}" for i, t, x in a if i % stride == 0 or i == a[-1][0]))
PY
done
