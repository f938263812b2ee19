"""Moving loads on the bare soil surface (issue 28, item 5): the nodal loads, and the same
run on 1 and 2 ranks (the steady-state verification: test_moving_load_halfspace.py)."""

from __future__ import annotations

import numpy as np
import pytest
from moving_load_cases import run_moving_load
from mpi4py import MPI
from wave_cases import box_mesh

from railvib_hpc.transient.surface_load import (
    MovingSurfaceLoad,
    SurfaceLoadPath,
    ramp,
    spreading,
)

comm = MPI.COMM_WORLD


def _load(half_width: float, y: float = 1.0, x_start: float = 2.0, nt: int = 40,
          offsets=(0.0, -1.5)):
    mesh = box_mesh((8, 4, 3), (8.0, 4.0, 3.0), origin=(0.0, 0.0, -3.0))
    index = np.arange(mesh.n_nodes * 3).reshape(-1, 3)
    path = SurfaceLoadPath(forces=np.array([10.0, 20.0])[:len(offsets)],
                           offsets=np.array(offsets), x_start=x_start, y=y, speed=5.0,
                           ramp_time=0.2, half_width=half_width)
    return mesh, path, MovingSurfaceLoad(mesh, index, path, 0.025, nt)


@pytest.mark.parametrize("half_width", [0.0, 1.25])
def test_nodal_loads_carry_the_force_where_the_load_is(half_width):
    """Every step: the vertical nodal forces of each load sum to ``-P s(t)``, lie on the
    surface nodes of the load's element(s), and their centroid is the load's position
    (linear shape functions, a symmetric spreading)."""
    mesh, path, load = _load(half_width, offsets=(0.0,))
    t = np.arange(41) * 0.025
    inside = path.positions(t)[:, 0] + half_width <= 8.0       # wholly on the soil
    assert inside.sum() > 30
    for n in np.flatnonzero(inside):
        dofs, values = load(n)
        own = dofs >= 0
        nodes = dofs[own] // 3
        assert np.all(dofs[own] % 3 == 2)                       # uz only
        assert values[own].sum() == pytest.approx(-10.0 * float(ramp(t[n], 0.2)), abs=1e-9)
        if values[own].sum() < -1e-9:
            below = mesh.points[nodes, 2] < -1e-6
            assert np.abs(values[own][below]).sum() < 1e-7 * abs(values[own].sum())
            centre = (mesh.points[nodes] * values[own, None]).sum(axis=0) / values[own].sum()
            assert centre[0] == pytest.approx(path.positions(t[n:n + 1])[0, 0], abs=1e-7)
            assert centre[1] == pytest.approx(1.0, abs=1e-7)


def test_ramp_and_spreading():
    t = np.linspace(-0.1, 0.5, 61)
    s = ramp(t, 0.2)
    assert s[t < 0].max() == 0.0 and np.all(s[t >= 0.2] == 1.0)
    assert np.all(np.diff(s) >= 0) and s[np.argmin(np.abs(t - 0.1))] == pytest.approx(0.5)
    assert np.all(ramp(t, 0.0) == (t >= 0))
    offs, w = spreading(1.0, 0.1)
    assert w.sum() == pytest.approx(1.0) and np.abs(offs).max() < 1.0
    assert (offs * w).sum() == pytest.approx(0.0, abs=1e-15)
    assert spreading(0.0, 0.1)[0].tolist() == [0.0]


def test_a_load_leaving_the_soil_is_off_and_one_never_on_it_is_refused():
    _, _, load = _load(0.0, x_start=6.0, nt=40, offsets=(0.0,))   # at x = 8: t = 0.4
    x = load.x[:, 0]
    for n in range(41):
        total = load(n)[1].sum()
        if x[n] > 8.0 + 1e-9:
            assert total == 0.0
    assert load.on_surface[:, 0].sum() < 41
    with pytest.raises(ValueError, match=r"y = 9 m never stand on the soil surface"):
        _load(0.0, y=9.0)


@pytest.mark.mpi
def test_one_and_two_ranks_agree():
    """A tiny moving-load run (explicit engine, absorbing faces) on all ranks and on each
    rank alone: the same receiver velocities (to round-off)."""
    kw = {"h": 1.0, "n": (12, 6, 6), "receivers": (2.0, 4.0), "speed_ratio": 0.5,
          "x_start": 1.0, "x_receiver": 8.0, "ramp_time": 0.02, "t_end": 0.06,
          "virtual_thickness": 6.0, "half_width": 1.5}
    world = run_moving_load(comm, **kw)
    alone = run_moving_load(MPI.COMM_SELF, **kw)
    scale = np.abs(alone["v"]).max()
    assert scale > 0
    assert world["dt"] == pytest.approx(alone["dt"], rel=1e-6)
    assert np.abs(world["v"] - alone["v"]).max() < 1e-9 * scale


def test_a_harmonic_load_varies_as_a_cosine_after_its_switch_on():
    """``frequency``: every step's nodal forces sum to ``-P s(t) cos(2 pi f t)``."""
    from dataclasses import replace

    mesh, path, _ = _load(0.0, offsets=(0.0,))
    path = replace(path, frequency=3.0)
    load = MovingSurfaceLoad(mesh, np.arange(mesh.n_nodes * 3).reshape(-1, 3), path, 0.025, 40)
    t = np.arange(41) * 0.025
    expected = -10.0 * ramp(t, 0.2) * np.cos(2 * np.pi * 3.0 * t)
    on = path.positions(t)[:, 0] <= 8.0
    sums = np.array([load(n)[1][load(n)[0] >= 0].sum() for n in range(41)])
    np.testing.assert_allclose(sums[on], expected[on], atol=1e-12)
    assert np.ptp(np.sign(expected[on])) == 2                  # it changes sign
