"""Numerical dispersion of the trilinear hexahedron with a time scheme (docs/transient.md).

A plane wave ``u = U exp(i (k . x - omega t))`` on an unbounded uniform grid of cubic
8-node hexahedra (edge ``h``) satisfies the discrete equations exactly when ``U`` and
``omega`` solve the 3 x 3 Bloch eigenproblem

    K(k) U = omega_h^2 M(k) U,   K(k)_ij = sum_ab K^e_(ai,bj) exp(i k . (X_b - X_a)),

summed over the node pairs ``(a, b)`` of one element (every node of the grid is node ``a``
of exactly one element for each ``a``; :func:`bloch_frequencies`). The consistent mass
gives ``M(k) = sum_ab m_ab exp(i k . (X_b - X_a)) I`` (``m_ab = rho int N_a N_b``), the
row-sum lumped mass ``M = rho h^3 I``. This is the dispersion analysis of Mullen &
Belytschko (1982, "Dispersion analysis of finite element semidiscretizations of the
two-dimensional wave equation", Int. J. Numer. Meth. Eng. 18, 11-29) and Marfurt (1984,
"Accuracy of finite-difference and finite-element modeling of the scalar and elastic wave
equations", Geophysics 49, 533-549), done numerically with the project's own element
matrices (:mod:`.hex8`, any of its stiffness formulations) so that it holds in every
direction and for both masses. Along a grid axis it reduces to the 1-D two-node element
(checked in the tests)::

    consistent: omega_h^2 h^2 / c^2 = 6 (1 - cos kh) / (2 + cos kh)  ~ (kh)^2 (1 + (kh)^2/12)
    lumped:     omega_h^2 h^2 / c^2 = 4 sin^2(kh / 2)                ~ (kh)^2 (1 - (kh)^2/12)

so the consistent mass makes waves too fast and the lumped mass too slow, by
``(kh)^2 / 24`` in phase velocity each (Marfurt 1984).

The time scheme adds its own dispersion (Hughes 1987, "The Finite Element Method", ch. 9):
a mode of frequency ``omega_h`` oscillates in the stepped solution with ``Omega``,

    central differences (the explicit engine):  sin(Omega dt / 2) = omega_h dt / 2,
    trapezoidal rule (generalized-alpha, rho_inf = 1): tan(Omega dt / 2) = omega_h dt / 2,

and for ``rho_inf < 1`` from the principal eigenvalues of the amplification matrix of
Chung & Hulbert (1993, J. Appl. Mech. 60, 371-375) (:func:`time_frequency`). Central
differences speed a mode up and partly cancel the lumped mass's lag (exactly in 1-D at
Courant number 1); the trapezoidal rule slows it down and partly cancels the consistent
mass's lead.

A source at frequency ``omega`` therefore launches the discrete wavenumber ``k_h`` with
``Omega(k_h) = omega`` (:func:`wavenumber_ratio`): after a distance of ``L`` wavelengths
the phase is late by ``L (k_h / k - 1)`` periods (:func:`phase_error`). The predicted
peak-velocity error is the harmonic bound ``1 - cos(2 pi phase)`` at the band's top
frequency (:func:`peak_velocity_error`), which bounds the peak error of any zero-phase
pulse inside the band; :func:`pulse_peak_error` and :func:`propagate` carry whole pulses
and time histories through the relation (FFT), which is exact between two nodes of the grid
(``tests/transient/test_dispersion_engines.py`` checks it against both engines).

Sizes are dimensionless: ``epw`` (elements per wavelength) is ``lambda / h`` of the wave
in question (``c_P / (f h)`` for P waves, ``c_S / (f h)`` for S waves) and the step enters
as the Courant number ``courant = c_P dt / h`` of the grid.

Examples
--------
>>> from railvib_hpc.fem.dispersion import phase_velocity_ratio
>>> round(float(phase_velocity_ratio(10.0, "S", "axis", mass="consistent")), 4)
1.016
>>> round(float(phase_velocity_ratio(10.0, "S", "axis", mass="lumped")), 4)
0.9831
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from .hex8 import hex8_mass, hex8_stiffness

__all__ = [
    "DIRECTIONS",
    "MASSES",
    "SCHEMES",
    "WAVES",
    "bloch_frequencies",
    "courant_of_steps",
    "critical_courant",
    "elements_needed",
    "peak_velocity_error",
    "phase_error",
    "phase_velocity_ratio",
    "propagate",
    "pulse_peak_error",
    "time_frequency",
    "wavenumber_ratio",
    "worst_of",
    "worst_peak_error",
]

#: Unit propagation directions: a grid axis, the diagonal of a face, the diagonal of the cube.
DIRECTIONS = {
    "axis": np.array([1.0, 0.0, 0.0]),
    "face_diagonal": np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0),
    "body_diagonal": np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0),
}
#: The mass matrices of :func:`bloch_frequencies`.
MASSES = ("consistent", "lumped")
#: Wave branches: the longitudinal one and the slower and faster transverse ones (equal
#: along an axis and a body diagonal).
WAVES = ("P", "S", "S_slow", "S_fast")
#: Time schemes of :func:`time_frequency`: none (the semidiscretisation, e.g. the modal
#: path), central differences (``transient.engine = "explicit"``), generalized-alpha
#: (``"direct"``; ``rho_inf = 1`` is the trapezoidal rule).
SCHEMES = ("none", "central", "generalized_alpha")
#: Bisection steps of :func:`wavenumber_ratio` within one interval of its table (2^-42 of
#: pi / 512: machine precision).
_BISECTIONS = 42
#: Points of the table on which the acoustic branch's first maximum is located.
_TABLE = 513
#: Unit cube, gmsh/VTK corner order (the element of the nondimensional grid, h = 1).
_CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float)
#: Ricker pulse of :func:`pulse_peak_error`: samples per period of the centre frequency and
#: window length in periods (the dispersed tail of 13 wavelengths at 4 elements per
#: wavelength stays well inside).
_SAMPLES_PER_PERIOD = 32
_WINDOW_PERIODS = 256


def _cp_over_cs(nu: float) -> float:
    """``c_P / c_S = sqrt(2 (1 - nu) / (1 - 2 nu))``."""
    return float(np.sqrt(2.0 * (1.0 - nu) / (1.0 - 2.0 * nu)))


@lru_cache(maxsize=64)
def _element(nu: float, formulation: str) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness (8, 3, 8, 3) and scalar consistent mass (8, 8) of the unit cube with
    ``mu = rho = 1`` (so ``c_S = 1``)."""
    E = 2.0 * (1.0 + nu)
    K = hex8_stiffness(_CUBE[None], E, nu, formulation=formulation)[0].reshape(8, 3, 8, 3)
    m = hex8_mass(_CUBE[None], 1.0)[0].reshape(8, 3, 8, 3)[:, 0, :, 0]
    return K, m


def bloch_frequencies(kh: ArrayLike, nu: float = 0.3, mass: str = "consistent",
                      formulation: str = "bbar") -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and polarisations of the plane waves of a uniform cubic hex8 grid.

    Parameters
    ----------
    kh
        Wave vectors times the element edge, shape (..., 3).
    nu
        Poisson's ratio.
    mass
        ``"consistent"`` or ``"lumped"`` (row sum).
    formulation
        Stiffness of :func:`~railvib_hpc.fem.hex8.hex8_stiffness` (``"bbar"``,
        ``"incompatible"``, ``"full"``).

    Returns
    -------
    omega : ndarray, shape (..., 3)
        ``omega_h h / c_S``, ascending.
    modes : ndarray, shape (..., 3, 3)
        Unit polarisations, ``modes[..., :, j]`` for ``omega[..., j]``.

    Examples
    --------
    >>> import numpy as np
    >>> w, _ = bloch_frequencies([0.01, 0.0, 0.0], nu=0.25)
    >>> np.round(w / 0.01, 4)                     # c_S, c_S, c_P = sqrt(3) c_S
    array([1.    , 1.    , 1.7321])
    """
    if mass not in MASSES:
        raise ValueError(f"mass must be one of {MASSES}, got {mass!r}")
    kh = np.asarray(kh, dtype=float)
    K, m = _element(float(nu), formulation)
    dx = _CUBE[None, :, :] - _CUBE[:, None, :]                       # X_b - X_a, (a, b, 3)
    phase = np.exp(1j * np.einsum("...j,abj->...ab", kh, dx))        # (..., 8, 8)
    Kk = np.einsum("...ab,aibj->...ij", phase, K)
    mk = np.einsum("...ab,ab->...", phase, m).real if mass == "consistent" \
        else np.full(kh.shape[:-1], m.sum())
    lam, vec = np.linalg.eigh(0.5 * (Kk + np.conj(np.swapaxes(Kk, -1, -2))))
    return np.sqrt(np.maximum(lam, 0.0) / mk[..., None]), vec


def time_frequency(omega_dt: ArrayLike, scheme: str = "none", rho_inf: float = 1.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Frequency and damping ratio of a mode ``omega_h`` in the stepped solution.

    Parameters
    ----------
    omega_dt
        ``omega_h dt`` of the modes.
    scheme
        ``"none"`` (exact in time), ``"central"`` (``sin(Omega dt/2) = omega_h dt/2``;
        NaN above the stability limit ``omega_h dt = 2``) or ``"generalized_alpha"``
        (Chung & Hulbert 1993 with spectral radius ``rho_inf``; ``rho_inf = 1``:
        ``tan(Omega dt/2) = omega_h dt/2``).
    rho_inf
        Spectral radius at infinite frequency of the generalized-alpha scheme.

    Returns
    -------
    Omega_dt, xi : ndarray
        ``Omega dt`` and the algorithmic damping ratio per mode.

    Examples
    --------
    >>> import numpy as np
    >>> w = 2 * np.pi / 20                           # 20 steps per period
    >>> a, _ = time_frequency(w, "generalized_alpha")
    >>> round(float(w / a - 1), 4)                   # the period error of scheme.py
    0.0082
    >>> c, _ = time_frequency(w, "central")
    >>> round(float(w / c - 1), 4)
    -0.0041
    """
    w = np.asarray(omega_dt, dtype=float)
    if scheme == "none":
        return w.copy(), np.zeros_like(w)
    if scheme == "central":
        with np.errstate(invalid="ignore"):
            return 2.0 * np.arcsin(np.where(w <= 2.0, 0.5 * w, np.nan)), np.zeros_like(w)
    if scheme != "generalized_alpha":
        raise ValueError(f"scheme must be one of {SCHEMES}, got {scheme!r}")
    if rho_inf == 1.0:                                # the trapezoidal rule, in closed form
        return 2.0 * np.arctan(0.5 * w), np.zeros_like(w)
    return _alpha_frequency(w, rho_inf)


#: Below this ``omega_h dt`` generalized-alpha's frequency and damping come from its
#: expansion, ``Omega dt = w (1 + O(w^2))`` and ``xi = O(w^3)`` (second-order accurate:
#: Chung & Hulbert 1993; at 1e-4 the terms left out are <= 4.6e-9 relative and <= 5e-13,
#: at rho_inf = 0, measured as 0.46 w^2 and 0.5 w^3), not
#: from the amplification matrix: its principal pair is a double root 1 at ``w = 0``, split
#: by ``~ w``, and a dense eigensolver resolves a double root only to ``~ sqrt(u)`` = 1.5e-8.
#: Measured at the grid's zero wavenumber (``w`` = 7.3e-9, round-off): the pair came back as
#: two real roots with OpenBLAS's Sandybridge kernel, the spurious one was picked
#: (``Omega dt = pi``) and the dispersion relation's table broke (a phase lag of +30 periods
#: predicted for -0.159 measured); at 1e-6 the eigenvalues gave ``Omega dt`` 3e-5 off.
ALPHA_SERIES_BELOW = 1e-4


def _alpha_frequency(w: np.ndarray, rho_inf: float) -> tuple[np.ndarray, np.ndarray]:
    """``Omega dt`` and damping ratio of generalized-alpha from its amplification matrix
    (below :data:`ALPHA_SERIES_BELOW`, its low-frequency limit)."""
    am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    af = rho_inf / (rho_inf + 1.0)
    g, b = 0.5 - am + af, 0.25 * (1.0 - am + af) ** 2
    # one step of u'' + w^2 u = 0 in (u, dt v, dt^2 a): L y_{n+1} = R y_n
    w2 = (w * w)[..., None, None]
    shape = w.shape + (3, 3)
    L = np.broadcast_to(np.array([[0, 0, 1 - am], [1, 0, -b], [0, 1, -g]], float), shape).copy()
    R = np.broadcast_to(np.array([[0, 0, -am], [1, 1, 0.5 - b], [0, 1, 1 - g]], float),
                        shape).copy()
    L[..., 0, 0] = (w2 * (1.0 - af))[..., 0, 0]
    R[..., 0, 0] = (-w2 * af)[..., 0, 0]
    lam = np.linalg.eigvals(np.linalg.solve(L, R))
    pick = np.take_along_axis(lam, np.argmax(np.abs(lam.imag), axis=-1)[..., None], -1)[..., 0]
    phase = np.abs(np.angle(pick))
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = np.where(phase > 0, -np.log(np.abs(pick)) / phase, np.inf)
    low = np.abs(w) < ALPHA_SERIES_BELOW
    return np.where(low, w, np.where(phase > 0, phase, np.nan)), np.where(low, 0.0, xi)


def critical_courant(nu: float = 0.3, formulation: str = "bbar", points: int = 9) -> float:
    """Largest stable ``c_P dt / h`` of central differences on the lumped-mass grid.

    ``2 / omega_max`` with ``omega_max`` the largest Bloch frequency over the Brillouin zone
    (sampled on ``points^3`` wave vectors of ``[0, pi]^3``, which include the zone's
    corners and the ends of its axes). For the hexahedra of :mod:`.hex8` it is 1: the
    highest mode is the P wave of wavelength ``2 h`` along an axis, ``omega_max = 2 c_P / h``,
    as in the 1-D chain.

    >>> round(critical_courant(0.3), 4)
    1.0
    """
    q = np.linspace(0.0, np.pi, points)
    kh = np.stack(np.meshgrid(q, q, q, indexing="ij"), axis=-1).reshape(-1, 3)
    w, _ = bloch_frequencies(kh, nu, "lumped", formulation)
    return float(2.0 / w.max() * _cp_over_cs(nu))


def courant_of_steps(epw: float, steps_per_period: float, wave: str = "S",
                     nu: float = 0.3) -> float:
    """``c_P dt / h`` of a step with ``steps_per_period`` steps per period of the frequency
    that has ``epw`` elements per wavelength of ``wave`` (the direct engine's automatic
    step at ``transient.f_max``)."""
    ratio = 1.0 if wave == "P" else _cp_over_cs(nu)
    return float(ratio * epw / steps_per_period)


@lru_cache(maxsize=64)
def _line_terms(direction: str, nu: float, mass: str, formulation: str
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Bloch sums of :func:`bloch_frequencies` along one direction ``d``, grouped by the
    distinct node offsets ``s = d . (X_b - X_a)``: ``K(kappa d) = sum_s K_s exp(i kappa s)``
    and likewise the mass (the lumped one: its total at ``s = 0``)."""
    K, m = _element(nu, formulation)
    dx = _CUBE[None, :, :] - _CUBE[:, None, :]
    s = np.round(dx @ DIRECTIONS[direction], 12)
    shifts = np.unique(s)
    K_terms = np.stack([np.einsum("ab,aibj->ij", (s == v).astype(float), K) for v in shifts])
    if mass == "consistent":
        m_terms = np.array([m[s == v].sum() for v in shifts])
    elif mass == "lumped":
        m_terms = np.where(shifts == 0.0, m.sum(), 0.0)
    else:
        raise ValueError(f"mass must be one of {MASSES}, got {mass!r}")
    return shifts, K_terms.astype(complex), m_terms.astype(complex)


def _branch(omega: np.ndarray, modes: np.ndarray, direction: np.ndarray, wave: str
            ) -> np.ndarray:
    """The frequencies of one wave branch: P is the polarisation closest to the direction."""
    along = np.abs(np.einsum("...ij,i->...j", modes, direction))
    p = np.argmax(along, axis=-1)
    if wave == "P":
        return np.take_along_axis(omega, p[..., None], -1)[..., 0]
    s = np.sort(np.where(np.arange(3) == p[..., None], np.inf, omega), axis=-1)
    return s[..., 0] if wave == "S_slow" else s[..., 1]


def wavenumber_ratio(epw: ArrayLike, wave: str = "S", direction: str = "axis",
                     nu: float = 0.3, mass: str = "consistent", scheme: str = "none",
                     courant: float = 0.0, rho_inf: float = 1.0,
                     formulation: str = "bbar") -> np.ndarray:
    """``k_h / k``: the discrete wavenumber a source of frequency ``f`` launches, over the
    exact one.

    Parameters
    ----------
    epw
        Elements per wavelength of ``wave`` at ``f`` (``lambda / h``).
    wave
        ``"P"``, ``"S_slow"``, ``"S_fast"`` (the transverse branches; equal along an axis
        and a body diagonal) or ``"S"``, the one of the two with the larger error.
    direction
        A key of :data:`DIRECTIONS`.
    nu
        Poisson's ratio.
    mass
        ``"consistent"`` or ``"lumped"``.
    scheme, courant, rho_inf
        Time scheme (:func:`time_frequency`) and its step as ``c_P dt / h``; ignored for
        ``scheme = "none"``.
    formulation
        Stiffness formulation of the hexahedron.

    Returns
    -------
    ndarray
        ``k_h / k`` (> 1: the numerical wave is slower); NaN where the grid cannot carry
        the frequency (beyond the branch's cut-off).
    """
    if wave == "S":
        a, b = (wavenumber_ratio(epw, w, direction, nu, mass, scheme, courant, rho_inf,
                                 formulation) for w in ("S_slow", "S_fast"))
        return np.where(np.abs(a - 1.0) >= np.abs(b - 1.0), a, b)
    if wave not in WAVES:
        raise ValueError(f"wave must be one of {WAVES}, got {wave!r}")
    d = DIRECTIONS[direction]
    speed = _cp_over_cs(nu) if wave == "P" else 1.0                 # c / c_S
    dt = courant / _cp_over_cs(nu) if scheme != "none" else 0.0     # dt c_S / h

    shifts, K_terms, m_terms = _line_terms(direction, float(nu), mass, formulation)

    def discrete(kappa: np.ndarray) -> np.ndarray:
        # bloch_frequencies along d: the phases take only the few values exp(i kappa s)
        ph = np.exp(1j * kappa[..., None] * shifts)
        Kk = np.einsum("...v,vij->...ij", ph, K_terms)
        lam, modes = np.linalg.eigh(0.5 * (Kk + np.conj(np.swapaxes(Kk, -1, -2))))
        w = np.sqrt(np.maximum(lam, 0.0) / (ph @ m_terms).real[..., None])
        w = _branch(w, modes, d, wave)
        if scheme == "none":
            return w
        return time_frequency(w * dt, scheme, rho_inf)[0] / dt

    # the branch rises from 0 to its first maximum (the zone boundary along the axis)
    kmax = np.pi / np.abs(d).max()
    table = np.linspace(0.0, kmax, _TABLE)
    values = np.nan_to_num(discrete(table), nan=-np.inf)
    falls = np.flatnonzero(np.diff(values) <= 0.0)
    top = table[falls[0]] if falls.size else kmax
    epw = np.asarray(epw, dtype=float)
    k = 2.0 * np.pi / epw                                            # exact k h
    target = speed * k                                               # omega h / c_S
    # bracket in the table's rising part, then bisect within one table interval
    rising = table <= top
    i = np.clip(np.searchsorted(values[rising], target), 1, int(rising.sum()) - 1)
    lo, hi = table[i - 1], np.minimum(table[i], top)
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        up = np.nan_to_num(discrete(mid), nan=np.inf) >= target
        lo, hi = np.where(up, lo, mid), np.where(up, mid, hi)
    ok = np.nan_to_num(discrete(np.full_like(k, top)), nan=-np.inf) >= target
    return np.where(ok, 0.5 * (lo + hi) / k, np.nan)


def phase_velocity_ratio(epw: ArrayLike, wave: str = "S", direction: str = "axis",
                         **kw) -> np.ndarray:
    """``c_h / c = k / k_h`` at a fixed frequency (arguments of :func:`wavenumber_ratio`)."""
    return 1.0 / wavenumber_ratio(epw, wave, direction, **kw)


def phase_error(epw: ArrayLike, wavelengths: float = 1.0, wave: str = "S",
                direction: str = "axis", **kw) -> np.ndarray:
    """Phase lag after ``wavelengths`` wavelengths travelled, in periods:
    ``L (k_h / k - 1)`` (> 0: the numerical wave arrives late; arguments of
    :func:`wavenumber_ratio`).

    >>> round(float(phase_error(6.0, 13.3, "S", mass="consistent")), 3)   # 25 m, 80 Hz, 150 m/s
    -0.541
    """
    return wavelengths * (wavenumber_ratio(epw, wave, direction, **kw) - 1.0)


def peak_velocity_error(epw: ArrayLike, wavelengths: float, wave: str = "S",
                        direction: str = "axis", **kw) -> np.ndarray:
    """Predicted relative error of the peak velocity after ``wavelengths`` wavelengths.

    The conservative measure of the mesh check: a harmonic wave of the band's frequency
    whose phase is off by ``dphi = 2 pi`` :func:`phase_error` reads, at the exact wave's
    crest, ``cos(dphi)`` of its amplitude, so the error is ``1 - cos(dphi)`` (the whole
    error where the phase is off by a half period or more: 1 from ``|dphi| >= pi/2`` on,
    capped there), plus the amplitude lost to algorithmic damping (generalized-alpha with
    ``rho_inf < 1``: ``1 - exp(-2 pi xi L)``). A transient pulse's measured peak moves
    less (its crest slides under the envelope: :func:`pulse_peak_error`); the harmonic
    bound is the one that holds for a long, narrow-band passage.

    >>> round(float(peak_velocity_error(6.0, 13.3, "S", mass="consistent")), 2)
    1.0
    >>> round(float(peak_velocity_error(20.0, 13.3, "S", mass="consistent")), 3)
    0.057
    """
    return _harmonic(phase_error(epw, wavelengths, wave, direction, **kw),
                     _damping(epw, wave, **kw), wavelengths)


def _harmonic(phase: np.ndarray, xi: ArrayLike, wavelengths: float) -> np.ndarray:
    """The harmonic bound of :func:`peak_velocity_error` from the phase error [periods] and
    the algorithmic damping ratio (NaN phase, beyond the cut-off: 1)."""
    dphi = 2.0 * np.pi * np.abs(phase)
    with np.errstate(invalid="ignore"):
        err = np.where(dphi >= 0.5 * np.pi, 1.0, 1.0 - np.cos(dphi))
    err = 1.0 - (1.0 - err) * np.exp(-2.0 * np.pi * np.asarray(xi) * wavelengths)
    return np.where(np.isnan(dphi), 1.0, err)


def _damping(epw: ArrayLike, wave: str, **kw) -> np.ndarray:
    """Algorithmic damping ratio of generalized-alpha (``rho_inf < 1``) at the frequency
    with ``epw`` elements per wavelength (taken at ``omega dt``, the source's frequency, for
    ``Omega dt``: they differ by the period error); 0 for the other schemes."""
    epw = np.asarray(epw, dtype=float)
    scheme, rho_inf = kw.get("scheme", "none"), kw.get("rho_inf", 1.0)
    if scheme != "generalized_alpha" or rho_inf >= 1.0:
        return np.zeros_like(epw)
    speed = 1.0 if wave == "P" else 1.0 / _cp_over_cs(kw.get("nu", 0.3))   # c / c_P
    return time_frequency(2.0 * np.pi / epw * speed * kw.get("courant", 0.0), scheme,
                          rho_inf)[1]


def _transfer(fr: np.ndarray, epw: float, wavelengths: float, wave: str, direction: str,
              retarded: bool, **kw) -> np.ndarray:
    """``exp(-i k_h(f') D)`` at the frequencies ``fr`` (in units of the reference ``f``),
    less the exact wave's ``exp(-i k(f') D)`` when ``retarded``; 0 at ``f' = 0`` and beyond
    the cut-off. ``epw``, ``wavelengths``: elements per wavelength and ``D`` in wavelengths
    at ``f``."""
    out = np.zeros(fr.shape, complex)
    pos = np.flatnonzero(fr > 0)
    ratio = wavenumber_ratio(epw / fr[pos], wave, direction, **kw)
    ok = np.isfinite(ratio)
    lag = 2.0 * np.pi * fr[pos] * wavelengths * (ratio - (1.0 if retarded else 0.0))
    # algorithmic damping: the amplitude of a mode decays as exp(-xi Omega t) and the wave
    # takes t = D / c_h to arrive (the group velocity taken as the phase velocity)
    decay = 2.0 * np.pi * _damping(epw / fr[pos], wave, **kw) * fr[pos] * wavelengths * ratio
    out[pos[ok]] = np.exp(-1j * lag[ok] - decay[ok])
    return out


def propagate(signal: ArrayLike, dt: float, h: float, c: float, distance: float,
              wave: str = "S", direction: str = "axis", **kw) -> np.ndarray:
    """A time history carried ``distance`` further by the discrete grid.

    Each frequency of ``signal`` (FFT over the samples given: pad them with zeros so that
    the propagated pulse fits) is multiplied by ``exp(-i k_h distance)``; the components
    beyond the grid's cut-off are dropped. Between two nodes of a uniform grid, for a wave
    in one direction, this is exact (it is the discrete system's own transfer).

    Parameters
    ----------
    signal
        Samples at ``dt`` [s].
    dt
        Sample step [s].
    h, c
        Element edge [m] and speed of ``wave`` [m/s].
    distance
        How far [m].
    wave, direction, kw
        As :func:`wavenumber_ratio` (``courant`` is the grid's ``c_P dt_step / h`` of the
        time scheme, not the sample step's).

    Returns
    -------
    ndarray
        The propagated samples.
    """
    v = np.asarray(signal, dtype=float)
    n = v.size
    fr = np.fft.rfftfreq(n, dt)                                       # Hz
    f_ref = c / h                                                     # one element per wavelength
    tr = _transfer(fr / f_ref, 1.0, distance / h, wave, direction, False, **kw)
    return np.fft.irfft(np.fft.rfft(v) * tr, n)


def pulse_peak_error(epw: float, wavelengths: float, wave: str = "S",
                     direction: str = "axis", pulse: str = "band", **kw
                     ) -> tuple[float, float, float]:
    """A pulse of band-top (or centre) frequency ``f`` propagated with the discrete dispersion.

    Every frequency ``f'`` of the pulse travels with its own ``k_h(f') / k(f')``
    (:func:`wavenumber_ratio` at ``epw f / f'``; the frequencies beyond the cut-off are
    lost) over ``wavelengths`` wavelengths of ``f`` (FFT, 32 samples per period of ``f``, a
    window of 256 periods; ``kw`` as :func:`wavenumber_ratio`).

    Parameters
    ----------
    pulse
        ``"band"``: the zero-phase pulse of the octave below ``f`` (a Hann taper over
        ``f/2 <= f' <= f``: all of it inside a band whose top is ``f``); its peak error is
        at most the harmonic bound of :func:`peak_velocity_error` (the crest of every
        component is off by less than at ``f``). ``"ricker"``: the Ricker wavelet of centre
        frequency ``f`` (content up to ~2.5 f, so more sensitive than a band ending at f).

    Returns
    -------
    peak, waveform, delay : float
        ``max|v_h| / max|v| - 1``, ``max|v_h - v| / max|v|`` and the shift of the
        pulse's largest value, in periods of ``f`` (> 0: late).

    >>> p, w, d = pulse_peak_error(20.0, 13.3, "S", mass="lumped")
    >>> round(p, 3), round(w, 2), round(d, 3)
    (-0.001, 0.15, 0.031)
    """
    n = _SAMPLES_PER_PERIOD * _WINDOW_PERIODS
    fr = np.fft.rfftfreq(n, 1.0 / _SAMPLES_PER_PERIOD)                # in units of f
    if pulse == "ricker":
        spec = fr**2 * np.exp(-(fr**2))
    elif pulse == "band":
        inside = (fr >= 0.5) & (fr <= 1.0)
        spec = np.where(inside, np.sin(2.0 * np.pi * (fr - 0.5)) ** 2, 0.0)
    else:
        raise ValueError(f"pulse must be 'band' or 'ricker', got {pulse!r}")
    keep = spec > 1e-10 * spec.max()
    tr = np.zeros(fr.shape, complex)
    tr[keep] = _transfer(fr[keep], epw, wavelengths, wave, direction, True, **kw)
    v = np.fft.fftshift(np.fft.irfft(spec.astype(complex), n))
    vh = np.fft.fftshift(np.fft.irfft(spec * tr, n))
    t = (np.arange(n) - n // 2) / _SAMPLES_PER_PERIOD                 # periods of f
    peak = float(np.abs(vh).max() / np.abs(v).max() - 1.0)
    waveform = float(np.abs(vh - v).max() / np.abs(v).max())
    delay = float(t[np.argmax(np.abs(vh))] - t[np.argmax(np.abs(v))])
    return peak, waveform, delay


def worst_peak_error(epw: float, wavelengths: float, nu: float = 0.3,
                     mass: str = "consistent", schemes: tuple[tuple[str, float], ...] = (
                         ("none", 0.0),), rho_inf: float = 1.0,
                     formulation: str = "bbar", measure: str = "peak") -> tuple[float, str]:
    """The largest :func:`peak_velocity_error` (``measure = "peak"``) or ``|``
    :func:`phase_error` ``|`` in periods (``"phase"``; inf beyond the cut-off) of S waves over
    the directions of :data:`DIRECTIONS` and the time schemes ``(scheme, courant)`` given.

    Returns
    -------
    error, where : float, str
        The error and the direction and scheme that give it.

    >>> e, where = worst_peak_error(20.0, 13.3, mass="consistent")
    >>> round(e, 3), where
    (0.057, 'axis, none')
    >>> e, where = worst_peak_error(20.0, 13.3, mass="consistent", measure="phase")
    >>> round(e, 3), where
    (0.054, 'axis, none')
    """
    def ratio(direction: str, scheme: str, courant: float) -> float:
        return _s_ratio(float(epw), direction, float(nu), mass, scheme, float(courant),
                        float(rho_inf), formulation)

    return worst_of(ratio, DIRECTIONS, epw, wavelengths, nu, schemes, rho_inf, measure)


def worst_of(ratio, directions, epw: float, wavelengths: float, nu: float,
             schemes: tuple[tuple[str, float], ...], rho_inf: float,
             measure: str = "peak") -> tuple[float, str]:
    """The largest harmonic bound (``"peak"``) or ``|`` phase lag ``|`` (``"phase"``) over
    ``directions`` and ``schemes``, from ``ratio(direction, scheme, courant) = k_h / k``
    (:func:`worst_peak_error`'s S waves, or the Rayleigh wave's
    :func:`~.dispersion_rayleigh.worst_surface_error`); ``(error, "direction, scheme")``."""
    if measure not in ("peak", "phase"):
        raise ValueError(f"measure must be 'peak' or 'phase', got {measure!r}")
    best = (-1.0, "")
    for direction in directions:
        for scheme, courant in schemes:
            phase = wavelengths * (ratio(direction, scheme, courant) - 1.0)
            if measure == "peak":
                xi = float(_damping(epw, "S", nu=nu, scheme=scheme, courant=courant,
                                    rho_inf=rho_inf))
                e = float(_harmonic(np.asarray(phase), xi, wavelengths))
            else:
                e = abs(phase) if np.isfinite(phase) else np.inf
            if e > best[0]:
                best = (e, f"{direction}, {scheme}")
    return best


@lru_cache(maxsize=4096)
def _s_ratio(epw: float, direction: str, nu: float, mass: str, scheme: str, courant: float,
             rho_inf: float, formulation: str) -> float:
    """:func:`wavenumber_ratio` of S waves for one size (cached: the mesh check asks for the
    phase and the peak error of the same grids)."""
    return float(wavenumber_ratio(epw, "S", direction, nu=nu, mass=mass, scheme=scheme,
                                  courant=courant, rho_inf=rho_inf, formulation=formulation))


def elements_needed(limit: float, wavelengths: float, lo: float = 2.0, hi: float = 200.0,
                    worst=None, rtol: float = 2e-3, **kw) -> float:
    """Fewest elements per wavelength with ``worst`` (default :func:`worst_peak_error`; the
    mesh check gives :func:`~.dispersion_rayleigh.worst_surface_error`) below ``limit``
    (``kw`` as :func:`worst_peak_error`; a callable ``schemes(epw)`` gives step-dependent
    schemes), to ``rtol`` (0.2 %): the bracket ``[lo, hi]`` is narrowed from ``lo`` up by
    doubling, then bisected. ``inf`` when even ``hi`` is not enough.

    >>> round(elements_needed(0.05, 13.3, mass="consistent"), 1)
    20.7
    """
    schemes = kw.pop("schemes", (("none", 0.0),))
    worst = worst or worst_peak_error

    def ok(n: float) -> bool:
        s = schemes(n) if callable(schemes) else schemes
        return worst(n, wavelengths, schemes=s, **kw)[0] < limit

    top = lo
    while not ok(top):
        if top >= hi:
            return float("inf")
        lo, top = top, min(2.0 * top, hi)
    while top - lo > rtol * top:
        mid = 0.5 * (lo + top)
        lo, top = (lo, mid) if ok(mid) else (mid, top)
    return top
