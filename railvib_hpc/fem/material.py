"""Linear isotropic elasticity in Voigt notation.

Voigt order is ``xx, yy, zz, yz, xz, xy`` with engineering shear strains
(``gamma_yz = 2 eps_yz`` ...), so that ``sigma = D @ eps``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def lame_parameters(E: ArrayLike, nu: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Lame constants ``(lambda, mu)`` from Young's modulus and Poisson's ratio.

    Parameters
    ----------
    E
        Young's modulus (Pa), scalar or array.
    nu
        Poisson's ratio, ``-1 < nu < 0.5``, broadcastable with ``E``.

    Returns
    -------
    lam, mu : ndarray
        First Lame constant and shear modulus (Pa), broadcast shape of the inputs.
    """
    E = np.asarray(E, dtype=float)
    nu = np.asarray(nu, dtype=float)
    if np.any(nu <= -1.0) or np.any(nu >= 0.5):
        raise ValueError("Poisson's ratio must satisfy -1 < nu < 0.5")
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    return lam, mu


def isotropic_elasticity_batch(E: ArrayLike, nu: ArrayLike) -> np.ndarray:
    """Isotropic Voigt elasticity matrices for arrays of material constants.

    Parameters
    ----------
    E
        Young's moduli (Pa), shape (nel,) or scalar.
    nu
        Poisson's ratios, broadcastable with ``E``.

    Returns
    -------
    ndarray, shape (nel, 6, 6)
        ``D`` with ``sigma = D @ eps``; ``nel`` is the broadcast size of ``E`` and ``nu``
        (1 for scalars).
    """
    lam, mu = lame_parameters(E, nu)
    lam, mu = np.broadcast_arrays(np.atleast_1d(lam), np.atleast_1d(mu))
    D = np.zeros(lam.shape + (6, 6))
    D[:, :3, :3] = lam[:, None, None]
    idx = np.arange(3)
    D[:, idx, idx] += 2.0 * mu[:, None]
    D[:, idx + 3, idx + 3] = mu[:, None]
    return D


def isotropic_elasticity(E: float, nu: float) -> np.ndarray:
    """Isotropic Voigt elasticity matrix.

    Parameters
    ----------
    E
        Young's modulus (Pa).
    nu
        Poisson's ratio.

    Returns
    -------
    ndarray, shape (6, 6)
        ``D`` with ``sigma = D @ eps`` (order xx, yy, zz, yz, xz, xy; engineering shear).
    """
    return isotropic_elasticity_batch(float(E), float(nu))[0]
