"""Eigenvector normalisation and a small generalized-eigenvalue helper."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["lowest_modes", "mass_normalise"]


def _dense(A: np.ndarray | sp.spmatrix) -> np.ndarray:
    return A.toarray() if sp.issparse(A) else np.asarray(A, dtype=float)


def mass_normalise(phi: np.ndarray, M: np.ndarray | sp.spmatrix,
                   K: np.ndarray | sp.spmatrix | None = None) -> np.ndarray:
    """Make mode shapes M-orthonormal, ``phi.T @ M @ phi = I``.

    Without ``K`` the columns are orthonormalised symmetrically (Loewdin:
    ``phi (phi^T M phi)^{-1/2}``), which only rescales columns that are already
    M-orthogonal and changes them as little as possible otherwise (e.g. non-orthogonal
    vectors spanning the eigenspace of a repeated eigenvalue). With ``K`` a Rayleigh-Ritz
    step in the span of ``phi`` is done as well, so that ``phi.T @ K @ phi`` is diagonal
    (ascending) to round-off.

    Parameters
    ----------
    phi
        Mode shapes as columns, shape (n, m), linearly independent.
    M
        Mass matrix (n, n), symmetric positive definite on the span of ``phi``.
    K
        Optional stiffness matrix (n, n).

    Returns
    -------
    ndarray, shape (n, m)
    """
    phi = np.asarray(phi, dtype=float)
    if K is not None:
        G = _gram(phi, M)
        Kr = phi.T @ (K @ phi)
        phi = phi @ la.eigh(0.5 * (Kr + Kr.T), G)[1]
    # Loewdin twice: the second pass removes the round-off left by an ill-conditioned basis
    for _ in range(2):
        w, V = la.eigh(_gram(phi, M))
        if w[0] <= 0.0:
            raise ValueError("mode shapes are linearly dependent or M is not positive")
        phi = phi @ (V / np.sqrt(w)) @ V.T
    return phi


def _gram(phi: np.ndarray, M: np.ndarray | sp.spmatrix) -> np.ndarray:
    G = phi.T @ (M @ phi)
    return 0.5 * (G + G.T)


def lowest_modes(K: np.ndarray | sp.spmatrix, M: np.ndarray | sp.spmatrix, n: int,
                 sigma: float = 0.0, dense_below: int = 400
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``n`` eigenpairs of ``K phi = omega^2 M phi``.

    Parameters
    ----------
    K, M
        Stiffness and mass (dense or sparse), symmetric; ``M`` positive definite.
    n
        Number of modes.
    sigma
        Shift (rad^2/s^2) for the shift-invert Lanczos solver; must not be an
        eigenvalue (use a small negative value for free structures).
    dense_below
        Problems with fewer DOFs are solved densely with :func:`scipy.linalg.eigh`.

    Returns
    -------
    freq : ndarray, shape (n,)
        Natural frequencies in Hz (negative round-off eigenvalues give 0).
    phi : ndarray, shape (ndof, n)
        Mass-normalised mode shapes.
    """
    ndof = K.shape[0]
    if ndof < dense_below:
        lam, phi = la.eigh(_dense(K), _dense(M), subset_by_index=[0, n - 1])
    else:
        lam, phi = spla.eigsh(sp.csc_matrix(K), k=n, M=sp.csc_matrix(M), sigma=sigma,
                              which="LM")
        order = np.argsort(lam)
        lam, phi = lam[order], mass_normalise(phi[:, order], M)
    return np.sqrt(np.clip(lam, 0.0, None)) / (2.0 * np.pi), phi
