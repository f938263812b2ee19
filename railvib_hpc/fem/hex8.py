"""Batched kernels of the 8-node trilinear hexahedron (ANSYS SOLID185-like).

Node order is gmsh/VTK: reference corners (-1,-1,-1), (1,-1,-1), (1,1,-1), (-1,1,-1),
(-1,-1,1), (1,-1,1), (1,1,1), (-1,1,1). Element DOFs are node-major,
``[u0x, u0y, u0z, u1x, ..., u7z]`` (24 per element). All kernels work on whole
batches of elements, ``x`` of shape (nel, 8, 3), without Python loops over elements
(the stiffness only walks over blocks of 8192 elements to bound temporary memory).

The stiffness uses 2x2x2 Gauss integration in one of three formulations:

``"bbar"`` (default)
    Hughes' B-bar treatment of the volumetric strain (ANSYS SOLID185 KEYOPT(2)=0,
    "selective reduced integration"): the dilatational part of the strain-displacement
    matrix is replaced by its volume average over the element, which removes volumetric
    locking for nearly incompressible materials while keeping full rank. In bending it
    also averages the dilatation of the bending strain away, so a slab or beam one
    element thick is too flexible (1.2-2.1x the cantilever deflection in the tests).
``"incompatible"``
    Wilson's incompatible modes with Taylor's correction (Taylor, Beresford & Wilson
    1976; ANSYS SOLID185 KEYOPT(2)=3, "simplified enhanced strain"): nine internal
    bubble displacements ``(1 - xi_k^2) alpha_ki`` enrich the strain and are condensed
    out per element. Represents pure bending of rectangular elements exactly, so one
    element through a slab's thickness bends correctly; passes the patch test on
    distorted meshes (the bubble gradients use the centre Jacobian, scaled by
    ``det J_0 / det J``, so they integrate to zero).
``"full"``
    Plain full integration (locks in bending and for ``nu -> 0.5``; for tests).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .material import isotropic_elasticity, isotropic_elasticity_batch, lame_parameters
from .reference import (
    GAUSS_POINTS,
    GAUSS_VALUES,
    GAUSS_WEIGHTS,
    ElementGeometryError,
    hex_centre_jacobians,
    hex_gauss_geometry,
    hex_volumes,
)

__all__ = [
    "FORMULATIONS",
    "ElementGeometryError",
    "hex8_jacobians",
    "hex8_lumped_mass_diagonal",
    "hex8_mass",
    "hex8_stiffness",
    "hex8_strain_displacement",
    "hex8_volume",
    "isotropic_elasticity",
    "isotropic_elasticity_batch",
]

_XI, _W = GAUSS_POINTS, GAUSS_WEIGHTS
_N = GAUSS_VALUES                   # (8 points, 8 nodes)
#: Elements per block in :func:`hex8_stiffness` (bounds temporary memory to ~100 MB).
_BLOCK = 8192
#: Stiffness formulations of :func:`hex8_stiffness`.
FORMULATIONS = ("bbar", "incompatible", "full")


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
    ElementGeometryError
        (a ``ValueError``) If the Jacobian determinant is not positive at some Gauss point
        (inverted or degenerate element).
    """
    grad, det = hex_gauss_geometry(_as_coords(x))
    bad = np.flatnonzero(np.any(~(det > 0.0), axis=1))
    if bad.size:
        raise ElementGeometryError(f"{bad.size} hexahedra have a non-positive Jacobian "
                                   f"(first: element {bad[0]})")
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

    Raises
    ------
    ElementGeometryError
        For inverted or degenerate elements (:func:`railvib_hpc.fem.reference.hex_volumes`
        returns signed volumes without checking).
    """
    x = _as_coords(x)
    volumes = hex_volumes(x)
    bad = np.flatnonzero(~(volumes > 0.0))
    if bad.size:
        raise ElementGeometryError(f"{bad.size} hexahedra have a non-positive volume "
                                   f"(first: element {bad[0]})")
    return volumes


def _strain_matrix(grad: np.ndarray) -> np.ndarray:
    """Voigt strain-displacement matrices from gradients (..., n, 3) -> (..., 6, n, 3)."""
    B = np.zeros(grad.shape[:-2] + (6,) + grad.shape[-2:])
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


def _incompatible_gradients(x: np.ndarray, det: np.ndarray) -> np.ndarray:
    """Taylor-corrected physical gradients of the three bubble modes ``1 - xi_k^2``.

    ``g[e, q, k, j] = det J_0 / det J_q * (J_0^-1)_{jk} * (-2 xi_qk)``: the reference
    gradient is mapped with the centre Jacobian ``J_0`` and scaled so that every
    gradient integrates to zero over the element (patch test).

    ``det`` (nel, 8) are the Jacobian determinants at the Gauss points.

    Returns
    -------
    ndarray, shape (nel, 8, 3, 3)
    """
    J0 = hex_centre_jacobians(x)                              # (nel, 3, 3), J0[i, j] = dx_j/dxi_i
    inv0 = np.linalg.inv(J0)                                  # inv0[j, i]: d xi_i / d x_j
    det0 = np.linalg.det(J0)
    # g[e, q, k, j] = det0/det_q * inv0[e, j, k] * (-2 xi_qk)
    return ((det0[:, None] / det)[:, :, None, None]
            * inv0.transpose(0, 2, 1)[:, None, :, :] * (-2.0 * _XI)[None, :, :, None])


def _condense_incompatible(x: np.ndarray, grad: np.ndarray, wdet: np.ndarray,
                           D: np.ndarray) -> np.ndarray:
    """``K_ua K_aa^-1 K_au``: what the condensed bubble modes remove from ``K_uu``."""
    n = x.shape[0]
    B = _strain_matrix(grad).reshape(n, 8, 6, 24)
    G = _strain_matrix(_incompatible_gradients(x, wdet / _W)).reshape(n, 8, 6, 9)
    DG = np.matmul(D[:, None], G) * wdet[:, :, None, None]          # (n, 8, 6, 9)
    DG = DG.reshape(n, 48, 9)
    Kua = np.matmul(B.reshape(n, 48, 24).transpose(0, 2, 1), DG)      # sum over q and i
    Kaa = np.matmul(G.reshape(n, 48, 9).transpose(0, 2, 1), DG)
    return np.matmul(Kua, np.linalg.solve(Kaa, Kua.transpose(0, 2, 1)))


def hex8_stiffness(x: ArrayLike, E: ArrayLike, nu: ArrayLike, bbar: bool = True,
                   formulation: str | None = None) -> np.ndarray:
    """Element stiffness matrices of isotropic linear-elastic hexahedra.

    Equivalent to ``sum_q w_q det J_q B_q^T D B_q`` with the (B-bar) strain-displacement
    matrices of :func:`hex8_strain_displacement`, but evaluated from the shape-function
    gradients ``g`` directly, which is several times cheaper. For isotropic material the
    node-block ``(a, b)``, component ``(i, j)`` entry is::

        full:  int mu (g_a . g_b delta_ij + g_aj g_bi) + lambda g_ai g_bj dV
        B-bar: int mu (g_a . g_b delta_ij + g_aj g_bi) - 2 mu / 3 g_ai g_bj dV
               + kappa V gbar_ai gbar_bj

    (deviatoric part from ``B``, dilatation from the volume-averaged gradients ``gbar``;
    ``kappa = lambda + 2 mu / 3`` is the bulk modulus). The incompatible-modes
    formulation subtracts ``K_ua K_aa^-1 K_au`` from the full-integration matrix
    (static condensation of the nine bubble DOFs, see the module docstring).

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).
    E
        Young's moduli (Pa), shape (nel,) or scalar.
    nu
        Poisson's ratios, shape (nel,) or scalar.
    bbar
        Shorthand kept for the two classical cases: ``True`` is ``"bbar"``, ``False``
        ``"full"``; ignored when ``formulation`` is given.
    formulation
        ``"bbar"``, ``"incompatible"`` or ``"full"`` (see the module docstring).

    Returns
    -------
    ndarray, shape (nel, 24, 24)
        Symmetric stiffness matrices, node-major DOF order.

    Raises
    ------
    ValueError
        For an unknown ``formulation``.
    """
    if formulation is None:
        formulation = "bbar" if bbar else "full"
    if formulation not in FORMULATIONS:
        raise ValueError(f"hex8 formulation must be one of {FORMULATIONS}, got {formulation!r}")
    bbar = formulation == "bbar"
    x = _as_coords(x)
    nel = x.shape[0]
    E, nu = _per_element(E, nel), _per_element(nu, nel)
    lam, mu = lame_parameters(E, nu)
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
            if formulation == "incompatible":
                D = isotropic_elasticity_batch(E[e], nu[e])
                Ke -= _condense_incompatible(x[e], grad, wdet, D)
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
