"""Numerical dispersion of spectral hexahedra (GLL, order N) with the lumped mass.

The counterpart of :mod:`.dispersion` (the trilinear grid) for the spectral elements of
:mod:`.spectral_kernel`. A plane wave ``u = U exp(i (k . x - omega t))`` on an unbounded
grid of cubic GLL elements of order ``N`` (edge ``h``) is a Bloch mode of one periodic cell:
its ``(N + 1)^3`` nodes condensed onto the cell's ``N^3`` distinct ones (the nodes with index
``N`` are the next cell's index 0, with the phase ``exp(i k_d h)``), so

    K(k) U = omega_h^2 M U,   K(k) = T(k)^H K_e T(k),   M = T^H M_e T (diagonal),

a Hermitian eigenproblem of size ``3 N^3`` with ``3 N^3`` branches (the acoustic one and the
optical ones of the nodes inside the cell). The physical branch at ``k`` is the mode that
best matches the sampled plane wave ``exp(i k . x_n)`` (largest overlap in the mass inner
product; Seriani & Oliveira 2008, "Dispersion analysis of spectral element methods for
elastic wave propagation", Wave Motion 45, 729-744; De Basabe & Sen 2007, "Grid dispersion
and stability criteria of some common finite-element methods for acoustic and elastic wave
equations", Geophysics 72, T81-T95). A direction with ``k_d = 0`` is condensed to one node
along it (the fields constant along it span an invariant subspace of ``M^-1 K`` on the box
grid), so along an axis the problem is the 1-D one, on a face diagonal the 2-D one.

The element is :func:`~.spectral_kernel.box_element_matrix` of the unit cube with ``mu =
rho = 1`` (``c_S = 1``); sizes are dimensionless as in :mod:`.dispersion`: ``epw`` is
**elements** per wavelength ``lambda / h`` of the wave in question (the points per
wavelength are ``N epw``), the step enters as ``courant = c_P dt / h`` (the element's edge,
not the node spacing). A source of frequency ``omega`` launches the ``k_h`` with
``Omega(k_h) = omega`` (:func:`wavenumber_ratio`; the time scheme's ``Omega`` of
:func:`~.dispersion.time_frequency`), found by the fixed-point iteration ``k <- k omega /
Omega(k)``, which converges like ``2 N`` times the (tiny) relative error per step.

Theory (Ainsworth 2004, "Discrete dispersion relation for hp-version finite element
approximation at high wave number", SIAM J. Numer. Anal. 42, 553-575; Ainsworth & Wajid
2009, "Dispersive and dissipative behavior of the spectral element method", SIAM J. Numer.
Anal. 47, 3910-3937): for ``kh -> 0`` the lumped GLL element's relative phase error is
``O((kh)^(2N))`` (the consistent-mass element's too, with another constant); at a fixed
number of points per wavelength above ``~ pi`` it falls super-exponentially in ``N``. The
tests (``tests/fem/test_dispersion_gll.py``) measure both rates.

Examples
--------
At 1.5 elements (6 points) per S wavelength, order 4 lags 0.04 % along an axis, where the
trilinear lumped grid at 6 points per wavelength lags 5 %:

>>> from railvib_hpc.fem.dispersion_gll import wavenumber_ratio
>>> r = float(wavenumber_ratio(1.5, "S", "axis", order=4))
>>> round(100 * (r - 1.0), 3)
0.043
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg, sparse
from scipy.sparse.linalg import eigsh

from .dispersion import DIRECTIONS, _cp_over_cs, time_frequency, worst_of
from .gll import check_order, gll_points
from .spectral_kernel import box_element_matrix

__all__ = [
    "BLOCH_MATCH",
    "bloch_branches",
    "critical_courant",
    "peak_velocity_error",
    "phase_error",
    "wavenumber_ratio",
    "worst_peak_error",
]

#: Least overlap of a Bloch mode with the sampled plane wave for it to count as the
#: physical branch (resolved waves have > 0.99; below this the grid does not carry the
#: wave: NaN, as beyond the trilinear grid's cut-off).
BLOCH_MATCH = 0.5
#: Steps of :func:`wavenumber_ratio`'s root search at most, and the relative change at which
#: it stops (each fixed-point step multiplies the error by about ``2 N`` times the phase
#: error; the secant steps after :data:`_FIXED_POINT_START` converge where that is slow).
_FIXED_POINT_STEPS, _FIXED_POINT_TOL, _FIXED_POINT_START = 12, 1e-13, 2
#: Brillouin-zone points per axis of :func:`critical_courant` on ``[0, pi]`` (they include the
#: zone's centre and corners, where the highest optical modes sit).
_ZONE_POINTS = 3
#: Wave branches of :func:`wavenumber_ratio` (as :data:`~.dispersion.WAVES`).
WAVES = ("P", "S", "S_slow", "S_fast")


def _lame(nu: float) -> tuple[float, float]:
    """``(lambda, mu)`` with ``mu = 1``."""
    return 2.0 * nu / (1.0 - 2.0 * nu), 1.0


@lru_cache(maxsize=32)
def unit_element(order: int, nu: float) -> tuple[np.ndarray, np.ndarray]:
    """The unit cube's stiffness ``(nq, 3, nq, 3)`` (``mu = 1``) and lumped mass ``(nq,)``
    (``rho = 1``) of order ``N``, lexicographic local order (cached; read-only)."""
    n = check_order(order)
    lam, mu = _lame(nu)
    nq = (n + 1) ** 3
    k = box_element_matrix(n, 1.0, lam, mu).reshape(nq, 3, nq, 3)
    _, w = gll_points(n)
    m = np.einsum("k,j,i->kji", w, w, w).ravel() / 8.0
    k.setflags(write=False)
    m.setflags(write=False)
    return k, m


def _cell_map(n: int, kh: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The Bloch map of the periodic cell: per local node its distinct node and phase, the
    distinct nodes' positions (fractions of ``h``), and their number. Axes with ``k_d = 0``
    are condensed to one node."""
    n1 = n + 1
    a = np.arange(n1**3)
    ijk = np.stack([a % n1, (a // n1) % n1, a // (n1 * n1)], axis=1)
    x, _ = gll_points(n)
    active = np.abs(kh) > 0.0
    sizes = np.where(active, n, 1)
    idx = np.where(active, ijk % n, 0)
    unique = idx[:, 0] + sizes[0] * (idx[:, 1] + sizes[1] * idx[:, 2])
    wrap = (ijk == n) & active
    phase = np.exp(1j * (wrap * kh).sum(axis=1))
    count = int(np.prod(sizes))
    pos = np.zeros((count, 3))
    inside = ~wrap.any(axis=1)                        # these cover every distinct node
    pos[unique[inside]] = np.where(active, (x[ijk] + 1.0) / 2.0, 0.0)[inside]
    return unique, phase, pos, count


def _cell_problem(n: int, nu: float, kh: np.ndarray):
    """``A = M^-1/2 K(k) M^-1/2`` (3 count, 3 count), ``sqrt(M)`` per DOF and the distinct
    nodes' positions. ``K(k) = T^H K_e T`` with ``T`` one phase per row, as two sparse
    products (cost ~ the element matrix's size)."""
    k_e, m_e = unit_element(n, nu)
    unique, phase, pos, count = _cell_map(n, kh)
    nq = len(unique)
    rows = (3 * unique[:, None] + np.arange(3)).ravel()                    # (3 nq,)
    ph = np.repeat(phase, 3)
    pick = sparse.csr_matrix((np.ones(3 * nq), (np.arange(3 * nq), rows)),
                             shape=(3 * nq, 3 * count))
    k_t = np.asarray((pick.T @ (k_e.reshape(3 * nq, 3 * nq) * ph[None, :]).T).T)
    K = np.asarray(pick.T @ (np.conj(ph)[:, None] * k_t))
    m = np.repeat(np.bincount(unique, m_e, count), 3)
    s = 1.0 / np.sqrt(m)
    A = s[:, None] * K * s[None, :]
    return 0.5 * (A + np.conj(A.T)), np.sqrt(m), pos


def bloch_branches(kh: ArrayLike, order: int, nu: float = 0.3) -> tuple[np.ndarray,
                                                                        np.ndarray]:
    """The physical branches at one wave vector: frequencies and polarisations.

    Parameters
    ----------
    kh
        Wave vector times the element edge, shape (3,) (any length: the Bloch phase is
        ``exp(i k h)``, the plane wave's own ``k`` picks the branch).
    order
        ``N`` (1..8).
    nu
        Poisson's ratio.

    Returns
    -------
    omega : ndarray, shape (3,)
        ``omega_h h / c_S`` of the three modes that match the plane wave best, ascending
        (NaN where the best match is below :data:`BLOCH_MATCH`).
    polarisations : ndarray, shape (3, 3)
        Unit polarisations (real parts, columns), ``[:, j]`` for ``omega[j]``.

    Examples
    --------
    A long wave along an axis: two S waves at ``c_S k`` and the P wave at ``c_P k``
    (``c_P / c_S = sqrt(3)`` for ``nu = 1/4``):

    >>> import numpy as np
    >>> w, _ = bloch_branches([0.01, 0.0, 0.0], 3, nu=0.25)
    >>> np.round(w / 0.01, 6).tolist()
    [1.0, 1.0, 1.732051]
    """
    n = check_order(order)
    kh = np.asarray(kh, dtype=float)
    return _matched_modes(*_cell_problem(n, float(nu), kh), kh)


def _matched_modes(A: np.ndarray, sqrt_m: np.ndarray, pos: np.ndarray, kh: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bloch_branches` of an assembled cell problem (``eigh``)."""
    lam, vec = linalg.eigh(A)
    wave = np.exp(1j * (pos @ kh))                                     # sampled plane wave
    count = len(pos)
    # overlap of each mode with wave x e_c in the mass inner product
    vm = vec.reshape(count, 3, -1)
    proj = np.einsum("n,n,ncm->cm", np.conj(wave), sqrt_m[::3], vm)     # (3, modes)
    norm = np.sqrt(np.sum(sqrt_m[::3] ** 2))
    overlap = np.sqrt(np.sum(np.abs(proj) ** 2, axis=0)) / norm
    best = np.argsort(-overlap)[:3]
    order_ = best[np.argsort(lam[best])]
    omega = np.sqrt(np.maximum(lam[order_], 0.0))
    omega = np.where(overlap[order_] >= BLOCH_MATCH, omega, np.nan)
    pol = proj[:, order_]
    # a real polarisation: rotate each column's phase onto its largest component
    ref = pol[np.argmax(np.abs(pol), axis=0), np.arange(3)]
    pol = (pol * np.conj(ref) / np.abs(ref)).real
    return omega, pol / np.linalg.norm(pol, axis=0)


def _branch(omega: np.ndarray, pol: np.ndarray, direction: np.ndarray, wave: str) -> float:
    """The frequency of one branch: P is the polarisation closest to the direction."""
    along = np.abs(direction @ pol)
    p = int(np.argmax(along))
    if wave == "P":
        return float(omega[p])
    s = np.sort(np.delete(omega, p))
    return float(s[0] if wave == "S_slow" else s[1])


def _stepped(omega_h: float, scheme: str, dt: float, rho_inf: float) -> float:
    """The frequency in the stepped solution (``dt`` in units of ``h / c_S``)."""
    if scheme == "none" or not np.isfinite(omega_h):
        return omega_h
    return float(time_frequency(np.array([omega_h * dt]), scheme, rho_inf)[0][0]) / dt


def wavenumber_ratio(epw: ArrayLike, wave: str = "S", direction: str = "axis",
                     nu: float = 0.3, order: int = 4, scheme: str = "none",
                     courant: float = 0.0, rho_inf: float = 1.0) -> np.ndarray:
    """``k_h / k``: the discrete wavenumber a source of frequency ``f`` launches on the GLL
    grid of order ``order``, over the exact one (:func:`~.dispersion.wavenumber_ratio`
    with the order as a parameter; the mass is GLL's lumped one).

    Parameters
    ----------
    epw
        Elements per wavelength of ``wave`` at ``f`` (``lambda / h``; points per wavelength
        ``order * epw``).
    wave
        ``"P"``, ``"S_slow"``, ``"S_fast"`` or ``"S"`` (the one of the two transverse
        branches with the larger error).
    direction
        A key of :data:`~.dispersion.DIRECTIONS`.
    nu
        Poisson's ratio.
    order
        ``N`` (1..8).
    scheme, courant, rho_inf
        Time scheme (:func:`~.dispersion.time_frequency`) and its step as ``c_P dt / h``.

    Returns
    -------
    ndarray
        ``k_h / k`` (> 1: the numerical wave is slower); NaN where the grid does not carry
        the wave (no Bloch mode matches, or beyond the scheme's stability limit).

    Examples
    --------
    >>> r = wavenumber_ratio([1.5, 3.0], "S", "axis", order=4)
    >>> (r - 1 > 0).tolist()                            # the lumped mass lags
    [True, True]
    """
    if wave == "S":
        a, b = (wavenumber_ratio(epw, w, direction, nu, order, scheme, courant, rho_inf)
                for w in ("S_slow", "S_fast"))
        return np.where(np.abs(a - 1.0) >= np.abs(b - 1.0), a, b)
    if wave not in WAVES:
        raise ValueError(f"wave must be one of {WAVES}, got {wave!r}")
    d = DIRECTIONS[direction]
    speed = _cp_over_cs(nu) if wave == "P" else 1.0                 # c / c_S
    dt = courant / _cp_over_cs(nu) if scheme != "none" else 0.0     # dt c_S / h
    out = []
    for e in np.atleast_1d(np.asarray(epw, dtype=float)):
        out.append(_ratio(float(e), wave, direction, float(nu), check_order(order), scheme,
                          float(dt), float(rho_inf), speed, d))
    return np.array(out).reshape(np.shape(epw))


#: Cell problems up to this size are solved by a full ``eigh``; larger ones (orders 6-8
#: off the axes) by block inverse iteration at the exact wave's frequency (an LU of the
#: cell matrix is ~10 times cheaper than its eigendecomposition: 0.15 s against 1.5 s at
#: N = 8 on the body diagonal, measured).
_DENSE_LIMIT = 400
#: Inverse iterations at most, and the relative residual at which they stop.
_INVERSE_STEPS, _INVERSE_TOL = 12, 1e-10


def _transverse(d: np.ndarray) -> np.ndarray:
    """Two unit vectors perpendicular to ``d`` (3, 2)."""
    q, _ = np.linalg.qr(np.column_stack([d, np.eye(3)]))
    return q[:, 1:3]


@lru_cache(maxsize=8192)
def _omega_of(kappa: float, wave: str, direction: str, nu: float, n: int) -> float:
    """The branch's ``omega_h h / c_S`` at ``|k| h = kappa`` along ``direction`` (NaN where
    no Bloch mode matches the plane wave). Large cells: block inverse iteration with the
    shift at the exact ``omega^2``, started from the sampled plane waves of the branch's
    polarisations (P: along ``d``; S: the two transverse ones), then Rayleigh-Ritz."""
    d = DIRECTIONS[direction]
    kh = kappa * d
    A, sqrt_m, pos = _cell_problem(n, nu, kh)
    if len(A) <= _DENSE_LIMIT:
        omega, pol = _matched_modes(A, sqrt_m, pos, kh)
        if not np.all(np.isfinite(omega)):
            return float("nan")
        return _branch(omega, pol, d, wave)
    polar = d[:, None] if wave == "P" else _transverse(d)
    wave_nodes = np.exp(1j * (pos @ kh))
    start = (sqrt_m.reshape(-1, 3)[:, :, None] * wave_nodes[:, None, None]
             * polar[None, :, :]).reshape(len(A), -1)
    speed = _cp_over_cs(nu) if wave == "P" else 1.0
    sigma = (speed * kappa) ** 2
    lu = linalg.lu_factor(A - sigma * np.eye(len(A)))
    y, _ = np.linalg.qr(start)
    for _ in range(_INVERSE_STEPS):
        y, _ = np.linalg.qr(linalg.lu_solve(lu, y))
        theta, z = np.linalg.eigh(np.conj(y.T) @ A @ y)
        modes = y @ z
        residual = np.linalg.norm(A @ modes - modes * theta, axis=0)
        if residual.max() <= _INVERSE_TOL * max(abs(theta).max(), 1.0):
            break
    overlap = np.abs(np.conj(start / np.linalg.norm(start, axis=0)).T @ modes)
    if overlap.sum(axis=0).min() < BLOCH_MATCH:
        return float("nan")
    omega = np.sqrt(np.maximum(np.sort(theta), 0.0))
    if wave == "P":
        return float(omega[0])
    return float(omega[0] if wave == "S_slow" else omega[1])


def _ratio(epw: float, wave: str, direction: str, nu: float, n: int, scheme: str, dt: float,
           rho_inf: float, speed: float, d: np.ndarray) -> float:
    """The fixed point ``kappa = kappa omega / Omega(kappa)`` for one size. Where it does not
    converge the frequency lies in one of the narrow stop bands of the periodic GLL lattice
    at ``kappa = m pi`` (the nodes are not evenly spaced): ``k_h`` is pinned there."""
    k = 2.0 * np.pi / epw                                           # exact k h
    target = speed * k                                               # omega h / c_S

    def residual(kappa: float) -> float:
        return _stepped(_omega_of(kappa, wave, direction, nu, n), scheme, dt, rho_inf) - target

    return _solve(residual, k, target) / k


def _solve(residual, k: float, target: float) -> float:
    """``kappa`` with ``residual(kappa) = 0`` from ``k``: :data:`_FIXED_POINT_START` fixed-point
    steps ``kappa <- kappa target / Omega``, then secant steps, at most
    :data:`_FIXED_POINT_STEPS` in all; NaN where the grid does not carry the wave; where it
    does not converge (a stop band at ``kappa = m pi``) the wavenumber pinned there."""
    kappa, previous = k, None
    r = residual(kappa)
    for step in range(_FIXED_POINT_STEPS):
        if not np.isfinite(r) or r + target <= 0.0:
            return float("nan")
        if previous is None or step < _FIXED_POINT_START or r == previous[1]:
            new = kappa * target / (r + target)
        else:
            new = kappa - r * (kappa - previous[0]) / (r - previous[1])
        if abs(new - kappa) <= _FIXED_POINT_TOL * kappa:
            return new
        previous, kappa = (kappa, r), new
        r = residual(kappa)
    return round(kappa / np.pi) * np.pi


def phase_error(epw: ArrayLike, wavelengths: float = 1.0, wave: str = "S",
                direction: str = "axis", **kw) -> np.ndarray:
    """Phase lag after ``wavelengths`` wavelengths, in periods: ``L (k_h / k - 1)``
    (arguments of :func:`wavenumber_ratio`).

    >>> round(float(phase_error(1.5, 13.3, order=4)), 4)     # 6 points/lambda, N = 4
    0.0058
    """
    return wavelengths * (wavenumber_ratio(epw, wave, direction, **kw) - 1.0)


def peak_velocity_error(epw: ArrayLike, wavelengths: float, wave: str = "S",
                        direction: str = "axis", **kw) -> np.ndarray:
    """The harmonic bound ``1 - cos(2 pi phase)`` of the peak-velocity error after
    ``wavelengths`` wavelengths (:func:`~.dispersion.peak_velocity_error`; 1 from a quarter
    period on or where the grid does not carry the wave).

    >>> round(float(peak_velocity_error(1.5, 10.0, order=4)), 5)   # 6 points/lambda
    0.00037
    """
    phase = np.asarray(phase_error(epw, wavelengths, wave, direction, **kw))
    dphi = 2.0 * np.pi * np.abs(phase)
    with np.errstate(invalid="ignore"):
        err = np.where(dphi >= 0.5 * np.pi, 1.0, 1.0 - np.cos(dphi))
    return np.where(np.isnan(dphi), 1.0, err)


def worst_peak_error(epw: float, wavelengths: float, nu: float = 0.3, order: int = 4,
                     schemes: tuple[tuple[str, float], ...] = (("none", 0.0),),
                     rho_inf: float = 1.0, measure: str = "peak",
                     directions: tuple[str, ...] = tuple(DIRECTIONS)) -> tuple[float, str]:
    """The largest harmonic bound (``"peak"``) or ``|`` phase lag ``|`` (``"phase"``) of S
    waves over ``directions`` (default: the axis, face and body diagonals) and the
    ``(scheme, courant)`` given (:func:`~.dispersion.worst_peak_error` with the order as a
    parameter). For GLL the body diagonal is the best direction at every order measured
    (``tests/fem/test_dispersion_gll.py``), and its cell the only 3-D one (seconds per
    evaluation at N = 8): the advisor checks the axis and the face diagonal.

    Returns
    -------
    error, where : float, str

    >>> e, where = worst_peak_error(1.5, 13.3, order=4, measure="phase")
    >>> round(e, 4), where
    (0.0058, 'axis, none')
    """
    def ratio(direction: str, scheme: str, courant: float) -> float:
        return float(wavenumber_ratio(float(epw), "S", direction, float(nu), order, scheme,
                                      float(courant), float(rho_inf)))

    return worst_of(ratio, directions, epw, wavelengths, nu, schemes, rho_inf, measure)


@lru_cache(maxsize=64)
def critical_courant(order: int, nu: float = 0.3) -> float:
    """Largest stable ``c_P dt / h`` of central differences on the GLL grid of order ``N``
    (``h`` the element edge): ``2 / omega_max`` over the Bloch spectrum of the periodic cell
    (all ``3 N^3`` branches at the wave vectors ``{0, pi/2, pi}^3``; the highest modes are
    optical ones at the zone's centre and corners). An estimate for the advice: a mesh's
    free surface raises its ``omega_max`` a little (a free box of order 2 / 3 measured
    0.306 / 0.163 against 0.311 / 0.174 here), so an engine takes its own step from the
    mesh (:func:`~.spectral_kernel.max_frequency_squared`). Order 1 (nodal quadrature) is
    ``sqrt(3/5)`` at ``nu = 1/4``, below the Gauss-integrated trilinear grid's 1 (its
    stiffness is not under-integrated at the zone corner).

    >>> round(critical_courant(1, 0.25), 6), round(critical_courant(4, 0.25), 4)
    (0.774597, 0.1115)
    """
    n = check_order(order)
    q = np.linspace(0.0, np.pi, _ZONE_POINTS)
    grid = np.stack(np.meshgrid(q, q, q, indexing="ij"), axis=-1).reshape(-1, 3)
    top = 0.0
    for kh in np.unique(np.sort(grid, axis=1), axis=0):          # the cube's symmetry
        A, _, _ = _cell_problem(n, float(nu), np.where(kh == 0.0, 1e-300, kh))
        top = max(top, _largest_eigenvalue(A))
    return float(2.0 / np.sqrt(top) * _cp_over_cs(nu))


#: Cell problems up to this size get the largest eigenvalue from a full ``eigvalsh``; larger
#: ones from Lanczos (ARPACK, a fixed start vector: the same answer on every run), which
#: is ~10 times cheaper at order 7 (0.03 s against 0.35 s for 1,029 unknowns, measured).
_LANCZOS_FROM = 200
#: Relative accuracy of the Lanczos eigenvalue (the step's Courant number to ~1e-12).
_LANCZOS_TOL = 1e-12


def _largest_eigenvalue(A: np.ndarray) -> float:
    """The largest eigenvalue of the Hermitian ``A``."""
    if len(A) < _LANCZOS_FROM:
        return float(np.linalg.eigvalsh(A)[-1])
    v0 = np.ones(len(A), dtype=A.dtype)
    return float(eigsh(A, k=1, which="LA", tol=_LANCZOS_TOL, v0=v0,
                       return_eigenvectors=False)[0])
