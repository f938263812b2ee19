"""Distributed assembly of K and M into PETSc MPIAIJ matrices (PETSc code lives here).

Each rank owns a contiguous range of nodes/DOFs (:class:`~railvib_hpc.modal.dofmap.DofMap`).
It computes the matrices of every element touching one of its nodes (elements
on a partition boundary are computed by each rank that touches them), keeps
the entries of its own rows, sums duplicates into one CSR structure shared by
K and M, and hands the CSR to PETSc in one call (``createAIJ(csr=...)``), which
is also the exact preallocation: no mallocs during assembly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..config import Case
from ..mesh.model import Mesh
from .dofmap import DofMap
from .elements import element_batches


@dataclass
class LocalCSR:
    """Owned rows of K and M in CSR form (same pattern)."""

    indptr: np.ndarray
    indices: np.ndarray
    K: np.ndarray
    M: np.ndarray
    n_elements: int
    timings: dict[str, float] = field(default_factory=dict)


def local_csr(mesh: Mesh, case: Case, dofmap: DofMap, rank: int) -> LocalCSR:
    """Compute the owned rows of K and M for ``rank`` (pure numpy).

    The sparsity pattern is built on the node graph (every pair of nodes sharing an element;
    8 x 8 per hexahedron instead of 24 x 24) and expanded to DOFs: all DOF rows of a node
    share the node's column list. Element entries are then placed by index arithmetic and
    summed with ``bincount``; no sort over all element entries is needed.
    """
    t0 = time.perf_counter()
    r0, r1 = dofmap.owned_dofs(rank)
    nodes = dofmap.owned_nodes(rank)
    n0, n1 = nodes.start, nodes.stop
    n_nodes = mesh.n_nodes
    idx = dofmap.index
    free = idx >= 0
    nfree = free.sum(axis=1)
    comp_pos = np.cumsum(free, axis=1) - 1                     # rank of a component in its node
    first = np.where(nfree > 0, np.where(free, idx, np.iinfo(np.int64).max).min(axis=1), 0)
    node_mask = np.zeros(n_nodes, dtype=bool)
    node_mask[nodes] = True
    hex_mask = node_mask[mesh.hexes].any(axis=1)
    line_mask = node_mask[mesh.lines].any(axis=1)

    # --- node graph of the owned rows (diagonal included: every node pairs with itself)
    keys = [np.arange(n0, n1, dtype=np.int64) * (n_nodes + 1) - n0 * n_nodes]
    for conn in (mesh.hexes[hex_mask], mesh.lines[line_mask]):
        a = np.broadcast_to(conn[:, :, None], conn.shape + conn.shape[1:])
        b = np.broadcast_to(conn[:, None, :], conn.shape + conn.shape[1:])
        own = (a >= n0) & (a < n1)
        keys.append((a[own] - n0) * np.int64(n_nodes) + b[own])
    ukeys = np.unique(np.concatenate(keys))
    pa, pb = ukeys // n_nodes, ukeys % n_nodes                 # local row node, column node
    width = nfree[pb]
    n_local_nodes = n1 - n0
    rowlen = np.bincount(pa, weights=width, minlength=n_local_nodes).astype(np.int64)
    node_col_start = np.concatenate(([0], np.cumsum(rowlen)))
    pair_start = np.cumsum(width) - width - node_col_start[pa]  # offset of pair in its row
    # columns of each node's rows: the free DOFs of its neighbours, in node order
    cols_node = (np.repeat(first[pb] - np.cumsum(width) + width, width)
                 + np.arange(int(width.sum())))
    rows_per_node = nfree[n0:n1]
    row_len = np.repeat(rowlen, rows_per_node)
    indptr = np.concatenate(([0], np.cumsum(row_len))).astype(np.int64)
    nnz = int(indptr[-1])
    row_node = np.repeat(np.arange(n_local_nodes), rows_per_node)
    entry_row = np.repeat(np.arange(len(row_len)), row_len)
    indices = cols_node[node_col_start[row_node[entry_row]] + np.arange(nnz) - indptr[entry_row]]
    t1 = time.perf_counter()

    kdata = np.zeros(nnz)
    mdata = np.zeros(nnz)
    t_kernels = 0.0
    n_elements = int(hex_mask.sum() + line_mask.sum())
    t_k = time.perf_counter()
    for batch in element_batches(mesh, case, hex_mask, line_mask):
        t_kernels += time.perf_counter() - t_k
        conn = batch.conn
        a = conn[:, :, None]
        b = conn[:, None, :]
        own = (a >= n0) & (a < n1)
        pair = np.minimum(np.searchsorted(ukeys, (np.where(own, a, n0) - n0) * np.int64(n_nodes)
                                          + b), len(ukeys) - 1)
        node_k = conn[:, batch.slot]                            # (nel, nd)
        row = idx[node_k, batch.comp] - r0                      # local row or < 0 / >= owned
        colpos = comp_pos[node_k, batch.comp]                   # (nel, nd)
        colfree = free[node_k, batch.comp]
        valid = ((row >= 0) & (row < r1 - r0))[:, :, None] & colfree[:, None, :]
        pos = (indptr[np.clip(row, 0, r1 - r0 - 1)][:, :, None]
               + pair_start[pair[:, batch.slot[:, None], batch.slot[None, :]]]
               + colpos[:, None, :])
        p = pos[valid]
        if p.size:
            lo, hi = int(p.min()), int(p.max()) + 1       # batches touch a band of rows
            p -= lo
            kdata[lo:hi] += np.bincount(p, weights=batch.K[valid], minlength=hi - lo)
            if batch.M is not None:
                mdata[lo:hi] += np.bincount(p, weights=batch.M[valid], minlength=hi - lo)
        t_k = time.perf_counter()
    t2 = time.perf_counter()
    return LocalCSR(indptr, indices.astype(np.int64), kdata, mdata, n_elements=n_elements,
                    timings={"element_kernels": t_kernels, "pattern": t1 - t0,
                             "scatter": t2 - t1 - t_kernels})


def petsc_matrices(csr: LocalCSR, dofmap: DofMap, comm):
    """Create assembled PETSc AIJ matrices K and M from the owned CSR rows."""
    from petsc4py import PETSc

    r0, r1 = dofmap.owned_dofs(comm.rank)
    n_local, n_global = r1 - r0, dofmap.n_dofs
    ip = csr.indptr.astype(PETSc.IntType)
    ix = csr.indices.astype(PETSc.IntType)
    mats = []
    for data in (csr.K, csr.M):
        A = PETSc.Mat().createAIJ(size=((n_local, n_global), (n_local, n_global)),
                                  csr=(ip, ix, data), comm=comm)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        A.assemble()
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        A.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
        mats.append(A)
    return mats[0], mats[1]


def assemble(mesh: Mesh, case: Case, dofmap: DofMap, comm):
    """Assemble distributed K and M. Returns ``(K, M, info)`` with timings and counts."""
    t0 = time.perf_counter()
    csr = local_csr(mesh, case, dofmap, comm.rank)
    t1 = time.perf_counter()
    K, M = petsc_matrices(csr, dofmap, comm)
    t2 = time.perf_counter()
    info = dict(csr.timings, numpy_total=t1 - t0, petsc=t2 - t1, local_elements=csr.n_elements,
                local_nnz=int(len(csr.indices)))
    return K, M, info
