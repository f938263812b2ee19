"""The derived tolerances of :mod:`railvib_hpc.tolerances` bound what they claim to bound."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from fem_tools import box_mesh, solid_matrices

from railvib_hpc import tolerances


def test_docstring_examples():
    assert doctest.testmod(tolerances).failed == 0


def _column(n: int = 10):
    pts, hexes = box_mesh(1, 1, n, 0.5, 0.5, 5.0)
    K, M = solid_matrices(pts, hexes, 2e8, 0.2, 1850.0)
    free = np.flatnonzero(pts[:, 2] > 0)
    dofs = (3 * free[:, None] + np.arange(3)).ravel()
    return sp.csr_matrix(K[dofs][:, dofs]), sp.csr_matrix(M[dofs][:, dofs])


def test_normwise_bound_covers_a_backward_error_perturbation():
    """Perturb K by u ||K|| in random symmetric directions: every eigenvalue moves by less
    than the derived tolerance, and the low modes move the most in relative terms."""
    K, M = (A.toarray() for A in _column())
    lam = la.eigh(K, M, eigvals_only=True)
    rng = np.random.default_rng(1)
    n = len(K)
    worst = np.zeros(n)
    for _ in range(5):
        E = rng.standard_normal(K.shape)
        E = 0.5 * (E + E.T)
        E *= tolerances.EPS * la.norm(K, 2) / la.norm(E, 2)
        moved = la.eigh(K + E, M, eigvals_only=True)
        worst = np.maximum(worst, np.abs(moved / lam - 1))
    rtol = tolerances.eigenvalue_rtol(tolerances.normwise_condition(lam, lam[-1]), n)
    assert np.all(worst <= rtol)
    assert rtol[0] > 100 * rtol[-1]


@pytest.mark.slow
def test_lambda_max_sparse_is_an_upper_bound_within_the_mass_conditioning():
    pts, hexes = box_mesh(4, 4, 60, 1.0, 1.0, 6.0)        # 2,745 DOFs: the sparse branch
    K, M = solid_matrices(pts, hexes, 2e8, 0.2, 1850.0)
    free = np.flatnonzero(pts[:, 2] > 0)
    dofs = (3 * free[:, None] + np.arange(3)).ravel()
    K, M = sp.csr_matrix(K[dofs][:, dofs]), sp.csr_matrix(M[dofs][:, dofs])
    # the extreme eigenvalues by Lanczos to round-off (a dense eigh of 2,745 took 45-60 s
    # of the slow tier); converged to the default tolerance, machine precision
    exact = spla.eigsh(K, k=1, M=M, which="LA", return_eigenvectors=False)[0]
    bound = tolerances.lambda_max(K, M)
    assert exact <= bound <= 27.0 * exact                 # trilinear mass: cond <= 27
    d, mu = tolerances.mass_scaling(M)
    scaled = sp.diags(1.0 / d) @ M @ sp.diags(1.0 / d)
    lowest = spla.eigsh(scaled.tocsc(), k=1, sigma=0.0, return_eigenvectors=False)[0]
    # a lower bound of the scaled mass spectrum, which is >= 1/8 (trilinear consistent mass)
    assert 0.12 < mu <= lowest


def test_subspace_sines_are_accurate_for_tiny_angles():
    x = np.zeros((4, 2))
    x[0, 0] = x[1, 1] = 1.0
    for angle in (1e-14, 1e-9, 0.3):
        y = x.copy()
        y[:, 1] = [0.0, np.cos(angle), np.sin(angle), 0.0]
        s = tolerances.subspace_sines(x, 3.0 * y)             # scaling does not matter
        assert s[0] == np.float64(np.sin(angle)) or abs(s[0] / np.sin(angle) - 1) < 1e-6
        assert s[1] < 1e-15


def test_residual_norms_bound_the_true_residual_and_davis_kahan_the_angle():
    K, M = _column()
    Kd, Md = K.toarray(), M.toarray()
    _, phi = la.eigh(Kd, Md, subset_by_index=[0, 5])
    rng = np.random.default_rng(2)
    noisy = phi + 1e-6 * rng.standard_normal(phi.shape)
    noisy /= np.sqrt(np.einsum("ij,ij->j", noisy, Md @ noisy))
    rq = np.einsum("ij,ij->j", noisy, Kd @ noisy)
    r = Kd @ noisy - Md @ noisy * rq
    true = np.sqrt(np.einsum("ij,ij->j", r, la.solve(Md, r)))
    bound = tolerances.residual_norms(K, M, noisy, rq)
    assert np.all(true <= bound) and np.all(bound <= 30 * true)
    lam_all = la.eigh(Kd, Md, eigvals_only=True)
    for i in range(6):
        gap = min(lam_all[i] - (lam_all[i - 1] if i else -np.inf), lam_all[i + 1] - lam_all[i])
        angle = tolerances.subspace_sines(phi[:, [i]], noisy[:, [i]], Md)[0]
        assert angle <= tolerances.davis_kahan(bound[[i]], gap)


def test_clusters_and_gaps():
    lam = np.array([1.0, 1.0 + 1e-12, 2.0, 4.0])
    assert tolerances.clusters(lam, 1e-10).tolist() == [0, 0, 1, 2]
    gaps = tolerances.cluster_gaps(lam, 1e-10)
    assert np.allclose(gaps, [1.0, 1.0, 0.5, 0.5])
    # the Kato-Temple term grows as the gap closes
    r = tolerances.eigenvalue_rtol(np.ones(4), 100, solver_tol=1e-6, rel_gap=gaps)
    assert r[2] > r[0]


def test_product_error_covers_an_orthonormalised_basis():
    from railvib_hpc.fem import mass_normalise

    K, M = _column()
    phi = la.eigh(K.toarray(), M.toarray(), subset_by_index=[0, 5])[1]
    mixed = mass_normalise(phi @ np.random.default_rng(3).normal(size=(6, 6)), M, K)
    dev = np.abs(mixed.T @ (M @ mixed) - np.eye(6))
    assert np.all(dev <= tolerances.product_error(M, mixed))
