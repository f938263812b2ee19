"""A two-layer soil column on a perfectly matched layer (issue 29, item 2: "the same
checks in a two-layer column"): 1-D P and S pulses from the free top through an
interface into a base layer that the lower soil runs through, against the same column
60-80 m deeper with a fixed base (through the package's path, :mod:`pml_cases`)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import C_P, C_S, E, _set_layers, run_box
from wave_cases import box_mesh

comm = MPI.COMM_WORLD
#: 1 m elements, a 12 Hz Ricker, a base layer of 8 elements (the defaults R, p).
H, F0, LAYER = 1.0, 12.0, 8
#: The upper layer's depth, the layer's inner face and the receiver [m below the top]:
#: the receiver in the lower soil, 5 m above the layer.
INTERFACE, FACE, RECEIVER = 20.0, 30.0, 25.0
#: The lower soil: 1.5 x stiffer (c 1.22 x), its material entered as the subballast's.
LOWER_E_FACTOR = 1.5
#: The reference's depth [m]: its fixed base's echo reaches the receiver after the window.
REFERENCE_DEPTH = 110.0
#: Free DOFs per kind: u_z alone (P) or u_x alone (S).
FIXED_DOFS = {"P": ("ux", "uy"), "S": ("uy", "uz")}
COMPONENT = {"P": 2, "S": 0}
#: The issue's limit on the reflected energy, and the bound the test keeps (above the
#: measured values, given in the test).
LIMIT, BOUND = 0.01, 1e-3


def _speeds(kind: str) -> tuple[float, float]:
    c = C_P if kind == "P" else C_S
    return c, c * np.sqrt(LOWER_E_FACTOR)


def window(kind: str) -> float:
    """The pulse down to the layer and back up to the receiver, plus 2.4 / f0 [s]."""
    upper, lower = _speeds(kind)
    return INTERFACE / upper + (2 * FACE - INTERFACE - RECEIVER) / lower + 2.4 / F0


def _column(depth: float):
    n = int(round(depth / H))
    mesh = box_mesh((1, 1, n), (H, H, n * H), (0.0, 0.0, -depth))
    _set_layers(mesh, [(depth - INTERFACE, "subballast")])
    return mesh


def column_reflection(kind: str, comm_=comm) -> dict:
    """Reflected over incident energy at the receiver (``R_E``; the difference from the
    deep column over the deep column's signal in the window), and the first echo time of
    the deep column's base."""
    faces = {"x_min": "free", "x_max": "free", "y_min": "free", "y_max": "free"}
    source = [((0.0, 0.0, 0.0), COMPONENT[kind], 1e4), ((H, 0.0, 0.0), COMPONENT[kind], 1e4)]
    receiver = np.array([[0.0, 0.0, -RECEIVER]])
    extra = (f"materials.subballast.E={LOWER_E_FACTOR * E}",)
    t_end = window(kind)
    a = run_box(_column(FACE + LAYER * H), {**faces, "base": "pml"}, LAYER * H, source,
                receiver, t_end, F0, comm_, plane_strain=FIXED_DOFS[kind], extra=extra)
    ref = run_box(_column(REFERENCE_DEPTH), {**faces, "base": "fixed"}, 0.0, source,
                  receiver, t_end, F0, comm_, plane_strain=FIXED_DOFS[kind], extra=extra,
                  courant=a["dt"] * C_P / H)
    n = min(len(a["t"]), len(ref["t"]))
    diff = ((a["v"][:n] - ref["v"][:n]) ** 2).sum()
    upper, lower = _speeds(kind)
    echo = INTERFACE / upper + (2 * REFERENCE_DEPTH - INTERFACE - RECEIVER) / lower
    return {"R_E": float(diff / (ref["v"][:n] ** 2).sum()), "echo": echo, "t_end": t_end}


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["P", "S"])
def test_a_two_layer_column_sends_back_far_below_1_percent(kind):
    """P and S pulses through the interface (the lower soil 1.5 x stiffer, through the
    layer): reflected energy below 1 % (the issue) and below 1e-3 (measured: P 3.3e-5,
    S 5.2e-5), the reference's base echo after the window; 1 and 2 ranks."""
    out = column_reflection(kind)
    assert out["echo"] > out["t_end"], out
    assert out["R_E"] < LIMIT and out["R_E"] < BOUND, out


def test_a_fixed_base_in_place_of_the_layer_is_seen():
    """The column cut at the layer's inner face and fixed there (no layer): the measure
    sees the reflection (R_E above 0.1)."""
    faces = {"x_min": "free", "x_max": "free", "y_min": "free", "y_max": "free"}
    source = [((0.0, 0.0, 0.0), 2, 1e4), ((H, 0.0, 0.0), 2, 1e4)]
    receiver = np.array([[0.0, 0.0, -RECEIVER]])
    extra = (f"materials.subballast.E={LOWER_E_FACTOR * E}",)
    t_end = window("P")
    a = run_box(_column(FACE), {**faces, "base": "fixed"}, 0.0, source, receiver, t_end, F0,
                comm, plane_strain=FIXED_DOFS["P"], extra=extra)
    ref = run_box(_column(REFERENCE_DEPTH), {**faces, "base": "fixed"}, 0.0, source,
                  receiver, t_end, F0, comm, plane_strain=FIXED_DOFS["P"], extra=extra,
                  courant=a["dt"] * C_P / H)
    n = min(len(a["t"]), len(ref["t"]))
    r_e = ((a["v"][:n] - ref["v"][:n]) ** 2).sum() / (ref["v"][:n] ** 2).sum()
    assert r_e > 0.1, r_e
