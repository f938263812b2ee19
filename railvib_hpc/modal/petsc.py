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
    """Compute the owned rows of K and M for ``rank`` (pure numpy)."""
    t0 = time.perf_counter()
    r0, r1 = dofmap.owned_dofs(rank)
    n_global = dofmap.n_dofs
    node_mask = np.zeros(mesh.n_nodes, dtype=bool)
    node_mask[dofmap.owned_nodes(rank)] = True
    hex_mask = node_mask[mesh.hexes].any(axis=1)
    line_mask = node_mask[mesh.lines].any(axis=1)
    keys, kvals, mvals = [], [], []
    t_kernels = 0.0
    t_k = time.perf_counter()
    for batch in element_batches(mesh, case, dofmap, hex_mask, line_mask):
        t_kernels += time.perf_counter() - t_k
        d = batch.dofs
        nel, nd = d.shape
        rows = np.broadcast_to(d[:, :, None], (nel, nd, nd))
        cols = np.broadcast_to(d[:, None, :], (nel, nd, nd))
        keep = (rows >= r0) & (rows < r1) & (cols >= 0)
        keys.append((rows[keep] - r0) * np.int64(n_global) + cols[keep])
        kvals.append(batch.K[keep])
        mvals.append(batch.M[keep] if batch.M is not None else np.zeros(int(keep.sum())))
        t_k = time.perf_counter()
    t1 = time.perf_counter()
    # every owned row gets its diagonal, even if only springs/constraints touch it
    diag = np.arange(r1 - r0, dtype=np.int64)
    keys.append(diag * n_global + (diag + r0))
    kvals.append(np.zeros(len(diag)))
    mvals.append(np.zeros(len(diag)))
    allkeys = np.concatenate(keys)
    uniq, inverse = np.unique(allkeys, return_inverse=True)
    kdata = np.bincount(inverse, weights=np.concatenate(kvals), minlength=len(uniq))
    mdata = np.bincount(inverse, weights=np.concatenate(mvals), minlength=len(uniq))
    rows = uniq // n_global
    indptr = np.searchsorted(rows, np.arange(r1 - r0 + 1)).astype(np.int64)
    indices = (uniq % n_global).astype(np.int64)
    t2 = time.perf_counter()
    return LocalCSR(indptr, indices, kdata, mdata,
                    n_elements=int(hex_mask.sum() + line_mask.sum()),
                    timings={"element_kernels": t_kernels, "scatter": t1 - t0 - t_kernels,
                             "csr": t2 - t1})


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
