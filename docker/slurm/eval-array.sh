#!/bin/bash
# A sim-bridge evaluation campaign as a SLURM job array: task K of N drives share K
# (`eval --shard $SLURM_ARRAY_TASK_ID/N`) with its own local agent server; a dependent job
# merges the parts when every task has ended. Keep --array=0-(N-1) and SHARES equal
# (tests/tests/cluster_manifests.rs checks).
#
#   sbatch docker/slurm/eval-array.sh                 # prints "Submitted batch job JOBID"
#   sbatch --dependency=afterany:JOBID --wrap \
#       "sim-bridge results merge $RESULTS/part-*-of-8.json --out $RESULTS/results.json"
#
# RESULTS must be on a file system every node sees; sim-bridge and ssr-agent on PATH (or set
# SIM_BRIDGE). A task requeued after a node failure resumes its part (--resume).
#SBATCH --job-name=ssrdrive-eval
#SBATCH --array=0-7
#SBATCH --cpus-per-task=2
#SBATCH --mem=6G
#SBATCH --time=12:00:00
#SBATCH --requeue
#SBATCH --output=ssrdrive-eval-%A_%a.log
set -euo pipefail

SHARES=8
RESULTS=${RESULTS:-$PWD/results}
SIM_BRIDGE=${SIM_BRIDGE:-sim-bridge}
mkdir -p "$RESULTS"
export SSR_AGENT_COMPUTE_THREADS=${SLURM_CPUS_PER_TASK:-2}
exec "$SIM_BRIDGE" eval --agent local --routes town05-long-style --repetitions 3 \
    --shard "$SLURM_ARRAY_TASK_ID/$SHARES" \
    --out "$RESULTS/part-$SLURM_ARRAY_TASK_ID-of-$SHARES.json" --resume --quiet
