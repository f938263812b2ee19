"""Gauss-Lobatto-Legendre (GLL) nodes and weights, and the 1-D Lagrange basis on them.

The spectral hexahedron of order ``N`` (:mod:`.spectral_mesh`, :mod:`.spectral_kernel`)
carries the ``N + 1`` GLL points per direction as its nodes and as its quadrature points,
so that its mass matrix is diagonal (Patera 1984; Komatitsch & Vilotte 1998). On [-1, 1]
the points are ``-1``, the ``N - 1`` roots of ``P_N'`` (the derivative of the Legendre
polynomial of degree ``N``) and ``+1``; the weights are ``w_j = 2 / (N (N + 1) P_N(x_j)^2)``
and the rule integrates polynomials of degree ``2 N - 1`` exactly (Canuto, Hussaini,
Quarteroni & Zang 2006, "Spectral Methods: Fundamentals in Single Domains", eq. 2.3.12;
Karniadakis & Sherwin 2005, "Spectral/hp Element Methods", appendix B). ``N = 1`` is the
2-point trapezoidal rule on the corners: the trilinear hexahedron with nodal quadrature.

The 1-D Lagrange polynomials ``l_j`` of degree ``N`` through the points give

* :func:`derivative_matrix`: ``D[i, j] = l_j'(x_i)`` in closed form (Canuto et al. 2006,
  eq. 2.3.28): ``P_N(x_i) / (P_N(x_j) (x_i - x_j))`` off the diagonal, ``-N (N + 1) / 4`` and
  ``N (N + 1) / 4`` at the two ends, 0 elsewhere on the diagonal;
* :func:`interpolation_matrix`: ``l_j(xi)`` at any reference points (barycentric form,
  Berrut & Trefethen 2004, "Barycentric Lagrange interpolation", SIAM Review 46, 501-517),
  and :func:`interpolation_derivatives` their derivatives; :func:`hex_interpolation`, the
  tensor product on the reference hexahedron for probes at any point of an element.

Every function returns new float64 arrays; the tables are computed once per order and
cached (copies are handed out).

Examples
--------
>>> import numpy as np
>>> from railvib_hpc.fem.gll import gll_points
>>> x, w = gll_points(4)
>>> np.round(x, 6).tolist()
[-1.0, -0.654654, 0.0, 0.654654, 1.0]
>>> round(float(w.sum()), 12)
2.0
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "MAX_ORDER",
    "MIN_ORDER",
    "check_order",
    "derivative_matrix",
    "gll_points",
    "hex_interpolation",
    "interpolation_derivatives",
    "interpolation_matrix",
    "lexicographic_index",
]

#: Orders of the spectral hexahedra (1: the trilinear element with nodal quadrature; 8: the
#: highest the kernels are compiled and tested for; SPECFEM3D and SEM3D use 4-5).
MIN_ORDER, MAX_ORDER = 1, 8
#: Newton steps that polish the interior points (the eigenvalues of the Jacobi matrix are
#: within ~1e-15 already; two steps are at machine precision, four are safe).
_NEWTON_STEPS = 4


def check_order(order: int) -> int:
    """The order as an ``int``, or a ``ValueError`` naming the allowed range.

    >>> check_order(4)
    4
    >>> check_order(9)
    Traceback (most recent call last):
    ...
    ValueError: spectral order must be an integer in 1..8, got 9
    """
    if isinstance(order, bool) or int(order) != order or not MIN_ORDER <= order <= MAX_ORDER:
        raise ValueError(f"spectral order must be an integer in {MIN_ORDER}..{MAX_ORDER}, "
                         f"got {order!r}")
    return int(order)


def _legendre(n: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``P_n(x)`` and ``P_n'(x)`` by the three-term recurrence (Bonnet)."""
    p0, p1 = np.ones_like(x), x.copy()
    if n == 0:
        return p0, np.zeros_like(x)
    for k in range(2, n + 1):
        p0, p1 = p1, ((2 * k - 1) * x * p1 - (k - 1) * p0) / k
    with np.errstate(divide="ignore", invalid="ignore"):
        dp = n * (x * p1 - p0) / (x * x - 1.0)
    # at the ends P_n'(+-1) = (+-1)^(n-1) n (n + 1) / 2
    ends = np.abs(np.abs(x) - 1.0) < 1e-300
    dp = np.where(ends, np.sign(x) ** (n - 1) * n * (n + 1) / 2.0, dp)
    return p1, dp


@cache
def _gll(order: int) -> tuple[np.ndarray, np.ndarray]:
    n = check_order(order)
    if n == 1:
        return np.array([-1.0, 1.0]), np.array([1.0, 1.0])
    # interior points: the roots of P_N', the eigenvalues of the symmetric Jacobi matrix of
    # the Jacobi polynomials P^(1,1)_(N-1) (Golub & Welsch 1969), then Newton on P_N'
    k = np.arange(1, n - 1, dtype=float)
    off = np.sqrt(k * (k + 2.0) / ((2.0 * k + 1.0) * (2.0 * k + 3.0)))
    inner = np.linalg.eigvalsh(np.diag(off, 1) + np.diag(off, -1)) if n > 2 else np.zeros(1)
    for _ in range(_NEWTON_STEPS):
        p, dp = _legendre(n, inner)
        # (1 - x^2) P_N'' = 2 x P_N' - N (N + 1) P_N
        d2p = (2.0 * inner * dp - n * (n + 1) * p) / (1.0 - inner * inner)
        inner = inner - dp / d2p
    x = np.concatenate([[-1.0], np.sort(inner), [1.0]])
    x = 0.5 * (x - x[::-1])                                   # exactly antisymmetric
    p, _ = _legendre(n, x)
    w = 2.0 / (n * (n + 1) * p * p)
    return x, 0.5 * (w + w[::-1])


def gll_points(order: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``order + 1`` Gauss-Lobatto-Legendre points and weights on [-1, 1].

    Parameters
    ----------
    order
        The polynomial order ``N`` (1..8).

    Returns
    -------
    points : ndarray, shape (N + 1,)
        Ascending, ``-1`` and ``1`` included, symmetric about 0.
    weights : ndarray, shape (N + 1,)
        Positive, summing to 2; exact for polynomials of degree ``2 N - 1``.

    Examples
    --------
    >>> x, w = gll_points(2)
    >>> x.tolist(), np.round(w, 12).tolist()
    ([-1.0, 0.0, 1.0], [0.333333333333, 1.333333333333, 0.333333333333])
    """
    x, w = _gll(order)
    return x.copy(), w.copy()


@cache
def _derivative(order: int) -> np.ndarray:
    n = check_order(order)
    x, _ = _gll(n)
    p, _ = _legendre(n, x)
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    d = p[:, None] / (p[None, :] * diff)
    np.fill_diagonal(d, 0.0)
    d[0, 0], d[n, n] = -n * (n + 1) / 4.0, n * (n + 1) / 4.0
    return d


def derivative_matrix(order: int) -> np.ndarray:
    """The 1-D GLL differentiation matrix ``D[i, j] = l_j'(x_i)``.

    ``(D @ u)[i]`` is the derivative at point ``x_i`` of the polynomial of degree ``N``
    through the values ``u`` at the GLL points (exact for polynomials of degree ``N``).

    Parameters
    ----------
    order
        The polynomial order ``N`` (1..8).

    Returns
    -------
    ndarray, shape (N + 1, N + 1)
        Rows sum to 0 (a constant has no slope).

    Examples
    --------
    >>> derivative_matrix(1).tolist()
    [[-0.5, 0.5], [-0.5, 0.5]]
    >>> derivative_matrix(2).tolist()
    [[-1.5, 2.0, -0.5], [-0.5, 0.0, 0.5], [0.5, -2.0, 1.5]]
    """
    return _derivative(order).copy()


def _barycentric_weights(x: np.ndarray) -> np.ndarray:
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    return 1.0 / diff.prod(axis=1)


def interpolation_matrix(order: int, xi: ArrayLike) -> np.ndarray:
    """The Lagrange polynomials on the GLL points, ``L[..., j] = l_j(xi)``.

    Parameters
    ----------
    order
        The polynomial order ``N`` (1..8).
    xi
        Reference coordinates, any shape (within [-1, 1] for interpolation; outside it the
        polynomials extrapolate).

    Returns
    -------
    ndarray, shape ``xi.shape + (N + 1,)``
        Each row sums to 1; ``l_j(x_i) = delta_ij`` exactly at the points.

    Examples
    --------
    >>> np.round(interpolation_matrix(2, [0.5]), 12).tolist()
    [[-0.125, 0.75, 0.375]]
    """
    x, _ = _gll(check_order(order))
    xi = np.asarray(xi, dtype=float)
    lam = _barycentric_weights(x)
    diff = xi[..., None] - x
    exact = diff == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = lam / diff
        out = terms / terms.sum(axis=-1, keepdims=True)
    hit = exact.any(axis=-1)
    return np.where(hit[..., None], exact.astype(float), out)


def interpolation_derivatives(order: int, xi: ArrayLike) -> np.ndarray:
    """Derivatives of the Lagrange polynomials on the GLL points, ``l_j'(xi)``.

    The product rule on ``l_j = prod_(m != j) (xi - x_m) / (x_j - x_m)``, exact (no
    division by ``xi - x_m``), so it holds at the points too (where it is
    :func:`derivative_matrix`).

    Parameters
    ----------
    order
        The polynomial order ``N`` (1..8).
    xi
        Reference coordinates, any shape.

    Returns
    -------
    ndarray, shape ``xi.shape + (N + 1,)``
        Each row sums to 0.

    Examples
    --------
    >>> x, _ = gll_points(3)
    >>> bool(np.allclose(interpolation_derivatives(3, x), derivative_matrix(3)))
    True
    """
    n = check_order(order)
    x, _ = _gll(n)
    xi = np.asarray(xi, dtype=float)
    lam = _barycentric_weights(x)
    diff = xi[..., None] - x                                      # (..., N + 1)
    out = np.zeros(xi.shape + (n + 1,))
    for j in range(n + 1):
        for skip in range(n + 1):
            if skip == j:
                continue
            others = [m for m in range(n + 1) if m not in (j, skip)]
            out[..., j] += np.prod(diff[..., others], axis=-1)
        out[..., j] *= lam[j]
    return out


def lexicographic_index(order: int) -> np.ndarray:
    """``(i, j, k)`` of the element's local nodes in their order ``a = i + (N+1) j +
    (N+1)^2 k`` (``i`` along the first reference axis, fastest).

    >>> lexicographic_index(1).tolist()
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1]]
    """
    n1 = check_order(order) + 1
    a = np.arange(n1**3)
    return np.stack([a % n1, (a // n1) % n1, a // (n1 * n1)], axis=1)


def hex_interpolation(order: int, xi: ArrayLike, derivatives: bool = False):
    """The element's basis at reference points of the hexahedron (probes at any point).

    Parameters
    ----------
    order
        The polynomial order ``N`` (1..8).
    xi
        Reference coordinates, shape (npts, 3) in [-1, 1]^3.
    derivatives
        Also return the reference gradients.

    Returns
    -------
    values : ndarray, shape (npts, (N + 1)^3)
        ``phi_a(xi)`` in the local node order of :func:`lexicographic_index`; a field
        ``u`` of shape ((N+1)^3, ...) at the element's nodes reads ``values @ u`` there.
    gradients : ndarray, shape (npts, (N + 1)^3, 3)
        ``d phi_a / d xi_k`` (only when ``derivatives``).

    Examples
    --------
    >>> v = hex_interpolation(2, [[0.0, 0.0, 0.0]])
    >>> int(np.argmax(v[0])), float(v[0].max())     # the centre node i = j = k = 1
    (13, 1.0)
    """
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    ijk = lexicographic_index(order)
    lv = [interpolation_matrix(order, xi[:, d])[:, ijk[:, d]] for d in range(3)]
    values = lv[0] * lv[1] * lv[2]
    if not derivatives:
        return values
    ld = [interpolation_derivatives(order, xi[:, d])[:, ijk[:, d]] for d in range(3)]
    grads = np.stack([ld[0] * lv[1] * lv[2], lv[0] * ld[1] * lv[2], lv[0] * lv[1] * ld[2]],
                     axis=-1)
    return values, grads
