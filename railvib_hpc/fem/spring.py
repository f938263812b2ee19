"""Directional 2-node spring-damper (ANSYS COMBIN14 with KEYOPT(2) = 1, 2, 3).

The element couples one global translation direction ``d`` (0 = x, 1 = y, 2 = z) of
its two nodes: element DOFs are ``(node_a dof d, node_b dof d)``. Stiffness and damping
matrices have the same form, ``k [[1, -1], [-1, 1]]``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["damper_matrices", "spring_dofs", "spring_matrices"]

_PAIR = np.array([[1.0, -1.0], [-1.0, 1.0]])


def _check_direction(direction: ArrayLike, nel: int) -> np.ndarray:
    d = np.broadcast_to(np.asarray(direction), (nel,))
    if not np.issubdtype(d.dtype, np.integer) or np.any((d < 0) | (d > 2)):
        raise ValueError("spring direction must be an integer 0 (x), 1 (y) or 2 (z)")
    return d.astype(np.int64)


def spring_matrices(k: ArrayLike, direction: ArrayLike) -> np.ndarray:
    """Stiffness matrices of directional springs.

    Parameters
    ----------
    k
        Spring stiffnesses (N/m), shape (nel,) or scalar.
    direction
        Global translation direction of each spring (0, 1 or 2), shape (nel,) or scalar;
        validated here, used by :func:`spring_dofs` to place the matrices.

    Returns
    -------
    ndarray, shape (nel, 2, 2)
        ``k [[1, -1], [-1, 1]]`` acting on ``(node_a dof d, node_b dof d)``.
    """
    k = np.atleast_1d(np.asarray(k, dtype=float))
    d = np.atleast_1d(np.asarray(direction))
    nel = np.broadcast_shapes(k.shape, d.shape)[0]
    _check_direction(d, nel)
    return np.broadcast_to(k, (nel,))[:, None, None] * _PAIR


def damper_matrices(c: ArrayLike, direction: ArrayLike) -> np.ndarray:
    """Damping matrices of directional dampers (same form as :func:`spring_matrices`).

    Parameters
    ----------
    c
        Damping coefficients (N s/m), shape (nel,) or scalar.
    direction
        Global translation direction of each damper (0, 1 or 2).

    Returns
    -------
    ndarray, shape (nel, 2, 2)
    """
    return spring_matrices(c, direction)


def spring_dofs(nodes: ArrayLike, direction: ArrayLike, dof_offset: ArrayLike) -> np.ndarray:
    """Global DOF index pairs of directional springs.

    Parameters
    ----------
    nodes
        Node pairs ``(node_a, node_b)``, shape (nel, 2).
    direction
        Translation direction per spring (0, 1 or 2), shape (nel,) or scalar.
    dof_offset
        Global index of the first DOF of every node, shape (nnode,); the translation DOFs
        of node ``n`` are ``dof_offset[n] + (0, 1, 2)``.

    Returns
    -------
    ndarray of int64, shape (nel, 2)
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    if nodes.ndim != 2 or nodes.shape[1] != 2:
        raise ValueError(f"spring nodes must have shape (nel, 2), got {nodes.shape}")
    d = _check_direction(direction, nodes.shape[0])
    return np.asarray(dof_offset, dtype=np.int64)[nodes] + d[:, None]
