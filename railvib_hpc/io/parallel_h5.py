"""Collective, atomic HDF5 files: every rank writes its slice, rank 0 renames when complete."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mpi4py import MPI


def h5py_parallel_ok(comm: MPI.Comm) -> bool:
    """True when h5py can open files with the mpio driver on this communicator."""
    import h5py

    return comm.size > 1 and bool(h5py.get_config().mpi)


def write_collective(path: Path, comm: MPI.Comm, fill: Callable[[object, bool], None]) -> None:
    """Create ``path`` collectively through ``fill(file, parallel)``; atomic.

    With MPI-enabled h5py and several ranks the file is opened with the
    ``mpio`` driver on every rank (``fill`` must then create the datasets
    identically on all ranks and write each rank's slice); otherwise only rank 0
    opens it (``fill`` must have gathered the data there). The file is written
    under a temporary name with the attribute ``complete = 0``; when every rank
    succeeded rank 0 sets ``complete = 1`` and renames it. Errors on any rank
    raise ``OSError`` on every rank and leave no file behind.
    """
    import h5py

    tmp = comm.bcast(str(path.with_name(f".{path.name}.part-{os.getpid()}"))
                     if comm.rank == 0 else None, root=0)
    parallel = h5py_parallel_ok(comm)
    error = None
    if parallel or comm.rank == 0:
        try:
            kw = {"driver": "mpio", "comm": comm} if parallel else {}
            with h5py.File(tmp, "w", **kw) as f:
                f.attrs["complete"] = 0
                fill(f, parallel)
        except Exception as exc:
            error = f"{type(exc).__name__}: {exc}"
    errors = comm.allgather(error)
    if any(errors):
        if comm.rank == 0 and os.path.exists(tmp):
            os.unlink(tmp)
        raise OSError(f"writing {path} failed: {next(e for e in errors if e)}")
    if comm.rank == 0:
        with h5py.File(tmp, "a") as f:
            f.attrs["complete"] = 1
        os.replace(tmp, path)
    comm.Barrier()
