#!/bin/bash
# The merge step of a sharded troupe study (docs/scale-out.md): after every task of
# docs/slurm/sweep-array.sh, rebuild OUT/<study>/results.csv, aggregate.csv and the
# plots from the runs the shards finished.
#
#   jid=$(sbatch --parsable --array=0-15 --export=ALL,STUDY=$STUDY,OUT=$OUT \
#       docs/slurm/sweep-array.sh)
#   sbatch --dependency=afterany:$jid --export=ALL,STUDY=$STUDY,OUT=$OUT docs/slurm/merge.sh
#
# `afterany`: it runs even when some tasks failed, and then lists the runs still
# missing (and fails); resubmit those tasks and merge again.
#
#SBATCH --job-name=troupe-merge
#SBATCH --cpus-per-task=1
#SBATCH --time=00:30:00
#SBATCH --output=troupe-merge-%j.out
set -euo pipefail

: "${STUDY:?set STUDY to the study file (sbatch --export=ALL,STUDY=...)}"
OUT=${OUT:-runs}
# The runs are found anywhere under OUT (runs of other studies there are passed over).
exec "${TROUPE:-troupe}" sweep "$STUDY" --merge "$OUT" --out "$OUT"
