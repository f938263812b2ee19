"""Closed-form and semi-analytic reference solutions for the FEM tests.

Timoshenko beam (deflection ``w``, cross-section rotation ``psi``), time-harmonic::

    -rho A w^2 w   = k G A (w'' - psi')
    -rho I w^2 psi = E I psi'' + k G A (w' - psi)
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

#: beta_n L of a clamped-free Euler-Bernoulli beam (roots of cos x cosh x = -1).
EB_CANTILEVER_BETA_L = np.array([brentq(lambda x: np.cos(x) * np.cosh(x) + 1.0, a, b)
                                 for a, b in ((1.5, 2.5), (4.0, 5.0), (7.5, 8.2), (10.5, 11.2))])


def eb_cantilever_frequency(mode: int, L, E, I, rho, A) -> float:
    """Euler-Bernoulli clamped-free natural frequency (Hz), ``mode`` >= 1."""
    bl = EB_CANTILEVER_BETA_L[mode - 1]
    return bl**2 / (2 * np.pi * L**2) * np.sqrt(E * I / (rho * A))


def eb_pinned_frequency(mode: int, L, E, I, rho, A) -> float:
    """Euler-Bernoulli pinned-pinned natural frequency (Hz)."""
    return (mode * np.pi / L) ** 2 / (2 * np.pi) * np.sqrt(E * I / (rho * A))


def timoshenko_pinned_frequency(mode: int, L, E, G, k, A, I, rho, rotary=True) -> float:
    """Lower-branch Timoshenko pinned-pinned frequency (Hz).

    With ``w = W sin(q x)``, ``psi = Psi cos(q x)``, ``q = n pi / L`` the equations give the
    quadratic ``rhoA rhoI W^2 - W [rhoA (E I q^2 + kGA) + rhoI kGA q^2] + kGA E I q^4 = 0``
    in ``W = omega^2``; the smaller root is the bending branch.
    """
    q = mode * np.pi / L
    kga, ra, ri = k * G * A, rho * A, (rho * I if rotary else 0.0)
    b = ra * (E * I * q**2 + kga) + ri * kga * q**2
    c = kga * E * I * q**4
    if ri == 0.0:
        return np.sqrt(c / b) / (2 * np.pi)
    a = ra * ri
    w2 = (b - np.sqrt(b * b - 4 * a * c)) / (2 * a)
    return np.sqrt(w2) / (2 * np.pi)


def _timoshenko_bc_matrix(omega, L, E, G, k, A, I, rho, bcs, rotary):
    kga, ei, ra, ri = k * G * A, E * I, rho * A, (rho * I if rotary else 0.0)
    w2 = omega**2
    a, b, c0 = kga * ei, w2 * (kga * ri + ra * ei), ra * w2 * (ri * w2 - kga)
    disc = np.sqrt(b * b - 4 * a * c0)
    al = np.sqrt((-b + disc) / (2 * a))
    be = np.sqrt((b + disc) / (2 * a))
    c = ra * w2 / kga

    def fields(x):
        ch, sh, co, si = np.cosh(al * x), np.sinh(al * x), np.cos(be * x), np.sin(be * x)
        pa, pb = (al**2 + c) / al, (c - be**2) / be
        w = np.array([ch, sh, co, si])
        psi = np.array([pa * sh, pa * ch, pb * si, -pb * co])
        dpsi = np.array([pa * al * ch, pa * al * sh, pb * be * co, pb * be * si])
        # shear strain w' - psi in closed form (avoids cancellation when k G A is large)
        gam = np.array([-c / al * sh, -c / al * ch, -c / be * si, c / be * co])
        return w, psi, dpsi, gam

    rows = []
    for x, bc in zip((0.0, L), bcs):
        w, psi, dpsi, gam = fields(x)
        rows += {"clamped": [w, psi], "pinned": [w, dpsi], "free": [dpsi, gam]}[bc]
    return np.array(rows)


def timoshenko_frequencies(nmodes: int, L, E, G, k, A, I, rho, bcs=("clamped", "free"),
                           rotary=True, fmax=None) -> np.ndarray:
    """Lowest Timoshenko natural frequencies (Hz) for end conditions ``bcs``.

    Roots of the 4x4 boundary-condition determinant built from the exact solution
    (``cosh, sinh`` and ``cos, sin`` branches below the cut-off frequency), bracketed on
    a fine frequency grid up to ``fmax`` and refined with Brent's method.
    ``rotary=False`` drops the rotary inertia (``fmax`` is then required).
    """
    if fmax is None:  # just below the cut-off of the second spectrum
        fmax = 0.999 * np.sqrt(k * G * A / (rho * I)) / (2 * np.pi)
    f = np.geomspace(fmax * 1e-6, fmax, 20000)

    def det(fr):
        m = _timoshenko_bc_matrix(2 * np.pi * fr, L, E, G, k, A, I, rho, bcs, rotary)
        m = m / np.linalg.norm(m, axis=0)
        return np.linalg.det(m)

    d = np.array([det(fr) for fr in f])
    idx = np.flatnonzero(np.sign(d[:-1]) != np.sign(d[1:]))
    roots = [brentq(det, f[i], f[i + 1], xtol=1e-14, rtol=1e-15) for i in idx[:nmodes]]
    return np.array(roots)


def bar_fixed_free_frequency(mode: int, L, c) -> float:
    """Fixed-free bar (axial or torsion), wave speed ``c``: ``(2 m - 1) c / (4 L)`` (Hz)."""
    return (2 * mode - 1) * c / (4 * L)


def bar_fixed_free_discrete(mode: int, L, c, n: int) -> float:
    """Exact eigenfrequency (Hz) of ``n`` equal linear elements with consistent mass.

    The discrete modes are ``sin(q x_j)`` with ``q = (2 m - 1) pi / (2 L)``, whence
    ``omega^2 = 6 c^2 (1 - cos q h) / (h^2 (2 + cos q h))``.
    """
    h = L / n
    q = (2 * mode - 1) * np.pi / (2 * L)
    return np.sqrt(6 * c**2 * (1 - np.cos(q * h)) / (h**2 * (2 + np.cos(q * h)))) / (2 * np.pi)
