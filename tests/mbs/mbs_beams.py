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
