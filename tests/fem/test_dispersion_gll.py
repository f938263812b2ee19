"""Dispersion of the GLL grid (:mod:`railvib_hpc.fem.dispersion_gll`,
:mod:`~railvib_hpc.fem.dispersion_gll_rayleigh`) and the order advice
(:mod:`~railvib_hpc.fem.spectral_advice`): the trilinear relation at order 1, the
``(kh)^(2N)`` rate of the phase error (Ainsworth 2004), its fall in ``N``, the directions
where the grid is worst, the Rayleigh wave's limit, and the advisor."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.fem import dispersion as trilinear
from railvib_hpc.fem import dispersion_gll as gll
from railvib_hpc.fem.dispersion_gll_rayleigh import (
    MIN_POINTS_PER_WAVELENGTH,
    ZONE_WINDOW,
    checked_surface_error,
    rayleigh_frequency,
    rayleigh_wavenumber_ratio,
    worst_surface_error,
)
from railvib_hpc.fem.dispersion_rayleigh import rayleigh_wavenumber_ratio as trilinear_rayleigh
from railvib_hpc.fem.halfspace import rayleigh_mach_limit
from railvib_hpc.fem.spectral_advice import advice_table, order_advice
from railvib_hpc.fem.spectral_kernel import box_element_matrix


@pytest.mark.parametrize("wave", ("P", "S"))
def test_order_one_along_an_axis_is_the_trilinear_lumped_relation(wave):
    """Along an axis both are the 1-D chain ``omega^2 h^2 / c^2 = 4 sin^2(kh / 2)``, with and
    without central differences. (Off the axes they differ: order 1 integrates the
    stiffness on the nodes, the project's hexahedron with 2 x 2 x 2 Gauss points.)"""
    for epw in (4.0, 8.0, 16.0):
        for scheme, courant in (("none", 0.0), ("central", 0.6)):
            a = gll.wavenumber_ratio(epw, wave, "axis", nu=0.3, order=1, scheme=scheme,
                                     courant=courant)
            b = trilinear.wavenumber_ratio(epw, wave, "axis", nu=0.3, mass="lumped",
                                           scheme=scheme, courant=courant)
            assert abs(a - b) < 1e-12
    kh = 2 * np.pi / 8.0
    omega = 2.0 * np.sin(kh / 2)                      # the chain at k h
    w, _ = gll.bloch_branches([kh, 0.0, 0.0], 1, nu=0.3)
    assert np.isclose(w[0], omega, rtol=1e-13)


@pytest.mark.parametrize("order, sizes", ((2, (4, 5, 6, 8)), (3, (2.5, 3, 4, 5)),
                                          (4, (2.2, 2.6, 3.0, 3.5)), (5, (2.1, 2.4, 2.8, 3.2))))
def test_phase_error_converges_at_kh_to_the_2n(order, sizes):
    """Axis S waves, elements per wavelength in the asymptotic range (away from the stop
    bands at ``kh = m pi``): polyfit slopes 4.12, 6.08, 7.96, 9.90 measured (Ainsworth 2004:
    ``2 N``)."""
    errors = [abs(float(gll.wavenumber_ratio(e, "S", "axis", order=order)) - 1) for e in sizes]
    slope = np.polyfit(np.log(1.0 / np.array(sizes)), np.log(errors), 1)[0]
    assert abs(slope - 2 * order) < 0.4, slope


def test_phase_error_falls_with_the_order_at_fixed_points_per_wavelength():
    """7.5 points per S wavelength (``N epw``), axis and face diagonal: measured along the
    axis 3.2e-2, 3.1e-3, 4.4e-4, 7.2e-5, 1.4e-5, 3.0e-6 for N = 1..6."""
    for direction in ("axis", "face_diagonal"):
        errors = [abs(float(gll.wavenumber_ratio(7.5 / n, "S", direction, order=n)) - 1)
                  for n in range(1, 7)]
        assert all(a > 3 * b for a, b in zip(errors, errors[1:])), errors


def test_long_waves_travel_at_the_continuum_speeds():
    for order in (2, 5):
        w, pol = gll.bloch_branches([1e-3, 1e-3, 0.0], order, nu=0.25)
        assert np.allclose(w / (1e-3 * np.sqrt(2)), [1, 1, np.sqrt(3)], rtol=1e-6)
        assert abs(abs(pol[:, 2] @ np.array([1, 1, 0]) / np.sqrt(2)) - 1) < 1e-6
    c_r = rayleigh_mach_limit(0.25)
    assert np.isclose(rayleigh_frequency(0.3, order=3, nu=0.25) / 0.3, c_r, rtol=1e-6)


def test_the_large_cell_solver_equals_the_dense_one(monkeypatch):
    """The block inverse iteration (orders 6-8 off the axes) against ``eigh``, order 4."""
    dense = {w: float(gll.wavenumber_ratio(1.25, w, "body_diagonal", order=4))
             for w in ("P", "S_slow", "S_fast")}
    gll._omega_of.cache_clear()
    monkeypatch.setattr(gll, "_DENSE_LIMIT", 0)
    for wave, ref in dense.items():
        assert abs(float(gll.wavenumber_ratio(1.25, wave, "body_diagonal", order=4)) - ref) \
            < 1e-12
    gll._omega_of.cache_clear()


@pytest.mark.parametrize("order", (3, pytest.param(4, marks=pytest.mark.slow),
                                   pytest.param(5, marks=pytest.mark.slow)))
def test_the_worst_directions_are_those_the_advisor_checks(order):
    """S waves: the body diagonal is never the worst; the Rayleigh wave: from order 4 on
    the axis is worse than the face diagonal (5.5, 7.5 and 9 points per wavelength, clear of
    the stop bands at ``2 N / m``, where the wavenumber is pinned; order 3
    too, though the advisor checks both there, and order 2, where the diagonal can be worse:
    :data:`~railvib_hpc.fem.spectral_advice.SURFACE_DIRECTIONS`)."""
    for ppw in (5.5, 7.5, 9.0):
        epw = ppw / order
        s = {d: abs(float(gll.wavenumber_ratio(epw, "S", d, order=order)) - 1)
             for d in gll.DIRECTIONS}
        assert s["body_diagonal"] < max(s["axis"], s["face_diagonal"]), s
        r = {d: abs(float(rayleigh_wavenumber_ratio(epw, 0.3, order, direction=d)[0]) - 1)
             for d in ("axis", "face_diagonal")}
        assert r["face_diagonal"] < r["axis"], r


def test_rayleigh_order_one_is_closer_than_half_a_percent_at_16_and_orders_improve():
    """Order 1 (nodal quadrature) and the project's trilinear B-bar element both converge
    to ``c_R``; order 4 at 6 points per wavelength beats both at 16."""
    a = float(rayleigh_wavenumber_ratio(16.0, 0.25, 1)[0])
    b = float(trilinear_rayleigh(16.0, 0.25, "lumped")[0])
    assert abs(a - 1) < 0.007 and abs(b - 1) < 0.007
    c = float(rayleigh_wavenumber_ratio(1.5, 0.25, 4)[0])
    assert abs(c - 1) < min(abs(a - 1), abs(b - 1)) / 5
    e, where = worst_surface_error(1.5, 10.0, nu=0.25, order=4)
    assert e < 0.01 and where


def test_critical_courant():
    """Order 1 against the power iteration of a box of 4 x 4 x 4 elements (its largest mode
    is the grid's); every order above the element bound (Irons: the free element's largest
    ``omega`` bounds the assembled grid's), and falling with the order."""
    from spectral_cases import LAM, MU, spectral_box

    from railvib_hpc.fem.spectral_kernel import max_frequency_squared

    nu = LAM / (2 * (LAM + MU))
    _, op = spectral_box(1, (4, 4, 4))
    c_p_over_h = 4.0 * np.sqrt(3.0 * MU / 2000.0)
    box = 2.0 / np.sqrt(max_frequency_squared(op, iterations=3000)) * c_p_over_h
    assert abs(box / gll.critical_courant(1, nu) - 1) < 1e-3
    for order in (2, 3, 4):
        k = box_element_matrix(order, 1.0, *gll._lame(0.3))
        _, m = gll.unit_element(order, 0.3)
        mm = np.repeat(m, 3)
        top = np.linalg.eigvalsh(k / np.sqrt(np.outer(mm, mm))).max()
        bound = 2.0 / np.sqrt(top) * trilinear._cp_over_cs(0.3)
        assert bound <= gll.critical_courant(order, 0.3) * (1 + 1e-12)
        assert gll.critical_courant(order, 0.3) < gll.critical_courant(order - 1, 0.3)


def test_the_lanczos_critical_courant_equals_the_dense_one(monkeypatch):
    """Order 6's cells (648 unknowns and more) take the Lanczos eigenvalue; the dense
    ``eigvalsh`` of every cell gives the same Courant number to 1e-12."""
    lanczos = gll.critical_courant(6, 0.3)
    monkeypatch.setattr(gll, "_LANCZOS_FROM", 10**9)
    gll.critical_courant.cache_clear()
    try:
        assert abs(gll.critical_courant(6, 0.3) / lanczos - 1) < 1e-12
    finally:
        gll.critical_courant.cache_clear()


@pytest.mark.parametrize("order", (2, 5, 8))
def test_below_four_points_per_wavelength_the_checked_relation_resolves_nothing(order):
    """Below :data:`MIN_POINTS_PER_WAVELENGTH` the checked relation says "not resolved" (the
    peak bound 1, the phase inf), whatever mode the column matches there; above it, a finite
    error."""
    below = 0.97 * MIN_POINTS_PER_WAVELENGTH / order
    assert checked_surface_error(below, 3.0, order=order, directions=("axis",)) == (
        1.0, "fewer than 4 points per wavelength")
    assert checked_surface_error(below, 3.0, order=order, directions=("axis",),
                                 measure="phase")[0] == np.inf
    e, _ = checked_surface_error(6.0 / order, 3.0, order=order, directions=("axis",))
    assert 0.0 <= e < 1.0


def test_the_checked_relation_does_not_understate_the_error_at_a_zone_boundary():
    """About ``k h = pi`` at order 3 (6 points per wavelength) the lattice has a narrow stop
    band and the column's wave and its alias are degenerate: the phase error per wavelength
    read there can be far below the grid's on either side (measured: 7.6e-4 at 6.05 points
    between 4.3e-3 at 5.95 and 1.9e-3 at 6.2). Through the window the checked relation at
    every size from 5.9 to 6.1 points is at least the grid's error at 6.3 points, the finer
    side beyond the window (which grows with the frequency), and at least the unchecked
    relation at the same size."""
    order, directions = 3, ("axis",)
    finer = worst_surface_error(6.3 / order, 1.0, order=order, measure="phase",
                                directions=directions)[0]
    for ppw in (5.9, 5.95, 6.0, 6.05, 6.1):
        checked = checked_surface_error(ppw / order, 1.0, order=order, measure="phase",
                                        directions=directions)[0]
        raw = worst_surface_error(ppw / order, 1.0, order=order, measure="phase",
                                  directions=directions)[0]
        assert np.isfinite(checked) and checked >= max(finer, raw), (ppw, checked, finer)
    assert 0.0 < ZONE_WINDOW <= 0.05


def test_the_advisor_at_order_four():
    advice = order_advice(80.0, 150.0, 25.0, nu=0.3, target=0.05, orders=(4,))
    row = advice["best"]
    assert row["order"] == 4 and 5.0 < row["ppw_s"] < 7.0
    assert np.isclose(row["dofs_per_m3"], 3 * (4 / row["h"]) ** 3)
    assert len(advice_table(advice)) == 3
    with pytest.raises(ValueError, match="criterion"):
        order_advice(80.0, 150.0, 25.0, criterion="speed")
    with pytest.raises(ValueError, match="distance must be > 0"):
        order_advice(80.0, 150.0, 0.0)


@pytest.mark.slow
def test_the_advisor_prefers_high_orders_and_reproduces_the_trilinear_need():
    """The 80 Hz site (c_S = 150 m/s, 25 m, 5 %): order 1 needs 26 elements per S
    wavelength (the trilinear explicit engine's lumped grid: 25-26.75 in docs/transient.md),
    order 4 about 6 points per wavelength and 100 times fewer DOFs."""
    advice = order_advice(80.0, 150.0, 25.0, nu=0.3, target=0.05, orders=(1, 2, 4))
    rows = {r["order"]: r for r in advice["rows"]}
    assert rows[2]["dofs_per_m3"] > 3 * rows[4]["dofs_per_m3"]
    assert 24.0 < rows[1]["epw_s"] < 28.0
    assert 5.0 < rows[4]["ppw_s"] < 7.0
    assert rows[1]["dofs_per_m3"] > 50 * rows[4]["dofs_per_m3"]
    assert advice["best"]["order"] == 4
