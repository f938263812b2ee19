"""1D soil column of hexahedra: shear and compression modes vs the exact column.

Column of height H (1 x 1 element cross-section, n elements in z), base fixed.

* Compression: lateral faces on rollers (normal displacement fixed). With one element
  across, every node lies on two lateral faces, so only u_z remains: the constrained
  (P-wave) column, f_m = (2m - 1) c_P / (4H).
* Shear: rollers would also fix the horizontal shear motion, so the lateral faces are
  tied periodically instead (the four nodes of each level move together), the usual
  1D site-response column: f_m = (2m - 1) c_S / (4H).

For uniform-in-plane fields the trilinear hex column is exactly a chain of linear 1D
elements with consistent mass, whose eigenfrequencies are known in closed form
(:func:`analytic.bar_fixed_free_discrete`); the error versus the continuum is
(q h)^2 / 24 (1 + (q h)^2 / 80 + ...), i.e. second order and from above.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from fem_analytic import bar_fixed_free_discrete, bar_fixed_free_frequency
from fem_tools import box_mesh, frequency_rtol, solid_matrices

from railvib_hpc.fem import eliminate_dofs, lowest_modes

H, E, NU, RHO = 5.8, 200e6, 0.2, 1850.0
G = E / (2 * (1 + NU))
M_P = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
C_S, C_P = np.sqrt(G / RHO), np.sqrt(M_P / RHO)
NS = (8, 16, 32, 64)


def column(n: int, lumped: bool = False):
    pts, hexes = box_mesh(1, 1, n, 1.0, 1.0, H)
    K, M = solid_matrices(pts, hexes, E, NU, RHO, bbar=True, lumped=lumped)
    return pts, K, M


def tied_modes(n: int, nmodes: int, lumped: bool = False, matrices: bool = False):
    """Periodic lateral ties, base fixed: reduced DOFs (level k >= 1, component).

    x-shear, y-shear and compression decouple exactly, so the spectrum is the union of
    the shear frequencies (each twice) and the compression frequencies. ``matrices``:
    also return the reduced K, M.
    """
    pts, K, M = column(n, lumped)
    level = np.rint(pts[:, 2] / (H / n)).astype(int)
    rows = np.arange(3 * len(pts))
    cols = 3 * (level[:, None] - 1) + np.arange(3)
    keep = np.repeat(level >= 1, 3)
    P = sp.csr_matrix((np.ones(keep.sum()), (rows[keep], cols.ravel()[keep])),
                      shape=(3 * len(pts), 3 * n))
    Kr, Mr = (P.T @ K @ P).tocsc(), (P.T @ M @ P).tocsc()
    f = lowest_modes(Kr, Mr, nmodes, sigma=0.0, dense_below=0)[0]   # shift-invert Lanczos
    return (f, Kr, Mr) if matrices else f


def compression_modes(n: int, nmodes: int, lumped: bool = False, matrices: bool = False):
    """Rollers on all lateral faces and fixed base: only u_z of levels >= 1 is free."""
    pts, K, M = column(n, lumped)
    fixed = np.zeros(K.shape[0], dtype=bool)
    fixed[0::3] = fixed[1::3] = True
    fixed[2::3] = pts[:, 2] == 0.0
    Kr, Mr, _ = eliminate_dofs(K, M, fixed)
    f = lowest_modes(Kr, Mr, nmodes)[0]
    return (f, Kr, Mr) if matrices else f


def test_wave_speeds_and_reference_frequencies():
    assert pytest.approx(212.24, abs=0.005) == C_S
    assert pytest.approx(346.58, abs=0.005) == C_P
    for m, f in zip((1, 2, 3), (9.148, 27.445, 45.741)):
        assert bar_fixed_free_frequency(m, H, C_S) == pytest.approx(f, abs=5e-4)
    assert bar_fixed_free_frequency(1, H, C_P) == pytest.approx(14.939, abs=5e-4)


def measured_errors():
    """Relative errors (n, [shear 1, 2, 3, compression 1]) of the tied column.

    Each FE frequency is first matched to the exact discrete value of its family."""
    err = np.zeros((len(NS), 4))
    for i, n in enumerate(NS):
        f, K, M = tied_modes(n, 8, matrices=True)
        # labelled exact discrete spectrum: (frequency, family, mode)
        ref = sorted([(bar_fixed_free_discrete(m, H, C_S, n), "S", m) for m in (1, 2, 3)] * 2
                     + [(bar_fixed_free_discrete(m, H, C_P, n), "P", m) for m in (1, 2)])[:8]
        fd = np.array([r[0] for r in ref])
        # eigenvalue round-off: sqrt(n) u lambda_max / lambda (railvib_hpc.tolerances)
        assert np.all(np.abs(f / fd - 1) <= frequency_rtol(K, M, fd, computations=1))
        pos = {r[1:]: k for k, r in enumerate(ref)}
        for j, (fam, m) in enumerate((("S", 1), ("S", 2), ("S", 3), ("P", 1))):
            err[i, j] = f[pos[fam, m]] / bar_fixed_free_frequency(
                m, H, C_S if fam == "S" else C_P) - 1
        # rollers: the compression family alone
        fc, Kc, Mc = compression_modes(n, 1, matrices=True)
        rtol = frequency_rtol(Kc, Mc, fc, computations=1) + frequency_rtol(K, M, fc,
                                                                           computations=1)
        assert fc[0] == pytest.approx(f[pos["P", 1]], rel=rtol[0])
    return err


def test_soil_column_converges_from_above_at_rate_two():
    err = measured_errors()
    assert np.all(err > 0)                                   # consistent mass: from above
    h = H / np.array(NS)
    for j, mode in enumerate((1, 2, 3, 1)):
        slope = np.polyfit(np.log(h), np.log(err[:, j]), 1)[0]
        qh = (2 * mode - 1) * np.pi / (2 * H) * h[0]
        # local slope = 2 + (q h)^2 / 40 + ...: allow twice that plus round-off
        assert abs(slope - 2.0) <= qh**2 / 20 + 1e-3
    assert err[-1, 0] < 1e-4


def test_lumped_mass_converges_from_below():
    fl, K, M = compression_modes(32, 1, lumped=True, matrices=True)
    f_l = fl[0]
    f_c = compression_modes(32, 1)[0]
    exact = bar_fixed_free_frequency(1, H, C_P)
    assert f_l < exact < f_c
    # lumped: omega_h = (2 c / h) sin(q h / 2), relative error -(q h)^2 / 24
    q, h = np.pi / (2 * H), H / 32
    assert f_l == pytest.approx(2 * C_P / h * np.sin(q * h / 2) / (2 * np.pi),
                                rel=frequency_rtol(K, M, fl, computations=1)[0])
