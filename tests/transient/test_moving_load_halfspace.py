"""The free field of a load moving over the bare soil surface against the steady state of a
point load moving over an elastic half-space (issue 28, items 5 and 7).

Reference: :mod:`railvib_hpc.fem.halfspace` (the double Fourier integral of Eason 1965 /
de Barros & Luco 1994, in Barber's 1996 closed form; checked in
tests/fem/test_halfspace.py), convolved with the load's spreading along x
(:func:`~railvib_hpc.transient.surface_load.spreading`).

Model (:mod:`moving_load_cases`): half of the half-space (``y >= 0``, the path a symmetry
plane), 1 m cubes of the thesis subgrade with ``nu = 1/4`` (c_S 208 m/s, c_R 191 m/s),
absorbing faces with virtual-thickness springs (``boundary.virtual_thickness``: without
them the box floats on its dashpots and sinks under the load's weight, which swamps the
quasi-static field far from the path), the explicit engine at its allowed step. The load
runs at half the Rayleigh speed, switched on over its first 40 m, spread over +-3 m (a point
load pulses at ``c / h`` as it crosses the nodes and radiates grid waves that swamp the
quasi-static field: measured +20 to +250 % at 2-12 m with a point load).

The comparison: the largest downward velocity while the load approaches a receiver beside
the path (``0 < xi <= 2 d``), after the start's Rayleigh pulse has passed it, before
anything reflected from the far faces arrives. What limits it is the truncation of the
static near field (the box's faces lie 12-20 m from the receivers; the field decays as
1/r only) and the departure phase (``xi < 0``) carries the start pulse's reflections.
"""

from __future__ import annotations

import numpy as np
import pytest
from moving_load_cases import run_moving_load
from mpi4py import MPI

comm = MPI.COMM_WORLD

#: The run (module notes).
SETTINGS = {"h": 1.0, "n": (96, 24, 24), "receivers": (4.0, 8.0), "speed_ratio": 0.5,
            "x_start": 6.0, "x_receiver": 72.0, "virtual_thickness": 12.0,
            "half_width": 3.0}
#: Load speed [m/s]: 0.5 c_R of the soil (c_R = 191.19 m/s,
#: :func:`railvib_hpc.site.rayleigh_speed`).
SPEED = 0.5 * 191.19
#: Switch-on [s] (the load's first 40 m) and the run's end [s] (the load 4 m before x_max).
RAMP_TIME, T_END = 40.0 / SPEED, (92.0 - 6.0) / SPEED
#: Measured approach-peak errors at 4 and 8 m (module notes) and the bounds they must stay
#: within (a regression guard; the issue's 5 % is met at 4 m only).
MEASURED = (0.0678, 0.1361)
BOUNDS = (0.08, 0.15)


def approach_peak_errors(run: dict) -> list[float]:
    """Largest downward velocity while the load approaches (``0 < xi <= 2 d``), FE over
    the steady state, minus 1, per receiver."""
    xi = run["xi"]
    out = []
    for j, d in enumerate(run["receivers"]):
        window = (xi > 0) & (xi <= 2 * d)
        out.append(float(run["v"][window, j].max() / run["v_exact"][window, j].max() - 1))
    return out


@pytest.mark.slow
def test_moving_load_free_field_against_the_half_space():
    run = run_moving_load(comm, ramp_time=RAMP_TIME, t_end=T_END, **SETTINGS)
    errors = approach_peak_errors(run)
    print(f"moving load at {run['speed']:.1f} m/s ({run['dofs']:,} DOFs, "
          f"{len(run['t']) - 1} steps, {run['seconds']:.1f} s on {comm.size} rank(s)): "
          + ", ".join(f"{d:g} m {e:+.2%}" for d, e in zip(run["receivers"], errors)))
    assert run["speed"] == pytest.approx(SPEED, rel=1e-3)
    assert np.all(np.abs(errors) < BOUNDS), errors
    assert np.allclose(errors, MEASURED, atol=0.01), errors
