"""The layers do not shorten the conditionally stable engines' step (Basu 2009 reports
explicit PML steps like those of the elastic model): their ``M_e2`` is taken at the
Newmark average displacement (:meth:`~railvib_hpc.transient.explicit.ExplicitSystem.
effective_mass`; in K_eff on the imex engine), so the limit is the elastic one; and runs
at that step stay stable."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import FACES, run_box
from wave_cases import box_mesh

comm = MPI.COMM_WORLD
#: Element layers of every layer (1-m hexahedra, layers of 5 m).
LAYER = 5


def _box(inside):
    n = (inside[0] + 2 * LAYER, inside[1] + 2 * LAYER, inside[2] + LAYER)
    return box_mesh(n, tuple(float(k) for k in n), (-LAYER, -LAYER, -LAYER)), \
        np.array([inside[0] / 2, inside[1] / 2, float(inside[2])])


def _run(inside, faces, thickness, t_end, engine="explicit", record_energy=False,
         extra=()):
    mesh, centre = _box(inside)
    implicit = None
    if engine == "imex":
        c = mesh.points[mesh.hexes].mean(axis=1)
        implicit = ((np.abs(c[:, 0] - centre[0]) < 2) & (np.abs(c[:, 1] - centre[1]) < 2)
                    & (c[:, 2] > centre[2] - 2))
    return run_box(mesh, faces, thickness, (centre, 2, 1e6), centre[None, :], t_end, 12.0,
                   comm, implicit=implicit, record_energy=record_energy, extra=extra)


@pytest.mark.parametrize("engine", ["explicit", "imex"])
def test_the_layers_do_not_shorten_the_step(engine):
    """A 16 x 16 x 8 m box of 1-m hexahedra with 5-m layers on all five faces: the allowed
    step is that of the same box with fixed faces within 0.2 % (all of its hexahedra with
    the plain full integration that the layers' elements take; measured: explicit 2.6227e-3
    against 2.6226e-3 s, imex 2.6403e-3 against 2.6393e-3 s; with ``M_e2`` in the limit
    both were 1.554e-3 s, 1.69 x shorter)."""
    pml = _run((6, 6, 3), {f: "pml" for f in FACES}, float(LAYER), 1e-4, engine)
    fixed = _run((6, 6, 3), {}, 0.0, 1e-4, engine, extra=("modal.hex_formulation=full",))
    assert pml["dt"] > 0.998 * fixed["dt"], (pml["dt"], fixed["dt"])


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["explicit", "imex"])
def test_10_s_at_the_elastic_step_with_layers_on_five_faces_shows_no_growth(engine):
    """10 s undamped at the engine's allowed step (~3,800 steps) after a vertical force on
    the surface: every second's largest energy after the first below 1e-6 of the peak,
    none above the one before, the last below the second's (measured on the 20 x 20 x 10
    m box: explicit 1.5e-8 falling to 3.8e-9, imex 1.1e-7 to 7.1e-8)."""
    out = _run((6, 6, 3), {f: "pml" for f in FACES}, float(LAYER), 10.0, engine,
               record_energy=True)
    e, dt = out["energy"], out["dt"]
    per = [e[int(k / dt):int((k + 1) / dt)].max() / e.max() for k in range(10)]
    assert max(per[1:]) < 1e-6, per
    assert all(b <= a for a, b in zip(per[1:], per[2:])), per
    assert per[-1] < per[1], per
