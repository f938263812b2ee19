"""Static solutions for unit loads on the rail DOFs (static correction of the modal basis).

For every rail node of both flexible rails and each of its DOFs ``w`` (vertical
displacement) and ``ry`` (rotation about the lateral axis), the static response
``x = K^-1 e`` to a unit load on that DOF. Computed with the Cholesky factor of
K of the block Lanczos eigensolve when it factors K itself (shift 0), else
with its own factorization. Written to ``static.h5`` (collective, like
``modes.h5``; the format, its writer and reader: :mod:`railvib_hpc.io.formats.static`):

* ``/static/rail_flexibility`` (n_r, n_r): ``K^-1`` on the rail DOFs (zero rows and
  columns for constrained DOFs, e.g. rotations fixed at the pads);
* ``/static/translation`` (n_r, n_nodes, 3): the static displacement fields;
* ``/static/residual_mass`` (n_r, n_r): ``X'^T M X'`` of the static fields with the
  modes of ``modes.h5`` taken out, ``X' = X - Phi Phi^T M X`` (:func:`deflate`; the mass of
  the residual vectors of :func:`railvib_hpc.mbs.static_correction.residual_modes`, formed
  without the cancellation of ``X^T M X - Phi_r^T Lambda^-2 Phi_r``);
* ``/static/load_dofs`` (n_r, 3): rail index, node (global id), component (0 w, 1 ry);
* the provenance attributes of :func:`railvib_hpc.io.provenance.provenance` (its
  ``upstream_sha256`` names the ``modes.h5`` it belongs to) and ``complete``.

Column ordering ``(rail * k + node) * 2 + c`` as in :mod:`railvib_hpc.mbs.static_correction`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..constants import BYTES_PER_DOUBLE, BYTES_PER_GB
from ..io.formats.static import write_static_h5
from ..io.parallel_h5 import h5py_parallel_ok

if TYPE_CHECKING:
    from mpi4py import MPI


def rail_load_dofs(mesh, dofmap) -> tuple[np.ndarray, np.ndarray]:
    """Global free-DOF index of every rail DOF (-1 if constrained) and its description.

    Returns
    -------
    dofs
        (n_r,) global DOF numbers in the column ordering.
    table
        (n_r, 3) rail index, node id, component (0: ``w`` = uz, 1: ``ry``).
    """
    from ..mesh.checks import require_parts

    require_parts(mesh, ("rail",), "mbs.static_correction = true (unit loads on the rails)")
    rails = mesh.rail_nodes()
    if np.any(rails < 0):
        raise ValueError("the rails must have the same number of nodes")
    comp = np.array([2, 4])                        # uz, ry in the node's 6 components
    nodes = np.repeat(rails.reshape(-1), 2)
    c = np.tile([0, 1], rails.size)
    dofs = dofmap.index[nodes, comp[c]]
    table = np.stack([np.repeat(np.arange(rails.shape[0]), rails.shape[1] * 2), nodes, c], axis=1)
    return dofs.astype(np.int64), table.astype(np.int64)


def unit_loads(dofs: np.ndarray, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
    """This rank's rows of the unit load vectors of the free rail DOFs.

    Returns
    -------
    rhs
        (r1 - r0, n_free) right-hand sides.
    free
        (n_free,) columns (positions in ``dofs``) they belong to.
    """
    free = np.flatnonzero(dofs >= 0)
    rhs = np.zeros((r1 - r0, free.size))
    own = (dofs[free] >= r0) & (dofs[free] < r1)
    rhs[dofs[free][own] - r0, np.flatnonzero(own)] = 1.0
    return rhs, free


def rail_flexibility(x_local: np.ndarray, dofs: np.ndarray, free: np.ndarray, r0: int,
                     comm: MPI.Comm) -> np.ndarray:
    """``K^-1`` restricted to the rail DOFs (n_r, n_r), from the distributed solutions."""
    n_r = dofs.size
    part = np.zeros((n_r, n_r))
    rows = np.flatnonzero((dofs >= r0) & (dofs < r0 + x_local.shape[0]))
    part[np.ix_(rows, free)] = x_local[dofs[rows] - r0]
    from mpi4py import MPI

    out = np.empty_like(part)
    comm.Allreduce(part, out, op=MPI.SUM)
    return 0.5 * (out + out.T)


def static_columns(x_local: np.ndarray, free: np.ndarray, n_r: int) -> np.ndarray:
    """This rank's rows (n_local, n_r) of the static fields in the rail-DOF ordering
    (zero columns for constrained rail DOFs)."""
    cols = np.zeros((x_local.shape[0], n_r))
    cols[:, free] = x_local
    return cols


def deflate(M, phi: np.ndarray, cols: np.ndarray, comm: MPI.Comm) -> np.ndarray:
    """This rank's rows of ``X' = X - Phi (Phi^T M X)``: the static fields with the
    (mass-normalised) modes taken out, M-orthogonal to them (collective)."""
    from mpi4py import MPI

    from ..model.factor import sparse_times_block

    coef = phi.T @ sparse_times_block(M, cols, comm)
    comm.Allreduce(MPI.IN_PLACE, coef, op=MPI.SUM)
    return cols - phi @ coef


def residual_mass(M, phi: np.ndarray, x_local: np.ndarray, free: np.ndarray, n_r: int,
                  comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray]:
    """The deflated static fields (this rank's rows, rail-DOF columns) and their mass
    ``X'^T M X'`` (n_r, n_r), the same on every rank (collective)."""
    from .projection import project

    x_def = deflate(M, phi, static_columns(x_local, free, n_r), comm)
    return x_def, project(M, x_def, comm)


def write_static(path: Path, comm: MPI.Comm, mesh, dofmap, x_local: np.ndarray, free: np.ndarray,
                 dofs: np.ndarray, table: np.ndarray, attrs: dict, mass: np.ndarray) -> str:
    """Write ``static.h5`` (collective; checked, atomic, recorded); returns its digest.

    ``attrs``: its provenance (:func:`railvib_hpc.io.provenance.provenance`); ``mass``:
    ``X'^T M X'`` (n_r, n_r) of :func:`residual_mass`, the same on every rank.
    """
    n_r = dofs.size
    r0 = dofmap.owned_dofs(comm.rank)[0]
    flex = rail_flexibility(x_local, dofs, free, r0, comm)
    cols = static_columns(x_local, free, n_r)
    translation, _, _, _, nodes = dofmap.node_arrays(cols, comm.rank)
    parallel = h5py_parallel_ok(comm)
    if not parallel and comm.size > 1:
        parts = comm.gather(translation, root=0)
        if comm.rank == 0:
            translation = np.concatenate(parts, axis=1)
            nodes = slice(0, mesh.n_nodes)
    return write_static_h5(path, comm, mesh.n_nodes, flex, mass, table, translation, nodes,
                           attrs, parallel)


def solve_static(K, M, comm: MPI.Comm, rhs: np.ndarray) -> np.ndarray:
    """``K^-1 rhs`` with its own MUMPS Cholesky factorization (options prefix railvib_eig_)."""
    from ..model.factor import ShiftInvertFactor
    from .eigen import PREFIX

    # dense blocks held besides the factor: the right-hand sides and the solutions (all ranks)
    extra_gb = 2 * BYTES_PER_DOUBLE * comm.allreduce(rhs.size) / BYTES_PER_GB
    op = ShiftInvertFactor(K, M, 0.0, comm, PREFIX, extra_gb=extra_gb)
    try:
        return op.solve(rhs)
    finally:
        op.destroy()
