"""Steady state of a vertical point load moving over the surface of an elastic half-space.

The reference of the moving-load verification (docs/verification.md): a constant vertical force
``P`` (downwards) moves at a constant speed ``c`` along ``x`` on the surface ``z = 0`` of a
homogeneous, isotropic, linearly elastic half-space ``z < 0`` (shear modulus ``mu``,
Poisson's ratio ``nu``, density ``rho``; optionally a hysteretic loss factor ``eta``). Below
the Rayleigh speed the response seen from the load is steady: a function of
``xi = x - c t`` and ``y`` alone.

Source. In the moving frame the surface displacement is the double Fourier integral of the
half-space's surface Green's function at the Doppler frequency ``omega = k_x c``
(Eason 1965, *Int. J. Eng. Sci.* 3, 235-270; de Barros & Luco 1994, *Wave Motion* 19,
189-210; Lefeuve-Mesgouez, Le Houedec & Peplow 2000, *Comput. Geotech.* 26, 299-327)::

    w(xi, y) = 1/(4 pi^2) iint w^(k_x, k_y) exp(i (k_x xi + k_y y)) dk_x dk_y,
    w^ = -P k_S^2 alpha / (mu F(k)),   F = (2 k^2 - k_S^2)^2 - 4 k^2 alpha beta,

with ``k^2 = k_x^2 + k_y^2``, ``k_S = omega / c_S``, ``alpha = sqrt(k^2 - (omega / c_P)^2)``,
``beta = sqrt(k^2 - k_S^2)`` (real parts >= 0) and ``w`` the downward displacement. With
``omega = k_x c`` every wavenumber scales out: in polar wavenumbers ``(k, theta)``,
``w^ = P A(theta) / (mu k)`` with::

    A(theta) = -q M_S^2 sqrt(1 - q M_P^2) / ((2 - q M_S^2)^2
               - 4 sqrt(1 - q M_P^2) sqrt(1 - q M_S^2)) * mu / mu*,   q = cos^2 theta,

(``M_S^2 = rho c^2 / mu*``, ``M_P^2 = rho c^2 / (lambda* + 2 mu*)``, the moduli
``mu* = mu (1 - i eta sgn(omega))`` for the time factor ``exp(-i omega t)``, real without
damping; ``A`` of the opposite direction is the complex conjugate). The radial
integral is the distribution ``int_0^inf exp(i k s) dk = pi delta(s) + i PV 1/s``, which
reduces the double integral to one over the direction::

    w(r, phi) = P / (2 pi mu r) [Re A(phi + pi/2)
                 - (1/pi) PV int_{-pi/2}^{pi/2} Im A(phi + psi) / cos(psi) dpsi]

(``xi = r cos phi``, ``y = r sin phi``). Without damping ``A`` is real and the second term
vanishes: the closed form of Barber (1996, *J. Appl. Mech.* 63, 245-251)
``w = P D(s) / (2 pi mu r)``, ``s = |y| / r``, symmetric fore and aft (no radiation below
the Rayleigh speed), ``D -> 1 - nu`` (Boussinesq) as ``c -> 0`` and ``D(0) = 1 - nu`` on the
load's path at any subsonic speed. It grows without bound beside the load (``s -> 1``) as
``c -> c_R``, where the Rayleigh denominator vanishes.

The vertical velocity at a fixed surface point is ``dw/dt = -c dw/dxi``
(:func:`moving_load_velocity`).

Examples
--------
>>> import math
>>> w = moving_load_displacement([3.0], [4.0], force=1.0, mu=1.0, nu=0.25, c_s=1.0,
...                              speed=1e-3)
>>> round(float(w[0] * 2 * math.pi * 5.0), 5)        # Boussinesq: (1 - nu) / (2 pi mu r)
0.75
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["DEFAULT_DIRECTIONS", "direction_kernel", "mach_numbers", "moving_load_displacement",
           "moving_load_velocity", "rayleigh_mach_limit"]

#: Gauss-Legendre nodes of the principal-value integral over the directions (damped case
#: only), over its two pieces together (checked against twice as many in the tests).
DEFAULT_DIRECTIONS = 400


def mach_numbers(speed: float, c_s: float, nu: float) -> tuple[float, float]:
    """``(M_S, M_P) = (c / c_S, c / c_P)`` of a load at ``speed`` in a soil of ``c_s``, ``nu``."""
    kappa2 = (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))            # (c_S / c_P)^2
    return speed / c_s, speed / c_s * math.sqrt(kappa2)


def rayleigh_mach_limit(nu: float) -> float:
    """``c_R / c_S``: the speed (in units of ``c_S``) at which the steady state ceases to
    exist (root of Rayleigh's equation; Achenbach 1973, eq. 5.62)."""
    kappa2 = (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))
    roots = np.roots([1.0, -8.0, 24.0 - 16.0 * kappa2, -16.0 * (1.0 - kappa2)])
    real = roots[(np.abs(roots.imag) < 1e-12) & (roots.real > 0) & (roots.real < 1)].real
    return float(math.sqrt(real.min()))


def direction_kernel(theta: np.ndarray, m_s: float, m_p: float, eta: float = 0.0
                     ) -> np.ndarray:
    """``A(theta)``: ``mu k / P`` times the downward surface displacement's transform.

    Parameters
    ----------
    theta
        Direction of the wavevector from the direction of motion [rad].
    m_s, m_p
        Mach numbers of the load against the S and P waves (:func:`mach_numbers`),
        ``m_s > 0``.
    eta
        Hysteretic loss factor of both moduli (0: elastic).

    Returns
    -------
    numpy.ndarray
        Complex ``A``; real without damping, ``1 - nu`` at ``c = 0``.
    """
    theta = np.asarray(theta, dtype=float)
    cos = np.cos(theta)
    q = cos * cos
    loss = 1.0 - 1j * eta * np.sign(cos)                     # mu* / mu, time exp(-i omega t)
    ms2, mp2 = m_s * m_s / loss, m_p * m_p / loss
    root_p, root_s = np.sqrt(1.0 - q * mp2 + 0j), np.sqrt(1.0 - q * ms2 + 0j)
    rayleigh = (2.0 - q * ms2) ** 2 - 4.0 * root_p * root_s
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = -ms2 * root_p / (rayleigh / np.where(q > 0, q, 1.0))
    # q -> 0 (wavevector across the motion, omega -> 0): the ratio's static limit
    # 1 / (2 (1 - (c_S / c_P)^2)) = 1 - nu
    static = 1.0 / (2.0 * (1.0 - (m_p / m_s) ** 2))
    ratio = np.where(q > 1e-30, ratio, static)
    return ratio / loss


def _check(speed: float, c_s: float, nu: float, eta: float) -> None:
    if not 0.0 <= nu < 0.5:
        raise ValueError(f"nu = {nu}: allowed 0 <= nu < 0.5")
    if not (c_s > 0 and speed > 0):
        raise ValueError(f"speed = {speed}, c_s = {c_s}: both must be > 0")
    limit = rayleigh_mach_limit(nu) * c_s
    if speed >= limit:
        raise ValueError(f"speed = {speed:g} m/s: at or above the Rayleigh speed "
                         f"{limit:.4g} m/s there is no steady state; allowed: < {limit:.4g}")
    if not 0.0 <= eta < 1.0:
        raise ValueError(f"eta = {eta}: allowed 0 <= eta < 1")


def _principal_value(phi: np.ndarray, m_s: float, m_p: float, eta: float,
                     n_nodes: int) -> np.ndarray:
    """``PV int_{-pi/2}^{pi/2} Im A(phi + psi) / cos(psi) dpsi`` for every ``phi``.

    ``Im A`` jumps where the Doppler frequency changes sign (``cos(phi + psi) = 0``, the
    hysteretic model's ``sgn(omega)``): the interval is split there and each piece
    integrated by Gauss-Legendre. The singular ends carry opposite residues (``A`` of the
    opposite direction is the conjugate), so ``sin(psi)`` times their mean is subtracted
    (its principal value is 0) and the rest is bounded.
    """
    half = 0.5 * math.pi
    jump = np.mod(half - phi + half, math.pi) - half             # in [-pi/2, pi/2)
    ends = 0.5 * (direction_kernel(phi + half, m_s, m_p, eta).imag
                  - direction_kernel(phi - half, m_s, m_p, eta).imag)
    t, wt = np.polynomial.legendre.leggauss(max(8, int(n_nodes) // 2))
    total = np.zeros(phi.shape)
    for lo, hi in ((np.full(phi.shape, -half), jump), (jump, np.full(phi.shape, half))):
        mid, rad = 0.5 * (hi + lo), 0.5 * (hi - lo)
        psi = mid[:, None] + rad[:, None] * t[None, :]
        im = direction_kernel(phi[:, None] + psi, m_s, m_p, eta).imag
        f = (im - np.sin(psi) * ends[:, None]) / np.cos(psi)
        total += rad * (f @ wt)
    return total


def moving_load_displacement(xi, y, force: float, mu: float, nu: float, c_s: float,
                             speed: float, eta: float = 0.0,
                             n_directions: int = DEFAULT_DIRECTIONS) -> np.ndarray:
    """Steady downward surface displacement at ``(xi, y)`` from the moving load [m].

    Parameters
    ----------
    xi, y
        Position relative to the load: ``xi = x - c t`` ahead of it (> 0), ``y`` across
        [m]; broadcast together. ``(0, 0)`` (under the load) is singular.
    force
        Load ``P`` [N], downwards.
    mu, nu, c_s
        Shear modulus [Pa], Poisson's ratio and shear-wave speed [m/s] of the soil.
    speed
        Load speed ``c`` [m/s], ``0 < c < c_R``.
    eta
        Hysteretic loss factor (0: elastic, the closed form).
    n_directions
        Nodes of the principal-value rule (damped case only; :func:`_principal_value`).

    Returns
    -------
    numpy.ndarray
        ``w`` (positive downwards), shape of the broadcast inputs.

    Raises
    ------
    ValueError
        ``speed`` at or above the Rayleigh speed, or another value out of range.
    """
    _check(speed, c_s, nu, eta)
    xi, y = np.broadcast_arrays(np.asarray(xi, dtype=float), np.asarray(y, dtype=float))
    r = np.hypot(xi, y)
    phi = np.arctan2(y, xi)
    m_s, m_p = mach_numbers(speed, c_s, nu)
    shape = direction_kernel(phi + 0.5 * math.pi, m_s, m_p, eta).real
    if eta > 0:
        shape = shape - _principal_value(phi.ravel(), m_s, m_p, eta,
                                         n_directions).reshape(phi.shape) / math.pi
    return force * shape / (2.0 * math.pi * mu * r)


def moving_load_velocity(xi, y, force: float, mu: float, nu: float, c_s: float,
                         speed: float, eta: float = 0.0,
                         n_directions: int = DEFAULT_DIRECTIONS) -> np.ndarray:
    """Steady downward surface velocity ``dw/dt = -c dw/dxi`` at ``(xi, y)`` [m/s].

    A central difference of :func:`moving_load_displacement` with the step ``1e-5 r``
    (its error ``1e-10`` relative: the field is smooth away from the load). Parameters as
    there.
    """
    xi, y = np.broadcast_arrays(np.asarray(xi, dtype=float), np.asarray(y, dtype=float))
    h = 1e-5 * np.hypot(xi, y)
    args = (force, mu, nu, c_s, speed, eta, n_directions)
    return -speed * (moving_load_displacement(xi + h, y, *args)
                     - moving_load_displacement(xi - h, y, *args)) / (2.0 * h)
