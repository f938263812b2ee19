"""The free field of a load moving over the bare soil surface against the steady state of a
point load moving over an elastic half-space (issue 28, items 5 and 7).

Reference: :mod:`railvib_hpc.fem.halfspace` (the double Fourier integral of Eason 1965 /
de Barros & Luco 1994, in Barber's 1996 closed form; checked in
tests/fem/test_halfspace.py), convolved with the load's spreading along x
(:func:`~railvib_hpc.transient.surface_load.spreading`).

Model (:mod:`moving_load_cases`): half of the half-space (``y >= 0``, the path a
symmetry plane), 96 x 36 x 30 cubes of 1 m of the thesis subgrade with ``nu = 1/4``
(c_S 208 m/s, c_R 191 m/s), absorbing faces with virtual-thickness springs of 12 m
(``boundary.virtual_thickness``: without them the box floats on its dashpots and sinks
under the load's weight, which swamps the quasi-static field far from the path), the
explicit engine at its allowed step. The load runs at half the Rayleigh speed, switched
on over its first 40 m, spread over +-3 m (a point load pulses at ``c / h`` as it crosses
the nodes; docs/verification.md has what each choice changed).

The comparison: the largest downward velocity while the load approaches a receiver beside
the path (``0 < xi <= 2 d``), after the start's Rayleigh pulse has passed it, before
anything reflected from the far faces arrives. The departure phase (``xi < 0``) carries the
start pulse's reflections and is not compared. Measured (1 rank, 330,770 DOFs, 872 steps,
31 s of stepping): +2.7, -1.1, -4.1 % at 4, 8, 12 m (+5.8 % at 2 m, inside the
spreading's reach).
"""

from __future__ import annotations

import numpy as np
import pytest
from moving_load_cases import run_moving_load
from mpi4py import MPI

comm = MPI.COMM_WORLD

#: The run (module notes).
SETTINGS = {"h": 1.0, "n": (96, 36, 30), "receivers": (4.0, 8.0, 12.0), "speed_ratio": 0.5,
            "x_start": 6.0, "x_receiver": 72.0, "virtual_thickness": 12.0,
            "half_width": 3.0}
#: Load speed [m/s]: 0.5 c_R of the soil (c_R = 191.19 m/s,
#: :func:`railvib_hpc.site.rayleigh_speed`).
SPEED = 0.5 * 191.19
#: Switch-on and the run's end [s]: 40 m and 86 m of travel (to 4 m before x_max) at
#: 94.75 m/s, the speed first estimated for the run (the load itself runs at SPEED).
RAMP_TIME, T_END = 40.0 / 94.75, 86.0 / 94.75
#: Measured approach-peak errors at 4, 8 and 12 m (docs/verification.md) and the bound
#: they must stay within (the issue's 5 %).
MEASURED = (0.0274, -0.0106, -0.0413)
BOUNDS = (0.05, 0.05, 0.05)


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
