"""Gauss-Legendre quadrature rules on [-1, 1] and on the reference hexahedron."""

from __future__ import annotations

import numpy as np


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and weights of the ``n``-point Gauss-Legendre rule on [-1, 1].

    Parameters
    ----------
    n
        Number of points; the rule integrates polynomials of degree ``2 n - 1`` exactly.

    Returns
    -------
    points : ndarray, shape (n,)
    weights : ndarray, shape (n,)
    """
    return np.polynomial.legendre.leggauss(n)


def gauss_hex(n: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Tensor-product Gauss rule on the reference hexahedron [-1, 1]^3.

    Parameters
    ----------
    n
        Points per direction (``n**3`` points in total).

    Returns
    -------
    points : ndarray, shape (n**3, 3)
        Reference coordinates (xi, eta, zeta), xi varying fastest.
    weights : ndarray, shape (n**3,)
    """
    p, w = gauss_legendre(n)
    pz, py, px = np.meshgrid(p, p, p, indexing="ij")
    wz, wy, wx = np.meshgrid(w, w, w, indexing="ij")
    points = np.stack([px.ravel(), py.ravel(), pz.ravel()], axis=1)
    return points, (wx * wy * wz).ravel()
