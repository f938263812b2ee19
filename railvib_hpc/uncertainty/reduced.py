"""The parametric reduced model of the uncertainty study (pure numpy/scipy, plain values).

The full model's stiffness and mass are split into the parts a sample scales,
``K(p) = K_rest + sum_g s_g(p) K_g`` and ``M(p) = M_rest + sum_g t_g(p) M_g`` (``g``: a
material group or a rail-pad direction; ``s_g = E_g / E_g0`` or ``k / k0``, ``t_g =
rho_g / rho_g0``), each part projected once on an M-orthonormal basis ``V`` (the nominal
modes augmented with the static sensitivity vectors ``K0^-1 K_g Phi``, ``K0^-1 M_g Phi``
of the varied parts). A sample then costs the dense eigenproblem of
:func:`reduced_matrices` (``m_aug`` x ``m_aug``, :func:`reduced_eigenpairs`), whose Ritz
vectors ``V Y`` are checked against the sample's own full matrices
(:mod:`railvib_hpc.modal.reduced`).

This module holds the dense algebra only; what the parts are and how they are projected
is :mod:`railvib_hpc.modal.reduced`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

#: ``uncertainty.model``: every sample solved in full, or by the reduced model.
MODELS = ("full", "reduced")
#: Default ``uncertainty.reduced_tol``, the largest relative residual of an accepted
#: reduced mode. Measured on the coarse thesis model (docs/uncertainty.md, 'The reduced
#: model'): residuals up to 0.022 went with frequency errors below 4e-5, probe peaks
#: within 0.4 % and metrics within 5.6 % of the full solves; 0.106 with metrics off by 9 %.
REDUCED_TOL = 3e-2
#: Relative size (to the largest) below which an eigenvalue of the augmented basis's mass
#: Gram matrix counts as a linear dependence and its direction is dropped: 1e-10 keeps the
#: basis's M-orthonormality error at ~1e-16 / 1e-10 ~ 1e-6 at worst after one
#: re-orthonormalisation (the Gram matrix's condition bounds the loss, Björck, Numerical
#: Methods for Least Squares Problems, SIAM 1996, sec. 2.4).
DEPENDENCE_RTOL = 1e-10


def orthonormalising_map(gram: np.ndarray, rtol: float = DEPENDENCE_RTOL) -> np.ndarray:
    """The (k, r) map ``C`` with ``C^T G C = I`` on the well-conditioned part of ``G``
    (after scaling its columns to unit norm).

    Parameters
    ----------
    gram
        ``V^T M V`` (k, k) of the augmented basis, symmetric positive semi-definite.
    rtol
        Directions with an eigenvalue below ``rtol`` times the largest are dropped.

    Returns
    -------
    numpy.ndarray
        ``C`` (k, r), r <= k: ``V C`` is M-orthonormal.
    """
    # columns scaled to unit norm first: the sensitivity vectors' norms differ by orders
    # of magnitude (a stiff pad's), which would hide the others below rtol
    d = 1.0 / np.sqrt(np.maximum(np.diag(gram), np.finfo(float).tiny))
    w, u = np.linalg.eigh(0.5 * (gram + gram.T) * d[:, None] * d[None, :])
    keep = w > rtol * w.max()
    return d[:, None] * u[:, keep] / np.sqrt(w[keep])


def reduced_matrices(rest_k: np.ndarray, rest_m: np.ndarray, k_parts: np.ndarray,
                     m_parts: np.ndarray, s: np.ndarray, t: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """``K_r = K_rest + sum_g s_g K_g``, ``M_r = M_rest + sum_g t_g M_g``.

    Parameters
    ----------
    rest_k, rest_m
        (r, r) projected parts that no parameter scales.
    k_parts, m_parts
        (G, r, r) projected stiffness and mass of each scaled part.
    s, t
        (G,) stiffness and mass factors of the sample.
    """
    kr = rest_k + np.tensordot(np.asarray(s, float), k_parts, axes=1)
    mr = rest_m + np.tensordot(np.asarray(t, float), m_parts, axes=1)
    return 0.5 * (kr + kr.T), 0.5 * (mr + mr.T)


def reduced_eigenpairs(kr: np.ndarray, mr: np.ndarray, n: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` lowest eigenpairs of ``K_r y = lambda M_r y`` (``Y^T M_r Y = I``).

    Raises
    ------
    ValueError
        When the reduced space holds fewer than ``n`` directions.
    """
    r = kr.shape[0]
    if n > r:
        raise ValueError(f"the reduced basis has {r} directions, fewer than the {n} modes "
                         "asked for")
    lam, y = scipy.linalg.eigh(kr, mr, subset_by_index=[0, n - 1])
    return lam, y


def relative_residuals(r_sq: np.ndarray, k_phi_sq: np.ndarray) -> np.ndarray:
    """``||K phi - lambda M phi|| / ||K phi||`` per pair from the global sums
    ``||r_j||^2`` and ``||K phi_j||^2`` (n,)."""
    return np.sqrt(r_sq / np.maximum(k_phi_sq, np.finfo(float).tiny))
