"""Dispersion of the Rayleigh wave on a hexahedral grid's half-space.

:mod:`railvib_hpc.fem.dispersion` gives the plane waves of an unbounded cubic hex8 grid;
the surface's own wave is a different mode of the grid: its depth profile is sampled by
the elements too. This module finds it as a Bloch mode: one column of unit cubes, periodic
in ``x`` and ``y`` with the horizontal wave vector ``k d`` (``d`` a grid axis or a face
diagonal; the phases of :func:`~.dispersion.bloch_frequencies`), ``n`` elements deep on a
fixed base, free on top. Its lowest mode is the grid's Rayleigh wave once the column is a
few wavelengths deep (the wave decays as ``exp(-0.85 k z)``; four wavelengths change the
result by less than 1e-8 from six; the horizontally polarised modes start at ``c_S k``,
above it).

Verified against the moving harmonic load's FE runs (tests/transient/test_moving_harmonic_load.py):
the phase the FE wave collects per wavelength ahead of the load is this relation's, times
the Doppler factor ``c_R / (c_R - c)`` (the wave ahead has ``|k| = omega_0 / (c_R - c)``:
a phase-speed error ``epsilon`` becomes ``epsilon c_R / (c_R - c)`` in ``k``).

Examples
--------
At 64 elements per wavelength the lumped grid's Rayleigh speed is within 0.04 % of
``c_R = 0.91940 c_S`` (``nu = 1/4``):

>>> round(rayleigh_frequency(2 * np.pi / 64, nu=0.25, mass="lumped") / (2 * np.pi / 64), 4)
0.919
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import solve_banded
from scipy.optimize import brentq

from .dispersion import (
    _CUBE,
    MASSES,
    _cp_over_cs,
    _element,
    time_frequency,
    worst_of,
)
from .halfspace import rayleigh_mach_limit

__all__ = ["DEPTH_WAVELENGTHS", "SURFACE_DIRECTIONS", "rayleigh_frequency",
           "rayleigh_wavenumber_ratio", "worst_surface_error"]

#: Depth of the column in wavelengths (its base changes the result by < 1e-8 from 4 to 6).
DEPTH_WAVELENGTHS = 4.0


#: Horizontal directions of the surface wave (of :data:`~.dispersion.DIRECTIONS`).
SURFACE_DIRECTIONS = {"axis": np.array([1.0, 0.0]),
                      "face_diagonal": np.array([1.0, 1.0]) / math.sqrt(2.0)}


def _column_blocks(kh: float, direction: str, nu: float, mass: str, formulation: str):
    """The element's stiffness condensed on its two levels with the Bloch phases of the
    horizontal wave vector, (2, 3, 2, 3), and its lumped or consistent level mass (2, 2)."""
    K, m = _element(float(nu), formulation)
    kvec = kh * SURFACE_DIRECTIONS[direction]
    phase = np.exp(1j * ((_CUBE[None, :, :2] - _CUBE[:, None, :2]) @ kvec))   # (a, b)
    level = np.eye(2)[_CUBE[:, 2].astype(int)]                             # (a, level)
    Ke = np.einsum("ap,ab,aibj,bq->piqj", level, phase, K, level)
    if mass == "lumped":
        me = np.diag(level.T @ m.sum(axis=1)).astype(complex)   # row sums, unphased
    else:
        me = np.einsum("ap,ab,ab,bq->pq", level, phase, m, level)
    return Ke, me


def rayleigh_frequency(kh: float, nu: float = 0.3, mass: str = "consistent",
                       formulation: str = "bbar", depth: int | None = None,
                       direction: str = "axis") -> float:
    """``omega_h h / c_S`` of the grid's Rayleigh wave of wavenumber ``k`` (``kh = k h``).

    Parameters
    ----------
    kh
        Wavenumber times the element edge, ``0 < kh < pi``.
    nu
        Poisson's ratio.
    mass
        ``"consistent"`` or ``"lumped"`` (row sum).
    formulation
        Stiffness of :func:`~railvib_hpc.fem.hex8.hex8_stiffness`.
    depth
        Elements in the column (default: :data:`DEPTH_WAVELENGTHS` wavelengths).
    direction
        A key of :data:`SURFACE_DIRECTIONS`.

    Returns
    -------
    float
        The lowest frequency of the periodic column (semidiscrete, no time scheme).
    """
    if mass not in MASSES:
        raise ValueError(f"mass must be one of {MASSES}, got {mass!r}")
    n_el = depth or int(math.ceil(DEPTH_WAVELENGTHS * 2.0 * math.pi / kh))
    Ke, me = _column_blocks(kh, direction, nu, mass, formulation)
    K, M = _banded(Ke, me, n_el)
    return math.sqrt(_lowest(K, M, rayleigh_mach_limit(nu) * kh))


#: Half-bandwidth of the column's matrices: three displacements per level, neighbours only.
_BAND = 5
#: Inverse iterations at the fixed shift, then Rayleigh-quotient iterations (cubic).
_INVERSE_STEPS, _RQI_STEPS = 8, 4


def _banded(Ke: np.ndarray, me: np.ndarray, n_el: int) -> tuple[np.ndarray, np.ndarray]:
    """The column's K and M in LAPACK's general band storage (``ab[u + i - j, j]``),
    levels 1..n (the base, level 0, fixed), ``u = l = 5``."""
    n = 3 * n_el
    blocks_k = np.zeros((2, 2, 3, 3), complex)
    blocks_k[:] = Ke.transpose(0, 2, 1, 3)                     # (p, q, i, j)
    blocks_m = me[:, :, None, None] * np.eye(3)[None, None]
    out = []
    for blocks in (blocks_k, blocks_m):
        ab = np.zeros((2 * _BAND + 1, n), complex)
        for p in (0, 1):
            for q in (0, 1):
                # element e couples levels e + p and e + q; unknown index (level - 1) * 3 + c
                lev_r, lev_c = np.arange(n_el) + p, np.arange(n_el) + q
                ok = (lev_r >= 1) & (lev_c >= 1)
                for i in range(3):
                    for j in range(3):
                        r = 3 * (lev_r[ok] - 1) + i
                        c = 3 * (lev_c[ok] - 1) + j
                        np.add.at(ab, (_BAND + r - c, c), blocks[p, q, i, j])
        out.append(ab)
    return out[0], out[1]


def _band_matvec(ab: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x`` of a band-stored matrix."""
    n = x.size
    y = np.zeros(n, complex)
    for d in range(-_BAND, _BAND + 1):                         # diagonal i - j = d
        row = ab[_BAND + d]
        if d >= 0:
            y[d:] += row[:n - d] * x[:n - d]
        else:
            y[:n + d] += row[-d:] * x[-d:]
    return y


def _lowest(K: np.ndarray, M: np.ndarray, omega_guess: float) -> float:
    """The lowest eigenvalue of ``K x = lambda M x`` (Hermitian, M positive definite):
    inverse iteration shifted below it (half the continuum's ``omega^2``), then
    Rayleigh-quotient iteration."""
    n = K.shape[1]
    x = np.ones(n, complex)
    sigma = 0.5 * omega_guess ** 2
    lam = sigma
    for step in range(_INVERSE_STEPS + _RQI_STEPS):
        y = solve_banded((_BAND, _BAND), K - sigma * M, _band_matvec(M, x))
        x = y / math.sqrt(abs(np.vdot(y, _band_matvec(M, y))))
        lam = float(np.vdot(x, _band_matvec(K, x)).real)
        if step >= _INVERSE_STEPS - 1:
            sigma = lam
    return max(lam, 0.0)


def rayleigh_wavenumber_ratio(epw: ArrayLike, nu: float = 0.3, mass: str = "consistent",
                              scheme: str = "none", courant: float = 0.0,
                              rho_inf: float = 1.0, formulation: str = "bbar",
                              direction: str = "axis") -> np.ndarray:
    """``k_h / k``: the grid's Rayleigh wavenumber at the frequency of the exact one with
    ``epw`` elements per wavelength (> 1: the grid's wave is slower) along ``direction``.

    Parameters
    ----------
    epw
        Elements per Rayleigh wavelength.
    nu, mass, formulation, direction
        As :func:`rayleigh_frequency`.
    scheme, courant, rho_inf
        The time scheme (:func:`~.dispersion.time_frequency`) and its step as
        ``c_P dt / h`` (ignored for ``"none"``).

    Returns
    -------
    numpy.ndarray
        ``k_h / k``; the phase lag per wavelength travelled is ``k_h / k - 1`` periods.

    Examples
    --------
    >>> r = rayleigh_wavenumber_ratio([12.0, 16.0], nu=0.25, mass="lumped",
    ...                               scheme="central", courant=0.876)
    >>> np.round(r - 1, 4).tolist()
    [0.0098, 0.0054]
    """
    c_r = rayleigh_mach_limit(nu)                          # c_R / c_S
    dt = courant / _cp_over_cs(nu) if scheme != "none" else 0.0

    def stepped(q: float) -> float:
        w = rayleigh_frequency(q, nu, mass, formulation, direction=direction)
        return w if scheme == "none" else float(time_frequency(np.array([w * dt]), scheme,
                                                               rho_inf)[0][0]) / dt

    out = []
    for e in np.atleast_1d(np.asarray(epw, dtype=float)):
        k = 2.0 * math.pi / e
        try:
            kh = brentq(lambda q, k=k: stepped(q) - c_r * k, 0.5 * k,
                        min(2.0 * k, 0.99 * math.pi), xtol=1e-12 * k)
        except ValueError:           # beyond the grid's cut-off (or the scheme's limit)
            kh = math.nan
        out.append(kh / k)
    return np.array(out)


@lru_cache(maxsize=4096)
def _ratio(epw: float, direction: str, nu: float, mass: str, scheme: str, courant: float,
           rho_inf: float, formulation: str) -> float:
    """:func:`rayleigh_wavenumber_ratio` for one size (cached: the mesh check asks for the
    phase and the peak error of the same grids)."""
    return float(rayleigh_wavenumber_ratio(epw, nu, mass, scheme, courant, rho_inf,
                                           formulation, direction)[0])


def worst_surface_error(epw: float, wavelengths: float, nu: float = 0.3,
                        mass: str = "consistent",
                        schemes: tuple[tuple[str, float], ...] = (("none", 0.0),),
                        rho_inf: float = 1.0, formulation: str = "bbar",
                        measure: str = "peak") -> tuple[float, str]:
    """:func:`~.dispersion.worst_peak_error` of the grid's Rayleigh wave: the largest
    harmonic bound (``"peak"``) or ``|`` phase lag ``|`` in periods (``"phase"``; inf beyond
    the cut-off) over :data:`SURFACE_DIRECTIONS` and the time schemes ``(scheme, courant)``
    (``courant = c_P dt / h``).

    Returns
    -------
    error, where : float, str
        The error and the direction and scheme that give it.

    >>> e, where = worst_surface_error(16.0, 10.0, nu=0.25, mass="lumped")
    >>> round(e, 3), where
    (0.244, 'face_diagonal, none')
    """
    def ratio(direction: str, scheme: str, courant: float) -> float:
        return _ratio(float(epw), direction, float(nu), mass, scheme, float(courant),
                      float(rho_inf), formulation)

    return worst_of(ratio, SURFACE_DIRECTIONS, epw, wavelengths, nu, schemes, rho_inf, measure)
