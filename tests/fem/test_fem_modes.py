"""Mass normalisation of mode shapes, including repeated eigenvalues."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la
from fem_tools import beam_matrices, line_mesh

from railvib_hpc.fem import lowest_modes, mass_normalise

EPS = np.finfo(float).eps
# square section: the two bending planes coincide -> every bending frequency is double
SQUARE = dict(E=210e9, G=80.77e9, A=0.01, Iyy=8.333e-6, Izz=8.333e-6, J=1.406e-5,
              ky=5 / 6, kz=5 / 6, rho=7850.0)


def square_cantilever(n: int = 12):
    pts, lines = line_mesh([0, 0, 0], [3.0, 0, 0], n)
    K, M = beam_matrices(pts, lines, SQUARE)
    free = np.arange(6, 6 * (n + 1))
    return K[free][:, free].toarray(), M[free][:, free].toarray()


def check_modal(phi, K, M, lam):
    m = len(lam)
    assert np.abs(phi.T @ M @ phi - np.eye(m)).max() < 1e3 * EPS
    kk = phi.T @ K @ phi
    # relative to the largest eigenvalue of the set (round-off of K products)
    assert np.abs(kk - np.diag(lam)).max() < 1e4 * EPS * lam.max()


def test_mass_normalise_repeated_eigenvalues():
    K, M = square_cantilever()
    lam, phi = la.eigh(K, M, subset_by_index=[0, 5])
    assert abs(lam[1] / lam[0] - 1) < 1e-10          # the double first bending mode
    # non-orthogonal, badly scaled basis of the same eigenspaces
    C = np.diag([3.0, 0.2, 7.0, 1.5, 0.01, 40.0])
    C[0, 1] = 0.8
    C[2, 3] = -2.0
    lam_pairs = lam.copy()
    lam_pairs[[0, 1]] = lam[0:2].mean()
    lam_pairs[[2, 3]] = lam[2:4].mean()
    psi = mass_normalise(phi @ C, M)
    check_modal(psi, K, M, lam_pairs)
    # degenerate pairs: the two vectors span the original eigenspace
    for i, j in ((0, 1), (2, 3)):
        proj = phi[:, [i, j]].T @ M @ psi[:, [i, j]]
        assert np.allclose(np.abs(la.svdvals(proj)), 1.0, atol=1e-9)


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
    assert np.allclose(lam, lam_ref, rtol=1e-9)
    check_modal(phi, K, M, lam)
