"""Lamb's problem: a vertical point load on an elastic half-space (Pekeris 1955, nu = 1/4).

Surface vertical displacement (in the direction of the load) at distance ``r`` for a step load
``P H(t)``::

    u(r, t) = P / (pi mu r) G(tau),    tau = c_S t / r,

with (``c_P = sqrt(3) c_S``, ``gamma^2 = (3 + sqrt 3) / 4`` = (c_S / c_R)^2,
``beta^2 = (3 - sqrt 3) / 4``)::

    G = 0                                                              tau < 1/sqrt(3)
    G = (6 - sqrt(3) / sqrt(tau^2 - 1/4) - sqrt(3 sqrt3 + 5) / sqrt(gamma^2 - tau^2)
         + sqrt(3 sqrt3 - 5) / sqrt(tau^2 - beta^2)) / 32                 1/sqrt(3) < tau < 1
    G = (6 - sqrt(3 sqrt3 + 5) / sqrt(gamma^2 - tau^2)) / 16              1 < tau < gamma
    G = 3/8                                                            tau > gamma

(P, S and Rayleigh arrivals at ``tau = 1/sqrt 3, 1, gamma``; ``3/8 = (1 - nu) / 2`` gives the
static limit ``P (1 - nu) / (2 pi mu r)``). The singularity at the Rayleigh arrival is
integrable: the antiderivative ``H(tau) = int G`` is closed form (arccosh, arcsin), so the
response to a smooth load ``P s(t)`` with ``s'(0) = s'(T) = 0`` is
``u(t) = P/(pi mu c_S) int_0^T s''(t') H(c_S (t - t')/r) dt'`` (integrated by parts), evaluated
here by quadrature of a continuous integrand.
"""

from __future__ import annotations

import math

import numpy as np

SQ3 = math.sqrt(3.0)
TAU_P = 1.0 / SQ3
GAMMA = math.sqrt((3.0 + SQ3) / 4.0)
BETA = math.sqrt((3.0 - SQ3) / 4.0)
A_R = math.sqrt(3.0 * SQ3 + 5.0)
A_B = math.sqrt(3.0 * SQ3 - 5.0)


def pekeris_g(tau: np.ndarray) -> np.ndarray:
    """The dimensionless step response G(tau) (finite away from tau = gamma)."""
    tau = np.asarray(tau, dtype=float)
    out = np.zeros_like(tau)
    a = (tau > TAU_P) & (tau < 1.0)
    t = tau[a]
    out[a] = (6.0 - SQ3 / np.sqrt(t * t - 0.25) - A_R / np.sqrt(GAMMA**2 - t * t)
              + A_B / np.sqrt(t * t - BETA**2)) / 32.0
    b = (tau >= 1.0) & (tau < GAMMA)
    t = tau[b]
    out[b] = (6.0 - A_R / np.sqrt(GAMMA**2 - t * t)) / 16.0
    out[tau >= GAMMA] = 3.0 / 8.0
    return out


def _h1(t):
    return (6.0 * (t - TAU_P) - SQ3 * (np.arccosh(2.0 * t) - math.acosh(2.0 * TAU_P))
            - A_R * (np.arcsin(t / GAMMA) - math.asin(TAU_P / GAMMA))
            + A_B * (np.arccosh(t / BETA) - math.acosh(TAU_P / BETA))) / 32.0


def _h2(t):
    return float(_h1(1.0)) + (6.0 * (t - 1.0) - A_R * (np.arcsin(np.minimum(t / GAMMA, 1.0))
                                                       - math.asin(1.0 / GAMMA))) / 16.0


def pekeris_h(tau: np.ndarray) -> np.ndarray:
    """``H(tau) = int_0^tau G`` (continuous, closed form)."""
    tau = np.asarray(tau, dtype=float)
    out = np.zeros_like(tau)
    a = (tau > TAU_P) & (tau <= 1.0)
    out[a] = _h1(tau[a])
    b = (tau > 1.0) & (tau <= GAMMA)
    out[b] = _h2(tau[b])
    c = tau > GAMMA
    out[c] = float(_h2(GAMMA)) + 3.0 / 8.0 * (tau[c] - GAMMA)
    return out


def pulse(t, duration: float):
    """Load pulse ``s(t) = sin^4(pi t / T)`` for ``0 <= t <= T``, else 0 (C^3: its spectrum
    falls like ``omega^-5``, so little of it lies where the mesh is dispersive)."""
    t = np.asarray(t, dtype=float)
    return np.where((t >= 0) & (t <= duration), np.sin(np.pi * t / duration) ** 4, 0.0)


def pulse_dd(t, duration: float):
    """``s''(t)`` of :func:`pulse`: ``4 (pi/T)^2 sin^2 (3 cos^2 - sin^2)``."""
    t = np.asarray(t, dtype=float)
    th = np.pi * t / duration
    s, c = np.sin(th), np.cos(th)
    out = 4.0 * (np.pi / duration) ** 2 * s * s * (3.0 * c * c - s * s)
    return np.where((t >= 0) & (t <= duration), out, 0.0)


def lamb_displacement(r: float, t: np.ndarray, force: float, mu: float, c_s: float,
                      duration: float, n_quad: int = 4000) -> np.ndarray:
    """Surface displacement (in the load direction) at ``r`` for the load
    ``P pulse(t, duration)`` (``s'(0) = s'(T) = 0``)."""
    tq = (np.arange(n_quad) + 0.5) * duration / n_quad             # midpoint rule on [0, T]
    sdd = pulse_dd(tq, duration)
    t = np.asarray(t, dtype=float)
    h = pekeris_h(c_s * (t[:, None] - tq[None, :]) / r)
    return force / (math.pi * mu * c_s) * (h @ sdd) * (duration / n_quad)


# --------------------------------------------------------------------------- 2-D (line load)
# Lamb (1904)'s plane-strain problem: a vertical line load ``p s(t)`` [N/m] on the surface of
# a half-space. Cagniard-de Hoop on the surface (z down, ``x > 0``; slowness ``q = t / x``,
# in units of ``1 / c_S``: ``a = c_S / c_P``): the displacement (in the load direction) of
# the impulse ``p delta(t)`` is ``p / (2 pi mu x) c_S G2(c_S t / x)`` with::
#
#     G2 = -2 Im(A / R),   A = i sqrt(q^2 - a^2),   R = (1 - 2 q^2)^2 + 4 q^2 A B,
#     B = sqrt(1 - q^2) (q < 1) or i sqrt(q^2 - 1) (q > 1)
#
# (the integrand's jump across the branch cut from ``i a``), zero before the P arrival
# ``q = a``. Past the S arrival R is real, the Rayleigh function, with its root at
# ``q_R = c_S / c_R``: there G2 has the pole ``K_R / (q - q_R)`` (a principal value; the
# half residues of the two sides of the cut cancel), so the Rayleigh pulse of the vertical
# displacement is the Hilbert transform of the load's history, of an amplitude that does
# not decay with distance, while the body waves decay. For ``q -> inf``,
# ``G2 -> 1 / ((1 - a^2) q) = 2 (1 - nu) / q``: the step load's displacement grows as
# ``p (1 - nu) / (pi mu) ln(c_S t / x)``, Flamant's static ``-p (1 - nu) / (pi mu) ln x``
# (checked in the tests).

def _a2(nu: float) -> float:
    """``(c_S / c_P)^2``."""
    return (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))


def rayleigh_function(q, nu: float):
    """``(1 - 2 q^2)^2 - 4 q^2 sqrt(q^2 - a^2) sqrt(q^2 - 1)`` for ``q >= 1``."""
    q = np.asarray(q, dtype=float)
    return (1 - 2 * q * q) ** 2 - 4 * q * q * np.sqrt(q * q - _a2(nu)) * np.sqrt(q * q - 1)


def rayleigh_slowness(nu: float) -> float:
    """``q_R = c_S / c_R``: the root of :func:`rayleigh_function` (bisection).

    >>> round(rayleigh_slowness(0.25), 6) == round(GAMMA, 6)
    True
    """
    lo, hi = 1.0 + 1e-14, 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rayleigh_function(mid, nu) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def line_kernel(q, nu: float) -> np.ndarray:
    """``G2(q)`` (finite away from ``q_R``)."""
    q = np.asarray(q, dtype=float)
    a2 = _a2(nu)
    out = np.zeros_like(q)
    body = (q * q > a2) & (q < 1.0)
    t = q[body]
    s = np.sqrt(t * t - a2)
    x, y = (1 - 2 * t * t) ** 2, 4 * t * t * s * np.sqrt(1 - t * t)
    out[body] = -2.0 * s * x / (x * x + y * y)
    late = q >= 1.0
    t = q[late]
    out[late] = -2.0 * np.sqrt(t * t - a2) / rayleigh_function(t, nu)
    return out


def rayleigh_residue(nu: float) -> float:
    """``K_R = lim (q - q_R) G2(q)`` = ``-2 sqrt(q_R^2 - a^2) / R'(q_R)``."""
    qr = rayleigh_slowness(nu)
    d = 1e-6 * qr                                  # R is smooth at q_R: a central difference
    slope = (rayleigh_function(qr + d, nu) - rayleigh_function(qr - d, nu)) / (2 * d)
    return float(-2.0 * math.sqrt(qr * qr - _a2(nu)) / slope)


#: Slowness step of the tabulated integrals of G2 (their error is below 1e-7 of the pulse).
_DQ = 2e-5


def line_step_integrals(q_max: float, nu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``q`` grid (from ``a``, step :data:`_DQ`), ``H(q) = int G2`` (the step load's
    displacement, log-singular at ``q_R``) and ``H2(q) = int H`` (continuous): the pole
    ``K_R / (q - q_R)`` is integrated in closed form, the rest by the trapezoidal rule."""
    a = math.sqrt(_a2(nu))
    qr, k = rayleigh_slowness(nu), rayleigh_residue(nu)
    q = a + _DQ * np.arange(int(math.ceil((q_max - a) / _DQ)) + 2)
    q = q[np.abs(q - qr) > 0.25 * _DQ] if np.any(np.abs(q - qr) <= 0.25 * _DQ) else q
    pole = np.where(q > 1.0, k / (q - qr), 0.0)
    rest = line_kernel(q, nu) - pole
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (rest[1:] + rest[:-1]) * np.diff(q))])

    def log_int(x):                                # int_1^x ln|s - q_R| ds
        y = x - qr
        return (y * np.log(np.abs(y)) - y) - ((1 - qr) * math.log(qr - 1) - (1 - qr))

    h = cum + np.where(q > 1.0, k * (np.log(np.abs(q - qr)) - math.log(qr - 1.0)), 0.0)
    # H2: the trapezoidal rule of the bounded part, the log part in closed form
    cum2 = np.concatenate([[0.0], np.cumsum(0.5 * (cum[1:] + cum[:-1]) * np.diff(q))])
    h2 = cum2 + np.where(q > 1.0, k * (log_int(np.maximum(q, 1.0))
                                       - math.log(qr - 1.0) * (q - 1.0)), 0.0)
    return q, h, h2


def pulse_ddd(t, duration: float):
    """``s'''(t)`` of :func:`pulse`: ``4 (pi/T)^3 sin cos (6 cos^2 - 10 sin^2)``."""
    t = np.asarray(t, dtype=float)
    th = np.pi * t / duration
    s, c = np.sin(th), np.cos(th)
    out = 4.0 * (np.pi / duration) ** 3 * s * c * (6.0 * c * c - 10.0 * s * s)
    return np.where((t >= 0) & (t <= duration), out, 0.0)


def lamb_line_response(x: float, t: np.ndarray, force: float, mu: float, c_s: float,
                       nu: float, duration: float, n_quad: int = 4000
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Surface displacement and velocity (in the load direction) at ``x > 0`` for the line
    load ``force * pulse(t, duration)`` [N/m]: ``u = p x / (2 pi mu c_S) int H2(c_S (t -
    t') / x) s''(t') dt'`` (integrated by parts twice; ``s, s'`` vanish at both ends, and
    ``s''`` too for the velocity's ``s'''``)."""
    t = np.asarray(t, dtype=float)
    q_max = c_s * (t.max() + 1e-9) / x + 2 * _DQ
    q, _, h2 = line_step_integrals(max(q_max, 1.5), nu)
    tq = (np.arange(n_quad) + 0.5) * duration / n_quad
    arg = c_s * (t[:, None] - tq[None, :]) / x
    table = np.interp(arg, q, h2, left=0.0)
    scale = force * x / (2 * math.pi * mu * c_s) * (duration / n_quad)
    return scale * (table @ pulse_dd(tq, duration)), scale * (table @ pulse_ddd(tq, duration))
