"""Lamb's problem in 3-D with perfectly matched layers (issue 29, item 2): a vertical
Ricker point force on the free surface of a box with layers on its four sides and its
base, against a box twice as large in every direction (its layers twice as far), through
the package's path (:mod:`pml_cases`)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import C_P, run_box
from wave_cases import box_mesh

comm = MPI.COMM_WORLD
#: 1 m hexahedra, a 12 Hz Ricker (7 elements per S wavelength at 30 Hz), layers of 5
#: elements, 0.25 s (the Rayleigh wave has passed every receiver).
H, F0, LAYER, T_END = 1.0, 12.0, 5, 0.25
#: The box's inside (without its layers): 20 x 20 m, 10 m deep; the reference's: 40 x 40 x 20.
INSIDE, REF_INSIDE = (20, 20, 10), (40, 40, 20)
ALL_PML = {f: "pml" for f in ("x_min", "x_max", "y_min", "y_max", "base")}
#: Receivers relative to the source at the surface's centre: at the surface 7 m out (3 m
#: from the side layers; the Rayleigh arrivals) along x, along y and on the diagonal, and
#: 7-8 m down (2-3 m above the base layer; the body arrivals).
SURFACE = np.array([[7.0, 0, 0], [0, 7.0, 0], [5.0, 5.0, 0]])
DEPTH = np.array([[0, 0, -7.0], [5.0, 0, -8.0]])
#: The issue's limit on peak velocity [-].
LIMIT = 0.02


def _box(inside):
    n = tuple(k + 2 * LAYER for k in inside[:2]) + (inside[2] + LAYER,)
    origin = (-LAYER * H, -LAYER * H, -LAYER * H)
    mesh = box_mesh(n, tuple(k * H for k in n), origin)
    centre = np.array([inside[0] * H / 2, inside[1] * H / 2, inside[2] * H])
    return mesh, centre


def lamb_3d(comm_=comm) -> dict:
    """Peak |v| at the receivers in the box and in the reference, and the runs' sizes."""
    out = {}
    for name, inside in (("box", INSIDE), ("reference", REF_INSIDE)):
        mesh, centre = _box(inside)
        receivers = centre + np.vstack([SURFACE, DEPTH])
        out[name] = run_box(mesh, ALL_PML, LAYER * H, (centre, 2, 1e6), receivers, T_END,
                            F0, comm_, courant=None if name == "box" else
                            out["box"]["dt"] * C_P / H)
    peaks = {k: np.linalg.norm(r["v"], axis=2).max(axis=0) for k, r in out.items()}
    return {"difference": np.abs(peaks["box"] / peaks["reference"] - 1.0),
            "dofs": (out["box"]["dofs"], out["reference"]["dofs"]),
            "time_per_step": (out["box"]["time_per_step"], out["reference"]["time_per_step"])}


@pytest.mark.slow
def test_receivers_next_to_the_layers_agree_with_a_box_twice_as_large():
    """Peak velocity within 2 % (the issue) at the surface receivers 3 m from the side
    layers (Rayleigh arrivals) and at those 2-3 m above the base layer (body arrivals)."""
    out = lamb_3d()
    assert out["difference"].max() < LIMIT, out
