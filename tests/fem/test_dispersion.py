"""The Bloch-wave dispersion of hex8 and the time schemes (railvib_hpc.fem.dispersion)."""

from __future__ import annotations

import doctest
import math

import numpy as np
import pytest
from scipy.linalg import eigh

from railvib_hpc.fem import dispersion as D
from railvib_hpc.fem.hex8 import hex8_lumped_mass_diagonal, hex8_mass, hex8_stiffness

NU = 0.3
CP = math.sqrt(2 * (1 - NU) / (1 - 2 * NU))          # c_P / c_S


def test_docstring_examples():
    result = doctest.testmod(D)
    assert result.attempted > 0 and result.failed == 0


@pytest.mark.parametrize("mass", D.MASSES)
def test_along_an_axis_the_grid_is_the_one_dimensional_chain(mass):
    """Plane waves along x are the two-node element's (Marfurt 1984): consistent
    ``6 (1 - cos kh) / (2 + cos kh)``, lumped ``4 sin^2(kh / 2)``, for S and P alike."""
    kh = np.linspace(0.05, np.pi, 40)
    w, modes = D.bloch_frequencies(np.c_[kh, 0 * kh, 0 * kh], NU, mass)
    chain = (np.sqrt(6 * (1 - np.cos(kh)) / (2 + np.cos(kh))) if mass == "consistent"
             else 2 * np.sin(kh / 2))
    p = np.argmax(np.abs(modes[:, 0, :]), axis=1)          # the x-polarised one
    s = np.sort(np.where(np.arange(3) == p[:, None], np.inf, w), axis=1)[:, :2]
    np.testing.assert_allclose(w[np.arange(kh.size), p], CP * chain, rtol=1e-12)
    np.testing.assert_allclose(s, np.c_[chain, chain], rtol=1e-12)


def test_small_kh_phase_error_is_plus_minus_kh_squared_over_24():
    """The leading term: consistent mass too fast, lumped too slow, by (kh)^2 / 24."""
    for epw in (40.0, 80.0):
        kh2 = (2 * np.pi / epw) ** 2
        c = float(D.phase_velocity_ratio(epw, "S", "axis", nu=NU, mass="consistent")) - 1
        m = float(D.phase_velocity_ratio(epw, "S", "axis", nu=NU, mass="lumped")) - 1
        assert c == pytest.approx(kh2 / 24, rel=0.02)
        assert m == pytest.approx(-kh2 / 24, rel=0.02)


def _periodic_box(n: int, lumped: bool, formulation: str):
    """Dense K, M of an n^3 grid of unit cubes, periodic in x, y, z (mu = rho = 1)."""
    ijk = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    corner = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                       [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    pos = ijk[:, None, :] + corner[None]                     # (nel, 8, 3), unwrapped
    wrapped = pos % n
    nodes = wrapped[..., 0] + n * wrapped[..., 1] + n * n * wrapped[..., 2]
    Ke = hex8_stiffness(pos.astype(float), 2 * (1 + NU), NU, formulation=formulation)
    Me = (np.apply_along_axis(np.diag, 1, hex8_lumped_mass_diagonal(pos.astype(float), 1.0))
          if lumped else hex8_mass(pos.astype(float), 1.0))
    dofs = (3 * nodes[..., None] + np.arange(3)).reshape(len(pos), 24)
    N = 3 * n**3
    K, M = np.zeros((N, N)), np.zeros((N, N))
    rows = np.repeat(dofs[:, :, None], 24, 2)
    cols = np.repeat(dofs[:, None, :], 24, 1)
    np.add.at(K, (rows, cols), Ke)
    np.add.at(M, (rows, cols), Me)
    return K, M


@pytest.mark.parametrize("mass, formulation", [("consistent", "bbar"), ("lumped", "bbar"),
                                               ("consistent", "full"),
                                               ("lumped", "incompatible")])
def test_bloch_frequencies_are_the_periodic_grids_eigenvalues(mass, formulation):
    """Every direction at once: the 192 eigenfrequencies of a periodic 4 x 4 x 4 grid are
    the Bloch frequencies at its 64 wave vectors ``2 pi m / 4``."""
    n = 4
    K, M = _periodic_box(n, mass == "lumped", formulation)
    lam = eigh(K, M, eigvals_only=True)
    m = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    w, _ = D.bloch_frequencies(2 * np.pi * m / n, NU, mass, formulation)
    np.testing.assert_allclose(lam, np.sort(w.ravel()) ** 2, atol=1e-9 * lam.max())


def test_the_lumped_grids_stability_limit_is_courant_one():
    """The largest eigenfrequency of the periodic lumped grid is 2 c_P / h (Courant 1)."""
    K, M = _periodic_box(4, True, "bbar")
    w_max = math.sqrt(eigh(K, M, eigvals_only=True).max())
    assert w_max == pytest.approx(2 * CP, rel=1e-12)
    assert D.critical_courant(NU) == pytest.approx(1.0, rel=1e-12)


def test_time_frequency_against_the_schemes():
    """Central differences: the explicit engine's own one-step map; generalized-alpha: the
    period error and damping of :class:`~railvib_hpc.transient.scheme.GeneralizedAlpha`."""
    from railvib_hpc.transient.scheme import GeneralizedAlpha

    for w in (0.1, 0.6, 1.5):
        # u1 = u + h v + h^2/2 a; vh = v + h/2 a; a1 = -w2 u1; v1 = vh + h/2 a1 (h = 1)
        u1 = np.array([1.0, 1.0, 0.5])
        vh = np.array([0.0, 1.0, 0.5])
        a1 = -w * w * u1
        lam = np.linalg.eigvals(np.array([u1, vh + 0.5 * a1, a1]).T)
        principal = lam[np.argmax(np.abs(lam.imag))]
        cd, xi = D.time_frequency(w, "central")
        assert float(cd) == pytest.approx(abs(np.angle(principal)), rel=1e-12)
        assert abs(principal) == pytest.approx(1.0, rel=1e-12)
        assert float(xi) == 0.0
        trap, _ = D.time_frequency(w, "generalized_alpha", 1.0)
        assert float(trap) == pytest.approx(float(D._alpha_frequency(np.array(w), 1.0)[0]),
                                            rel=1e-12)
        for rho in (1.0, 0.8, 0.5):
            dt = 1e-3
            f = w / dt / (2 * np.pi)
            pe, xi_s = GeneralizedAlpha.from_radius(dt, rho).accuracy(f)
            om, xi = D.time_frequency(w, "generalized_alpha", rho)
            assert w / float(om) - 1 == pytest.approx(pe, rel=1e-9, abs=1e-14)
            assert float(xi) == pytest.approx(xi_s, rel=1e-9, abs=1e-14)
    assert np.isnan(D.time_frequency(2.01, "central")[0])


def test_generalized_alpha_at_low_frequency_does_not_depend_on_the_eigensolver():
    """Near ``omega_h dt = 0`` the principal pair of the amplification matrix is a double
    root that a dense eigensolver resolves only to ~sqrt(u): at the grid's zero wavenumber
    (round-off ``w`` ~ 1e-8) OpenBLAS's Sandybridge kernel returned it as two real roots,
    the spurious one was taken (``Omega dt = pi``) and the dispersion relation's table broke.
    Below :data:`~railvib_hpc.fem.dispersion.ALPHA_SERIES_BELOW` the scheme's expansion
    holds (``Omega dt = w (1 + O(w^2))``, ``xi = O(w^3)``): equal to the eigenvalue path just
    above the switch to its period error (0.46 w^2 at rho_inf = 0, the largest) plus that
    path's rounding, ``u / w^2`` for a pair split by ``2 w`` (measured 6.6e-9 with the
    SkylakeX kernel)."""
    ws = D.ALPHA_SERIES_BELOW
    w = np.array([0.0, 7.3e-9, 1e-6, 0.99 * ws, 1.01 * ws])
    for rho in (0.8, 0.5, 0.0):
        om, xi = D.time_frequency(w, "generalized_alpha", rho)
        assert om[0] == 0.0 and xi[0] == 0.0
        rtol = 0.5 * ws**2 + np.finfo(float).eps / ws**2
        np.testing.assert_allclose(om[1:], w[1:], rtol=rtol, atol=0)
        # (the eigenvalue path's damping just above: rounding, measured <= 3.3e-12)
        assert np.all(np.abs(xi) <= 0.5 * ws**3 + 1e-11)


def test_signs_and_the_explicit_engines_partial_cancellation():
    """Consistent mass: early arrival; lumped: late; central differences at the engine's
    step reduce the lumped lag, the trapezoidal rule reduces the consistent lead."""
    L = 10.0
    c = float(D.phase_error(8.0, L, "S", nu=NU, mass="consistent"))
    m = float(D.phase_error(8.0, L, "S", nu=NU, mass="lumped"))
    cd = float(D.phase_error(8.0, L, "S", nu=NU, mass="lumped", scheme="central",
                             courant=0.9 * D.critical_courant(NU)))
    tr = float(D.phase_error(8.0, L, "S", nu=NU, mass="consistent",
                             scheme="generalized_alpha",
                             courant=D.courant_of_steps(8.0, 20, "S", NU)))
    assert c < 0 < m
    assert 0 < cd < m
    assert c < tr < 0
    # 1-D at Courant 1 central differences cancel the lumped mass exactly (P along an axis)
    assert float(D.phase_error(6.0, L, "P", nu=NU, mass="lumped", scheme="central",
                               courant=1.0)) == pytest.approx(0.0, abs=1e-9)


def test_beyond_the_cutoff_the_frequency_is_not_carried():
    assert np.isnan(D.wavenumber_ratio(1.5, "S", nu=NU, mass="lumped"))
    assert float(D.peak_velocity_error(1.5, 1.0, "S", nu=NU, mass="lumped")) == 1.0


@pytest.mark.parametrize("mass, direction, epw", [("consistent", "axis", 10.0),
                                                  ("lumped", "face_diagonal", 16.0),
                                                  ("lumped", "body_diagonal", 24.0)])
def test_the_harmonic_bound_holds_for_a_pulse_inside_the_band(mass, direction, epw):
    """A zero-phase pulse whose content lies below the band's top: its peak error is at
    most ``1 - cos(phase error at the top)`` (every component's crest is off by less)."""
    bound = float(D.peak_velocity_error(epw, 13.3, "S", direction, nu=NU, mass=mass))
    peak, waveform, _ = D.pulse_peak_error(epw, 13.3, "S", direction, "band", nu=NU,
                                           mass=mass)
    assert abs(peak) <= bound
    assert waveform > abs(peak)


def test_elements_needed_is_the_threshold():
    need = D.elements_needed(0.05, 13.3, nu=NU, mass="lumped")
    assert D.worst_peak_error(need, 13.3, NU, "lumped")[0] < 0.05
    assert D.worst_peak_error(need - 0.05, 13.3, NU, "lumped")[0] >= 0.05
    assert D.elements_needed(0.05, 13.3, nu=NU, mass="consistent", hi=10.0) == math.inf
