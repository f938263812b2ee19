#!/bin/bash
# Band-sliced modes as array sub-jobs, then the merge (PBS Pro; Torque: -t and
# depend=afterokarray). See jobs/slurm/submit_bands.sh.
#
#   jobs/pbs/submit_bands.sh CASE OUT FMAX NBANDS [key=value ...]
set -euo pipefail
CASE=$1; OUT=$2; FMAX=$3; NBANDS=$4; shift 4
SETS="$*"
HERE=$(cd "$(dirname "$0")" && pwd)
EDGES=$(python -c "import json; from railvib_hpc.modal.bands import weyl_edges; \
print(';'.join(f'{e:.6f}' for e in weyl_edges(0.0, $FMAX, $NBANDS)))")
# EDGES travels as 40.9;51.6;59.1 (commas would split the --export / -v list)
VARS="CASE=$CASE,OUT=$OUT,FMAX=$FMAX,EDGES=$EDGES,SETS=$SETS"
A=$(qsub -J 1-"$NBANDS" -v "$VARS" "$HERE/modes_band.pbs")
M=$(qsub -W depend=afterok:"$A" -v "$VARS" "$HERE/modes_merge.pbs")
echo "modes below $FMAX Hz in $NBANDS bands (edges $EDGES): array job $A, merge job $M"
