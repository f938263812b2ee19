"""Rayleigh damping coefficients of the full-order model (pure numpy).

A Rayleigh damping matrix ``C = alpha M + beta K`` gives a mode of circular frequency
``omega`` the damping ratio

    zeta(omega) = alpha / (2 omega) + beta omega / 2.

Matching a ratio ``zeta`` at two frequencies ``f1 < f2`` of the analysis band
(``damping.f1``, ``damping.f2``) gives

    alpha = 2 zeta omega1 omega2 / (omega1 + omega2),   beta = 2 zeta / (omega1 + omega2);

between them ``zeta(omega)`` dips to ``2 zeta sqrt(f1 f2) / (f1 + f2)`` at ``sqrt(f1 f2)``
(8 and 40 Hz: 0.745 zeta at 17.9 Hz), above ``f2`` it grows in proportion to the
frequency (numerical noise far above the band is damped out), below ``f1`` like ``1/f``.
Per material (``damping.model = 'per_material'``) every material group gets its own
``alpha_g, beta_g`` from ``materials.<g>.damping_ratio`` at the same two frequencies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..problem import Problem
from .elements import group_damping_ratio


def rayleigh_coefficients(zeta: float, f1: float, f2: float) -> tuple[float, float]:
    """``(alpha, beta)`` with ``zeta(2 pi f1) = zeta(2 pi f2) = zeta``.

    >>> a, b = rayleigh_coefficients(0.03, 8.0, 40.0)
    >>> round(float(rayleigh_ratio(a, b, 2 * math.pi * 8.0)), 12)
    0.03
    """
    w1, w2 = 2.0 * math.pi * f1, 2.0 * math.pi * f2
    return 2.0 * zeta * w1 * w2 / (w1 + w2), 2.0 * zeta / (w1 + w2)


def rayleigh_ratio(alpha: float, beta: float, omega: float | np.ndarray) -> np.ndarray:
    """Damping ratio ``alpha / (2 omega) + beta omega / 2`` of modes at ``omega`` [rad/s]."""
    om = np.asarray(omega, dtype=float)
    with np.errstate(divide="ignore"):
        return np.where(om > 0.0, alpha / (2.0 * np.where(om > 0, om, 1.0)) + 0.5 * beta * om,
                        np.inf if alpha > 0 else 0.0)


def material_rayleigh(problem: Problem, groups: Sequence[str]
                      ) -> dict[str, tuple[float, float]]:
    """``{group: (alpha_g, beta_g)}`` of ``damping.model = 'per_material'``."""
    out = {}
    for g in groups:
        zeta = group_damping_ratio(problem, g)
        out[g] = rayleigh_coefficients(zeta, problem.damping.f1, problem.damping.f2)
    return out


def problem_rayleigh(problem: Problem) -> tuple[float, float]:
    """Global ``(alpha, beta)`` of ``damping.model = 'rayleigh'`` (``modal.damping_ratio``)."""
    return rayleigh_coefficients(problem.damping.ratio, problem.damping.f1,
                                 problem.damping.f2)
