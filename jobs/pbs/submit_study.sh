#!/bin/bash
# Submit a study as  prepare -> array of variants -> merge  (PBS Pro dependencies).
#
#   jobs/pbs/submit_study.sh KIND CASE OUT [key=value ...]
#
# Torque: replace "-J 0-N" by "-t 0-N" and "afterany:$A" by "afteranyarray:$A".
set -euo pipefail
KIND=$1; CASE=$2; OUT=$3; shift 3
SETS="$*"
HERE=$(cd "$(dirname "$0")" && pwd)
STUDY_SETS=()
for s in $SETS; do STUDY_SETS+=(--study-set "$s"); done
N=$(railvib study "$KIND" "$CASE" --out "$OUT" "${STUDY_SETS[@]}" --list | awk '$1 ~ /^[0-9]+$/' | wc -l)
VARS="KIND=$KIND,CASE=$CASE,OUT=$OUT,SETS=$SETS"
DEP=()
if [ "$KIND" = modes ] || [ "$KIND" = speed ]; then
    P=$(qsub -v "$VARS" "$HERE/study_prepare.pbs")
    DEP=(-W "depend=afterok:$P")
fi
if [ "$N" -gt 1 ]; then
    A=$(qsub "${DEP[@]}" -J "0-$((N - 1))" -v "$VARS" "$HERE/study_variant.pbs")
else
    A=$(qsub "${DEP[@]}" -v "$VARS,PBS_ARRAYID=0" "$HERE/study_variant.pbs")
fi
M=$(qsub -W "depend=afterany:$A" -v "$VARS" "$HERE/study_merge.pbs")
echo "study $KIND: $N variants, array job $A, merge job $M; results in $OUT/$KIND/"
