"""The free field of a load moving over the bare soil surface against the steady state of a
point load moving over an elastic half-space (issue 28, items 5 and 7).

Reference: :mod:`railvib_hpc.fem.halfspace` (the double Fourier integral of Eason 1965 /
de Barros & Luco 1994, in Barber's 1996 closed form; checked in
tests/fem/test_halfspace.py), convolved with the load's spreading along x
(:func:`~railvib_hpc.transient.surface_load.spreading`).

Model (:mod:`moving_load_cases`): half of the half-space (``y >= 0``, the path a
symmetry plane), 96 x 36 x 30 cubes of 1 m of the thesis subgrade with ``nu = 1/4``
(c_S 208 m/s, c_R 191 m/s), absorbing faces with virtual-thickness springs
(``boundary.virtual_thickness``: without them the box floats on its dashpots and sinks
under the load's weight), the explicit engine at its allowed step. The load runs at half
the Rayleigh speed, switched on over its first 40 m, spread over +-3 m (a point load
pulses at ``c / h`` as it crosses the nodes; docs/verification.md has what each choice
changed).

The springs: the field of a load moving below the Rayleigh speed is quasi-static (it
decays as ``1/r`` and moves with the load), so the faces must carry the static stiffness
of the half-space beyond them. A viscous-spring boundary (Deeks & Randolph 1994; Liu et
al. 2006) sets springs ``~ G / R`` with ``R`` the distance from the source to the face:
a virtual thickness of the order of the faces' distance from the load (30-36 m here).
36 m is taken; 12 m (the earlier choice) is three times stiffer and holds the far field
down (measured with the same model, averaged at the peak: -6.5 / -16 / -47 % at 4 / 8 /
12 m with 12 m, -5.5 / -17 / -58 % with 6 m; docs/verification.md).

The comparison, per receiver beside the path: the steady state's peak while the load
approaches (``0 < xi <= 2 d``), and the FE velocity there, both averaged over ``|xi -
xi_peak| <= d / 4`` (the receivers' signals carry a grid noise of 10-20 % from sample to
sample: 1 m cubes, the step at the explicit limit; a window's maximum takes its top, and
at 12 m the switch-on's Rayleigh pulse, which lies 17.7 m ahead of the load). Within 5 %
at 4, 8 and 12 m (the issue). The departure phase (``xi < 0``) carries the start pulse's
reflections and is not compared; at 2 m the receiver lies within the spreading's reach.
"""

from __future__ import annotations

import numpy as np
import pytest
from moving_load_cases import run_moving_load
from mpi4py import MPI

comm = MPI.COMM_WORLD

#: The run (module notes).
SETTINGS = {"h": 1.0, "n": (96, 36, 30), "receivers": (4.0, 8.0, 12.0), "speed_ratio": 0.5,
            "x_start": 6.0, "x_receiver": 72.0, "virtual_thickness": 36.0,
            "half_width": 3.0}
#: Load speed [m/s]: 0.5 c_R of the soil (c_R = 191.19 m/s,
#: :func:`railvib_hpc.site.rayleigh_speed`).
SPEED = 0.5 * 191.19
#: Switch-on and the run's end [s]: 40 m and 86 m of travel (to 4 m before x_max) at
#: 94.75 m/s, the speed first estimated for the run (the load itself runs at SPEED).
RAMP_TIME, T_END = 40.0 / 94.75, 86.0 / 94.75
#: The bound of the issue (5 %) at 4, 8 and 12 m.
LIMIT = 0.05
#: Half-width of the averaging around the steady state's peak, over the distance d.
PEAK_SPAN = 0.25


def peak_errors(run: dict) -> list[float]:
    """Per receiver: the FE downward velocity over the steady state's, both averaged over
    ``|xi - xi_peak| <= PEAK_SPAN d`` around the steady state's peak while the load
    approaches (``0 < xi <= 2 d``), minus 1."""
    xi = run["xi"]
    out = []
    for j, d in enumerate(run["receivers"]):
        w = np.flatnonzero((xi > 0) & (xi <= 2 * d))
        xi_peak = xi[w[np.argmax(run["v_exact"][w, j])]]
        near = np.abs(xi - xi_peak) <= PEAK_SPAN * d
        out.append(float(run["v"][near, j].mean() / run["v_exact"][near, j].mean() - 1.0))
    return out


@pytest.mark.slow
def test_moving_load_free_field_against_the_half_space():
    run = run_moving_load(comm, ramp_time=RAMP_TIME, t_end=T_END, **SETTINGS)
    errors = peak_errors(run)
    print(f"moving load at {run['speed']:.1f} m/s ({run['dofs']:,} DOFs, "
          f"{len(run['t']) - 1} steps, {run['seconds']:.1f} s on {comm.size} rank(s)): "
          + ", ".join(f"{d:g} m {e:+.2%}" for d, e in zip(run["receivers"], errors)))
    assert run["speed"] == pytest.approx(SPEED, rel=1e-3)
    assert np.all(np.abs(errors) < LIMIT), errors
