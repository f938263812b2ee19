"""Beam sections of the APDL script from SECDATA (railvib_hpc.sections) against hand values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railvib_hpc.sections import (
    APDL_RAIL,
    APDL_SLEEPER,
    RAIL_SECDATA,
    SLEEPER_SECDATA,
    apdl_rail_section,
    apdl_sleeper_section,
    i_section,
    i_section_torsion_estimates,
    plate_torsion_constant,
    quad_section,
    strip_shear_coefficient,
)


def rectangle_torsion_series(a: float, b: float, terms: int = 50) -> float:
    """Exact Saint-Venant J of an a x b rectangle, a >= b (Timoshenko & Goodier, §109)."""
    n = np.arange(1, 2 * terms, 2)
    s = np.sum(np.tanh(n * math.pi * a / (2 * b)) / n**5)
    return a * b**3 / 3.0 * (1.0 - 192.0 / math.pi**5 * b / a * s)


def test_rail_i_section_hand_values():
    """SECDATA,0.1524,0.07,0.19,0.0165,0.045,0.0175 = W1, W2, W3, t1, t2, t3."""
    s = i_section(*RAIL_SECDATA, cells=2)
    # by hand: foot 0.1524 x 0.0165, web 0.0175 x 0.1285, head 0.07 x 0.045
    assert s.area == pytest.approx(0.0025146 + 0.00224875 + 0.00315, rel=1e-14)
    zc = (0.0025146 * 0.00825 + 0.00224875 * 0.08075 + 0.00315 * 0.1675) / s.area
    assert s.centroid_height == pytest.approx(zc, rel=1e-14)
    iyy = (0.1524 * 0.0165**3 / 12 + 0.0025146 * (zc - 0.00825) ** 2
           + 0.0175 * 0.1285**3 / 12 + 0.00224875 * (zc - 0.08075) ** 2
           + 0.07 * 0.045**3 / 12 + 0.00315 * (zc - 0.1675) ** 2)
    izz = (0.0165 * 0.1524**3 + 0.1285 * 0.0175**3 + 0.045 * 0.07**3) / 12
    assert s.iyy == pytest.approx(iyy, rel=1e-13)
    assert s.izz == pytest.approx(izz, rel=1e-13)
    # benchmarks.md section 3: A 79.1 cm^2, I_vert ~ 3956 cm^4, I_lat ~ 621 cm^4, 60.9 kg/m
    assert s.area * 1e4 == pytest.approx(79.1, abs=0.05)
    assert s.iyy * 1e8 == pytest.approx(3956, abs=0.5)
    assert s.izz * 1e8 == pytest.approx(621, abs=0.5)
    assert s.mass_per_length(7700.0) == pytest.approx(60.9, abs=0.05)


def test_sleeper_trapezoid_hand_values():
    """SECDATA corners: a trapezoid 0.27 m (bottom) / 0.18 m (top) x 0.22 m."""
    a, b, h = 0.27, 0.18, 0.22
    s = quad_section(SLEEPER_SECDATA, cells=8)
    assert s.area == pytest.approx((a + b) / 2 * h, rel=1e-14)           # 495 cm^2
    assert s.iyy == pytest.approx(h**3 * (a * a + 4 * a * b + b * b) / (36 * (a + b)),
                                  rel=1e-13)                            # 19,699 cm^4
    assert s.izz == pytest.approx(h * (a + b) * (a * a + b * b) / 48, rel=1e-13)
    assert s.centroid_height == pytest.approx(h * (a + 2 * b) / (3 * (a + b)), rel=1e-13)
    assert s.area * 1e4 == pytest.approx(495.0, rel=1e-12)
    assert s.iyy * 1e8 == pytest.approx(19700, rel=1e-4)


def test_shear_coefficient_rectangle_and_i_section():
    # rectangle: the energy method gives exactly 5/6 (any width, either direction)
    assert strip_shear_coefficient([(0.0, 0.3, 0.1, 0.1)]) == pytest.approx(5 / 6, rel=1e-13)
    r = quad_section([(-0.2, 0.0), (0.2, 0.0), (0.2, 0.1), (-0.2, 0.1)], cells=4)
    assert r.shear_coefficient_y == pytest.approx(5 / 6, rel=1e-12)
    assert r.shear_coefficient_z == pytest.approx(5 / 6, rel=1e-12)
    # the rail, vertical: brute-force Jourawski integral on a 1e-6 m grid
    w1, w2, w3, t1, t2, t3 = RAIL_SECDATA
    s = np.linspace(0.0, w3, 190_001)
    ds = s[1] - s[0]
    sm = 0.5 * (s[1:] + s[:-1])
    b = np.where(sm < t1, w1, np.where(sm > w3 - t2, w2, t3))
    area = np.sum(b) * ds
    c = np.sum(b * sm) * ds / area
    inertia = np.sum(b * (sm - c) ** 2) * ds
    q = np.cumsum(b * (sm - c)) * ds
    k_brute = inertia**2 / (area * np.sum(q**2 / b) * ds)
    assert APDL_RAIL.shear_coefficient_y == pytest.approx(k_brute, rel=1e-4)
    # a thin-walled I carries vertical shear in the web: k tends to A_web / A
    thin = i_section(0.2, 0.2, 0.4, 0.002, 0.002, 0.002, cells=1)
    web = 0.002 * 0.396
    assert thin.shear_coefficient_y == pytest.approx(web / thin.area, rel=0.05)
    # and within 5 % of Cowper's (1966) thin-walled I formula at nu = 0.3
    nu, b, h, tf, tw = 0.3, 0.2, 0.398, 0.002, 0.002
    m, n = 2 * b * tf / (h * tw), b / h
    cowper = 10 * (1 + nu) * (1 + 3 * m) ** 2 / (
        (12 + 72 * m + 150 * m**2 + 90 * m**3) + nu * (11 + 66 * m + 135 * m**2 + 90 * m**3)
        + 10 * n**2 * ((3 + nu) * m + 3 * m**2))
    assert thin.shear_coefficient_y == pytest.approx(cowper, rel=0.05)


def test_torsion_solver_against_exact_rectangle():
    for a, b in ((0.2, 0.2), (0.3, 0.1)):
        exact = rectangle_torsion_series(a, b)
        s = quad_section([(-a / 2, 0.0), (a / 2, 0.0), (a / 2, b), (-a / 2, b)], cells=16)
        assert s.j == pytest.approx(exact, rel=2e-5), (a, b)
        # Roark's rectangle formula is within 0.5 % of the series
        assert plate_torsion_constant(a, b) == pytest.approx(exact, rel=5e-3)
    # the I-section mesher: a "I" whose flanges and web have equal width is a rectangle
    s = i_section(0.1, 0.1, 0.3, 0.1, 0.1, 0.1, cells=4)
    assert s.j == pytest.approx(rectangle_torsion_series(0.3, 0.1), rel=1e-4)


def test_rail_torsion_against_closed_forms():
    """Saint-Venant J of the rail section; the closed forms bracket it from above."""
    est = i_section_torsion_estimates(*RAIL_SECDATA)
    j = APDL_RAIL.j
    assert 1.84e-6 < j < 1.86e-6
    # thin-walled sum b t^3 / 3: 2.58e-6 (+40 %, the squat head is not thin)
    assert est["thin_walled"] == pytest.approx(2.584e-6, rel=1e-3)
    # El Darwish & Johnston / AISC DG9 (thick-walled, r = 0): 2.03e-6, within 10 %
    assert est["el_darwish_johnston"] == pytest.approx(2.0253e-6, rel=1e-3)
    assert j < est["el_darwish_johnston"] < est["thin_walled"]
    assert est["el_darwish_johnston"] / j - 1 < 0.10


def test_apdl_constants_are_the_computed_sections():
    for const, computed in ((APDL_RAIL, apdl_rail_section()),
                            (APDL_SLEEPER, apdl_sleeper_section())):
        for field in ("area", "iyy", "izz", "j", "shear_coefficient_y",
                      "shear_coefficient_z", "centroid_height"):
            assert getattr(const, field) == pytest.approx(getattr(computed, field),
                                                          rel=5e-5), field


def test_invalid_sections():
    with pytest.raises(ValueError, match="not an I-section"):
        i_section(0.1, 0.1, 0.05, 0.03, 0.03, 0.01)
    with pytest.raises(ValueError, match="4 corners"):
        quad_section([(0, 0), (1, 0), (1, 1)])
