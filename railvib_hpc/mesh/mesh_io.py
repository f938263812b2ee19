"""Mesh files: ``mesh.h5`` and ``mesh.xdmf`` as the mesh model.

The format (layout, writer, reader of the arrays, check) has one home,
:mod:`railvib_hpc.io.formats.mesh`; its writers are re-exported here and
:func:`read_mesh_h5` builds the mesh model (:class:`~railvib_hpc.mesh.model.Mesh`) of the
arrays it reads.
"""

from __future__ import annotations

from pathlib import Path

from ..io.formats.mesh import (  # noqa: F401 (re-exported: the format's writers)
    mesh_nbytes,
    mesh_xdmf,
    read_mesh_arrays,
    write_mesh_files,
    write_mesh_h5,
)
from .model import Mesh


def read_mesh_h5(path: Path) -> tuple[Mesh, dict]:
    """Read ``mesh.h5``; returns the mesh and the file attributes."""
    fields, attrs = read_mesh_arrays(path)
    return Mesh(**fields), attrs
