#!/usr/bin/env bash
# Attached against detached sampling for a rough conductor's roughness (issue 34): the gold ball of
# tests/data/scenes/attached_rough.xml at α ∈ {0.005, 0.02, 0.1, 0.3}, the loss against a target
# rendered at 1.25 α, its gradient by α over independent seeds with each sampling, interleaved.
# Prints per α and sampling the mean ± its standard error, the variance across seeds, the mean
# seconds of a gradient step (`grad --json`'s time_s), and the efficiency ratio
# (variance × seconds) detached ÷ attached: above 1, attached wins at equal time.
#   benches/attached_roughness.sh [PATHGRAD] [SEEDS] [SPP] [SIZE]
set -euo pipefail
bin=${1:-target/release/pathgrad}
seeds=${2:-16}
spp=${3:-8}
size=${4:-48}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cp tests/data/scenes/attached_sky.exr "$dir/"
for alpha in 0.005 0.02 0.1 0.3; do
  target_alpha=$(python3 -c "print($alpha * 1.25)")
  sed "s/name=\"alpha\" value=\"0.1\"/name=\"alpha\" value=\"$alpha\"/" tests/data/scenes/attached_rough.xml > "$dir/ball.xml"
  sed "s/name=\"alpha\" value=\"0.1\"/name=\"alpha\" value=\"$target_alpha\"/" tests/data/scenes/attached_rough.xml > "$dir/target.xml"
  "$bin" render "$dir/target.xml" --spp 256 --width "$size" --height "$size" -o "$dir/target.exr" >/dev/null 2>&1
  : > "$dir/detached"
  : > "$dir/attached"
  for ((s = 0; s < seeds; s++)); do
    for sampling in detached attached; do
      "$bin" grad "$dir/ball.xml" --param ball.bsdf.alpha.value --target "$dir/target.exr" --sampling "$sampling" \
        --seed "$s" --spp "$spp" --width "$size" --height "$size" --json 2>/dev/null \
        | python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["gradients"]["ball.bsdf.alpha.value"][0], j["time_s"])' \
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
    print(f"α {alpha}  {sampling:8}: mean {m:.5g} ± {(var / len(g)) ** 0.5:.2g}, variance {var:.3g}, {t:.3f} s a step, {len(g)} seeds")
print(f"α {alpha}  efficiency (variance × seconds) detached ÷ attached: {out['detached'] / out['attached']:.2f}")
PY
done
