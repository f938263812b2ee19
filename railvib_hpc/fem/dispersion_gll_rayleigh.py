"""Dispersion of the Rayleigh wave on a half-space of spectral hexahedra (GLL, order N).

The counterpart of :mod:`.dispersion_rayleigh` for the elements of :mod:`.spectral_kernel`:
one column of cubic GLL elements (edge ``h``, order ``N``), periodic in ``x`` and ``y`` with
the horizontal wave vector's Bloch phases (nodes with index ``N`` are the next column's
index 0; along a grid axis the ``y`` direction is condensed to one node, the fields being
constant along it), :data:`~.dispersion_rayleigh.DEPTH_WAVELENGTHS` wavelengths deep on a
fixed base, free on top. Its lowest mode is the grid's Rayleigh wave (the wave decays as
``exp(-0.85 k z)``; the horizontally polarised and body modes start at ``c_S k``, above it).
The eigenproblem ``K(k) x = omega^2 M x`` (sparse Hermitian, the lumped GLL mass) is solved
near the continuum's ``(c_R k)^2`` by block inverse iteration (one sparse LU), started from
the continuum's Rayleigh decay profiles; of the Ritz pairs the one whose surface motion
matches ``exp(i k . x)`` is taken. That is the physical wave even where ``k h > pi``, where
the column's lowest mode is the alias ``k - 2 pi / h`` (the Bloch phase cannot tell them
apart; the trilinear module never gets there: its grid resolves ``k h < pi`` only).

Sizes as in :mod:`.dispersion_gll`: ``epw`` elements per Rayleigh wavelength (``N epw``
points), ``courant = c_P dt / h``.

Examples
--------
At 1.5 elements (6 points) per wavelength, order 4's Rayleigh wave is within 0.1 % of
``c_R`` (the trilinear lumped grid at 6 per wavelength: 5 % slow):

>>> import math
>>> from railvib_hpc.fem.dispersion_gll_rayleigh import rayleigh_wavenumber_ratio
>>> r = float(rayleigh_wavenumber_ratio(1.5, nu=0.25, order=4)[0])
>>> bool(abs(r - 1) < 1e-3)
True
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse.linalg import splu

from .dispersion import _cp_over_cs, time_frequency, worst_of
from .dispersion_gll import BLOCH_MATCH, unit_element
from .dispersion_rayleigh import DEPTH_WAVELENGTHS, SURFACE_DIRECTIONS
from .gll import check_order, gll_points
from .halfspace import rayleigh_mach_limit

__all__ = ["MIN_POINTS_PER_WAVELENGTH", "ZONE_WINDOW", "checked_surface_error",
           "rayleigh_frequency", "rayleigh_wavenumber_ratio", "worst_surface_error"]

#: Fewest GLL points per Rayleigh wavelength (``N epw``) at which the relation is trusted:
#: ``N`` points per element resolve up to ``k h ~ N pi / 2`` (:func:`rayleigh_frequency`),
#: 4 points per wavelength. Below it the column's Bloch modes alias and the selection can
#: match a spurious mode (measured, nu = 0.3, 3 wavelengths, the semidiscrete grid: order 5
#: at 2.5 points 5.3 %, order 3 at 3 points 4e-5 and order 8 at 3.5 points 0.2 %, where the
#: neighbouring sizes match none).
MIN_POINTS_PER_WAVELENGTH = 4.0
#: Relative half-width of the frequency window whose worst error
#: :func:`checked_surface_error` takes. Within about 1 % of ``k h = m pi`` (the lattice's
#: zone boundaries: the GLL grid's nodes are not evenly spaced and it has narrow stop bands
#: there, and the wave and its alias are degenerate) the selected mode can be another
#: branch's: measured at order 3, ``k h = pi (1 +- 1e-3)`` gave ``omega_h / (c_R k) - 1`` of
#: -2.6e-3 .. -4.6e-3, against +1.5e-3 and +4.2e-3 at 6.1 and 5.9 points per wavelength on
#: either side, and NaN at order 4 and 8 just above ``k h = 2 pi`` and ``4 pi``. The
#: window's ends lie outside that band; the error grows with the frequency on each branch
#: (and jumps up across a stop band), so the window's upper end bounds it from above.
ZONE_WINDOW = 0.02

#: Fixed-point steps of :func:`rayleigh_wavenumber_ratio` at most, and the relative change
#: at which it stops (the inverse iteration's eigenvalues are good to ~1e-10; phase errors
#: of interest are >= 1e-6 per wavelength).
_FIXED_POINT_STEPS, _FIXED_POINT_TOL = 30, 1e-9
#: Where ``k h`` is a multiple of ``pi`` the Bloch phase is ``+-1`` and the wave and its
#: alias ``k - 2 pi m / h`` are one degenerate pair: the iteration steps off by this
#: relative amount.
_ALIAS_NUDGE = 1e-6


def _column(n: int, nu: float, kvec: np.ndarray, n_el: int):
    """The column's sparse ``K(k)`` (the element's nonzeros only), its lumped mass per DOF
    and the free nodes' positions (x, y, depth below the surface), the base removed."""
    k_e, m_e = unit_element(n, nu)
    n1 = n + 1
    a = np.arange(n1**3)
    ijk = np.stack([a % n1, (a // n1) % n1, a // (n1 * n1)], axis=1)
    active = np.abs(kvec) > 0.0
    nx, ny = (n if active[0] else 1), (n if active[1] else 1)
    ix = np.where(active[0], ijk[:, 0] % n, 0)
    iy = np.where(active[1], ijk[:, 1] % n, 0)
    phase = np.exp(1j * ((ijk[:, 0] == n) * active[0] * kvec[0]
                         + (ijk[:, 1] == n) * active[1] * kvec[1]))
    nq = n1**3
    ke = k_e.reshape(3 * nq, 3 * nq)
    r, c = np.nonzero(ke)
    ph = np.repeat(phase, 3)
    local = np.conj(ph[r]) * ke[r, c] * ph[c]
    size = 3 * nx * ny * n * n_el                                   # free levels 1 .. N n_el
    rows, cols, data, dofs, masses = [], [], [], [], []
    for e in range(n_el):                             # a loop over the column's levels
        z = e * n + ijk[:, 2]
        dof = np.where(z[:, None] > 0, 3 * (ix + nx * (iy + ny * (z - 1)))[:, None]
                       + np.arange(3), -1).ravel()
        keep = (dof[r] >= 0) & (dof[c] >= 0)
        rows.append(dof[r][keep])
        cols.append(dof[c][keep])
        data.append(local[keep])
        ok = dof >= 0
        dofs.append(dof[ok])
        masses.append(np.repeat(m_e, 3)[ok])
    K = sparse.csc_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
                          (size, size))
    m = np.bincount(np.concatenate(dofs), np.concatenate(masses), size)
    x, _ = gll_points(n)
    unit = (x + 1.0) / 2.0
    level = np.arange(1, n * n_el + 1)
    depth = n_el - (level // n + unit[level % n])                  # below the surface
    gz, gy, gx = np.meshgrid(depth, unit[:ny] if active[1] else [0.0],
                             unit[:nx] if active[0] else [0.0], indexing="ij")
    pos = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    return 0.5 * (K + K.getH()), m, pos


def _start_block(pos: np.ndarray, kvec: np.ndarray, nu: float) -> np.ndarray:
    """Two start vectors (per DOF): the continuum's Rayleigh decays ``exp(-q z) + exp(-s z)``
    (``q, s = k sqrt(1 - c_R^2 / c_{P,S}^2)``) times ``exp(i k . x)``, polarised along the
    horizontal wave vector and vertically."""
    k = float(np.linalg.norm(kvec))
    c_r = rayleigh_mach_limit(nu)
    q = k * math.sqrt(1.0 - (c_r / _cp_over_cs(nu)) ** 2)
    s = k * math.sqrt(1.0 - c_r**2)
    profile = np.exp(1j * (pos[:, :2] @ kvec)) * (np.exp(-q * pos[:, 2]) + np.exp(-s * pos[:, 2]))
    out = np.zeros((len(pos), 3, 2), complex)
    out[:, :, 0] = profile[:, None] * np.append(kvec / k, 0.0)
    out[:, 2, 1] = profile
    return out.reshape(-1, 2)


#: Inverse iterations at most, and the relative residual at which they stop.
_INVERSE_STEPS, _INVERSE_TOL = 20, 1e-10


def _rayleigh_mode(K, m: np.ndarray, pos: np.ndarray, kvec: np.ndarray, nu: float) -> float:
    """Block inverse iteration at the continuum's ``(c_R k)^2``, Rayleigh-Ritz, and the Ritz
    pair whose surface motion matches ``exp(i k . x)`` best: its ``omega^2`` (NaN below
    :data:`~.dispersion_gll.BLOCH_MATCH`)."""
    sigma = (rayleigh_mach_limit(nu) * float(np.linalg.norm(kvec))) ** 2
    lu = splu((K - sigma * sparse.diags(m)).tocsc(), permc_spec="MMD_AT_PLUS_A",
              options={"SymmetricMode": True})       # Hermitian: 2.5x faster (N = 8)
    root = np.sqrt(m)[:, None]
    y = _start_block(pos, kvec, nu)
    for _ in range(_INVERSE_STEPS):
        y, _ = np.linalg.qr(root * lu.solve(m[:, None] * y))          # M-orthonormal
        y = y / root
        theta, z = np.linalg.eigh(np.conj(y.T) @ (K @ y))
        modes = y @ z
        residual = np.linalg.norm((K @ modes - (m[:, None] * modes) * theta) / root, axis=0)
        if residual.max() <= _INVERSE_TOL * theta.max():
            break
    top = pos[:, 2] == 0.0
    wave = np.exp(1j * (pos[top, :2] @ kvec))
    weight = m[::3][top]
    surface = modes.reshape(len(pos), 3, -1)[top]                     # (nodes, 3, pairs)
    # per component the projection onto exp(i k . x), relative to the surface motion
    proj = np.einsum("n,nj...->j...", np.conj(wave) * weight, surface)   # (3, pairs)
    match = (np.sqrt(np.sum(np.abs(proj) ** 2, axis=0))
             / np.sqrt(np.einsum("n,njp->p", weight, np.abs(surface) ** 2) * weight.sum()))
    good = np.flatnonzero(match >= BLOCH_MATCH)
    # several true modes of this k match (Rayleigh and the column's body modes above c_S k):
    # the Rayleigh wave is the lowest of them; the alias k - 2 pi / h does not match
    return float(theta[good].min()) if good.size else math.nan


def rayleigh_frequency(kh: float, order: int = 4, nu: float = 0.3, depth: int | None = None,
                       direction: str = "axis") -> float:
    """``omega_h h / c_S`` of the GLL grid's Rayleigh wave of wavenumber ``k`` (``kh = k h``).

    Parameters
    ----------
    kh
        Wavenumber times the element edge (any positive value: ``N`` points per element
        resolve up to ``kh ~ N pi / 2``).
    order
        ``N`` (1..8).
    nu
        Poisson's ratio.
    depth
        Elements in the column (default: :data:`~.dispersion_rayleigh.DEPTH_WAVELENGTHS`
        wavelengths).
    direction
        A key of :data:`~.dispersion_rayleigh.SURFACE_DIRECTIONS`.

    Returns
    -------
    float
        The lowest frequency of the periodic column (semidiscrete).

    Examples
    --------
    >>> w = rayleigh_frequency(0.5, order=3, nu=0.25)
    >>> round(w / 0.5, 4)                        # c_R / c_S = 0.9194 for nu = 1/4
    0.9194
    """
    n = check_order(order)
    n_el = depth or int(math.ceil(DEPTH_WAVELENGTHS * 2.0 * math.pi / kh))
    kvec = np.zeros(2)
    kvec[:] = kh * SURFACE_DIRECTIONS[direction]
    K, m, pos = _column(n, float(nu), kvec, n_el)
    return math.sqrt(max(_rayleigh_mode(K, m, pos, kvec, float(nu)), 0.0))


@lru_cache(maxsize=4096)
def _frequency(kh: float, n: int, nu: float, direction: str) -> float:
    return rayleigh_frequency(kh, n, nu, direction=direction)


def rayleigh_wavenumber_ratio(epw: ArrayLike, nu: float = 0.3, order: int = 4,
                              scheme: str = "none", courant: float = 0.0,
                              rho_inf: float = 1.0, direction: str = "axis") -> np.ndarray:
    """``k_h / k`` of the GLL grid's Rayleigh wave at the frequency of the exact one with
    ``epw`` elements per wavelength (> 1: slower), along ``direction``
    (:func:`~.dispersion_rayleigh.rayleigh_wavenumber_ratio` with the order as a
    parameter).

    Parameters
    ----------
    epw
        Elements per Rayleigh wavelength.
    nu, order, direction
        As :func:`rayleigh_frequency`.
    scheme, courant, rho_inf
        The time scheme (:func:`~.dispersion.time_frequency`) and its step ``c_P dt / h``.

    Returns
    -------
    numpy.ndarray
        ``k_h / k`` (NaN beyond the scheme's stability limit).

    Examples
    --------
    >>> r = rayleigh_wavenumber_ratio([1.0, 2.0], nu=0.25, order=4)
    >>> bool(abs(r[1] - 1) < abs(r[0] - 1))            # finer is better
    True
    """
    n = check_order(order)
    c_r = rayleigh_mach_limit(nu)                          # c_R / c_S
    dt = courant / _cp_over_cs(nu) if scheme != "none" else 0.0
    out = []
    for e in np.atleast_1d(np.asarray(epw, dtype=float)):
        k = 2.0 * math.pi / e
        target = c_r * k
        kappa = k
        for _ in range(_FIXED_POINT_STEPS):
            w = _frequency(kappa, n, float(nu), direction)
            if not np.isfinite(w):
                w = _frequency(kappa * (1.0 + _ALIAS_NUDGE), n, float(nu), direction)
            if scheme != "none":
                w = float(time_frequency(np.array([w * dt]), scheme, rho_inf)[0][0]) / dt
            if not np.isfinite(w) or w <= 0.0:
                kappa = math.nan
                break
            new = kappa * target / w
            done = abs(new - kappa) <= _FIXED_POINT_TOL * kappa
            kappa = new
            if done:
                break
        out.append(kappa / k)
    return np.array(out)


def worst_surface_error(epw: float, wavelengths: float, nu: float = 0.3, order: int = 4,
                        schemes: tuple[tuple[str, float], ...] = (("none", 0.0),),
                        rho_inf: float = 1.0, measure: str = "peak",
                        directions: tuple[str, ...] = tuple(SURFACE_DIRECTIONS)
                        ) -> tuple[float, str]:
    """The largest harmonic bound (``"peak"``) or ``|`` phase lag ``|`` in periods
    (``"phase"``) of the GLL grid's Rayleigh wave over
    ``directions`` (keys of :data:`~.dispersion_rayleigh.SURFACE_DIRECTIONS`, default
    both) and the ``(scheme, courant)`` given. For GLL the grid axis is the worse of the
    two at every order >= 2 measured (``tests/fem/test_dispersion_gll.py``), and its
    column is 2-D (cheap), the diagonal's 3-D (seconds at N = 8).

    Returns
    -------
    error, where : float, str

    >>> e, where = worst_surface_error(1.5, 10.0, nu=0.25, order=4)
    >>> bool(e < 0.01), where.endswith("none")
    (True, True)
    """
    def ratio(direction: str, scheme: str, courant: float) -> float:
        return float(rayleigh_wavenumber_ratio(float(epw), float(nu), order, scheme,
                                               float(courant), float(rho_inf),
                                               direction)[0])

    return worst_of(ratio, directions, epw, wavelengths, nu, schemes, rho_inf, measure)


def checked_surface_error(epw: float, wavelengths: float, nu: float = 0.3, order: int = 4,
                          schemes: tuple[tuple[str, float], ...] = (("none", 0.0),),
                          rho_inf: float = 1.0, measure: str = "peak",
                          directions: tuple[str, ...] = tuple(SURFACE_DIRECTIONS)
                          ) -> tuple[float, str]:
    """:func:`worst_surface_error` as a mesh check can trust it: the worst over the band's
    top frequency and the window ``1 +- ZONE_WINDOW`` about it (the frequency ``s f`` has
    ``epw / s`` elements per wavelength and ``s wavelengths`` to the probe; the window's
    ends below :data:`MIN_POINTS_PER_WAVELENGTH` are left out), and "not resolved" (the
    peak bound 1, the phase inf, as beyond the trilinear grid's cut-off) when the top
    frequency has fewer than :data:`MIN_POINTS_PER_WAVELENGTH` points per wavelength.

    Returns
    -------
    error, where : float, str

    Examples
    --------
    >>> checked_surface_error(0.7, 10.0, nu=0.25, order=4)      # 2.8 points per wavelength
    (1.0, 'fewer than 4 points per wavelength')
    >>> e, where = checked_surface_error(1.5, 10.0, nu=0.25, order=4)
    >>> bool(e < 0.01)
    True
    """
    n = check_order(order)
    if n * epw < MIN_POINTS_PER_WAVELENGTH:
        return ((1.0 if measure == "peak" else math.inf),
                f"fewer than {MIN_POINTS_PER_WAVELENGTH:g} points per wavelength")
    best = (-1.0, "")
    for s in (1.0, 1.0 + ZONE_WINDOW, 1.0 - ZONE_WINDOW):
        if n * epw / s < MIN_POINTS_PER_WAVELENGTH:
            continue
        e, where = worst_surface_error(epw / s, wavelengths * s, nu, n, schemes, rho_inf,
                                       measure, directions)
        if e > best[0]:
            best = (e, where if s == 1.0 else f"{where}, at {s:g} f")
    return best
