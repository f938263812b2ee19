"""The static start against the steady state of a point load moving over a half-space, at
0.3, 0.6 and 0.8 c_R, 5, 10 and 20 m beside the path (slow; the harness:
:mod:`moving_load_steady`, whose notes derive the tolerance).

Box: 60 m along x (3-63 m), 35 m on either side of the path, 20 m deep, 1 m cubes of the
thesis subgrade with nu = 1/4 (272,853 DOFs), absorbing faces with 48 m springs, the
explicit engine. The load (100 kN, spread +-3 m) stands in static equilibrium at
x = 18 m, runs up to its speed over 10 m (``load.ramp_time``); the receivers are 5 m
beyond the run-up's end, from which on the comparison runs, until the load has passed
them by 20 m.

Measured (2026-12, on the shared 2-core machine, one rank; errors: the largest difference
over the reference's largest value, the FE signal without the content above the grid's
band, c_S / (6 h) = 35 Hz; ``tol`` = e_box + e_grid of the harness)::

    c/c_R  d [m]    u_z     v_z    tol    (u_z, v_z raw)
    0.30    5     7.95   17.1    7.47     8.00   18.8
    0.30   10    10.1    45.9    4.03    10.1    48.2
    0.30   20    26.3    99.7   29.5     26.5   132
    0.60    5    16.9    89.6    7.47    17.5   182
    0.60   10    29.2   138      4.03    29.6   139
    0.60   20    52.5   205     29.5     52.4   207
    0.80    5    43.8   145      7.47    43.5   156
    0.80   10    58.0   229      4.03    58.1   228
    0.80   20    72.6   236     29.5     72.6   234

The derived tolerance is met at 20 m for u_z at 0.3 c_R only: the trilinear soil in a box
this size does **not** reproduce the steady state within it (docs/verification.md, "The
static start against the steady state", says what limits it). This test therefore guards
the measured errors against regression (each bound 1.5 times the measured error, rounded
up), and prints the table with the derived tolerance beside it; it is the harness a
spectral soil will run with its own overrides and its own (tighter) bounds. Measured:
78-96 s per speed in a sweep, 108-168 s under pytest (388 s for the three) on the shared
machine at load ~9; about half of each is the static start's MUMPS factor. The slow tier
runs 0.6 c_R (:data:`TIER_RATIO`); ``bench/moving_load_steady.py`` prints the whole table.
"""

from __future__ import annotations

import pytest
from moving_load_steady import box_overrides, compare, format_rows, run_box, soil
from mpi4py import MPI

comm = MPI.COMM_WORLD

#: The measured errors (u_z, v_z) per speed and distance (module notes).
MEASURED = {0.3: {5.0: (0.0795, 0.171), 10.0: (0.101, 0.459), 20.0: (0.263, 0.997)},
            0.6: {5.0: (0.169, 0.896), 10.0: (0.292, 1.38), 20.0: (0.525, 2.05)},
            0.8: {5.0: (0.438, 1.45), 10.0: (0.580, 2.29), 20.0: (0.726, 2.36)}}
#: Headroom of the regression bounds over the measured errors.
HEADROOM = 1.5
#: The speed the slow tier runs: the side-by-side case against STEM (0.6 c_R); the
#: other two of the table, 0.3 and 0.8 c_R, are ``bench/moving_load_steady.py --ratios
#: 0.3 0.8`` (the three took 388 s of the slow tier).
TIER_RATIO = 0.6


@pytest.mark.slow
@pytest.mark.skipif(comm.size > 1, reason="one rank")
@pytest.mark.parametrize("ratio", [TIER_RATIO])
def test_the_static_start_against_the_steady_state(tmp_path, ratio):
    run = run_box(tmp_path / "box", box_overrides(ratio), MPI.COMM_SELF)
    rows = compare(run)
    print(f"\n{run.stats['n_dofs']:,} DOFs, {run.stats['n_steps']} steps of "
          f"{run.stats['dt']:.3g} s\n" + format_rows(rows, soil(run.case)["c_r"]))
    assert [r["d"] for r in rows] == sorted(MEASURED[ratio])
    for r in rows:
        u, v = MEASURED[ratio][r["d"]]
        assert r["e_u"] <= HEADROOM * u and r["e_v"] <= HEADROOM * v, r
        # the static start is the box's static answer: its settlement at t = 0 is within
        # the box's own truncation of Boussinesq's (e_box is measured, the grid adds its
        # discretisation, under 6 %)
        assert r["e_box"] < 0.35
