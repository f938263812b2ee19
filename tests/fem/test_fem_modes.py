"""Mass normalisation of mode shapes, including repeated eigenvalues.

Tolerances: :mod:`railvib_hpc.tolerances` (round-off from the size and the conditioning of
the pencil, subspaces for repeated eigenvalues)."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
from fem_tools import beam_matrices, line_mesh

from railvib_hpc import tolerances as tol
from railvib_hpc.fem import lowest_modes, mass_normalise

# square section: the two bending planes coincide -> every bending frequency is double
SQUARE = dict(E=210e9, G=80.77e9, A=0.01, Iyy=8.333e-6, Izz=8.333e-6, J=1.406e-5,
              ky=5 / 6, kz=5 / 6, rho=7850.0)


def square_cantilever(n: int = 12):
    pts, lines = line_mesh([0, 0, 0], [3.0, 0, 0], n)
    K, M = beam_matrices(pts, lines, SQUARE)
    free = np.arange(6, 6 * (n + 1))
    return K[free][:, free].toarray(), M[free][:, free].toarray()


def check_modal(phi, K, M, lam):
    """Phi^T M Phi = I and Phi^T K Phi = diag(lam) to the round-off of the products, plus
    the error of the reference eigenvalues ``lam`` (LAPACK, normwise)."""
    m = len(lam)
    assert np.all(np.abs(phi.T @ M @ phi - np.eye(m)) <= tol.product_error(M, phi))
    kk = phi.T @ K @ phi
    d_lam = lam * tol.eigenvalue_rtol(tol.normwise_condition(lam, tol.lambda_max(K, M)),
                                      len(K), computations=1)
    assert np.all(np.abs(kk - np.diag(lam)) <= tol.product_error(K, phi) + np.diag(d_lam))


def test_mass_normalise_repeated_eigenvalues():
    K, M = square_cantilever()
    lam, phi = la.eigh(K, M, subset_by_index=[0, 5])
    lam_max, n = tol.lambda_max(K, M), len(K)
    # the double first bending mode, split by round-off only (LAPACK: ~ u lambda_max)
    split = tol.eigenvalue_rtol(tol.normwise_condition(lam[0], lam_max), n, computations=1)
    assert abs(lam[1] / lam[0] - 1) <= split
    # non-orthogonal, badly scaled basis of the same eigenspaces
    C = np.diag([3.0, 0.2, 7.0, 1.5, 0.01, 40.0])
    C[0, 1] = 0.8
    C[2, 3] = -2.0
    lam_pairs = lam.copy()
    lam_pairs[[0, 1]] = lam[0:2].mean()
    lam_pairs[[2, 3]] = lam[2:4].mean()
    psi = mass_normalise(phi @ C, M)
    check_modal(psi, K, M, lam_pairs)
    # degenerate pairs: the two vectors span the original eigenspace (Davis-Kahan: angle
    # <= round-off / gap to the neighbouring eigenvalues)
    for i, j in ((0, 1), (2, 3)):
        gap = min(lam[j + 1] - lam[j], lam[i] - lam[i - 1] if i else np.inf)
        sines = tol.subspace_sines(phi[:, [i, j]], psi[:, [i, j]], M)
        assert sines.max() <= tol.subspace_tolerance(gap, lam_max, n)


def test_mass_normalise_rayleigh_ritz_with_k():
    K, M = square_cantilever()
    lam, phi = la.eigh(K, M, subset_by_index=[0, 5])
    mix = np.random.default_rng(0).normal(size=(6, 6))
    psi = mass_normalise(phi @ mix, M, K)
    check_modal(psi, K, M, lam)


def test_lowest_modes_shift_invert_is_mass_normalised():
    K, M = square_cantilever(40)
    f, phi = lowest_modes(K, M, 6, sigma=-1.0, dense_below=0)
    lam_ref = la.eigh(K, M, eigvals_only=True, subset_by_index=[0, 5])
    lam = (2 * np.pi * f) ** 2
    # ARPACK (tol = machine precision) on a SuperLU factor vs LAPACK: both normwise stable
    cond = tol.normwise_condition(lam_ref, tol.lambda_max(K, M))
    assert np.all(np.abs(lam / lam_ref - 1) <= tol.eigenvalue_rtol(cond, len(K)))
    check_modal(phi, K, M, lam)
