"""How accurately an eigenpair can be computed: tolerances derived, not tuned.

A comparison of two eigenvalue computations at a fixed "1e-9" passes on one CPU and fails on
another (the BLAS, the vector width and the reduction order change the round-off). This module
derives the tolerance of every eigenvalue, eigenvector and Gram comparison from the size of
the problem, its conditioning and the solver tolerance, so that a test fails only when an
answer is wrong, whatever the machine. The model, for the symmetric-definite pencil
``K phi = lambda M phi`` with M-normalised ``phi``, ``n`` unknowns and the unit round-off
``u = eps = 2.2e-16``:

1. **Round-off, normwise.** A backward-stable method (LAPACK ``sygvd``; a sparse Cholesky or
   LDL^T factorisation followed by a Krylov method) returns the exact eigenpairs of
   ``K + E, M + F`` with ``||E|| <~ c(n) u ||K||`` and ``||F|| <~ c(n) u ||M||`` (in the
   M-metric, ``||M^-1/2 E M^-1/2|| <~ c(n) u lambda_max``). To first order a simple
   eigenvalue moves by ``phi^T (E - lambda F) phi``, so its *relative* error is

   ``|d lambda_i| / lambda_i <~ c(n) u kappa_i``,  ``kappa_i = lambda_max / lambda_i``

   (Wilkinson; Golub & Van Loan, *Matrix Computations*, 4th ed., §8.7.2). The low modes of a
   finite-element model are the ill-conditioned ones: ``kappa_1`` is 3e6 for a 12-element
   cantilever with rotary inertia and 1.4e8 for a column of 0.1 m wide hexahedra.
   ``c(n)``: the worst-case bounds grow like ``n u``, the accumulated error of ``n`` rounded
   operations behaves like ``sqrt(n) u`` (Higham, *Accuracy and Stability of Numerical
   Algorithms*, 2nd ed., §2.8): :func:`accumulation` uses ``sqrt(n)`` for whole-problem
   quantities. Measured on the tests: 0.05 - 0.7 ``u kappa_i`` (LAPACK, ARPACK/SuperLU,
   block Lanczos and Krylov-Schur/MUMPS on Intel and AMD CPUs).

2. **Round-off, componentwise.** When the perturbation is componentwise, ``|E| <= c u |K|``
   (the same element matrices summed in another order on another number of ranks; a
   Rayleigh quotient ``phi^T K phi`` evaluated in floating point), the bound is
   ``|d lambda_i| <= c u |phi_i|^T |K| |phi_i|``: :func:`componentwise_condition`
   ``= |phi_i|^T |K| |phi_i| / lambda_i``, often far below ``kappa_i``. Products of few terms
   (one row of a sparse matrix: ``k`` entries) use the rigorous ``gamma_k = k u / (1 - k u)``
   (Higham §3.1): :func:`product_error`.

3. **Solver tolerance.** A Ritz pair whose residual ``r = K x - theta M x`` has
   ``||r||_{M^-1} <= rho`` satisfies ``|theta - lambda| <= rho^2 / gap`` (Kato-Temple; the gap
   to the rest of the spectrum). An eigensolver stopped at the relative residual ``tol``
   (``rho ~ tol lambda``) leaves ``|d lambda| / lambda <~ tol^2 / relgap``: negligible unless
   eigenvalues cluster. For a cluster of (numerically) repeated eigenvalues the gap is the
   distance from the cluster to the rest of the spectrum (:func:`cluster_gaps`).

4. **Eigenvectors.** The angle between a computed and the exact invariant subspace is at most
   ``(||E|| + rho) / gap`` (Davis-Kahan sin(Theta) theorem): :func:`subspace_tolerance`. The
   individual vectors of a cluster are not determined at all, so compare *subspaces*
   (principal angles in the M inner product, :func:`subspace_sines`), never single vectors.

Two computations of the same quantity differ by up to the sum of their errors
(``computations = 2``).

Examples
--------
>>> import numpy as np
>>> lam = np.array([1.0, 4.0, 100.0])
>>> rtol = eigenvalue_rtol(normwise_condition(lam, lam_max=1e6), n=100)
>>> bool(rtol[0] > rtol[1] > rtol[2])                  # low modes: worse conditioned
True
>>> float(eigenvalue_rtol(normwise_condition(lam, 1e6), 100)[0])   # 2 * 10 * u * 1e6
4.440892098500626e-09
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

#: Unit round-off of IEEE double precision.
EPS = float(np.finfo(float).eps)


def accumulation(n: int) -> float:
    """Growth of round-off over a computation with ``n`` unknowns: ``sqrt(n)``.

    The statistical rule (Higham 2002, §2.8; Wilkinson): rounding errors of independent
    operations add like a random walk. Worst-case bounds (``n``) are orders of magnitude
    pessimistic for whole eigenproblems and would make the tests unable to fail.
    """
    return math.sqrt(max(int(n), 1))


def _longest_row(A) -> int:
    """Entries of the longest row of a dense or sparse matrix."""
    if sp.issparse(A):
        return int(np.diff(sp.csr_matrix(A).indptr).max(initial=0))
    return int(A.shape[1])


def gamma(k: int) -> float:
    """Rigorous bound ``k u / (1 - k u)`` for a sum or dot product of ``k`` terms (Higham §3.1)."""
    return k * EPS / (1.0 - k * EPS)


def mass_scaling(M) -> tuple[np.ndarray, float]:
    """Diagonal scaling of a sparse M and a lower bound of its scaled spectrum.

    Returns ``d = sqrt(diag(M))`` and ``mu <= lambda_min(D^-1/2 M D^-1/2)``: the Lanczos
    estimate minus its residual norm (a rigorous bound for the eigenvalue it approximates).
    Finite-element mass matrices are well conditioned after this scaling (trilinear
    hexahedra: spectrum in [1/8, 27/8]), so the estimate is cheap: no factorisation.
    """
    from scipy.sparse.linalg import eigsh

    d = np.sqrt(np.asarray(M.diagonal(), dtype=float))
    Ms = sp.diags(1.0 / d) @ sp.csr_matrix(M) @ sp.diags(1.0 / d)
    val, vec = eigsh(Ms, k=1, which="SA", tol=1e-4)
    res = float(np.linalg.norm(Ms @ vec[:, 0] - val[0] * vec[:, 0]))
    return d, max(float(val[0]) - res, np.finfo(float).tiny)


def lambda_max(K, M) -> float:
    """Largest eigenvalue of the pencil (K, M) (symmetric, M > 0), or an upper bound.

    Dense (or up to 2,000 unknowns): exact (LAPACK). Sparse: ``lambda_max(D^-1/2 K D^-1/2)
    / lambda_min(D^-1/2 M D^-1/2)`` with ``D = diag(M)`` (a Rayleigh-quotient bound; at most
    ``cond(D^-1/2 M D^-1/2)`` above the truth, 27 for trilinear hexahedra), each from a
    factorisation-free Lanczos run plus its residual norm — the value only scales a
    tolerance, so an upper bound is what is needed.
    """
    n = K.shape[0]
    if n <= 2000 or not sp.issparse(K):
        Kd = K.toarray() if sp.issparse(K) else np.asarray(K)
        Md = M.toarray() if sp.issparse(M) else np.asarray(M)
        return float(la.eigh(Kd, Md, eigvals_only=True, subset_by_index=[n - 1, n - 1])[0])
    from scipy.sparse.linalg import eigsh

    d, mu = mass_scaling(M)
    Ks = sp.diags(1.0 / d) @ sp.csr_matrix(K) @ sp.diags(1.0 / d)
    val, vec = eigsh(Ks, k=1, which="LA", tol=1e-4)
    res = float(np.linalg.norm(Ks @ vec[:, 0] - val[0] * vec[:, 0]))
    return (float(val[0]) + res) / mu


def residual_norms(K, M, phi: np.ndarray, lam) -> np.ndarray:
    """Upper bounds of ``||K phi_i - lambda_i M phi_i||_{M^-1}`` (sparse or dense K, M).

    The computed residual plus its evaluation error ``gamma_k (|K| |phi| + |lambda| |M|
    |phi|)`` (k = longest row + 1), in the M^-1 norm bounded through the diagonal scaling
    of :func:`mass_scaling`: ``||r||_{M^-1} <= ||D^-1/2 r|| / sqrt(mu)``. With it the
    Davis-Kahan bound :func:`davis_kahan` needs no factorisation.
    """
    lam = np.asarray(lam, dtype=float)
    phi = np.asarray(phi, dtype=float)
    row = _longest_row(K)
    if sp.issparse(M):
        d, mu = mass_scaling(M)
    else:
        Md = np.asarray(M)
        d = np.sqrt(np.diag(Md))
        mu = float(la.eigvalsh(Md / np.outer(d, d), subset_by_index=[0, 0])[0])
    Ka = abs(K) if sp.issparse(K) else np.abs(np.asarray(K))
    Ma = abs(M) if sp.issparse(M) else np.abs(np.asarray(M))
    P = np.abs(phi)
    r = np.abs(K @ phi - (M @ phi) * lam) + gamma(row + 1) * (Ka @ P + (Ma @ P) * np.abs(lam))
    return np.linalg.norm(r / d[:, None], axis=0) / np.sqrt(mu)


def davis_kahan(residuals, gap_abs: float) -> float:
    """Sine of the largest principal angle between the span of computed M-orthonormal
    vectors and the exact invariant subspace of the eigenvalues they approximate:
    ``||R||_F / gap`` (Davis-Kahan sin(Theta) theorem, M-norms), with ``residuals`` the
    M^-1-norms of the columns of ``R = K Phi - M Phi Lambda`` (:func:`residual_norms`)
    and ``gap`` the distance from those eigenvalues to the rest of the spectrum."""
    if gap_abs <= 0:
        return np.inf
    return float(np.sqrt(np.sum(np.square(residuals)))) / gap_abs


def normwise_condition(lam, lam_max: float) -> np.ndarray:
    """``kappa_i = lambda_max / |lambda_i|``: relative sensitivity of each eigenvalue to a
    normwise backward error ``u ||K||`` (at least 1)."""
    lam = np.abs(np.asarray(lam, dtype=float))
    return np.maximum(lam_max / np.where(lam > 0, lam, np.inf), 1.0)


def componentwise_condition(K, phi: np.ndarray, lam) -> np.ndarray:
    """``|phi_i|^T |K| |phi_i| / |lambda_i|`` for M-normalised columns ``phi_i`` (at least 1).

    The relative sensitivity of each eigenvalue (and of the Rayleigh quotient that computes
    it) to a componentwise perturbation ``|E| <= u |K|``. ``K`` dense or scipy sparse.
    """
    A = abs(K) if sp.issparse(K) else np.abs(np.asarray(K))
    P = np.abs(np.asarray(phi, dtype=float))
    num = np.einsum("ij,ij->j", P, A @ P)
    lam = np.abs(np.asarray(lam, dtype=float))
    return np.maximum(num / np.where(lam > 0, lam, np.inf), 1.0)


def clusters(lam, rtol) -> np.ndarray:
    """Label of the cluster of every eigenvalue (``lam`` ascending).

    Neighbours closer than their (relative) tolerance ``rtol`` (scalar or per eigenvalue)
    cannot be told apart and form one cluster.
    """
    lam = np.asarray(lam, dtype=float)
    rtol = np.broadcast_to(np.asarray(rtol, dtype=float), lam.shape)
    if lam.size == 0:
        return np.zeros(0, dtype=int)
    scale = np.abs(lam) * rtol
    tied = np.diff(lam) <= np.maximum(scale[1:], scale[:-1])
    return np.concatenate(([0], np.cumsum(~tied)))


def cluster_gaps(lam, rtol, below: float = -np.inf, above: float = np.inf) -> np.ndarray:
    """Relative gap of every eigenvalue's cluster to the nearest eigenvalue outside it.

    ``below``/``above``: the nearest known eigenvalues outside ``lam`` (e.g. the next mode
    beyond the ones computed); ``inf`` when unknown. Returns ``gap / |lambda|``.
    """
    lam = np.asarray(lam, dtype=float)
    lab = clusters(lam, rtol)
    out = np.empty_like(lam)
    for c in np.unique(lab):
        idx = np.flatnonzero(lab == c)
        lo = lam[idx[0] - 1] if idx[0] > 0 else below
        hi = lam[idx[-1] + 1] if idx[-1] + 1 < lam.size else above
        gap = min(lam[idx[0]] - lo, hi - lam[idx[-1]])
        out[idx] = gap / np.maximum(np.abs(lam[idx]), np.finfo(float).tiny)
    return out


def eigenvalue_rtol(cond, n: int, solver_tol: float = 0.0, rel_gap=np.inf,
                    computations: int = 2) -> np.ndarray:
    """Relative tolerance for comparing eigenvalues.

    ``computations * (sqrt(n) u cond_i + solver_tol^2 / relgap_i)``: the round-off of
    item 1/2 of the module docstring (``cond`` from :func:`normwise_condition` or
    :func:`componentwise_condition`) plus the Kato-Temple term of a solver stopped at the
    relative residual ``solver_tol`` (0 for a direct dense solver), for each of the
    ``computations`` being compared (1: against an exact value).
    """
    cond = np.asarray(cond, dtype=float)
    rel_gap = np.broadcast_to(np.asarray(rel_gap, dtype=float), cond.shape)
    solver = np.where(rel_gap > 0, solver_tol**2 / np.where(rel_gap > 0, rel_gap, 1.0), np.inf)
    return computations * (accumulation(n) * EPS * cond + solver)


def zero_eigenvalue_bound(lam_max: float, n: int) -> float:
    """Largest |lambda| a computed zero eigenvalue (rigid-body mode) can show: ``sqrt(n) u
    lambda_max`` (item 1 with lambda = 0: absolute error ``u ||K||``)."""
    return accumulation(n) * EPS * lam_max


def subspace_tolerance(gap_abs: float, lam_max: float, n: int, residual: float = 0.0,
                       computations: int = 2) -> float:
    """Bound on the sine of the largest principal angle between computed and exact
    invariant subspaces (Davis-Kahan): ``computations * (sqrt(n) u lambda_max + residual)
    / gap``.

    ``gap_abs``: absolute distance of the (cluster of) eigenvalue(s) to the rest of the
    spectrum; ``residual``: ``||K x - lambda M x||_{M^-1}`` left by the solver (about
    ``tol * lambda`` for a solver stopped at the relative residual ``tol``).
    """
    if gap_abs <= 0:
        return np.inf
    return computations * (accumulation(n) * EPS * lam_max + residual) / gap_abs


def subspace_sines(phi_a: np.ndarray, phi_b: np.ndarray, M=None) -> np.ndarray:
    """Sines of the principal angles between span(phi_a) and span(phi_b), M inner product.

    Both bases are M-orthonormalised first (Cholesky of their Gram matrices), so they need
    not be normalised; ``M = None`` means the Euclidean inner product. The sines are the
    singular values of the part of ``phi_b`` outside span(phi_a) (accurate to round-off,
    unlike ``sqrt(1 - cos^2)``); returned largest first.
    """
    def mdot(X, Y):
        return X.T @ (Y if M is None else M @ Y)

    def orth(P):
        P = np.asarray(P, dtype=float).reshape(len(P), -1)
        G = mdot(P, P)
        return P @ la.inv(la.cholesky(0.5 * (G + G.T)))

    Qa, Qb = orth(phi_a), orth(phi_b)
    R = Qb - Qa @ mdot(Qa, Qb)
    G = mdot(R, R)
    s2 = la.eigvalsh(0.5 * (G + G.T))
    return np.sqrt(np.clip(s2, 0.0, None))[::-1]


def product_error(A, phi: np.ndarray, psi: np.ndarray | None = None,
                  computations: int = 2) -> np.ndarray:
    """Round-off allowance of the entries of ``phi^T A psi`` (Gram matrices ``Phi^T M Phi``,
    ``Phi^T K Phi`` of an orthonormalised basis).

    ``computations * gamma_k * max(P_ij, sqrt(P_ii P_jj))`` with ``P = |phi|^T |A| |psi|``
    and ``k`` = the longest row of A plus the length of the dot products (``n``) plus the
    number of columns: rigorous for one product (Higham §3.5). The geometric mean of the
    diagonal entries covers the basis change ``Phi X`` of the orthonormalisation, which mixes
    the columns with round-off-sized coefficients (so modes with disjoint supports, whose
    ``P_ij`` is 0, still get ``u``-sized off-diagonal entries). One computation is the
    algorithm's, one the check's.
    """
    psi = phi if psi is None else psi
    Aabs = abs(A) if sp.issparse(A) else np.abs(np.asarray(A))
    k = _longest_row(A) + A.shape[0] + phi.shape[1]
    P = np.abs(phi).T @ (Aabs @ np.abs(psi))
    da = np.einsum("ij,ij->j", np.abs(phi), Aabs @ np.abs(phi))
    db = np.einsum("ij,ij->j", np.abs(psi), Aabs @ np.abs(psi))
    return computations * gamma(k) * np.maximum(P, np.sqrt(np.outer(da, db)))
