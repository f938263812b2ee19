"""Distributed assembly of K and M into PETSc MPIAIJ matrices (PETSc code lives here).

Each rank owns a contiguous range of nodes/DOFs (:class:`~railvib_hpc.modal.dofmap.DofMap`).
It builds the exact sparsity pattern of its rows from the node graph (every pair of nodes
sharing an element, expanded to their free DOFs), creates K and M with that pattern in one
``createAIJ(csr=...)`` call each (exact preallocation: no mallocs, K and M share the
pattern), computes the matrices of every element touching one of its nodes in batches and
inserts each batch with one ``setValuesRCV`` call; rows of other ranks and eliminated DOFs
are passed as -1 and ignored, so no entries travel between ranks.
"""

from __future__ import annotations

import time
from collections.abc import Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..errors import MeshError
from ..fem.reference import ElementGeometryError
from ..mesh.model import Mesh
from ..schema import PART_ID
from .dofmap import DofMap
from .elements import element_batches

if TYPE_CHECKING:
    from mpi4py import MPI


@dataclass
class LocalPattern:
    """CSR pattern of the owned rows and the elements that touch the owned nodes."""

    indptr: np.ndarray
    indices: np.ndarray
    hex_mask: np.ndarray
    line_mask: np.ndarray


def local_pattern(mesh: Mesh, dofmap: DofMap, rank: int,
                  parts: Collection[str] | None = None) -> LocalPattern:
    """Sparsity pattern of the rows owned by ``rank`` (pure numpy).

    Built on the node graph (8 x 8 pairs per hexahedron instead of 24 x 24 entries): all DOF
    rows of a node share the node's column list, the free DOFs of its neighbours in order.
    ``parts`` restricts it to the elements of those parts (every owned row keeps its
    diagonal).
    """
    nodes = dofmap.owned_nodes(rank)
    n0, n1 = nodes.start, nodes.stop
    n_nodes = mesh.n_nodes
    free = dofmap.index >= 0
    nfree = free.sum(axis=1)
    first = np.where(nfree > 0, np.where(free, dofmap.index,
                                         np.iinfo(np.int64).max).min(axis=1), 0)
    node_mask = np.zeros(n_nodes, dtype=bool)
    node_mask[nodes] = True
    hex_mask = node_mask[mesh.hexes].any(axis=1)
    line_mask = node_mask[mesh.lines].any(axis=1)
    if parts is not None:
        ids = [PART_ID[p] for p in parts]
        hex_mask &= np.isin(mesh.hex_part, ids)
        line_mask &= np.isin(mesh.line_part, ids)
    # every owned node pairs with itself, so each owned row has its diagonal
    keys = [np.arange(n0, n1, dtype=np.int64) * (n_nodes + 1) - n0 * n_nodes]
    for conn in (mesh.hexes[hex_mask], mesh.lines[line_mask]):
        a = np.broadcast_to(conn[:, :, None], conn.shape + conn.shape[1:])
        b = np.broadcast_to(conn[:, None, :], conn.shape + conn.shape[1:])
        own = (a >= n0) & (a < n1)
        keys.append((a[own] - n0) * np.int64(n_nodes) + b[own])
    ukeys = np.unique(np.concatenate(keys))
    pa, pb = ukeys // n_nodes, ukeys % n_nodes                 # local row node, column node
    width = nfree[pb]
    rowlen = np.bincount(pa, weights=width, minlength=n1 - n0).astype(np.int64)
    node_col_start = np.concatenate(([0], np.cumsum(rowlen)))
    cols_node = (np.repeat(first[pb] - np.cumsum(width) + width, width)
                 + np.arange(int(width.sum())))
    rows_per_node = nfree[n0:n1]
    row_len = np.repeat(rowlen, rows_per_node)
    indptr = np.concatenate(([0], np.cumsum(row_len))).astype(np.int64)
    nnz = int(indptr[-1])
    row_node = np.repeat(np.arange(n1 - n0), rows_per_node)
    entry_row = np.repeat(np.arange(len(row_len)), row_len)
    indices = cols_node[node_col_start[row_node[entry_row]] + np.arange(nnz) - indptr[entry_row]]
    return LocalPattern(indptr, indices.astype(np.int64), hex_mask, line_mask)


def assemble(mesh: Mesh, case: Case, dofmap: DofMap, comm: MPI.Comm,
             parts: Collection[str] | None = None, mass: bool = True):
    """Assemble distributed K and M. Returns ``(K, M, info)`` with timings and counts.

    ``parts`` restricts the elements (and the sparsity pattern) to those parts, e.g. for
    the stiffness of one material; ``mass=False`` assembles K only (M is returned as None).
    """
    from petsc4py import PETSc

    t0 = time.perf_counter()
    pat = local_pattern(mesh, dofmap, comm.rank, parts)
    hex_mask, line_mask = pat.hex_mask, pat.line_mask
    r0, r1 = dofmap.owned_dofs(comm.rank)
    n_local, n_global = r1 - r0, dofmap.n_dofs
    ip = pat.indptr.astype(PETSc.IntType)
    ix = pat.indices.astype(PETSc.IntType)
    mats = []
    for _ in range(2 if mass else 1):
        A = PETSc.Mat().createAIJ(size=((n_local, n_global), (n_local, n_global)),
                                  csr=(ip, ix, np.zeros(len(ix))), comm=comm)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        mats.append(A)
    K, M = mats if mass else (mats[0], None)
    t1 = time.perf_counter()
    t_kernels = t_insert = 0.0
    add = PETSc.InsertMode.ADD_VALUES
    t_k = time.perf_counter()
    geometry_error = None
    try:
        for batch in element_batches(mesh, case, hex_mask, line_mask, with_mass=mass):
            t_b = time.perf_counter()
            t_kernels += t_b - t_k
            cols = batch.dofs(dofmap.index)
            rows = np.where((cols >= r0) & (cols < r1), cols, -1)  # other ranks' rows: skipped
            rows = np.ascontiguousarray(rows, dtype=PETSc.IntType)
            cols = np.ascontiguousarray(cols, dtype=PETSc.IntType)
            K.setValuesRCV(rows, cols, np.ascontiguousarray(batch.K), addv=add)
            if M is not None and batch.M is not None:
                M.setValuesRCV(rows, cols, np.ascontiguousarray(batch.M), addv=add)
            t_k = time.perf_counter()
            t_insert += t_k - t_b
    except ElementGeometryError as exc:       # local work only so far: no collective missed
        geometry_error = str(exc)
    errors = [e for e in comm.allgather(geometry_error) if e]
    if errors:
        for A in mats:
            A.destroy()
        raise MeshError(f"the mesh cannot be assembled: {errors[0]}; check mesh.file or "
                        "the geometry (mesh_report.json lists the element quality)")
    t2 = time.perf_counter()
    for A in mats:
        A.assemble()
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        A.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    t3 = time.perf_counter()
    info = {"pattern": t1 - t0, "element_kernels": t_kernels, "insert": t_insert,
            "final_assembly": t3 - t2, "total": t3 - t0,
            "local_elements": int(hex_mask.sum() + line_mask.sum()),
            "local_hexes": int(hex_mask.sum()), "local_nnz": int(len(ix))}
    return K, M, info
