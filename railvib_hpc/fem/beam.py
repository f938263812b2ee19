"""Batched 2-node 3D Timoshenko beam (ANSYS BEAM188-like, 6 DOF per node).

Element DOFs, node-major: ``[ux, uy, uz, rx, ry, rz]`` of node 0, then of node 1.

Local axes
----------
* ``x'`` runs along the element axis, from node 0 to node 1.
* ``y'`` is the reference vector ``up`` made orthogonal to ``x'`` (Gram-Schmidt).
* ``z' = x' x y'`` (right-handed).

Section properties
------------------
``Iyy`` (with shear coefficient ``ky``) governs bending in the ``x'y'`` plane, i.e.
deflection along ``y'`` and rotation about ``z'``. ``Izz`` (with ``kz``) governs
bending in the ``x'z'`` plane (deflection along ``z'``, rotation about ``y'``). With
``up`` = global z (vertical) this is the model convention of
:mod:`railvib_hpc.schema`: ``iyy`` for bending in the vertical plane, ``izz`` for
bending in the horizontal plane. Note that this is *not* the textbook convention where
``Iyy`` means "about y'".

Interpolation
-------------
The bending stiffness is the exact ("interdependent interpolation", Przemieniecki
1968) Timoshenko stiffness with shear-deformation factor
``Phi = 12 E I / (k G A L^2)``: one element reproduces the static response to end loads
exactly. The consistent mass integrates the same interdependent shape functions
(Friedman & Kosmatka 1993) with a 4-point Gauss rule (exact, the integrand is a
polynomial of degree 6). Axial and torsional fields are linear.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .quadrature import gauss_legendre

__all__ = [
    "beam_frames",
    "beam_mass",
    "beam_mass_local",
    "beam_stiffness",
    "beam_stiffness_local",
    "beam_transformation",
    "shear_deformation_factors",
    "shear_modulus",
    "timoshenko_shape_functions",
]

#: Local DOFs of the x'y' bending plane (v, rz) and the x'z' plane (w, ry) of both nodes.
_PLANE_Y = np.array([1, 5, 7, 11])
_PLANE_Z = np.array([2, 4, 8, 10])
#: In the x'z' plane ry = -dw/dx, so the plane-xy matrices are conjugated by this sign.
_SIGN_Z = np.array([1.0, -1.0, 1.0, -1.0])


def _per_element(value: ArrayLike, nel: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=float), (nel,))


def shear_modulus(E: ArrayLike, nu: ArrayLike) -> np.ndarray:
    """Shear modulus ``G = E / (2 (1 + nu))`` of an isotropic material.

    Parameters
    ----------
    E
        Young's modulus (Pa).
    nu
        Poisson's ratio.

    Returns
    -------
    ndarray
        Shear modulus (Pa), broadcast shape of the inputs.
    """
    return np.asarray(E, dtype=float) / (2.0 * (1.0 + np.asarray(nu, dtype=float)))


def beam_frames(x: ArrayLike, up: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Lengths and local frames of 2-node beam elements.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 2, 3).
    up
        Reference vectors defining ``y'``, shape (nel, 3) or (3,).

    Returns
    -------
    L : ndarray, shape (nel,)
        Element lengths.
    R : ndarray, shape (nel, 3, 3)
        Rotation matrices whose rows are the unit vectors ``x', y', z'`` in global
        coordinates, so that ``v_local = R @ v_global``.

    Raises
    ------
    ValueError
        For zero-length elements or a reference vector (nearly) parallel to the axis.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 3 or x.shape[1:] != (2, 3):
        raise ValueError(f"beam coordinates must have shape (nel, 2, 3), got {x.shape}")
    d = x[:, 1] - x[:, 0]
    L = np.linalg.norm(d, axis=1)
    if np.any(L <= 0.0):
        raise ValueError("beam elements of zero length")
    e1 = d / L[:, None]
    up = np.broadcast_to(np.asarray(up, dtype=float), d.shape)
    e2 = up - np.einsum("ei,ei->e", up, e1)[:, None] * e1
    n2 = np.linalg.norm(e2, axis=1)
    if np.any(n2 <= 1e-8 * np.linalg.norm(up, axis=1)):
        raise ValueError("beam reference vector 'up' is parallel to an element axis")
    e2 = e2 / n2[:, None]
    e3 = np.cross(e1, e2)
    return L, np.stack([e1, e2, e3], axis=1)


def beam_transformation(R: np.ndarray) -> np.ndarray:
    """Block-diagonal 12x12 transformation ``u_local = T @ u_global``.

    Parameters
    ----------
    R
        Local frames, shape (nel, 3, 3) (rows are the local unit vectors).

    Returns
    -------
    ndarray, shape (nel, 12, 12)
    """
    return np.einsum("ab,eij->eaibj", np.eye(4), R).reshape(-1, 12, 12)


def shear_deformation_factors(x: ArrayLike, E: ArrayLike, G: ArrayLike, A: ArrayLike,
                              Iyy: ArrayLike, Izz: ArrayLike, ky: ArrayLike,
                              kz: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Timoshenko shear-deformation factors ``Phi = 12 E I / (k G A L^2)`` of both planes.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 2, 3).
    E, G
        Young's and shear moduli (Pa), shape (nel,) or scalar.
    A
        Cross-section area (m^2).
    Iyy, Izz
        Second moments of area of the ``x'y'`` and ``x'z'`` bending planes (m^4).
    ky, kz
        Shear coefficients of the two planes (shear area = ``k A``).

    Returns
    -------
    phi_y, phi_z : ndarray, shape (nel,)
    """
    x = np.asarray(x, dtype=float)
    L = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    nel = L.shape[0]
    E, G, A, Iyy, Izz, ky, kz = (_per_element(v, nel) for v in (E, G, A, Iyy, Izz, ky, kz))
    return 12.0 * E * Iyy / (ky * G * A * L**2), 12.0 * E * Izz / (kz * G * A * L**2)


def timoshenko_shape_functions(s: ArrayLike, L: ArrayLike, phi: ArrayLike
                               ) -> tuple[np.ndarray, np.ndarray]:
    """Interdependent Timoshenko shape functions of one bending plane.

    Plane DOFs are ``(v0, psi0, v1, psi1)`` with deflection ``v`` and cross-section
    rotation ``psi`` (``psi = dv/dx`` without shear deformation).

    Parameters
    ----------
    s
        Normalised positions ``x / L`` in [0, 1], shape (q,).
    L
        Element lengths, shape (nel,).
    phi
        Shear-deformation factors, shape (nel,).

    Returns
    -------
    Nv : ndarray, shape (nel, q, 4)
        Deflection shape functions.
    Npsi : ndarray, shape (nel, q, 4)
        Rotation shape functions.
    """
    s = np.asarray(s, dtype=float)[None, :]
    L = np.atleast_1d(np.asarray(L, dtype=float))[:, None]
    f = np.atleast_1d(np.asarray(phi, dtype=float))[:, None]
    c = 1.0 / (1.0 + f)
    s2, s3 = s * s, s * s * s
    Nv = np.stack([c * (2 * s3 - 3 * s2 - f * s + 1 + f),
                   c * L * (s3 - (2 + f / 2) * s2 + (1 + f / 2) * s),
                   -c * (2 * s3 - 3 * s2 - f * s),
                   c * L * (s3 - (1 - f / 2) * s2 - (f / 2) * s)], axis=-1)
    Npsi = np.stack([c * 6 * (s2 - s) / L,
                     c * (3 * s2 - (4 + f) * s + 1 + f),
                     -c * 6 * (s2 - s) / L,
                     c * (3 * s2 - (2 - f) * s)], axis=-1)
    return Nv, Npsi


def _plane_stiffness(L: np.ndarray, EI: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Exact Timoshenko bending stiffness of one plane, (v0, psi0, v1, psi1) -> (nel, 4, 4)."""
    one = np.ones_like(L)
    k = np.stack([
        np.stack([12 * one, 6 * L, -12 * one, 6 * L], axis=-1),
        np.stack([6 * L, (4 + phi) * L**2, -6 * L, (2 - phi) * L**2], axis=-1),
        np.stack([-12 * one, -6 * L, 12 * one, -6 * L], axis=-1),
        np.stack([6 * L, (2 - phi) * L**2, -6 * L, (4 + phi) * L**2], axis=-1),
    ], axis=-2)
    return (EI / ((1.0 + phi) * L**3))[:, None, None] * k


def _bar(L: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    return (stiffness / L)[:, None, None] * np.array([[1.0, -1.0], [-1.0, 1.0]])


def _bar_mass(L: np.ndarray, density: np.ndarray) -> np.ndarray:
    return (density * L / 6.0)[:, None, None] * np.array([[2.0, 1.0], [1.0, 2.0]])


def _scatter(out: np.ndarray, idx: np.ndarray, block: np.ndarray) -> None:
    out[:, idx[:, None], idx[None, :]] += block


def beam_stiffness_local(L: ArrayLike, E: ArrayLike, G: ArrayLike, A: ArrayLike,
                         Iyy: ArrayLike, Izz: ArrayLike, J: ArrayLike, ky: ArrayLike,
                         kz: ArrayLike) -> np.ndarray:
    """Timoshenko beam stiffness matrices in local coordinates.

    Parameters
    ----------
    L
        Element lengths (m), shape (nel,).
    E, G
        Young's and shear moduli (Pa), shape (nel,) or scalar.
    A
        Area (m^2).
    Iyy, Izz
        Second moments of area for bending in the ``x'y'`` and ``x'z'`` planes (m^4).
    J
        Torsion constant (m^4).
    ky, kz
        Shear coefficients of the ``x'y'`` and ``x'z'`` planes.

    Returns
    -------
    ndarray, shape (nel, 12, 12)
    """
    L = np.atleast_1d(np.asarray(L, dtype=float))
    nel = L.shape[0]
    E, G, A, Iyy, Izz, J, ky, kz = (_per_element(v, nel)
                                    for v in (E, G, A, Iyy, Izz, J, ky, kz))
    K = np.zeros((nel, 12, 12))
    _scatter(K, np.array([0, 6]), _bar(L, E * A))
    _scatter(K, np.array([3, 9]), _bar(L, G * J))
    phi_y = 12.0 * E * Iyy / (ky * G * A * L**2)
    phi_z = 12.0 * E * Izz / (kz * G * A * L**2)
    _scatter(K, _PLANE_Y, _plane_stiffness(L, E * Iyy, phi_y))
    sz = _SIGN_Z[:, None] * _SIGN_Z[None, :]
    _scatter(K, _PLANE_Z, sz * _plane_stiffness(L, E * Izz, phi_z))
    return K


def _plane_mass(L: np.ndarray, rhoA: np.ndarray, rhoI: np.ndarray, phi: np.ndarray
                ) -> np.ndarray:
    """Consistent translational + rotary mass of one bending plane -> (nel, 4, 4)."""
    p, w = gauss_legendre(4)
    s, w = 0.5 * (p + 1.0), 0.5 * w
    Nv, Npsi = timoshenko_shape_functions(s, L, phi)
    return (np.einsum("e,q,eqa,eqb->eab", rhoA * L, w, Nv, Nv)
            + np.einsum("e,q,eqa,eqb->eab", rhoI * L, w, Npsi, Npsi))


def beam_mass_local(L: ArrayLike, rho: ArrayLike, A: ArrayLike, Iyy: ArrayLike,
                    Izz: ArrayLike, rotary_inertia: bool = True, phi_y: ArrayLike = 0.0,
                    phi_z: ArrayLike = 0.0) -> np.ndarray:
    """Consistent beam mass matrices in local coordinates.

    Parameters
    ----------
    L
        Element lengths (m), shape (nel,).
    rho
        Density (kg/m^3), shape (nel,) or scalar.
    A
        Area (m^2).
    Iyy, Izz
        Second moments of area of the ``x'y'`` and ``x'z'`` bending planes (m^4); they
        give the rotary inertia of the bending rotations and the polar mass moment
        ``rho (Iyy + Izz)`` of torsion.
    rotary_inertia
        Include the rotary inertia of the bending rotations (torsional inertia is always
        included).
    phi_y, phi_z
        Shear-deformation factors (see :func:`shear_deformation_factors`) selecting the
        interdependent interpolation; 0 gives the Euler-Bernoulli (Hermite) mass.

    Returns
    -------
    ndarray, shape (nel, 12, 12)
    """
    L = np.atleast_1d(np.asarray(L, dtype=float))
    nel = L.shape[0]
    rho, A, Iyy, Izz, phi_y, phi_z = (_per_element(v, nel)
                                      for v in (rho, A, Iyy, Izz, phi_y, phi_z))
    rot = 1.0 if rotary_inertia else 0.0
    M = np.zeros((nel, 12, 12))
    _scatter(M, np.array([0, 6]), _bar_mass(L, rho * A))
    _scatter(M, np.array([3, 9]), _bar_mass(L, rho * (Iyy + Izz)))
    _scatter(M, _PLANE_Y, _plane_mass(L, rho * A, rot * rho * Iyy, phi_y))
    sz = _SIGN_Z[:, None] * _SIGN_Z[None, :]
    _scatter(M, _PLANE_Z, sz * _plane_mass(L, rho * A, rot * rho * Izz, phi_z))
    return M


def _to_global(T: np.ndarray, K: np.ndarray) -> np.ndarray:
    Kg = np.einsum("eki,ekl,elj->eij", T, K, T, optimize=True)
    return 0.5 * (Kg + Kg.transpose(0, 2, 1))


def beam_stiffness(x: ArrayLike, E: ArrayLike, G: ArrayLike, A: ArrayLike, Iyy: ArrayLike,
                   Izz: ArrayLike, J: ArrayLike, ky: ArrayLike, kz: ArrayLike,
                   up: ArrayLike) -> np.ndarray:
    """Timoshenko beam stiffness matrices in global coordinates.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 2, 3).
    E, G
        Young's and shear moduli (Pa), shape (nel,) or scalar (``G`` from
        :func:`shear_modulus` for isotropic material).
    A
        Area (m^2).
    Iyy, Izz
        Second moments of area for bending in the ``x'y'`` plane (vertical plane when
        ``up`` is vertical) and in the ``x'z'`` plane (m^4).
    J
        Torsion constant (m^4).
    ky, kz
        Shear coefficients paired with ``Iyy`` and ``Izz``.
    up
        Reference vectors defining the local ``y'`` axis, shape (nel, 3) or (3,).

    Returns
    -------
    ndarray, shape (nel, 12, 12)
        Node-major DOF order ``[ux, uy, uz, rx, ry, rz] * 2``.
    """
    L, R = beam_frames(x, up)
    K = beam_stiffness_local(L, E, G, A, Iyy, Izz, J, ky, kz)
    return _to_global(beam_transformation(R), K)


def beam_mass(x: ArrayLike, rho: ArrayLike, A: ArrayLike, Iyy: ArrayLike, Izz: ArrayLike,
              up: ArrayLike, rotary_inertia: bool = True, *, phi_y: ArrayLike = 0.0,
              phi_z: ArrayLike = 0.0) -> np.ndarray:
    """Consistent beam mass matrices in global coordinates.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 2, 3).
    rho
        Density (kg/m^3).
    A
        Area (m^2).
    Iyy, Izz
        Second moments of area of the ``x'y'`` and ``x'z'`` bending planes (m^4).
    up
        Reference vectors defining the local ``y'`` axis, shape (nel, 3) or (3,).
    rotary_inertia
        Include rotary inertia of the bending rotations.
    phi_y, phi_z
        Shear-deformation factors from :func:`shear_deformation_factors`, making the
        mass consistent with the Timoshenko stiffness; 0 (default) gives Hermite shape
        functions.

    Returns
    -------
    ndarray, shape (nel, 12, 12)
    """
    L, R = beam_frames(x, up)
    M = beam_mass_local(L, rho, A, Iyy, Izz, rotary_inertia, phi_y, phi_z)
    return _to_global(beam_transformation(R), M)
