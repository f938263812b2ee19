"""The moving-load half-space reference (:mod:`railvib_hpc.fem.halfspace`) against its limits
and against an independent evaluation of the double Fourier integral (2-D FFT)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railvib_hpc.fem.halfspace import (
    direction_kernel,
    mach_numbers,
    moving_load_displacement,
    moving_load_velocity,
    rayleigh_mach_limit,
)

NU = 0.25
#: soil in units: mu = 1, c_S = 1, P = 1
ARGS = {"force": 1.0, "mu": 1.0, "nu": NU, "c_s": 1.0}


def _w(xi, y, speed, eta=0.0, **kw):
    return moving_load_displacement(xi, y, speed=speed, eta=eta, **{**ARGS, **kw})


def test_slow_load_is_boussinesq():
    """c -> 0: ``P (1 - nu) / (2 pi mu r)`` everywhere (the static point load)."""
    xi, y = np.meshgrid([-7.0, -1.0, 0.5, 3.0], [-2.0, 0.0, 0.3, 4.0])
    r = np.hypot(xi, y)
    w = _w(xi, y, 1e-3)
    assert np.allclose(w, (1 - NU) / (2 * math.pi * r), rtol=1e-5)


def test_symmetry_scaling_and_the_path():
    """Elastic: fore-aft and left-right symmetric (no radiation below c_R); ``w`` scales
    as ``P / (mu r)`` at a given direction; on the path ``D = 1 - nu`` at any speed."""
    xi, y = np.array([0.7, 2.0, 5.0]), np.array([1.0, 3.0, 0.2])
    for speed in (0.3, 0.6, 0.85):
        w = _w(xi, y, speed)
        assert np.allclose(w, _w(-xi, y, speed), rtol=1e-13)
        assert np.allclose(w, _w(xi, -y, speed), rtol=1e-13)
        assert np.allclose(_w(2 * xi, 2 * y, speed), 0.5 * w, rtol=1e-13)
        assert np.allclose(moving_load_displacement(xi, y, 3.0, 2.0, NU, 1.0, speed),
                           1.5 * w, rtol=1e-13)
        path = _w(np.array([1.0, -4.0]), 0.0, speed) * 2 * math.pi * np.array([1.0, 4.0])
        assert np.allclose(path, 1 - NU, rtol=1e-12)
    # a faster load: the bowl widens beside it, without bound as c -> c_R
    beside = [float(_w(0.0, 1.0, s * rayleigh_mach_limit(NU)))
              for s in (0.2, 0.5, 0.9, 0.99, 0.999)]
    assert np.all(np.diff(beside) > 0) and beside[-1] > 20 * beside[0]


def test_rayleigh_speed_is_refused():
    c_r = rayleigh_mach_limit(NU)
    assert c_r == pytest.approx(0.919402, abs=1e-6)          # Achenbach Table 5.1, nu = 1/4
    with pytest.raises(ValueError, match="Rayleigh speed"):
        _w(1.0, 1.0, c_r)
    with pytest.raises(ValueError, match="Rayleigh speed"):
        _w(1.0, 1.0, 1.2)


def test_velocity_is_the_moving_derivative():
    """``v = -c dw/dxi``: antisymmetric fore-aft (elastic); slowly, its peak is at
    ``xi = y / sqrt 2`` with ``c P (1 - nu) / (2 pi mu) 2 / (3 sqrt 3 y^2)``."""
    y, c = 2.0, 0.01
    xi = np.linspace(-8.0, 8.0, 16001)
    v = moving_load_velocity(xi, y, speed=c, **ARGS)
    assert np.allclose(v, -v[::-1], atol=1e-12 * np.abs(v).max())
    k = int(np.argmax(v))
    assert xi[k] == pytest.approx(y / math.sqrt(2), abs=5e-3)
    assert v[k] == pytest.approx(c * (1 - NU) / (2 * math.pi) * 2 / (3 * math.sqrt(3) * y * y),
                                 rel=2e-3)


def _fft_field(speed: float, eta: float, n: int = 1024, length: float = 200.0):
    """The double Fourier integral of the surface Green's function on an ``n x n`` grid
    (period ``length``), by the inverse FFT: ``w`` up to a constant (the k = 0 term)."""
    k1 = 2 * np.pi * np.fft.fftfreq(n, length / n)
    kx, ky = np.meshgrid(k1, k1, indexing="ij")
    k = np.hypot(kx, ky)
    m_s, m_p = mach_numbers(speed, 1.0, NU)
    spectrum = np.where(k > 0, direction_kernel(np.arctan2(ky, kx), m_s, m_p, eta)
                        / np.where(k > 0, k, 1.0), 0.0)
    x = np.arange(n) * length / n
    x[x >= length / 2] -= length
    return x, np.fft.ifft2(spectrum).real * (n / length) ** 2


@pytest.mark.parametrize("eta", [0.0, 0.05])
def test_against_the_double_fourier_integral(eta):
    """The one-dimensional (direction) form against the two-dimensional integral evaluated
    by FFT (1024^2 points, 200 m period): the slope dw/dxi beside the path within 0.5 %
    (elastic and hysteretic)."""
    speed = 0.5
    x, w = _fft_field(speed, eta)
    dx = x[1] - x[0]
    j = int(round(10.0 / dx))
    errors = []
    for i in (-40, -20, 20, 40):
        slope_fft = (w[(i + 1) % x.size, j] - w[i - 1, j]) / (2 * dx)
        slope = -moving_load_velocity(x[i], x[j], speed=speed, eta=eta, **ARGS) / speed
        errors.append(slope_fft / float(slope) - 1)
    assert np.abs(errors).max() < 5e-3, errors


def test_damping_drags_the_bowl_behind_the_load():
    """Hysteretic damping: deeper behind the load than ahead; continuous as eta -> 0; the
    principal-value rule converged."""
    xi, y = np.array([3.0]), np.array([2.0])
    ahead, behind = _w(xi, y, 0.6, eta=0.05), _w(-xi, y, 0.6, eta=0.05)
    assert behind[0] > ahead[0]
    assert np.allclose(_w(xi, y, 0.6, eta=1e-7), _w(xi, y, 0.6), rtol=1e-5)
    assert np.allclose(_w(xi, y, 0.6, eta=0.05, n_directions=800), ahead, rtol=1e-9)
