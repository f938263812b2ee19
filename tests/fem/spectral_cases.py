"""Meshes and small solvers shared by the spectral-element tests."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from fem_tools import box_mesh

from railvib_hpc.fem.spectral_kernel import box_element_matrix, spectral_elasticity
from railvib_hpc.fem.spectral_mesh import spectral_mesh

#: Lame parameters and density of the test soil (nu = 1/4: c_P = sqrt(3) c_S).
LAM, MU, RHO = 1.0e8, 1.0e8, 2000.0


def distorted_box(n: int, size: float = 1.0, amount: float = 0.15, seed: int = 0):
    """``n^3`` hexahedra of a cube of edge ``size`` whose inner nodes are moved at random by
    up to ``amount`` of an element edge (its faces stay planar); (points, hexes)."""
    points, hexes = box_mesh(n, n, n, size, size, size)
    rng = np.random.default_rng(seed)
    inner = np.all((points > 1e-12) & (points < size - 1e-12), axis=1)
    points = points.copy()
    points[inner] += amount * size / n * rng.uniform(-1.0, 1.0, (int(inner.sum()), 3))
    return points, hexes


def spectral_box(order: int, n: tuple[int, int, int], lengths=(1.0, 1.0, 1.0),
                 geometry: str = "auto"):
    """A box of ``n`` elements of order ``order``: (mesh, operator)."""
    points, hexes = box_mesh(*n, *lengths)
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), order)
    op = spectral_elasticity(order, sm.points, sm.elements, LAM, MU, RHO, geometry=geometry)
    return sm, op


def assembled_stiffness(sm, lengths, n) -> sp.csr_matrix:
    """The global stiffness of a uniform box mesh from the tensor-construction element."""
    h = np.asarray(lengths, float) / np.asarray(n, float)
    ke = box_element_matrix(sm.order, h, LAM, MU)
    dofs = (3 * sm.elements[:, :, None] + np.arange(3)).reshape(len(sm.elements), -1)
    rows = np.broadcast_to(dofs[:, :, None], dofs.shape + (dofs.shape[1],)).ravel()
    cols = np.broadcast_to(dofs[:, None, :], dofs.shape[:1] + (dofs.shape[1],) * 2).ravel()
    data = np.broadcast_to(ke, (len(dofs),) + ke.shape).ravel()
    size = 3 * sm.n_nodes
    return sp.coo_matrix((data, (rows, cols)), shape=(size, size)).tocsr()


def roller_free(points, lengths) -> np.ndarray:
    """(n_nodes, 3) True where a component is free: rollers on the six faces of the box
    hold the normal component."""
    free = np.ones(points.shape, bool)
    for d in range(3):
        on = (np.abs(points[:, d]) < 1e-9) | (np.abs(points[:, d] - lengths[d]) < 1e-9)
        free[on, d] = False
    return free


def roller_box_frequencies(lengths, count: int, c_p: float, c_s: float) -> np.ndarray:
    """The lowest ``count`` angular frequencies of an elastic box on rollers (sliding on
    every face). Every mode is ``u = (A sin(a x) cos(b y) cos(c z), B cos(a x) sin(b y)
    cos(c z), C cos(a x) cos(b y) sin(c z))`` with ``(a, b, c) = pi (l / L_x, m / L_y,
    n / L_z)``, which meets the roller conditions for any ``(A, B, C)``; the components
    whose index is 0 vanish, so the Christoffel problem lives on the nonzero indices: one
    P mode at ``c_P |k|`` (polarisation along ``k``) and ``(nonzero - 1)`` S modes at
    ``c_S |k|``."""
    out = []
    top = 8
    for l in range(top):
        for m in range(top):
            for n in range(top):
                nonzero = (l > 0) + (m > 0) + (n > 0)
                if nonzero == 0:
                    continue
                k = np.pi * np.sqrt((l / lengths[0]) ** 2 + (m / lengths[1]) ** 2
                                    + (n / lengths[2]) ** 2)
                out.append(c_p * k)
                out.extend([c_s * k] * (nonzero - 1))
    return np.sort(out)[:count]
