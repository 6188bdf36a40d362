#!/bin/bash
# One shard of a troupe study per Slurm array task (docs/scale-out.md).
#
#   sbatch --array=0-15 --export=ALL,STUDY=sims/studies/link_constraint.toml,OUT=$PWD/runs \
#       docs/slurm/sweep-array.sh
#
# Task K of an array 0..N-1 flies `troupe sweep STUDY --shard K/N`: the runs at
# positions K, K+N, K+2N, ... of the study (`troupe sweep STUDY --dry-run` lists
# them in that order). Every task writes its runs under OUT/<study>/runs/ on the
# shared file system; merge them once all tasks are done (docs/slurm/merge.sh).
#
# Environment (pass with --export):
#   STUDY   the study file (required)
#   OUT     the output directory on a file system every node sees (default: runs)
#   TROUPE  the troupe binary (default: troupe on PATH)
#   SHARDS  N, the number of shards (default: the array's highest index + 1); set it
#           when resubmitting some tasks only, e.g. --array=3,7 of an array of 16
#
#SBATCH --job-name=troupe-sweep
#SBATCH --array=0-15
#SBATCH --cpus-per-task=8
#SBATCH --time=08:00:00
#SBATCH --output=troupe-sweep-%A_%a.out
set -euo pipefail

: "${STUDY:?set STUDY to the study file (sbatch --export=ALL,STUDY=...)}"
: "${SLURM_ARRAY_TASK_ID:?submit as a job array: sbatch --array=0-<N-1>}"
SHARDS=${SHARDS:-$((SLURM_ARRAY_TASK_MAX + 1))}

# --resume: a task that is requeued (node failure, preemption) keeps the runs it
# had finished.
exec "${TROUPE:-troupe}" sweep "$STUDY" \
    --shard "$SLURM_ARRAY_TASK_ID/$SHARDS" \
    --jobs "${SLURM_CPUS_PER_TASK:-1}" \
    --out "${OUT:-runs}" \
    --resume
