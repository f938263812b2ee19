"""Batched kernels of the 8-node trilinear hexahedron (ANSYS SOLID185-like).

Node order is gmsh/VTK: reference corners (-1,-1,-1), (1,-1,-1), (1,1,-1), (-1,1,-1),
(-1,-1,1), (1,-1,1), (1,1,1), (-1,1,1). Element DOFs are node-major,
``[u0x, u0y, u0z, u1x, ..., u7z]`` (24 per element). All kernels work on whole
batches of elements, ``x`` of shape (nel, 8, 3), without Python loops over elements
(the stiffness only walks over blocks of 8192 elements to bound temporary memory).

The stiffness uses 2x2x2 Gauss integration, optionally with Hughes' B-bar
treatment of the volumetric strain (ANSYS SOLID185 KEYOPT(2)=0, "selective reduced
integration"): the dilatational part of the strain-displacement matrix is replaced
by its volume average over the element, which removes volumetric locking for
nearly incompressible materials while keeping full rank.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..errors import MeshError
from ..mesh.model import hex_shape_gradients
from ..mesh.search import hex_shape_values
from .material import isotropic_elasticity, isotropic_elasticity_batch, lame_parameters
from .quadrature import gauss_hex

__all__ = [
    "hex8_jacobians",
    "hex8_lumped_mass_diagonal",
    "hex8_mass",
    "hex8_stiffness",
    "hex8_strain_displacement",
    "hex8_volume",
    "isotropic_elasticity",
    "isotropic_elasticity_batch",
]

_XI, _W = gauss_hex(2)
_DN = hex_shape_gradients(_XI)      # (8 points, 8 nodes, 3)
_DN_T = np.ascontiguousarray(_DN.transpose(0, 2, 1))
_N = hex_shape_values(_XI)          # (8 points, 8 nodes)
#: Elements per block in :func:`hex8_stiffness` (bounds temporary memory to ~100 MB).
_BLOCK = 8192


def _as_coords(x: ArrayLike) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim != 3 or x.shape[1:] != (8, 3):
        raise ValueError(f"hex coordinates must have shape (nel, 8, 3), got {x.shape}")
    return x


def _per_element(value: ArrayLike, nel: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=float), (nel,))


def hex8_jacobians(x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Physical shape-function gradients and integration weights at the 2x2x2 Gauss points.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).

    Returns
    -------
    grad : ndarray, shape (nel, 8, 8, 3)
        ``grad[e, q, a, j] = dN_a / dx_j`` at Gauss point ``q``.
    wdet : ndarray, shape (nel, 8)
        Gauss weight times Jacobian determinant (the volume attached to each point).

    Raises
    ------
    MeshError
        If the Jacobian determinant is not positive at some Gauss point (inverted or
        degenerate element).
    """
    x = _as_coords(x)
    J = np.matmul(_DN_T[None], x[:, None])           # J[i, j] = dx_j / dxi_i, (nel, 8, 3, 3)
    adj = np.cross(J[..., [1, 2, 0], :], J[..., [2, 0, 1], :])        # rows: cofactor rows
    det = np.einsum("eqj,eqj->eq", J[..., 0, :], adj[..., 0, :])
    bad = np.flatnonzero(np.any(det <= 0.0, axis=1))
    if bad.size:
        raise MeshError(f"{bad.size} hexahedra have a non-positive Jacobian "
                        f"(first: element {bad[0]})")
    # J^-1 has the cofactor rows as columns, so grad_a = J^-1 dN_a = dN_a^T adj / det
    grad = np.matmul(_DN[None], adj) / det[..., None, None]
    return grad, det * _W


def hex8_volume(x: ArrayLike) -> np.ndarray:
    """Volumes of trilinear hexahedra (exact: 2x2x2 Gauss integrates det J exactly).

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).

    Returns
    -------
    ndarray, shape (nel,)
    """
    return hex8_jacobians(x)[1].sum(axis=1)


def _strain_matrix(grad: np.ndarray) -> np.ndarray:
    """Voigt strain-displacement matrices from gradients (..., 8, 3) -> (..., 6, 8, 3)."""
    B = np.zeros(grad.shape[:-2] + (6, 8, 3))
    gx, gy, gz = grad[..., 0], grad[..., 1], grad[..., 2]
    B[..., 0, :, 0] = gx
    B[..., 1, :, 1] = gy
    B[..., 2, :, 2] = gz
    B[..., 3, :, 1] = gz
    B[..., 3, :, 2] = gy
    B[..., 4, :, 0] = gz
    B[..., 4, :, 2] = gx
    B[..., 5, :, 0] = gy
    B[..., 5, :, 1] = gx
    return B


def hex8_strain_displacement(x: ArrayLike, bbar: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Strain-displacement matrices at the 2x2x2 Gauss points.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).
    bbar
        Replace the volumetric part of ``B`` by its element volume average (Hughes' B-bar).

    Returns
    -------
    B : ndarray, shape (nel, 8, 6, 24)
        ``eps = B[e, q] @ u_e`` at Gauss point ``q`` (Voigt order xx, yy, zz, yz, xz, xy).
    wdet : ndarray, shape (nel, 8)
        Gauss weight times Jacobian determinant.
    """
    grad, wdet = hex8_jacobians(x)
    B = _strain_matrix(grad)
    if bbar:
        vol = wdet.sum(axis=1)
        gbar = np.einsum("eq,eqaj->eaj", wdet, grad) / vol[:, None, None]
        # volumetric part: rows xx, yy, zz of column (a, j) hold dN_a/dx_j / 3
        B[:, :, :3, :, :] += ((gbar[:, None] - grad) / 3.0)[:, :, None, :, :]
    return B.reshape(B.shape[:3] + (24,)), wdet


def hex8_stiffness(x: ArrayLike, E: ArrayLike, nu: ArrayLike, bbar: bool = True) -> np.ndarray:
    """Element stiffness matrices of isotropic linear-elastic hexahedra.

    Equivalent to ``sum_q w_q det J_q B_q^T D B_q`` with the (B-bar) strain-displacement
    matrices of :func:`hex8_strain_displacement`, but evaluated from the shape-function
    gradients ``g`` directly, which is several times cheaper. For isotropic material the
    node-block ``(a, b)``, component ``(i, j)`` entry is::

        full:  int mu (g_a . g_b delta_ij + g_aj g_bi) + lambda g_ai g_bj dV
        B-bar: int mu (g_a . g_b delta_ij + g_aj g_bi) - 2 mu / 3 g_ai g_bj dV
               + kappa V gbar_ai gbar_bj

    (deviatoric part from ``B``, dilatation from the volume-averaged gradients ``gbar``;
    ``kappa = lambda + 2 mu / 3`` is the bulk modulus).

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).
    E
        Young's moduli (Pa), shape (nel,) or scalar.
    nu
        Poisson's ratios, shape (nel,) or scalar.
    bbar
        Use the B-bar method (default, ANSYS SOLID185 default); ``False`` gives plain
        2x2x2 full integration (locks for ``nu -> 0.5``).

    Returns
    -------
    ndarray, shape (nel, 24, 24)
        Symmetric stiffness matrices, node-major DOF order.
    """
    x = _as_coords(x)
    nel = x.shape[0]
    lam, mu = lame_parameters(_per_element(E, nel), _per_element(nu, nel))
    K = np.empty((nel, 24, 24))
    # blocks of elements bound the temporary memory
    for s in range(0, nel, _BLOCK):
        e = slice(s, min(s + _BLOCK, nel))
        grad, wdet = hex8_jacobians(x[e])
        n = grad.shape[0]
        # gg[a, i, b, j] = sum_q w_q det J_q g_qai g_qbj, as one batched matrix product
        gw = (grad * wdet[:, :, None, None]).reshape(n, 8, 24)
        gg = np.matmul(gw.transpose(0, 2, 1), grad.reshape(n, 8, 24)).reshape(n, 8, 3, 8, 3)
        m = mu[e, None, None, None, None]
        Ke = m * gg.transpose(0, 1, 4, 3, 2)                       # mu g_aj g_bi
        mdot = mu[e, None, None] * np.einsum("eaibi->eab", gg)      # mu g_a . g_b
        for i in range(3):
            Ke[:, :, i, :, i] += mdot
        if bbar:
            vol = wdet.sum(axis=1)
            gbar = (np.einsum("eq,eqaj->eaj", wdet, grad) / vol[:, None, None]).reshape(n, 24)
            kappa_v = (lam[e] + 2.0 * mu[e] / 3.0) * vol
            Ke -= (2.0 / 3.0) * m * gg
            Ke = Ke.reshape(n, 24, 24)
            Ke += kappa_v[:, None, None] * gbar[:, :, None] * gbar[:, None, :]
        else:
            Ke += lam[e, None, None, None, None] * gg
            Ke = Ke.reshape(n, 24, 24)
        K[e] = 0.5 * (Ke + Ke.transpose(0, 2, 1))
    return K


def _scalar_mass(x: np.ndarray, rho: ArrayLike) -> np.ndarray:
    """Consistent scalar mass ``rho * int N_a N_b dV``, shape (nel, 8, 8)."""
    _, wdet = hex8_jacobians(x)
    rw = _per_element(rho, x.shape[0])[:, None] * wdet
    return np.einsum("eq,qa,qb->eab", rw, _N, _N)


def hex8_lumped_mass_diagonal(x: ArrayLike, rho: ArrayLike) -> np.ndarray:
    """Row-sum lumped mass of hexahedra, diagonal only.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).
    rho
        Densities (kg/m^3), shape (nel,) or scalar.

    Returns
    -------
    ndarray, shape (nel, 24)
        Diagonal of the lumped mass matrix, node-major DOF order.
    """
    x = _as_coords(x)
    return np.repeat(_scalar_mass(x, rho).sum(axis=2), 3, axis=1)


def hex8_mass(x: ArrayLike, rho: ArrayLike, lumped: bool = False) -> np.ndarray:
    """Element mass matrices of hexahedra.

    The consistent mass uses 2x2x2 Gauss integration, which is exact for trilinear
    parallelepipeds (constant Jacobian, integrand biquadratic per direction).

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).
    rho
        Densities (kg/m^3), shape (nel,) or scalar.
    lumped
        Return the row-sum lumped (diagonal) matrices instead of the consistent ones.

    Returns
    -------
    ndarray, shape (nel, 24, 24)
        Node-major DOF order.
    """
    x = _as_coords(x)
    if lumped:
        d = hex8_lumped_mass_diagonal(x, rho)
        M = np.zeros(d.shape + (24,))
        idx = np.arange(24)
        M[:, idx, idx] = d
        return M
    m = _scalar_mass(x, rho)
    return np.einsum("eab,ij->eaibj", m, np.eye(3)).reshape(-1, 24, 24)
