"""Absorbing-boundary kernels on bilinear quadrilateral faces (pure numpy, batched).

Lysmer-Kuhlemeyer (1969) viscous boundary: the soil beyond a truncation face is replaced by
dashpots that carry, per unit area, the tractions of plane waves leaving the model at normal
incidence,

    t = -rho c_P (n . v) n - rho c_S (v - (n . v) n),

i.e. the 3 x 3 impedance ``Z = rho (c_P n n^T + c_S (I - n n^T))``. An optional elastic
term of the same form, ``(lambda + 2 G) / t n n^T + G / t (I - n n^T)`` per unit area (the
stiffness of a layer of thickness ``t`` behind the face, the "virtual thickness" of
STEM/Kratos), gives the truncated model static support.

Face integral: **lumped**. Each face node ``a`` gets ``int_face N_a Z dA`` (2 x 2 Gauss
points, the normal evaluated at each point, so warped faces are integrated exactly up to
the quadrature): the tributary area of the node, i.e. the row sum of the consistent face
matrix ``int N_a N_b Z dA``. The lumped form couples no new DOFs (the node's own 3 x 3
block), so the damping matrix has the sparsity pattern of K; for a plane wave at normal
incidence (uniform motion of a face) both forms give the same traction.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .quadrature import gauss_legendre

#: Reference corners of a bilinear quadrilateral (counter-clockwise), shape (4, 2).
_QUAD_REF = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def _quad_rule() -> tuple[np.ndarray, np.ndarray]:
    p, w = gauss_legendre(2)
    s, t = np.meshgrid(p, p, indexing="ij")
    ws, wt = np.meshgrid(w, w, indexing="ij")
    return np.stack([s.ravel(), t.ravel()], axis=1), (ws * wt).ravel()


def quad_shape(st: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear shape functions (q, 4) and reference gradients (q, 4, 2) at points ``st``."""
    st = np.atleast_2d(st)
    f = 1.0 + st[:, None, :] * _QUAD_REF[None]                   # (q, 4, 2)
    n = 0.25 * f[..., 0] * f[..., 1]
    dn = np.empty(f.shape)
    dn[..., 0] = 0.25 * _QUAD_REF[:, 0] * f[..., 1]
    dn[..., 1] = 0.25 * _QUAD_REF[:, 1] * f[..., 0]
    return n, dn


def face_integrals(x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Nodal area vectors of quadrilateral faces.

    Parameters
    ----------
    x
        (nf, 4, 3) corner coordinates, counter-clockwise seen from the side the normal
        points to.

    Returns
    -------
    area : ndarray (nf, 4, q)
        ``N_a |J| w`` at the 4 Gauss points ``q``: summed over ``q`` it is the tributary
        area of node ``a``; summed over ``a`` and ``q`` the face area.
    normal : ndarray (nf, q, 3)
        Unit normal at each Gauss point.
    """
    x = np.asarray(x, dtype=float)
    st, w = _quad_rule()
    n, dn = quad_shape(st)
    ds = np.einsum("qa,fai->fqi", dn[..., 0], x)
    dt = np.einsum("qa,fai->fqi", dn[..., 1], x)
    cross = np.cross(ds, dt)                                      # (nf, q, 3)
    jac = np.linalg.norm(cross, axis=-1)
    if np.any(jac <= 0.0):
        raise ValueError("degenerate boundary face (zero area)")
    normal = cross / jac[..., None]
    area = np.einsum("qa,fq,q->faq", n, jac, w)
    return area, normal


def face_impedance(x: ArrayLike, normal_coefficient: ArrayLike,
                   tangential_coefficient: ArrayLike) -> np.ndarray:
    """Lumped nodal 3 x 3 blocks ``int N_a (c_n n n^T + c_t (I - n n^T)) dA``.

    Parameters
    ----------
    x
        (nf, 4, 3) face corners.
    normal_coefficient, tangential_coefficient
        Per unit area, scalar or (nf,): ``rho c_P`` and ``rho c_S`` for the dashpots
        [N s/m^3], ``(lambda + 2 G) / t`` and ``G / t`` for the springs [N/m^3].

    Returns
    -------
    ndarray (nf, 4, 3, 3)
        Block of each face node.

    Examples
    --------
    A unit square face normal to z with rho c_P = 2, rho c_S = 1 gives each corner a
    quarter of the area:

    >>> x = [[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]]
    >>> b = face_impedance(x, 2.0, 1.0)
    >>> [float(v) for v in b[0, 0].diagonal()]
    [0.25, 0.25, 0.5]
    """
    area, normal = face_integrals(x)
    nf = area.shape[0]
    cn = np.broadcast_to(np.asarray(normal_coefficient, dtype=float), (nf,))
    ct = np.broadcast_to(np.asarray(tangential_coefficient, dtype=float), (nf,))
    nn = np.einsum("fqi,fqj->fqij", normal, normal)
    z = (cn[:, None, None, None] * nn
         + ct[:, None, None, None] * (np.eye(3) - nn))            # (nf, q, 3, 3)
    return np.einsum("faq,fqij->faij", area, z)


def wave_speeds(E: ArrayLike, nu: ArrayLike, rho: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """P- and S-wave speeds ``c_P = sqrt((lambda + 2 G) / rho)``, ``c_S = sqrt(G / rho)``.

    >>> cp, cs = wave_speeds(200e6, 0.2, 1850.0)
    >>> round(float(cp), 2), round(float(cs), 2)
    (346.58, 212.24)
    """
    E, nu, rho = (np.asarray(a, dtype=float) for a in (E, nu, rho))
    g = E / (2.0 * (1.0 + nu))
    m = E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return np.sqrt(m / rho), np.sqrt(g / rho)


__all__ = ["face_impedance", "face_integrals", "quad_shape", "wave_speeds"]
