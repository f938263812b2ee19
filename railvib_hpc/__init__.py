"""railvib-hpc: MPI-parallel FE + multibody prediction of train-induced building vibration.

The public API is flat (``import railvib_hpc as rv``): :class:`~railvib_hpc.api.Case`,
:class:`~railvib_hpc.api.Pipeline` and its results, :func:`~railvib_hpc.api.run_study`,
the exceptions, :func:`~railvib_hpc.io.run_record.read_run_record`. Importing the package
is light: numpy, PETSc, h5py and gmsh load when a name is first used.

Examples
--------
>>> import railvib_hpc as rv
>>> case = rv.Case.defaults().replace({"vehicle.speed": 20.0})
>>> case["vehicle.speed"]
20.0
>>> sorted(set(rv.__all__) - set(dir(rv)))
[]
"""

__version__ = "0.1.0"

import os as _os

# Under mpirun with several ranks per node, one BLAS thread per rank avoids oversubscription
# (must be set before numpy loads OpenBLAS). Users can override by exporting the variables.
if int(_os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE", _os.environ.get("MPI_LOCALNRANKS", "1"))) > 1:
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        _os.environ.setdefault(_var, "1")

#: Public name -> module that defines it (imported on first use, PEP 562).
_EXPORTS = {
    "Case": "railvib_hpc.config",
    "Pipeline": "railvib_hpc.api",
    "run_study": "railvib_hpc.api",
    "StageResult": "railvib_hpc.api",
    "MeshResult": "railvib_hpc.api",
    "ModalResult": "railvib_hpc.api",
    "MBSResult": "railvib_hpc.api",
    "ReconstructResult": "railvib_hpc.api",
    "AssessResult": "railvib_hpc.api",
    "RunResult": "railvib_hpc.api",
    "StagesResult": "railvib_hpc.api",
    "ProbePeak": "railvib_hpc.api",
    "StudyResult": "railvib_hpc.api",
    "StudyTable": "railvib_hpc.api",
    "VariantStatus": "railvib_hpc.api",
    "read_run_record": "railvib_hpc.io.run_record",
    "UserError": "railvib_hpc.errors",
    "CaseError": "railvib_hpc.errors",
    "MeshError": "railvib_hpc.errors",
    "OutputError": "railvib_hpc.errors",
    "OutputLockedError": "railvib_hpc.errors",
    "StaleInputError": "railvib_hpc.errors",
    "ResourceError": "railvib_hpc.errors",
    "DataError": "railvib_hpc.errors",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'railvib_hpc' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
