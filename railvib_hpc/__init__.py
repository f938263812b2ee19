"""railvib-hpc: MPI-parallel FE + multibody prediction of train-induced building vibration."""

__version__ = "0.1.0"

import os as _os

# Under mpirun with several ranks per node, one BLAS thread per rank avoids oversubscription
# (must be set before numpy loads OpenBLAS). Users can override by exporting the variables.
if int(_os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE", _os.environ.get("MPI_LOCALNRANKS", "1"))) > 1:
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        _os.environ.setdefault(_var, "1")
