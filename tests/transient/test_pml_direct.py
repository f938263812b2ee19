"""Perfectly matched layers with the direct engine (issue 29, item 1: the layer works with
the direct ``railvib transient`` path): the Lamb slab of :mod:`test_pml` stepped by the
trapezoidal rule with one LU factor, against the slab 36 m larger; a two-layer slab; the
layer's stability at steps beyond the explicit engines' limit and on a long undamped run;
the affine split of the layer's force that the implicit step rests on; 1 and 2 ranks.

The layer is implicit here (:class:`~railvib_hpc.transient.petsc.TransientSystem`): the
part of its force that ``u_{n+1}`` makes (:meth:`~railvib_hpc.transient.pml.PmlLayer.
instant_matrix`, symmetric) is in K_eff, the history's part in the right-hand side.
(With the memory forces explicit at the step's start instead, the IMEX engine's implicit
elements in a layer grow 1000-fold in a second: :mod:`test_pml_imex`.)
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import run_box, slab_mesh
from test_pml import FIXED, LOWER_E, LOWER_TOP, MARGIN, PML, RECEIVERS, SOURCE, _differences
from test_pml_imex import _growth

comm = MPI.COMM_WORLD
#: The direct engine's step for the slab comparisons [s]: 83 steps per period of the
#: Ricker's 12 Hz peak (the explicit engine's allowed step on this slab with layers is
#: 2.60e-3 s, the elastic limit).
STEP = 1e-3
#: A step over twice the explicit engine's limit with layers on this slab [s]: the
#: implicit layer is not bound by it.
LONG_STEP = 6e-3


def _direct(faces=PML, thickness=8.0, mesh=None, t_end=0.2, dt=STEP, comm_=comm,
            layered=False, **kw):
    layers = [(LOWER_TOP, "subballast")] if layered else None
    mesh = slab_mesh(40, 20, 1.0, layers=layers) if mesh is None else mesh
    return run_box(mesh, faces, thickness, SOURCE, RECEIVERS, t_end, 12.0, comm_,
                   plane_strain=True, direct=dt, extra=(LOWER_E,) if layered else (), **kw)


def _reference(layered=False):
    layers = [(LOWER_TOP + MARGIN, "subballast")] if layered else None
    big = slab_mesh(40 + 2 * MARGIN, 20 + MARGIN, 1.0, origin=(-MARGIN, 0.0, -MARGIN),
                    layers=layers)
    return _direct(FIXED, 0.0, mesh=big, layered=layered)


@pytest.mark.parametrize("layered", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["uniform", "two-layer"])
def test_the_direct_engine_with_layers_matches_a_slab_36_m_larger(layered):
    """Layers of 8 elements on x_min, x_max and the base, the direct engine at 1e-3 s:
    peak |v| within 0.5 % and the difference's energy below 2e-4 of the signal's at every
    receiver against the slab 36 m larger with fixed faces (the same engine and step);
    the fixed faces of the small slab miss by over 2 % (measured, uniform: peaks
    0.009-0.13 %, energies 1.3e-5 to 4.4e-5, fixed faces 4.4 % and 0.14; two-layer:
    0.009-0.21 %, 1.7e-5 to 4.9e-5, fixed faces 14.7 % and 0.25)."""
    a, ref = _direct(layered=layered), _reference(layered)
    peak, energy = _differences(a, ref)
    assert peak.max() < 5e-3 and energy.max() < 2e-4, (peak, energy)
    fixed = _direct(FIXED, 0.0, layered=layered)
    assert _differences(fixed, ref)[0].max() > 2e-2


def test_an_undamped_direct_run_with_layers_beyond_the_explicit_limit_decays():
    """2 s undamped at 6e-3 s, over twice the explicit engine's allowed step with these
    layers (334 steps): the energy left after the first second is below 1e-6 of the peak
    (measured 4.1e-9; 3.3e-9 at 5e-3 s) and falls from the first second to the
    second."""
    explicit = run_box(slab_mesh(40, 20, 1.0), PML, 8.0, SOURCE, RECEIVERS, 1e-3, 12.0, comm,
                       plane_strain=True)
    assert 2.0 * explicit["dt"] < LONG_STEP, explicit["dt"]
    out = _direct(t_end=2.0, dt=LONG_STEP, record_energy=True)
    per_second = _growth(out["energy"], out["dt"])
    assert per_second[1] < 1e-6 and per_second[-1] <= per_second[1], per_second


#: The ten-second run's step [s]: 20,000 steps.
LONG_RUN_STEP = 5e-4


@pytest.mark.slow
def test_a_10_s_undamped_direct_run_of_20000_steps_shows_no_growth():
    """10 s at 5e-4 s (20,000 steps) on a slab 16 m x 8 m that is mostly layer (5
    elements on x_min, x_max and the base around 6 m x 3 m of soil; 110 layer elements,
    the cost of a step is the solver's): every second's largest energy after the first
    below 1e-6 of the peak, no second's above the one before by more than a factor 2
    (round-off level), the last below 1e-9 (measured: 1.3e-9 after the first second, the
    run ~50 s)."""
    out = run_box(slab_mesh(16, 8, 1.0), PML, 5.0, ((8.0, 0.0, 8.0), 2, 1e5),
                  np.array([[8.0, 0.0, 8.0], [10.0, 0.0, 6.0]]), 10.0, 12.0, comm,
                  plane_strain=True, direct=LONG_RUN_STEP, record_energy=True)
    assert len(out["energy"]) >= 20000
    per_second = _growth(out["energy"], out["dt"])
    assert max(per_second[1:]) < 1e-6, per_second
    assert all(b <= 2 * a for a, b in zip(per_second[1:], per_second[2:])), per_second
    assert per_second[-1] < 1e-9, per_second


def test_the_layer_force_is_its_instant_matrix_times_u_plus_the_history_part():
    """What the implicit step rests on: after some history (a static start ``u_0``, a few
    steps), ``force(u) = A u + peek(0)`` for any next ``u`` within round-off, ``peek``
    leaves the layer as it was, and ``A`` is symmetric to round-off (the identity of
    ``PmlElements.instant_matrices``: K_eff keeps its Cholesky factor)."""
    from pml_cases import serial_layer

    layer, n = serial_layer(slab_mesh(20, 10, 1.0), PML, "boundary.layer_thickness=5",
                            "boundary.pml_alpha=20")
    dt = 1e-3
    rng = np.random.default_rng(3)
    layer.start(rng.normal(size=n) * 1e-4)
    for _ in range(3):
        layer.force(rng.normal(size=n) * 1e-4, dt)
    A = layer.instant_matrix(dt)
    history = layer.peek(np.zeros(n), dt)
    u = rng.normal(size=n) * 1e-4
    again = layer.peek(u, dt)
    f = layer.force(u, dt)
    layer.destroy()
    scale = np.abs(f).max()
    assert np.abs(f - again).max() == 0.0                     # peek changed nothing
    assert np.abs(f - (A @ u + history)).max() < 1e-10 * scale
    assert abs(A - A.T).max() < 1e-13 * abs(A).max()


@pytest.mark.mpi
def test_the_same_direct_velocities_on_1_and_2_ranks():
    """The direct engine's Lamb slab with layers on COMM_WORLD and, on rank 0, alone on
    COMM_SELF: the same velocities within 1e-9 of their peak (MUMPS orders the factor
    differently on 2 ranks)."""
    a = _direct()
    if comm.size > 1 and comm.rank == 0:
        b = _direct(comm_=MPI.COMM_SELF)
        scale = np.abs(b["v"]).max()
        assert np.abs(a["v"] - b["v"]).max() < 1e-9 * scale
    comm.Barrier()
