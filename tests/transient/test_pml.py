"""The perfectly matched layer (issue 29) against larger domains, its long-run stability,
and the same answer on 1 and 2 ranks (plane-strain slabs through the package's path,
:mod:`pml_cases`)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import run_box, slab_mesh

comm = MPI.COMM_WORLD
#: Plane-strain Lamb: a 12 Hz Ricker line load on the free top of a 40 x 20 m slab (1 m
#: elements), layers of 8 elements on x_min, x_max and the base; receivers 1-5 m from the
#: side layer at the surface and at 10 m depth, 0.2 s.
PML = {"x_min": "pml", "x_max": "pml", "base": "pml", "y_min": "free", "y_max": "free"}
FIXED = {f: ("fixed" if k == "pml" else k) for f, k in PML.items()}
SOURCE = ((20.0, 0.0, 20.0), 2, 1e5)
RECEIVERS = np.array([[25, 0, 20], [29, 0, 20], [31, 0, 20], [20, 0, 10], [29, 0, 10]], float)
#: The reference slab: 36 m more on each side and below (its fixed faces' echoes arrive
#: after 0.2 s at the receivers).
MARGIN = 36


def _lamb(faces, comm_=comm):
    return run_box(slab_mesh(40, 20, 1.0), faces, 8.0, SOURCE, RECEIVERS, 0.2, 12.0, comm_,
                   plane_strain=True)


def _reference(dt):
    from pml_cases import C_P

    big = slab_mesh(40 + 2 * MARGIN, 20 + MARGIN, 1.0, origin=(-MARGIN, 0.0, -MARGIN))
    return run_box(big, FIXED, 0.0, SOURCE, RECEIVERS, 0.2, 12.0, comm, plane_strain=True,
                   courant=dt * C_P / 1.0)


def _differences(a, b):
    n = min(len(a["t"]), len(b["t"]))
    va, vb = a["v"][:n], b["v"][:n]
    peak = np.linalg.norm(va, axis=2).max(axis=0) / np.linalg.norm(vb, axis=2).max(axis=0) - 1
    energy = ((va - vb) ** 2).sum(axis=(0, 2)) / (vb ** 2).sum(axis=(0, 2))
    return np.abs(peak), energy


def test_the_layer_matches_a_slab_36_m_larger_where_a_fixed_face_does_not():
    """Peak |v| within 0.5 % and the difference's energy below 2e-4 of the signal's at
    every receiver (measured: 0.02-0.14 % and 1.4e-5 to 3.8e-5: second-order FE
    dispersion differs between the two meshes' steps only through the layer); the same
    slab with fixed faces in place of the layers is off by far more (the check can fail)."""
    a = _lamb(PML)
    ref = _reference(a["dt"])
    peak, energy = _differences(a, ref)
    assert peak.max() < 5e-3 and energy.max() < 2e-4, (peak, energy)
    fixed = run_box(slab_mesh(40, 20, 1.0), FIXED, 0.0, SOURCE, RECEIVERS, 0.2, 12.0, comm,
                    plane_strain=True, courant=a["dt"] * 346.6 / 1.0)
    _, energy_fixed = _differences(fixed, ref)
    assert energy_fixed.min() > 100 * energy.max(), energy_fixed


def _stability(t_end: float):
    out = run_box(slab_mesh(20, 10, 1.0), PML, 5.0, ((10.0, 0.0, 10.0), 2, 1e5),
                  np.array([[15.0, 0.0, 10.0]]), t_end, 12.0, comm, plane_strain=True,
                  record_energy=True)
    e = out["energy"]
    return e, out["dt"]


def test_an_undamped_slab_with_layers_loses_its_energy_and_stays_quiet():
    """3 s at the engine's allowed step (1,200 steps): the energy after 1 s stays below
    1e-4 of its peak and ends below 1e-6 (measured: the 20 s run of the slow tier ends at
    1e-12). With B-bar in the layer's elements or the classical alpha = 0 stretching
    this slab's energy grew without bound (docs/transient.md)."""
    e, dt = _stability(3.0)
    assert e[int(1.0 / dt):].max() < 1e-4 * e.max()
    assert e[-1] < 1e-6 * e.max()


@pytest.mark.slow
def test_a_20_s_undamped_run_shows_no_growth():
    """20 s, over 8,000 steps (the issue: 10 s, 20,000 steps; here at the slab's allowed
    step 2.47e-3 s): no second after the first holds more energy than 1.05 x the largest
    of the seconds before it (the trapped remainder beats by ~1 % from second to second
    while it decays: measured 6.9e-7, 3.5e-8, 2.6e-8, 7.5e-9, 2.31e-9, 2.33e-9, ... of the
    peak), the last second holds less than 1e-3 of the second one, and the end is below
    1e-10 of the peak (measured 1.0e-12). A growing layer fails all three."""
    e, dt = _stability(20.0)
    per_second = [e[int(k / dt):int((k + 1) / dt)].max() for k in range(1, 20)]
    assert all(per_second[k] <= 1.05 * max(per_second[:k])
               for k in range(1, len(per_second))), per_second
    assert per_second[-1] < 1e-3 * per_second[0], per_second
    assert e[-1] < 1e-10 * e.max()


@pytest.mark.mpi
def test_the_same_velocities_on_1_and_2_ranks():
    """The layer's elements at the partition are computed on both ranks with their nodes'
    displacements gathered (PETSc scatter): rank 0's rerun alone on MPI.COMM_SELF gives the
    same receiver velocities to round-off."""
    a = _lamb(PML)
    if comm.size > 1 and comm.rank == 0:
        alone = _lamb(PML, MPI.COMM_SELF)
        scale = np.abs(alone["v"]).max()
        assert np.abs(a["v"] - alone["v"]).max() < 1e-10 * scale
    comm.Barrier()
