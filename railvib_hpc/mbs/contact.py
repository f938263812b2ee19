"""Hertz normal wheel-rail contact.

Convention: ``delta`` is the *penetration*, positive when wheel and rail
overlap (the thesis, eq. in chapter 4, uses the gap ``-delta``, which is why
it writes the damping term with a minus sign). The normal force is

    F = K_H delta^(3/2) + C delta_dot |delta|   for delta > 0, clipped at F >= 0,
    F = 0                                       for delta <= 0 (loss of contact).

The damping term is the Hunt-Crossley form: it vanishes with the penetration,
so the force is continuous at first contact.

The Hertz constant follows Jenkins et al. (1974):
``G = 4.57 R^-0.149 * 1e-8 m/N^(2/3)``, ``K_H = G^(-3/2)``
(R = 0.46 m gives K_H = 8.6e10 N/m^1.5; a 7.69 kN wheel load then gives
delta = 20.0 um).
"""

from __future__ import annotations

import numpy as np


def jenkins_hertz_constant(wheel_radius: float) -> float:
    """Hertz constant ``K_H`` [N/m^1.5] from the wheel radius (Jenkins' formula).

    Parameters
    ----------
    wheel_radius
        Rolling radius R of the wheel [m].

    Returns
    -------
    float
        ``K_H = G^(-3/2)`` with ``G = 4.57 R^-0.149 * 1e-8`` [m/N^(2/3)].
    """
    if wheel_radius <= 0.0:
        raise ValueError("wheel_radius must be positive")
    g = 4.57 * wheel_radius ** (-0.149) * 1e-8
    return g ** (-1.5)


def hertz_force(
    delta: np.ndarray | float, k_hertz: float, delta_dot: np.ndarray | float = 0.0,
    damping: float = 0.0,
) -> np.ndarray:
    """Normal contact force for given penetrations (vectorised).

    Parameters
    ----------
    delta
        Penetration(s) [m], positive in contact.
    k_hertz
        Hertz constant ``K_H`` [N/m^1.5].
    delta_dot
        Penetration rate(s) [m/s].
    damping
        Contact damping constant ``C`` [N s/m^2].

    Returns
    -------
    numpy.ndarray
        Force(s) >= 0 [N], zero on separation.
    """
    d = np.maximum(np.asarray(delta, dtype=float), 0.0)
    f = k_hertz * d * np.sqrt(d) + damping * np.asarray(delta_dot, dtype=float) * d
    return np.maximum(f, 0.0)


def hertz_penetration(force: np.ndarray | float, k_hertz: float) -> np.ndarray:
    """Static penetration for a given contact force.

    Parameters
    ----------
    force
        Force(s) [N]; negative values are treated as 0.
    k_hertz
        Hertz constant [N/m^1.5].

    Returns
    -------
    numpy.ndarray
        ``(F / K_H)^(2/3)`` [m].
    """
    return (np.maximum(np.asarray(force, dtype=float), 0.0) / k_hertz) ** (2.0 / 3.0)


def hertz_linear_stiffness(force: float, k_hertz: float) -> float:
    """Tangent (linearised) Hertz stiffness at a static force.

    Parameters
    ----------
    force
        Static contact force [N].
    k_hertz
        Hertz constant [N/m^1.5].

    Returns
    -------
    float
        ``dF/ddelta = 1.5 K_H^(2/3) F^(1/3)`` [N/m].
    """
    return 1.5 * k_hertz ** (2.0 / 3.0) * max(force, 0.0) ** (1.0 / 3.0)


def hertz_energy(delta: np.ndarray | float, k_hertz: float) -> np.ndarray:
    """Elastic energy stored in the contact.

    Parameters
    ----------
    delta
        Penetration(s) [m].
    k_hertz
        Hertz constant [N/m^1.5].

    Returns
    -------
    numpy.ndarray
        ``0.4 K_H delta^(5/2)`` [J], zero on separation.
    """
    d = np.maximum(np.asarray(delta, dtype=float), 0.0)
    return 0.4 * k_hertz * d * d * np.sqrt(d)
