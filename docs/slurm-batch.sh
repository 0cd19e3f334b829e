#!/usr/bin/env bash
# A Slurm job array that runs a pathgrad manifest in 16 shards, then merges them.
#
#   sbatch docs/slurm-batch.sh            # the shards (one array task each)
#   sbatch --dependency=afterok:JOBID --wrap 'pathgrad reduce runs/sweep'   # once they are done
#
# Each array task runs the items whose index is ≡ its shard (mod 16): pathgrad reads
# SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_MIN and SLURM_ARRAY_TASK_COUNT itself. A GPU that Slurm
# assigns (--gres) is chosen by its UUID from CUDA_VISIBLE_DEVICES when it lists UUIDs. Every
# shard writes into the same directory (item files named after the items, one summary per
# shard); a requeued or rerun task skips the items it finished.
#SBATCH --job-name=pathgrad-sweep
#SBATCH --array=0-15
#SBATCH --cpus-per-task=4
#SBATCH --gres=gpu:1
#SBATCH --time=02:00:00
#SBATCH --output=runs/sweep/slurm-%A_%a.log
set -euo pipefail
mkdir -p runs/sweep
exec pathgrad batch manifests/sweep.jsonl -o runs/sweep
