"""Receptance of a rail on soft pads against the exact discretely supported beam.

Issue 15's check of the soft-rail-pad measure: a rail (Euler-Bernoulli: the thesis's rail
with the shear deflection switched off, no rotary inertia) on pads every a = 0.6 m, each a
spring k (1 + i eta) to a rigid base, driven by a harmonic vertical force at a support or
at midspan. The reference is exact for this system at every frequency: between supports the
rail obeys EI w'''' = rho A omega^2 w, whose solutions (cos, sin, cosh, sinh of beta x,
beta^4 = rho A omega^2 / EI) give each bay's exact 4 x 4 dynamic stiffness; the bays and
the pad springs are assembled like finite elements. The finite-element rail (cubic Hermite
beams with consistent mass, n per bay: the thesis uses 5) converges to it at rate 4 in the
element length (the consistent-mass error of cubic elements is (beta h)^4 relative).

Soft pads (120 kN/mm, the mitigation study's default, against the thesis's 7,000) put the
track resonance of the rail on its pads near 200 Hz; the band checked (20-800 Hz) holds it
and stays below the pinned-pinned frequency (1,270 Hz).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from fem_tools import beam_matrices, line_mesh, node_dofs

E, I, A, RHO = 210e9, 2010e-8, 64.5e-4, 7700.0
EI, RHO_A = E * I, RHO * A
BAY = 0.6                      # sleeper spacing [m]
K_SOFT, ETA = 1.2e8, 0.25      # soft pad [N/m] and its loss factor
BAYS = 40                      # each side of the load: the pad damping absorbs the rest
SECTION = dict(E=E, G=E / 2.6, A=A, Iyy=I, Izz=326e-8, J=2e-7, ky=1e9, kz=1e9, rho=RHO)
FREQS = np.array([20.0, 60.0, 120.0, 180.0, 220.0, 300.0, 450.0, 600.0, 800.0])


def exact_bay_stiffness(omega: float, length: float = BAY) -> np.ndarray:
    """Exact dynamic stiffness of an Euler-Bernoulli bay on (w0, w0', wL, wL'); nodal
    forces (F0, M0, FL, ML) = (EI w'''(0), -EI w''(0), -EI w'''(L), EI w''(L)): the sign
    convention of the finite-element beam stiffness."""
    b = (RHO_A * omega**2 / EI) ** 0.25

    def phi(x, d):
        c, s, ch, sh = np.cos(b * x), np.sin(b * x), np.cosh(b * x), np.sinh(b * x)
        return b**d * np.array([[c, s, ch, sh], [-s, c, sh, ch], [-c, -s, ch, sh],
                                [s, -c, sh, ch]][d])

    U = np.array([phi(0, 0), phi(0, 1), phi(length, 0), phi(length, 1)])
    F = EI * np.array([phi(0, 3), -phi(0, 2), -phi(length, 3), phi(length, 2)])
    return F @ np.linalg.inv(U)


def exact_receptance(f_hz: float, at_midspan: bool) -> complex:
    """Displacement / force at the load of the exactly modelled discretely supported rail."""
    omega = 2 * np.pi * f_hz
    n_bays = 2 * BAYS + (1 if at_midspan else 0)
    # at midspan: a node in the middle of the middle bay (two half bays)
    lengths = ([BAY] * BAYS + [BAY / 2, BAY / 2] + [BAY] * BAYS) if at_midspan else \
        [BAY] * n_bays
    n_nodes = len(lengths) + 1
    D = np.zeros((2 * n_nodes, 2 * n_nodes), complex)
    for k, length in enumerate(lengths):
        idx = np.r_[2 * k:2 * k + 4]
        D[np.ix_(idx, idx)] += exact_bay_stiffness(omega, length)
    x = np.concatenate(([0.0], np.cumsum(lengths)))
    supports = np.flatnonzero(np.isclose(np.mod(x + 1e-9, BAY), 0.0, atol=1e-6))
    D[2 * supports, 2 * supports] += K_SOFT * (1 + 1j * ETA)
    load = n_nodes // 2
    f = np.zeros(2 * n_nodes, complex)
    f[2 * load] = 1.0
    return np.linalg.solve(D, f)[2 * load]


def fe_receptance(f_hz: float, at_midspan: bool, per_bay: int) -> complex:
    """The same with the project's beam elements, ``per_bay`` (even) elements per bay."""
    omega = 2 * np.pi * f_hz
    n_bays = 2 * BAYS + (1 if at_midspan else 0)
    half = n_bays * BAY / 2
    pts, lines = line_mesh((-half, 0, 0), (half, 0, 0), n_bays * per_bay)
    K, M = beam_matrices(pts, lines, SECTION, rotary_inertia=False)
    uz = node_dofs(np.arange(len(pts)), [2], 6)
    ry = node_dofs(np.arange(len(pts)), [4], 6)
    keep = np.r_[uz, ry]                          # plane bending in x-z only
    A_ = (K - omega**2 * M).tocsr()[keep][:, keep].astype(complex)
    support = np.flatnonzero(np.isclose(np.mod(pts[:, 0] - pts[0, 0] + 1e-9, BAY), 0.0,
                                        atol=1e-6))
    n = len(pts)
    A_ = A_ + sp.csr_matrix((np.full(len(support), K_SOFT * (1 + 1j * ETA)),
                             (support, support)), shape=A_.shape)
    load = n // 2
    f = np.zeros(2 * n, complex)
    f[load] = 1.0
    return spla.spsolve(A_.tocsc(), f)[load]


def test_exact_bay_stiffness_tends_to_the_static_beam():
    L = BAY
    static = EI / L**3 * np.array([[12, 6 * L, -12, 6 * L], [6 * L, 4 * L**2, -6 * L, 2 * L**2],
                                   [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L**2, -6 * L, 4 * L**2]])
    D = exact_bay_stiffness(2 * np.pi * 0.01)
    assert np.allclose(D, static, rtol=1e-6, atol=1e-6 * np.abs(static).max())
    # symmetric at any frequency (reciprocity)
    D = exact_bay_stiffness(2 * np.pi * 700.0)
    assert np.allclose(D, D.T, rtol=1e-9, atol=1e-9 * np.abs(D).max())


def test_soft_pad_receptance_converges_to_the_discretely_supported_beam():
    errors = {}
    for at_midspan in (False, True):
        exact = np.array([exact_receptance(f, at_midspan) for f in FREQS])
        # soft pads: the low-frequency receptance is the rail on its pads, ~ 1 / (2.2 k)
        assert 0.3 / K_SOFT < abs(exact[0]) < 0.6 / K_SOFT
        # the track resonance of the rail on soft pads lies inside the band
        assert np.argmax(np.abs(exact)) not in (0, len(FREQS) - 1)
        for per_bay in (2, 4, 8):
            fe = np.array([fe_receptance(f, at_midspan, per_bay) for f in FREQS])
            errors[at_midspan, per_bay] = np.abs(fe / exact - 1)
    for at_midspan in (False, True):
        e2, e4, e8 = (errors[at_midspan, n].max() for n in (2, 4, 8))
        # rate 4 in h: each halving divides the error by ~16 (>= 10 allowed)
        assert e2 / e4 > 10 and e4 / e8 > 10, (e2, e4, e8)
        assert e8 < 3e-4           # measured 9.3e-5 (support), 1.0e-4 (midspan)
