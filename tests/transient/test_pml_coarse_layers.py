"""Perfectly matched layers one element thick, through two soils, on every engine: the
placement of the coarse thesis model, whose y-face layers (4 m over one 4-m element on
y_max, half an 8-m element on y_min) grew without bound before.

Why they grew (docs/transient.md, "Where the layer meets coarse elements"): the mass side
of the stretched weak form took ``d`` at the nodes, the memory terms at the Gauss points.
At the layer's inner nodes ``d = 0``, so the mass saw no stretching where the stiffness
did, and a mode whose stiffness sees a larger ``d`` than its mass grows (the cubic of
:func:`railvib_hpc.fem.pml.lumped_mass_coefficients`). Measured on the box below before
the fix: the energy grew ~1e22-fold per 0.5 s on all three engines.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import _set_layers, run_box
from wave_cases import box_mesh

from railvib_hpc.config import load_case
from railvib_hpc.problem import Problem
from railvib_hpc.transient.pml import pml_geometry

comm = MPI.COMM_WORLD
#: Element size [m] = the layers' thickness: one element across every layer.
H = 4.0
#: Layers on both y faces (as the thesis model's), x_min and the base (edges and corners).
FACES = {"y_min": "pml", "y_max": "pml", "x_min": "pml", "base": "pml"}
#: The lower half of the box (the layers' lower half too) three times stiffer.
LOWER = "materials.subballast.E=6e8"
#: Observation windows [s] of the energy.
WINDOW = 0.5


def _box():
    mesh = box_mesh((5, 5, 3), (5 * H, 5 * H, 3 * H))
    _set_layers(mesh, [(1.5 * H, "subballast")])
    return mesh


def _implicit_block(mesh) -> np.ndarray:
    """The soil under the source, outside the layers (a track bed's place)."""
    c = mesh.points[mesh.hexes].mean(axis=1)
    return ((np.abs(c[:, 0] - 2.5 * H) < H) & (np.abs(c[:, 1] - 2.5 * H) < H)
            & (c[:, 2] > 2 * H))


@pytest.mark.parametrize("engine", ["direct", "explicit", "imex"])
def test_one_element_layers_through_two_soils_lose_their_energy(engine):
    """A 12 Hz Ricker force on the surface of a 20 x 20 x 12 m box of 4-m elements, layers
    4 m thick on four faces, undamped, 3 s: the largest energy of every 0.5 s window is
    below that of the window before and the last below 1e-2 of the peak (measured: 0.31,
    0.064, 0.016, 0.0046, 0.0017 of the peak on the direct engine at 5e-3 s, 0.23 to
    7.5e-4 explicit and 0.28 to 1.1e-3 imex at their allowed steps, 9.14e-3 s; before the
    fix the last window held the peak, grown ~1e22-fold per window). The direct engine's
    trapezoidal rule maps the semi-discrete spectrum's right half-plane, and only it,
    outside the unit circle: its run tests the space discretisation at any step."""
    mesh = _box()
    kw = {"direct": {"direct": 5e-3}, "explicit": {},
          "imex": {"implicit": _implicit_block(mesh)}}[engine]
    out = run_box(mesh, FACES, H, ((2.5 * H, 2.5 * H, 3 * H), 2, 1e5),
                  np.array([[2.5 * H, 2.5 * H, 3 * H]]), 3.0, 12.0, comm, extra=(LOWER,),
                  record_energy=True, **kw)
    e, dt = out["energy"], out["dt"]
    per = [e[int(k * WINDOW / dt):int((k + 1) * WINDOW / dt)].max() / e.max()
           for k in range(int(3.0 / WINDOW))]
    assert all(b < a for a, b in zip(per, per[1:])), per
    assert per[-1] < 1e-2, per


def test_an_element_that_straddles_the_layer_is_in_it():
    """A 3.9 m layer on y_max over 8-m elements: their centroids lie 4 m from the face,
    their inner Gauss points 1.69 m: every element of that row is in the layer (the
    stretching acts where ``d > 0``; by the centroids none was, and a layer with a centroid
    at the thickness took elements in or out by round-off: 10 of 496 on the coarse thesis
    model), none of the next row."""
    mesh = box_mesh((2, 3, 2), (8.0, 24.0, 8.0))
    case = load_case(None, ["boundary.y_max=pml", "boundary.layer_thickness=3.9"])
    faces, inside = pml_geometry(mesh, Problem.from_case(case))
    c = mesh.points[mesh.hexes].mean(axis=1)
    assert np.array_equal(inside, c[:, 1] > 16.0)
    assert faces[0].elements == 4 and abs(faces[0].across - 3.9 / 8.0) < 1e-12
