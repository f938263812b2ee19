"""The reference of the moving harmonic line load (:mod:`railvib_hpc.fem.halfspace_line`)
against its two independent limits and its own numerical parameters.

- ``c = 0``: the time-harmonic Lamb problem, whose far field is the Rayleigh pole alone,
  amplitude ``P K_R / (2 mu)`` (``K_R`` from Lamb's Cagniard-de Hoop solution,
  tests/transient/lamb.py, itself checked against Flamant and the pole), times the
  spreading's transform at ``k_R``. The body waves' share decays as ``xi^-3/2``.
- ``f_0 = 0``: Cole & Huth's (1958) moving line load, ``V = P c A / (pi mu xi)`` with ``A``
  the direction kernel of :mod:`railvib_hpc.fem.halfspace` along the motion (checked
  there against Barber's closed form), convolved with the spreading: ``(1 + <s^2> /
  xi^2)`` to second order.
- The undamped limit's extrapolation and the grid: halving the loss factors, widening the
  wavenumber range and lengthening the FFT's period change the field at ten wavelengths by
  less than 5e-5.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import railvib_hpc.fem.halfspace_line as hl
from railvib_hpc.fem.halfspace import direction_kernel, mach_numbers, rayleigh_mach_limit

NU, C_S, MU, P, A = 0.25, 100.0, 1e4, 1.0, 2.0
C_R = rayleigh_mach_limit(NU) * C_S
#: 16 m Rayleigh wavelength at rest; the load at a quarter of the Rayleigh speed.
F0, SPEED = C_R / 16.0, 0.25 * C_R


def _residue(nu: float) -> float:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transient"))
    from lamb import rayleigh_residue

    return rayleigh_residue(nu)


def test_at_rest_the_far_field_is_lambs_rayleigh_pole():
    xi = np.linspace(40.0, 800.0, 77)
    w, _ = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, 0.0, F0, A)
    k_r = 2 * math.pi * F0 / C_R
    pole = P * _residue(NU) / (2 * MU) * float(hl.spread_transform(np.array([k_r]), A)[0])
    dev = np.abs(np.abs(w) / pole - 1)
    near, far = dev[xi <= 200].max(), dev[xi >= 560].max()
    print(f"|W| against the pole: {near:.2%} within 40-200 m, {far:.2%} within 560-800 m")
    # measured 6.0 % and 0.49 %: the body waves' share falls as xi^-3/2 (4.7 times from 200
    # to 560 m, 52 times from 40 m); the undamped extrapolation's error grows with xi
    assert far < 0.01 and near > 5 * far
    # symmetric at rest
    w_back, _ = hl.moving_harmonic_line_load(-xi[:5], P, MU, NU, C_S, 0.0, F0, A)
    np.testing.assert_allclose(w_back, w[:5], rtol=0, atol=1e-7 * np.abs(w).max())


def test_a_hysteretic_soil_damps_the_rayleigh_wave():
    """With a loss factor ``eta`` the Rayleigh wave's wavenumber is ``k_R (1 - i eta / 2)``
    to first order: far from the load the field falls as ``exp(-eta k_R xi / 2)`` against
    the undamped one (measured: within 0.2 % at 10 and 20 wavelengths, ``eta = 0.01``)."""
    xi = np.array([160.0, 320.0])
    k_r = 2 * math.pi * F0 / C_R
    damped, _ = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, 0.0, F0, A, loss=0.01)
    elastic, _ = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, 0.0, F0, A)
    np.testing.assert_allclose(np.abs(damped / elastic), np.exp(-0.01 * k_r * xi / 2),
                               rtol=5e-3)


def test_a_constant_moving_load_is_cole_and_huths():
    xi = np.array([20.0, 50.0, -50.0, 100.0])
    _, v = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, SPEED, 0.0, A)
    m_s, m_p = mach_numbers(SPEED, C_S, NU)
    kernel = float(direction_kernel(np.array([0.0]), m_s, m_p)[0].real)
    second = A * A * (1.0 / 3.0 - 2.0 / math.pi ** 2)           # <s^2> of the spreading
    exact = P * SPEED * kernel / (math.pi * MU * xi) * (1 + second / xi ** 2)
    # measured: 3e-6 ... 3e-5 (the FFT period's images, -(pi^2/3) (xi / L)^2)
    np.testing.assert_allclose(v.real, exact, rtol=2e-4)
    assert np.abs(v.imag).max() < 1e-6 * np.abs(v).max()


def test_the_doppler_wavelengths_ahead_and_behind():
    """The phase advances by one cycle per ``(c_R - c) / f_0`` ahead of the load and per
    ``(c_R + c) / f_0`` behind it, far from it."""
    lam_a, lam_b = (C_R - SPEED) / F0, (C_R + SPEED) / F0
    xi = np.concatenate([np.linspace(-12 * lam_b, -8 * lam_b, 161),
                         np.linspace(8 * lam_a, 12 * lam_a, 161)])
    w, _ = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, SPEED, F0, A)
    for part, lam in ((xi < 0, lam_b), (xi > 0, lam_a)):
        phase = np.unwrap(np.angle(w[part]))
        slope = np.polyfit(xi[part], phase, 1)[0]
        assert abs(abs(slope) * lam / (2 * math.pi) - 1) < 2e-3, (slope, lam)


@pytest.mark.slow
def test_the_numerical_parameters_are_converged(monkeypatch):
    lam_a, lam_b = (C_R - SPEED) / F0, (C_R + SPEED) / F0
    xi = np.array([-10 * lam_b, -lam_b, lam_a, 10 * lam_a])
    base = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, SPEED, F0, A)[1]
    changes = {}
    for name, value in (("LOSS_EXTRAPOLATION", (1e-3, 5e-4, 2.5e-4)), ("K_SPREAD", 20.0),
                        ("IMAGE_DECAY", 60.0)):
        with monkeypatch.context() as m:
            m.setattr(hl, name, value)
            other = hl.moving_harmonic_line_load(xi, P, MU, NU, C_S, SPEED, F0, A)[1]
        changes[name] = float(np.abs(other / base - 1).max())
    print(changes)
    # measured: 1.0e-5, 2.9e-6, 4e-10
    assert max(changes.values()) < 5e-5, changes


def test_out_of_range_is_refused():
    with pytest.raises(ValueError, match="speed = 95"):
        hl.moving_harmonic_line_load([1.0], P, MU, NU, C_S, 95.0, F0, A)
    with pytest.raises(ValueError, match="half_width = 0"):
        hl.moving_harmonic_line_load([1.0], P, MU, NU, C_S, SPEED, F0, 0.0)


def test_the_compliance_is_flamant_at_zero_frequency():
    k = np.array([0.1, 1.0, -3.0])
    got = hl.line_compliance(k, np.zeros(3), MU, NU, C_S, 0.0)
    np.testing.assert_allclose(got, (1 - NU) / np.abs(k), rtol=1e-14)
    # continuous through omega -> 0 (the cancelled form) and the direct form beyond
    small = hl.line_compliance(k, 1e-6 * np.abs(k) * C_S, MU, NU, C_S, 0.0)
    np.testing.assert_allclose(small, (1 - NU) / np.abs(k), rtol=1e-9)
    w = 0.6 * np.abs(k) * C_S                              # |k_S^2| > k^2 / 2: direct form
    direct = hl.line_compliance(k, w, MU, NU, C_S, 0.0)
    just = hl.line_compliance(k, w * (1 - 1e-9), MU, NU, C_S, 0.0)
    np.testing.assert_allclose(direct, just, rtol=1e-6)
