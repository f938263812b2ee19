"""Parallel HDF5 helpers: the ``mpio`` driver, collective hyperslab reads and writes.

Files are created and renamed by :func:`railvib_hpc.io.atomic.write_h5`; this
module only moves data in and out of open files.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mpi4py import MPI


def h5py_parallel_ok(comm: MPI.Comm) -> bool:
    """True when h5py can open files with the mpio driver on this communicator."""
    import h5py

    return comm is not None and comm.size > 1 and bool(h5py.get_config().mpi)


def open_h5(path: str | os.PathLike, mode: str, comm: MPI.Comm, parallel: bool):
    """Open an HDF5 file with the mpio driver on ``comm`` (``parallel``) or the plain driver."""
    import h5py

    if parallel:
        return h5py.File(path, mode, driver="mpio", comm=comm)
    return h5py.File(path, mode)


def _dxpl(collective: bool):
    """Dataset transfer property list: collective MPI-IO, or the default."""
    if not collective:
        return None
    from h5py import h5fd, h5p

    dxpl = h5p.create(h5p.DATASET_XFER)
    dxpl.set_dxpl_mpio(h5fd.MPIO_COLLECTIVE)
    return dxpl


def _selection(ds, start: Sequence[int], count: Sequence[int], buf: np.ndarray | None):
    """File and memory dataspaces for a hyperslab (an empty selection when ``count`` has a 0)."""
    from h5py import h5s

    fspace = ds.id.get_space()
    if buf is None or 0 in tuple(count):
        fspace.select_none()
        mspace = h5s.create_simple((1,))
        mspace.select_none()
        return fspace, mspace, np.zeros(1, dtype=ds.dtype)
    fspace.select_hyperslab(tuple(int(s) for s in start), tuple(int(c) for c in count))
    return fspace, h5s.create_simple(tuple(int(c) for c in count)), buf


def write_slab(ds, start: Sequence[int], count: Sequence[int], buf: np.ndarray | None,
               collective: bool) -> None:
    """Write ``buf`` (C-contiguous, shape ``count``) to the hyperslab at ``start``.

    Unlike ``ds[...] = buf`` this takes part in a collective write even when this rank's
    selection is empty (h5py skips empty selections, which would hang the other ranks).
    """
    if buf is not None:
        buf = np.ascontiguousarray(buf)
    fspace, mspace, data = _selection(ds, start, count, buf)
    ds.id.write(mspace, fspace, data, dxpl=_dxpl(collective))


def read_slab(ds, start: Sequence[int], count: Sequence[int], out: np.ndarray | None,
              collective: bool) -> None:
    """Read the hyperslab at ``start`` into ``out`` (C-contiguous, shape ``count``)."""
    if out is not None and not out.flags.c_contiguous:
        raise ValueError("read_slab needs a C-contiguous output array")
    fspace, mspace, data = _selection(ds, start, count, out)
    ds.id.read(mspace, fspace, data, dxpl=_dxpl(collective))
