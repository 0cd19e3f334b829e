#!/usr/bin/env bash
# `optimize` at equal time, every variance-reduction option against plain PRB and against the
# paper's method (issue 33): three scenes — Su & Gkioulekas's sphere (one near-specular roughness),
# the hero scene (two roughnesses and a blend weight) and the heterogeneous smoke (an RGB albedo) —
# each run for the same wall-time budget, the configurations interleaved per seed and scene so that
# a busy spell of the shared machine falls on all of them. Writes each run's folder under OUT and
# prints benches/optimize_equal_time.py's table of it.
#   [SCENES="sphere hero smoke"] [CONFIGS="plain paper cv cv+paper cv+adaptive"] [LR=0.01] \
#     [SPHERE_FROM=0.3] benches/optimize_equal_time.sh [PATHGRAD] [SECONDS] [SEEDS] [OUT]
# Configurations: `plain` (PRB, uniform pixels, no control variates), `paper` (Su & Gkioulekas:
# differential sampling where the parameters have a sampler, and adaptive pixels), `cv` (plain
# with control variates), `cv+paper`, `adaptive` (plain with adaptive pixels) and `cv+adaptive`
# (`optimize`'s default).
# The repository's path must not contain spaces (the scenes' arguments are split into words).
# SEEDS is a comma-separated list of base seeds (each run's iteration t uses seed + t); LR is
# Adam's learning rate for every run; SPHERE_FROM the sphere's initial roughness (its target is
# the scene's 0.008).
set -euo pipefail
bin=${1:-target/release/pathgrad}
budget=${2:-60}
seeds=${3:-0,100000}
out=${4:-out/optimize-equal-time}
here=$(cd "$(dirname "$0")" && pwd)
root=$(dirname "$here")
[ -f "$root/scenes/smoke/smoke.vol" ] || python3 "$root/scenes/smoke/make_smoke.py"

sphere_param=diff_bsdf.alpha.value
sphere="$root/benches/scenes/sphere/sphere.xml --param $sphere_param=${SPHERE_FROM:-0.3} --target-set $sphere_param=0.008 --width 64 --height 64"
hero_params="left.bsdf.alpha.value,right.bsdf.alpha.value,floor.bsdf.weight.value"
hero="$root/tests/data/scenes/hero_spheres.xml --param left.bsdf.alpha.value=0.3 --param right.bsdf.alpha.value=0.05 --param floor.bsdf.weight.value=0.2"
hero+=" --target-set left.bsdf.alpha.value=0.05 --target-set right.bsdf.alpha.value=0.25 --target-set floor.bsdf.weight.value=0.5 --width 64 --height 64"
smoke_param=smoke.interior_medium.albedo.value.value
smoke="$root/scenes/smoke/smoke.xml --param $smoke_param=0.5 --target-set $smoke_param=0.8 --width 64 --height 64"

# The paper's method per scene: differential sampling (these flags) with adaptive pixels where a
# lobe has a differential sampler; the smoke's albedo has none (∂f/∂albedo ∝ f), so there it is
# the adaptive pixels alone.
declare -A diff=(
  [sphere]="--strategy diff"
  [hero]="--strategy diff --diff-param $hero_params"
  [smoke]=""
)
declare -A args=([sphere]="$sphere" [hero]="$hero" [smoke]="$smoke")

mkdir -p "$out"
IFS=, read -r -a seed_list <<<"$seeds"
for seed in "${seed_list[@]}"; do
  for scene in ${SCENES:-sphere hero smoke}; do
    for config in ${CONFIGS:-plain paper cv cv+paper cv+adaptive}; do
      # Every configuration names both switches: `optimize` turns both on by default.
      case $config in
        plain) flags="--adaptive=false --control-variates=false" ;;
        paper) flags="--adaptive --control-variates=false ${diff[$scene]}" ;;
        cv) flags="--adaptive=false --control-variates" ;;
        cv+paper) flags="--adaptive --control-variates ${diff[$scene]}" ;;
        adaptive) flags="--adaptive --control-variates=false" ;;
        cv+adaptive) flags="--adaptive --control-variates" ;;
        *) echo "unknown configuration $config" >&2; exit 2 ;;
      esac
      dir="$out/$scene-$config-s$seed"
      rm -rf "$dir"
      # shellcheck disable=SC2086 # the scene's and the configuration's words are meant to split
      if "$bin" optimize ${args[$scene]} $flags --lr "${LR:-0.01}" --spp 128 --seed "$seed" --iters 100000 \
        --time-budget "$budget" -o "$dir" --json >"$dir.json" 2>"$dir.log"; then
        echo "$(date -u +%H:%M:%S) $scene $config seed $seed: $(grep -o '"iterations":[0-9]*' "$dir.json")"
      else
        echo "$(date -u +%H:%M:%S) $scene $config seed $seed: failed, see $dir.log" >&2
      fi
    done
  done
done
python3 "$here/optimize_equal_time.py" "$out"
