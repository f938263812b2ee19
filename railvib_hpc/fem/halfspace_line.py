"""Steady state of a harmonic vertical line load moving over an elastic half-space.

The reference of the moving *harmonic* load verification (docs/verification.md), in plane
strain: a vertical line load ``P cos(omega_0 t)`` per unit length (downwards) moves at a
constant speed ``c`` along ``x`` on the surface ``z = 0`` of a homogeneous, isotropic,
linearly elastic half-space ``z < 0`` (shear modulus ``mu``, Poisson's ratio ``nu``, shear
wave speed ``c_S``). Unlike a constant load, it radiates: Rayleigh waves of wavelength
``(c_R - c) / f_0`` ahead of the load and ``(c_R + c) / f_0`` behind it (Doppler), whose
amplitude in plane strain does not decay with distance. So the comparison "at ten
wavelengths" has a meaning here (``docs/verification.md``).

Long after the switch-on the response seen from the load is steady, in ``xi = x - c t``::

    w(x, t) = Re[W(xi) exp(i omega_0 t)],   dw/dt (x fixed) = Re[V(xi) exp(i omega_0 t)],
    W(xi) = 1/(2 pi) int W^(k) exp(i k xi) dk,
    V(xi) = 1/(2 pi) int i omega(k) W^(k) exp(i k xi) dk,   omega(k) = omega_0 - c k,

(``exp(i k xi + i omega_0 t) = exp(i k x + i omega t)``: the wavenumber ``k`` is seen at
the Doppler frequency ``omega``), with the plane-strain surface compliance of the
half-space for a downward surface traction and ``w`` positive downwards::

    W^ = -P k_S^2 alpha / (mu* F),   F = (2 k^2 - k_S^2)^2 - 4 k^2 alpha beta,
    k_S^2 = omega^2 / c_S*^2,  k_P^2 = omega^2 / c_P*^2,
    alpha = sqrt(k^2 - k_P^2),  beta = sqrt(k^2 - k_S^2)   (real parts >= 0).

Sources: the surface compliance is Lamb's (1904) plane-strain problem in the wavenumber
domain (Achenbach 1973, *Wave Propagation in Elastic Solids*, ch. 7; ``F`` is Rayleigh's
function); the moving frame with ``omega = omega_0 - c k`` is that of Sheng, Jones & Petyt
(1999, *J. Sound Vib.* 228, 129-156) for loads moving along a track. At ``c = 0`` it is
the time-harmonic Lamb problem, whose far field is the Rayleigh pole alone (amplitude
``P K_R / (2 mu)``, :data:`K_R` of Lamb's Cagniard solution); as ``omega_0 -> 0`` it is
Cole & Huth's (1958) moving line load, ``dW/dxi = -P A / (pi mu xi)`` with ``A`` the
kernel of :func:`railvib_hpc.fem.halfspace.direction_kernel` along the motion. Both
limits are checked in tests/fem/test_halfspace_line.py.

The undamped limit. The moduli carry a hysteretic loss factor ``eta``, ``mu* = mu (1 + i
eta sgn(omega))`` for the time factor ``exp(i omega t)`` (the radiation condition: every
wave decays away from the load); the undamped field (``loss = 0``) is Richardson's
extrapolation of ``eta``, ``eta / 2`` and ``eta / 4`` (:data:`LOSS_EXTRAPOLATION`): the Rayleigh
waves decay as ``exp(-eta k |xi| / 2)``, so the field is smooth in ``eta``.

The integral: the trapezoidal rule on a uniform grid of ``k`` as one FFT, with the grid
step chosen so that the periodic images of the field (``2 pi / dk`` away) have decayed by
``exp(-IMAGE_DECAY)``; the point load is spread as ``(1 + cos(pi s / a)) / (2 a)`` over
``|s| <= a`` (:func:`railvib_hpc.transient.surface_load.spreading`, the FE load), whose
transform falls as ``k^-3`` and bounds the grid at ``|k| <= K_SPREAD / a``. The values at
the asked ``xi`` are cubic splines of the FFT's grid (at least :data:`XI_PER_WAVELENGTH`
points per shortest wavelength).

Examples
--------
At rest, 10 Rayleigh wavelengths from the load, the field is Lamb's Rayleigh pole
``P K_R / (2 mu)``, ``K_R / 2 = 0.1835`` for ``nu = 1/4``, times the spreading's 0.96 (and 1 %
of body waves):

>>> w, v = moving_harmonic_line_load([160.0], force=1.0, mu=1.0, nu=0.25, c_s=1.0,
...                                  speed=0.0, frequency=0.0575, half_width=2.0)
>>> round(float(abs(w[0])), 2)
0.18
"""

from __future__ import annotations

import math

import numpy as np
from scipy.fft import next_fast_len
from scipy.interpolate import CubicSpline

from .halfspace import rayleigh_mach_limit

__all__ = ["K_SPREAD", "LOSS_EXTRAPOLATION", "line_compliance", "moving_harmonic_line_load",
           "spread_transform"]

#: Largest ``|k| a`` of the grid: the spreading's transform is below ``1e-2`` there
#: (``pi^2 / (k a)^3``); the fields at ``xi`` of a few ``a`` change by less than 1e-6
#: relative from 10 to 40 (measured: tests/fem/test_halfspace_line.py).
K_SPREAD = 10.0
#: Loss factors whose fields are extrapolated to the undamped one: Richardson's rule on
#: ``eta, eta/2, eta/4``, ``(W(eta) - 6 W(eta/2) + 8 W(eta/4)) / 3`` (error ``O(eta^3)``).
LOSS_EXTRAPOLATION = (2e-3, 1e-3, 5e-4)
#: The grid step makes the slowest decaying wave fall by ``exp(-IMAGE_DECAY)`` over the
#: FFT's period ``2 pi / dk``.
IMAGE_DECAY = 30.0
#: A constant load's FFT period over the farthest ``|xi|`` asked for.
STATIC_PERIOD = 200.0
#: Fewest FFT grid points per shortest wavelength before the splines.
XI_PER_WAVELENGTH = 40


def spread_transform(k: np.ndarray, half_width: float) -> np.ndarray:
    """``int s(x) exp(-i k x) dx`` of the spreading ``(1 + cos(pi x / a)) / (2 a)`` on
    ``|x| <= a``: ``sinc(k a / pi) / (1 - (k a / pi)^2)`` (1 at ``k = 0``, real, even).

    >>> float(spread_transform(np.array([0.0]), 2.0)[0])
    1.0
    """
    u = np.asarray(k, dtype=float) * half_width / math.pi
    near = np.isclose(np.abs(u), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.sinc(u) / (1.0 - u * u)
    return np.where(near, 0.5, out)


def line_compliance(k: np.ndarray, omega: np.ndarray, mu: float, nu: float, c_s: float,
                    eta: float) -> np.ndarray:
    """``mu W^ / P``: the downward surface displacement's transform per downward line load.

    Parameters
    ----------
    k, omega
        Wavenumbers [1/m] and their frequencies [rad/s] (time factor ``exp(i omega t)``);
        broadcast together.
    mu, nu, c_s
        Shear modulus [Pa], Poisson's ratio and shear wave speed [m/s].
    eta
        Hysteretic loss factor, ``mu* = mu (1 + i eta sgn(omega))``.

    Returns
    -------
    numpy.ndarray
        Complex; ``(1 - nu) / |k|`` at ``omega = 0`` (Flamant), which the direct form
        reaches only as ``0 / 0``: where ``|k_S^2| < k^2 / 2`` the leading terms of ``F``
        (both ``O(omega^2)``) are cancelled in closed form.
    """
    k, omega = np.broadcast_arrays(np.asarray(k, dtype=float), np.asarray(omega, dtype=float))
    loss = 1.0 + 1j * eta * np.sign(omega)                   # mu* / mu
    sig = 1.0 / (c_s * c_s * loss)                           # k_S^2 / omega^2
    pi_ = sig * (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))        # k_P^2 / omega^2
    kk, w2 = k * k, omega * omega
    s, p = w2 * sig, w2 * pi_
    alpha, beta = np.sqrt(kk - p + 0j), np.sqrt(kk - s + 0j)
    small = np.abs(s) < 0.5 * kk
    with np.errstate(divide="ignore", invalid="ignore"):
        g = alpha * beta / np.where(small, kk, 1.0)
        # F / omega^2 with 4 k^4 - 4 k^2 alpha beta = 4 k^2 (p + s - p s / k^2) / (1 + g)
        f_small = (4.0 * kk * (pi_ + sig - w2 * sig * pi_ / np.where(small, kk, 1.0))
                   / (1.0 + g) - 4.0 * kk * sig + w2 * sig * sig)
        f_direct = ((2.0 * kk - s) ** 2 - 4.0 * kk * alpha * beta) / np.where(small, 1.0, w2)
        f = np.where(small, f_small, f_direct)
        return -sig * alpha / (loss * f)


def _fields(k, omega0, speed, mu, nu, c_s, eta, spread, dk):
    """FFT of ``W^`` and ``i omega W^`` times the spreading: (W, V) on the FFT's xi grid."""
    omega = omega0 - speed * k
    what = line_compliance(k, omega, mu, nu, c_s, eta) * spread / mu
    # a constant load: W^ ~ 1 / |k| at k = 0 (the plane-strain static displacement is
    # defined up to a constant; the velocity's transform is bounded)
    what[(k == 0) & (omega == 0)] = 0.0
    n = k.size
    out = []
    for g in (what, 1j * omega * what):
        # sum_j g_j exp(i k_j xi_m) dk / (2 pi), k_j = (j - n/2) dk, xi_m = (m - n/2) dxi
        f = np.fft.fftshift(np.fft.ifft(np.fft.ifftshift(g))) * n * dk / (2.0 * math.pi)
        out.append(f)
    return out


def moving_harmonic_line_load(xi, force: float, mu: float, nu: float, c_s: float,
                              speed: float, frequency: float, half_width: float,
                              loss: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Complex amplitudes of the steady downward surface displacement and velocity.

    Parameters
    ----------
    xi
        Positions relative to the load, ``x - c t`` [m] (ahead: > 0).
    force
        Amplitude ``P`` of the line load [N/m], downwards.
    mu, nu, c_s
        Shear modulus [Pa], Poisson's ratio and shear wave speed [m/s] of the soil.
    speed
        Load speed ``c`` [m/s], ``0 <= c < c_R``.
    frequency
        Load frequency ``f_0`` [Hz] (0: a constant load, the fields then real).
    half_width
        Half-width ``a > 0`` of the load's spreading along ``x`` [m] (the point load's own
        near field is singular and its transform does not decay).
    loss
        Hysteretic loss factor ``eta`` of the soil (0: the undamped field, extrapolated).

    Returns
    -------
    tuple of numpy.ndarray
        ``W(xi)`` [m] and ``V(xi)`` [m/s]: ``w = Re[W exp(i omega_0 t)]`` and the velocity
        at a fixed point ``Re[V exp(i omega_0 t)]``.

    Raises
    ------
    ValueError
        A value out of range (the speed at or above the Rayleigh speed: no steady state).
    """
    c_r = rayleigh_mach_limit(nu) * c_s
    if not (0.0 <= speed < c_r and c_s > 0 and mu > 0 and half_width > 0
            and frequency >= 0 and 0 <= loss < 1 and 0 <= nu < 0.5):
        raise ValueError(f"speed = {speed}, c_s = {c_s}, mu = {mu}, nu = {nu}, half_width = "
                         f"{half_width}, frequency = {frequency}, loss = {loss}: allowed "
                         f"0 <= speed < c_R = {c_r:.6g}, c_s, mu, half_width > 0, "
                         "frequency >= 0, 0 <= loss < 1, 0 <= nu < 0.5")
    xi = np.asarray(xi, dtype=float)
    omega0 = 2.0 * math.pi * frequency
    etas = LOSS_EXTRAPOLATION if loss == 0 else (loss,)
    k_max = K_SPREAD / half_width
    # the slowest decay: the Rayleigh wave behind the load, exp(-eta k_1 |xi| / 2)
    reach = max(float(np.abs(xi).max()), half_width)
    if omega0 > 0:
        dk = 2.0 * math.pi * (0.5 * min(etas) * omega0 / (c_r + speed)) / IMAGE_DECAY
    else:
        # a constant load's field decays as 1 / xi only: the images' sum is
        # (pi / L) cot(pi xi / L) - 1 / xi ~ -(pi^2 / 3) xi / L^2, below 1e-4 of 1 / xi
        dk = 2.0 * math.pi / (STATIC_PERIOD * reach)
    k_short = max(omega0 / max(c_r - speed, 1e-300), k_max / 8.0)   # shortest wave: ahead
    dxi_max = 2.0 * math.pi / (k_short * XI_PER_WAVELENGTH)
    n = next_fast_len(2 * int(math.ceil(max(k_max / dk, math.pi / (dxi_max * dk)))))
    n += n % 2
    k = (np.arange(n) - n // 2) * dk
    spread = spread_transform(k, half_width)
    grid = (np.arange(n) - n // 2) * (2.0 * math.pi / (n * dk))
    keep = np.abs(grid) <= np.abs(xi).max() + 4.0 * (grid[1] - grid[0])
    fields = [_fields(k, omega0, speed, mu, nu, c_s, eta, spread, dk) for eta in etas]
    out = []
    for j in range(2):
        f = fields[0][j] if len(etas) == 1 else \
            (fields[0][j] - 6.0 * fields[1][j] + 8.0 * fields[2][j]) / 3.0
        f = f[keep] * force
        out.append(CubicSpline(grid[keep], f.real)(xi) + 1j * CubicSpline(grid[keep], f.imag)(xi))
    return out[0], out[1]
