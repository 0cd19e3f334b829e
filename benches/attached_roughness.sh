#!/usr/bin/env bash
# Attached against detached sampling for a rough BSDF's roughness (issue 34): a scene with one
# isotropic `alpha` (by default the gold ball of tests/data/scenes/attached_rough.xml; the rough glass
# sphere is tests/data/scenes/attached_rough_sphere.xml with glass.bsdf.alpha.value) at
# α ∈ {0.005, 0.02, 0.1, 0.3}, the loss against a target rendered at 1.25 α, its gradient by α over
# independent seeds with each sampling, interleaved.
# Prints per α and sampling the mean ± its standard error, the variance across seeds, the median
# and interquartile range (a spread that rare large values do not dominate), the mean seconds of a
# gradient step (`grad --json`'s time_s), and the efficiency ratio (variance × seconds)
# detached ÷ attached: above 1, attached wins at equal time.
#   benches/attached_roughness.sh [PATHGRAD] [SEEDS] [SPP] [SIZE] [SCENE] [PARAM] [MAX_DEPTH]
# (MAX_DEPTH: the target's and the gradients' --max-depth; default the scene's.)
set -euo pipefail
bin=${1:-target/release/pathgrad}
seeds=${2:-16}
spp=${3:-8}
size=${4:-48}
scene=${5:-tests/data/scenes/attached_rough.xml}
param=${6:-ball.bsdf.alpha.value}
depth=()
if [[ -n "${7:-}" ]]; then depth=(--max-depth "$7"); fi
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cp "$(dirname "$scene")/attached_sky.exr" "$dir/"
for alpha in 0.005 0.02 0.1 0.3; do
  target_alpha=$(python3 -c "print($alpha * 1.25)")
  sed "s/name=\"alpha\" value=\"[^\"]*\"/name=\"alpha\" value=\"$alpha\"/" "$scene" > "$dir/ball.xml"
  sed "s/name=\"alpha\" value=\"[^\"]*\"/name=\"alpha\" value=\"$target_alpha\"/" "$scene" > "$dir/target.xml"
  "$bin" render "$dir/target.xml" --spp 256 --width "$size" --height "$size" "${depth[@]}" -o "$dir/target.exr" >/dev/null 2>&1
  : > "$dir/detached"
  : > "$dir/attached"
  for ((s = 0; s < seeds; s++)); do
    for sampling in detached attached; do
      "$bin" grad "$dir/ball.xml" --param "$param" --target "$dir/target.exr" --sampling "$sampling" \
        --seed "$s" --spp "$spp" --width "$size" --height "$size" "${depth[@]}" --json 2>/dev/null \
        | python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["gradients"][sys.argv[1]][0], j["time_s"])' "$param" \
        >> "$dir/$sampling"
    done
  done
  python3 - "$dir" "$alpha" <<'PY'
import statistics as st, sys
d, alpha = sys.argv[1], sys.argv[2]
out = {}
for sampling in ("detached", "attached"):
    rows = [tuple(map(float, l.split())) for l in open(f"{d}/{sampling}") if l.strip()]
    g = [r[0] for r in rows]
    t = st.mean(r[1] for r in rows)
    m, var = st.mean(g), st.variance(g)
    out[sampling] = var * t
    q = st.quantiles(g, n=4)
    print(f"α {alpha}  {sampling:8}: mean {m:.5g} ± {(var / len(g)) ** 0.5:.2g}, variance {var:.3g}, median {q[1]:.3g}, "
          f"interquartile range {q[2] - q[0]:.3g}, {t:.3f} s a step, {len(g)} seeds")
print(f"α {alpha}  efficiency (variance × seconds) detached ÷ attached: {out['detached'] / out['attached']:.2f}")
PY
done
