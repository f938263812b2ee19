"""Analytic modal data of simply supported Euler-Bernoulli beams for the MBS tests."""

from __future__ import annotations

import numpy as np

from railvib_hpc.mbs import RailCoupling


def ss_beam(
    length: float, ei: float, rho_a: float, n_modes: int, n_nodes: int = 201
) -> tuple[np.ndarray, RailCoupling]:
    """Mass-normalised modes ``sqrt(2/(rho A L)) sin(n pi x / L)`` with rotations ``-dw/dx``.

    Returns
    -------
    omega
        (n_modes,) circular frequencies ``(n pi / L)^2 sqrt(EI / rho A)``.
    rail
        Coupling on ``n_nodes`` equally spaced nodes.
    """
    k = np.arange(1, n_modes + 1) * np.pi / length
    omega = k**2 * np.sqrt(ei / rho_a)
    xn = np.linspace(0.0, length, n_nodes)
    c = np.sqrt(2.0 / (rho_a * length))
    phi_w = c * np.sin(np.outer(k, xn))
    phi_r = -c * k[:, None] * np.cos(np.outer(k, xn))
    return omega, RailCoupling(xn, phi_w, phi_r)


def two_beams(
    length: float, ei: float, rho_a: float, n_modes: int, n_nodes: int = 201
) -> tuple[np.ndarray, tuple[RailCoupling, RailCoupling]]:
    """Two identical, independent beams (one per rail): block-diagonal modal rows."""
    omega, rail = ss_beam(length, ei, rho_a, n_modes, n_nodes)
    z = np.zeros_like(rail.phi_w)
    r0 = RailCoupling(rail.x_nodes, np.vstack([rail.phi_w, z]), np.vstack([rail.phi_r, z]))
    r1 = RailCoupling(rail.x_nodes, np.vstack([z, rail.phi_w]), np.vstack([z, rail.phi_r]))
    return np.concatenate([omega, omega]), (r0, r1)


def supported_beam_fe(length: float, n_el: int, ei: float, rho_a: float, k_pad: float,
                      spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Euler-Bernoulli Hermite FE beam, simply supported ends, springs every ``spacing``.

    Returns
    -------
    x
        (n_el + 1,) node coordinates.
    K, M
        Reduced (ends' w removed) stiffness and consistent mass, DOFs ``(w, ry)`` per
        node with ``ry = -dw/dx``.
    free
        (2 (n_el + 1),) index of each ``(node, [w, ry])`` DOF in K, -1 if constrained.
    """
    x = np.linspace(0.0, length, n_el + 1)
    h = length / n_el
    ke = ei / h**3 * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                               [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    me = rho_a * h / 420 * np.array([[156, 22 * h, 54, -13 * h],
                                      [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                                      [54, 13 * h, 156, -22 * h],
                                      [-13 * h, -3 * h * h, -22 * h, 4 * h * h]])
    s = np.diag([1.0, -1.0, 1.0, -1.0])        # theta = dw/dx  ->  ry = -theta
    ke, me = s @ ke @ s, s @ me @ s
    n = 2 * (n_el + 1)
    K, M = np.zeros((n, n)), np.zeros((n, n))
    for e in range(n_el):
        d = slice(2 * e, 2 * e + 4)
        K[d, d] += ke
        M[d, d] += me
    support = np.flatnonzero(np.isclose(np.mod(x + 0.5 * spacing, spacing), 0.0, atol=1e-9)
                             | np.isclose(np.mod(x + 0.5 * spacing, spacing), spacing,
                                          atol=1e-9))
    K[2 * support, 2 * support] += k_pad
    keep = np.ones(n, bool)
    keep[[0, n - 2]] = False
    free = np.full(n, -1)
    free[keep] = np.arange(keep.sum())
    return x, K[np.ix_(keep, keep)], M[np.ix_(keep, keep)], free
