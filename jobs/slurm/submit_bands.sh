#!/bin/bash
# Band-sliced modes as an array of independent jobs, then the merge (SLURM dependencies).
#
#   jobs/slurm/submit_bands.sh CASE OUT FMAX NBANDS [key=value ...]
#   jobs/slurm/submit_bands.sh jobs/engineering.toml $SCRATCH/eng 65 4
#
# The NBANDS - 1 inner edges split [0, FMAX] into bands of about equal mode counts (Weyl's
# law N(f) ~ f^3, railvib_hpc.modal.bands.weyl_edges); every task and the merge get them.
# The merge runs only when every band succeeded (afterok); a failed band is resubmitted
# with  sbatch --array=K ... jobs/slurm/modes_band.sbatch  and the merge again.
set -euo pipefail
CASE=$1; OUT=$2; FMAX=$3; NBANDS=$4; shift 4
SETS="$*"
HERE=$(cd "$(dirname "$0")" && pwd)
EDGES=$(python -c "import json; from railvib_hpc.modal.bands import weyl_edges; \
print(';'.join(f'{e:.6f}' for e in weyl_edges(0.0, $FMAX, $NBANDS)))")
# EDGES travels as 40.9;51.6;59.1 (commas would split the --export / -v list)
EXPORT="ALL,CASE=$CASE,OUT=$OUT,FMAX=$FMAX,EDGES=$EDGES,SETS=$SETS"
A=$(sbatch --parsable --array=1-"$NBANDS" --export="$EXPORT" "$HERE/modes_band.sbatch")
M=$(sbatch --parsable --dependency=afterok:"$A" --export="$EXPORT" "$HERE/modes_merge.sbatch")
echo "modes below $FMAX Hz in $NBANDS bands (edges $EDGES): array job $A, merge job $M"
