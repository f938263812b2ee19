#!/bin/bash
# Submit a study as  prepare -> array of variants -> merge  (SLURM dependencies).
#
#   jobs/slurm/submit_study.sh KIND CASE OUT [key=value ...]
#   jobs/slurm/submit_study.sh convergence jobs/mesh_convergence.toml $SCRATCH/studies
#   jobs/slurm/submit_study.sh convergence jobs/mesh_convergence.toml $SCRATCH/studies \
#       'levels=[0.5,0.75,1,1.25,1.5]'
#
# The merge runs after the array whatever its outcome (afterany): failed variants are
# reported (their failed.json says why, e.g. the modal stage's memory check); resubmit
# the array for them, then merge again.
set -euo pipefail
KIND=$1; CASE=$2; OUT=$3; shift 3
SETS="$*"
HERE=$(cd "$(dirname "$0")" && pwd)
STUDY_SETS=()
for s in $SETS; do STUDY_SETS+=(--study-set "$s"); done
N=$(railvib study "$KIND" "$CASE" --out "$OUT" "${STUDY_SETS[@]}" --list | awk '$1 ~ /^[0-9]+$/' | wc -l)
EXPORT="ALL,KIND=$KIND,CASE=$CASE,OUT=$OUT,SETS=$SETS"
DEP=""
if [ "$KIND" = modes ] || [ "$KIND" = speed ]; then
    P=$(sbatch --parsable --export="$EXPORT" "$HERE/study_prepare.sbatch")
    DEP="--dependency=afterok:$P"
fi
A=$(sbatch --parsable $DEP --array=0-$((N - 1)) --export="$EXPORT" "$HERE/study_variant.sbatch")
M=$(sbatch --parsable --dependency=afterany:$A --export="$EXPORT" "$HERE/study_merge.sbatch")
echo "study $KIND: $N variants, array job $A, merge job $M; results in $OUT/$KIND/"
