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
