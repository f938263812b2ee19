"""Hertz contact law and Jenkins' constant (benchmarks.md section 1)."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.mbs import hertz_force, hertz_penetration, jenkins_hertz_constant


def test_jenkins_constant_and_static_penetration():
    kh = jenkins_hertz_constant(0.46)
    # reference values are given to 2 and 3 significant digits: half a unit of the last digit
    assert abs(kh - 8.6e10) <= 0.05e10
    assert abs(hertz_penetration(7.69e3, kh) - 20.0e-6) <= 0.05e-6
    assert hertz_force(hertz_penetration(7.69e3, kh), kh) == pytest.approx(7.69e3, rel=1e-14)


def test_separation_and_damping():
    kh, c = 8.6e10, 1e9
    d = np.array([-1e-6, 0.0, 1e-5, 1e-5, 1e-5])
    dd = np.array([0.0, 0.0, 0.0, 0.01, -10.0])
    f = hertz_force(d, kh, dd, c)
    assert f[0] == 0.0 and f[1] == 0.0
    assert f[2] == pytest.approx(kh * 1e-5**1.5)
    assert f[3] > f[2]  # loading: damping adds to the force (dissipative)
    assert f[4] == 0.0  # fast unloading: no tensile contact force
    with pytest.raises(ValueError):
        jenkins_hertz_constant(0.0)
