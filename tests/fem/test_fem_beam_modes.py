"""Beam eigenfrequencies against Euler-Bernoulli, Timoshenko and bar theory.

Rail section: E = 210 GPa, nu = 0.3, A = 64.5 cm^2, Iyy = 2010 cm^4 (vertical plane),
Izz = 326 cm^4 (horizontal plane), rho = 7700 kg/m^3, shear coefficient k = 0.34 (the
model's rail value, effectively the web shear-area ratio), beam along x, up = z.

Tolerances
----------
* Discretisation: FE frequencies converge monotonically (rate 2 for the interdependent
  Timoshenko element with consistent mass, 4 in the Euler-Bernoulli limit), so the error
  on mesh n is bounded by the change from n/2 to n: |f_n - f| <= |f_n - f_{n/2}|.
* Round-off: FE against exact discrete values and FE against FE compare to
  :func:`fem_tools.frequency_rtol` (``railvib_hpc.tolerances``: ``sqrt(n) u lambda_max /
  lambda``); mode-shape directions to the Davis-Kahan angle bound.
* Slenderness: for pinned ends the exact Timoshenko frequency satisfies
  f_EB / sqrt(1 + eps) <= f_T <= f_EB, eps = (q r)^2 (1 + E / (k G)), q = n pi / L,
  r^2 = I / A (lower root of a quadratic >= c / b). For other end conditions the same
  first-order parameter with q = beta_n sets the size of the shear/rotary correction,
  1 - f_T / f_EB ~ eps / 2 times a boundary-condition factor of order one; it is checked
  against eps itself. For the 2 m rail cantilever eps = 2.4 %, 15 %, 41 % (modes 1-3):
  with k = 0.34 the Timoshenko modes lie 1.5 %, 9.4 % and 18.5 % below Euler-Bernoulli.
"""

from __future__ import annotations

import numpy as np
import pytest
from fem_analytic import (
    EB_CANTILEVER_BETA_L,
    bar_fixed_free_discrete,
    bar_fixed_free_frequency,
    eb_cantilever_frequency,
    eb_pinned_frequency,
    timoshenko_frequencies,
    timoshenko_pinned_frequency,
)
from fem_tools import beam_matrices, frequency_rtol, line_mesh, node_dofs

from railvib_hpc import tolerances
from railvib_hpc.fem import lowest_modes

E, NU, RHO, A = 210e9, 0.3, 7700.0, 64.5e-4
G = E / (2 * (1 + NU))
IYY, IZZ, J, KS = 2010e-8, 326e-8, 2.59e-6, 0.34
RAIL = dict(E=E, G=G, A=A, Iyy=IYY, Izz=IZZ, J=J, ky=KS, kz=KS, rho=RHO)
#: global DOFs (per node) of the vertical (Iyy) and horizontal (Izz) bending planes
VERTICAL, HORIZONTAL = [2, 4], [1, 5]


def planar_modes(L, n, comps, bcs, nmodes, sec=RAIL, rotary_inertia=True, matrices=False):
    """Lowest frequencies of one decoupled DOF family of an x-aligned beam line.

    ``bcs``: "cantilever" (node 0 clamped) or "pinned" (deflection fixed at both ends;
    ``comps[0]`` is the deflection component). ``matrices``: also return the reduced K, M.
    """
    pts, lines = line_mesh([0, 0, 0], [L, 0, 0], n)
    K, M = beam_matrices(pts, lines, sec, rotary_inertia=rotary_inertia)
    keep = node_dofs(np.arange(n + 1), comps, 6)
    if bcs == "cantilever":
        keep = keep[len(comps):]
    else:
        keep = np.setdiff1d(keep, [comps[0], 6 * n + comps[0]])
    Kr, Mr = K[keep][:, keep], M[keep][:, keep]
    f = lowest_modes(Kr, Mr, nmodes)[0]
    return (f, Kr, Mr) if matrices else f


def slenderness(q, I, k=KS):
    return q**2 * (I / A) * (1 + E / (k * G))


def converged(f_n, f_half, f_ref):
    """|f_n - f_ref| <= |f_n - f_{n/2}| elementwise (monotone convergence bound)."""
    return np.all(np.abs(f_n - f_ref) <= np.abs(f_n - f_half))


def test_pinned_slender_beam_matches_euler_bernoulli():
    L = 20.0
    f_eb = eb_pinned_frequency(1, L, E, IYY, RHO, A)
    f_t = timoshenko_pinned_frequency(1, L, E, G, KS, A, IYY, RHO)
    eps = slenderness(np.pi / L, IYY)
    assert f_eb / np.sqrt(1 + eps) <= f_t <= f_eb
    f8, f16 = (planar_modes(L, n, VERTICAL, "pinned", 1)[0] for n in (8, 16))
    assert converged(f16, f8, f_t)
    assert abs(f16 / f_eb - 1) <= (1 - 1 / np.sqrt(1 + eps)) + abs(f16 - f8) / f_eb


def test_pinned_short_rail_below_euler_bernoulli():
    """L = 0.6 m (sleeper spacing): EB 1272.0 Hz, Timoshenko far below."""
    L = 0.6
    f_eb = eb_pinned_frequency(1, L, E, IYY, RHO, A)
    assert f_eb == pytest.approx(1272.0, abs=0.05)
    f_t = timoshenko_pinned_frequency(1, L, E, G, KS, A, IYY, RHO)
    assert f_t == pytest.approx(timoshenko_frequencies(1, L, E, G, KS, A, IYY, RHO,
                                                       ("pinned", "pinned"))[0], rel=1e-10)
    ns = np.array([8, 16, 32])
    f = np.array([planar_modes(L, n, VERTICAL, "pinned", 1)[0] for n in ns])
    assert np.all(f < f_eb)
    assert converged(f[-1], f[-2], f_t)
    slope = np.polyfit(np.log(L / ns), np.log(f / f_t - 1), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.1)


@pytest.mark.parametrize("comps,I", [(VERTICAL, IYY), (HORIZONTAL, IZZ)])
def test_cantilever_rail(comps, I):
    L = 2.0
    f_eb = np.array([eb_cantilever_frequency(m, L, E, I, RHO, A) for m in (1, 2, 3)])
    if I == IYY:
        assert np.allclose(f_eb, [40.78, 255.59, 715.66], rtol=0, atol=0.005)
    # Euler-Bernoulli limit of the element (shear-rigid, no rotary inertia): rate 4
    stiff = dict(RAIL, G=G * 1e8)
    f8, f16 = (planar_modes(L, n, comps, "cantilever", 3, stiff, False) for n in (8, 16))
    assert converged(f16, f8, f_eb)
    rate = np.log2((f8 / f_eb - 1) / (f16 / f_eb - 1))
    assert np.allclose(rate, 4.0, atol=0.1)      # Hermite cubics; pre-asymptotic O(h^6)
    # Timoshenko: exact clamped-free solution
    f_t = timoshenko_frequencies(3, L, E, G, KS, A, I, RHO)
    f16, f32 = (planar_modes(L, n, comps, "cantilever", 3) for n in (16, 32))
    assert converged(f32, f16, f_t)
    eps = slenderness(EB_CANTILEVER_BETA_L[:3] / L, I)
    assert np.all((f32 < f_eb) & (1 - f32 / f_eb <= eps))


@pytest.mark.parametrize("kind", ["axial", "torsion"])
def test_fixed_free_bar_modes(kind):
    """Linear axial/torsion interpolation with consistent mass: FE = exact discrete
    dispersion to round-off; continuum error (q h)^2 / 24 from above."""
    L, n = 2.0, 20
    comps, c = ([0], np.sqrt(E / RHO)) if kind == "axial" else \
        ([3], np.sqrt(G * J / (RHO * (IYY + IZZ))))
    f, K, M = planar_modes(L, n, comps, "cantilever", 3, matrices=True)
    rtol = frequency_rtol(K, M, f, computations=1)
    for m in (1, 2, 3):
        assert f[m - 1] == pytest.approx(bar_fixed_free_discrete(m, L, c, n), rel=rtol[m - 1])
        exact = bar_fixed_free_frequency(m, L, c)
        qh = (2 * m - 1) * np.pi / (2 * n)
        assert 0 < f[m - 1] / exact - 1 <= qh**2 / 24 * (1 + qh**2 / 40)


def test_orientation_invariance_and_planes():
    """A skew 3D cantilever has the spectrum of the aligned one; the Iyy mode deflects
    along up, the Izz mode normal to it."""
    L, n = 2.0, 10
    axis = np.array([0.6, 0.48, 0.64])
    up = np.array([0.1, -0.3, 1.0])
    ey = up - (up @ axis) * axis
    ey /= np.linalg.norm(ey)
    spectra, shapes = [], []
    for p1, u in (([L, 0, 0], [0, 0, 1.0]), (L * axis, up)):
        pts, lines = line_mesh([0, 0, 0], p1, n)
        K, M = beam_matrices(pts, lines, RAIL, up=u)
        free = np.arange(6, 6 * (n + 1))
        K, M = K[free][:, free], M[free][:, free]
        f, phi = lowest_modes(K, M, 6)
        spectra.append(f)
        shapes.append(phi)
    assert np.all(np.abs(spectra[1] / spectra[0] - 1) <= frequency_rtol(K, M, spectra[0]))
    # direction of a simple mode: its angle to the exact one is at most round-off / gap
    # (Davis-Kahan), and a tip component equals the norm to 1 - cos = sin^2 / 2
    lam = (2 * np.pi * spectra[0]) ** 2
    gaps = np.minimum(np.diff(lam, prepend=-np.inf), np.diff(lam, append=np.inf))
    sin = np.array([tolerances.subspace_tolerance(g, tolerances.lambda_max(K, M), K.shape[0])
                    for g in gaps])
    # aligned model: the first mode is horizontal (Izz < Iyy), find the first vertical one
    tip0 = shapes[0][-6:-3]                       # tip translations of each mode, (3, 6)
    i_h = 0
    i_v = int(np.argmax(np.abs(tip0[2]) > 0.5 * np.linalg.norm(tip0, axis=0)))
    assert abs(tip0[1, i_h]) == pytest.approx(np.linalg.norm(tip0[:, i_h]), rel=sin[i_h])
    assert abs(tip0[2, i_v]) == pytest.approx(np.linalg.norm(tip0[:, i_v]), rel=sin[i_v])
    tip = shapes[1][-6:-3]
    assert abs(tip[:, i_v] @ ey) == pytest.approx(np.linalg.norm(tip[:, i_v]), rel=sin[i_v])
    assert abs(tip[:, i_h] @ ey) <= sin[i_h] * np.linalg.norm(tip[:, i_h])


def test_timoshenko_reference_solver():
    """The determinant solver reproduces the Euler-Bernoulli cantilever in the
    shear-rigid limit without rotary inertia, and the pinned closed form."""
    L = 2.0
    f = timoshenko_frequencies(3, L, E, G * 1e8, KS, A, IYY, RHO, rotary=False, fmax=2000.0)
    f_eb = [eb_cantilever_frequency(m, L, E, IYY, RHO, A) for m in (1, 2, 3)]
    assert np.allclose(f, f_eb, rtol=1e-8)       # residual shear flexibility ~ eps / 1e8
    fp = timoshenko_frequencies(3, L, E, G, KS, A, IYY, RHO, ("pinned", "pinned"))
    assert np.allclose(fp, [timoshenko_pinned_frequency(m, L, E, G, KS, A, IYY, RHO)
                            for m in (1, 2, 3)], rtol=1e-10)
