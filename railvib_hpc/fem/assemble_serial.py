"""Small serial sparse assembler (reference implementation and tests).

Everything is vectorised: element matrices (nel, n, n) and DOF maps (nel, n) are
flattened into COO triplets; duplicates are summed by the CSR conversion.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

__all__ = ["assemble_matrix", "assemble_vector", "element_dofs", "eliminate_dofs"]


def element_dofs(conn: ArrayLike, dofs_per_node: int, dof_offset: ArrayLike | None = None
                 ) -> np.ndarray:
    """Node-major element DOF maps.

    Parameters
    ----------
    conn
        Element connectivity, shape (nel, nen).
    dofs_per_node
        Number of element DOFs per node (3 for solids, 6 for beams).
    dof_offset
        Global index of the first DOF of every node, shape (nnode,). Default:
        ``dofs_per_node * node`` (all nodes have ``dofs_per_node`` DOFs).

    Returns
    -------
    ndarray of int64, shape (nel, nen * dofs_per_node)
        ``[n0 d0, n0 d1, ..., n1 d0, ...]``.
    """
    conn = np.asarray(conn, dtype=np.int64)
    first = conn * dofs_per_node if dof_offset is None else np.asarray(dof_offset)[conn]
    dofs = first[:, :, None] + np.arange(dofs_per_node)
    return dofs.reshape(conn.shape[0], -1).astype(np.int64)


def assemble_matrix(dofs: ArrayLike, ke: ArrayLike, ndof: int) -> sp.csr_matrix:
    """Assemble element matrices into a sparse global matrix.

    Parameters
    ----------
    dofs
        Global DOF indices of the element DOFs, shape (nel, n).
    ke
        Element matrices, shape (nel, n, n).
    ndof
        Number of global DOFs.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (ndof, ndof)
    """
    dofs = np.asarray(dofs, dtype=np.int64)
    ke = np.asarray(ke, dtype=float)
    n = dofs.shape[1]
    if ke.shape != (dofs.shape[0], n, n):
        raise ValueError(f"element matrices {ke.shape} do not match DOF maps {dofs.shape}")
    rows = np.broadcast_to(dofs[:, :, None], ke.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], ke.shape).ravel()
    return sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(ndof, ndof)).tocsr()


def assemble_vector(dofs: ArrayLike, fe: ArrayLike, ndof: int) -> np.ndarray:
    """Assemble element vectors (e.g. lumped-mass diagonals or loads).

    Parameters
    ----------
    dofs
        Global DOF indices, shape (nel, n).
    fe
        Element vectors, shape (nel, n).
    ndof
        Number of global DOFs.

    Returns
    -------
    ndarray, shape (ndof,)
    """
    return np.bincount(np.asarray(dofs, dtype=np.int64).ravel(),
                       weights=np.asarray(fe, dtype=float).ravel(), minlength=ndof)


def eliminate_dofs(K: sp.spmatrix, M: sp.spmatrix | None, fixed: ArrayLike
                   ) -> tuple[sp.csr_matrix, sp.csr_matrix | None, np.ndarray]:
    """Remove fixed (zero-displacement) DOFs from ``K`` and ``M``.

    Parameters
    ----------
    K
        Global stiffness, shape (ndof, ndof).
    M
        Global mass (same shape) or ``None``.
    fixed
        Indices of fixed DOFs (duplicates allowed) or a boolean mask of length ``ndof``.

    Returns
    -------
    Kr : scipy.sparse.csr_matrix
        ``K[free][:, free]``.
    Mr : scipy.sparse.csr_matrix or None
        ``M[free][:, free]``.
    free : ndarray of int64
        Global indices of the remaining DOFs, ascending.
    """
    ndof = K.shape[0]
    fixed = np.asarray(fixed)
    mask = np.zeros(ndof, dtype=bool)
    if fixed.dtype == bool:
        mask |= fixed
    else:
        mask[fixed.astype(np.int64)] = True
    free = np.flatnonzero(~mask)
    Kr = sp.csr_matrix(K)[free][:, free]
    Mr = None if M is None else sp.csr_matrix(M)[free][:, free]
    return Kr, Mr, free
