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

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import eigh
from scipy.optimize import brentq

from .dispersion import _CUBE, MASSES, _cp_over_cs, _element, time_frequency
from .halfspace import rayleigh_mach_limit

__all__ = ["DEPTH_WAVELENGTHS", "SURFACE_DIRECTIONS", "rayleigh_frequency",
           "rayleigh_wavenumber_ratio"]

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
    n = n_el + 1
    K = np.zeros((n, 3, n, 3), complex)
    M = np.zeros((n, n), complex)
    low = np.arange(n_el)
    for p, rows in ((0, low), (1, low + 1)):                  # the two levels of each element
        for q, cols in ((0, low), (1, low + 1)):
            K[rows, :, cols, :] += Ke[p, :, q, :]
            M[rows, cols] += me[p, q]
    keep = np.arange(3, 3 * n)                                # the base fixed
    Kr = K.reshape(3 * n, 3 * n)[np.ix_(keep, keep)]
    Mr = np.kron(M, np.eye(3))[np.ix_(keep, keep)]
    lam = eigh(0.5 * (Kr + Kr.conj().T), 0.5 * (Mr + Mr.conj().T), eigvals_only=True,
               subset_by_index=[0, 0])[0]
    return math.sqrt(max(float(lam.real), 0.0))


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
        kh = brentq(lambda q, k=k: stepped(q) - c_r * k, 0.5 * k, min(2.0 * k, 0.99 * math.pi),
                    xtol=1e-14 * k)
        out.append(kh / k)
    return np.array(out)
