"""The surface loads' static start (``load.start = 'static'``): at t = 0 the soil at rest in
static equilibrium under the full loads at their start positions (``K u0 = f0``, one solve
with the engine's own static solver), velocities zero; the loads then run up to their
speed over ``load.ramp_time``.

* The state at t = 0 solves ``K u0 = f0`` to the solver's round-off, with ``v0 = 0`` and
  ``a0`` zero to the same round-off, on every engine (the explicit, imex and direct
  engines' static solvers).
* A load that starts in equilibrium and barely moves leaves the soil at rest: no
  switch-on pulse (the ramped start of the same load sets the soil ringing).
* The run-up: the loads' positions are ``x_start + c int ramp``, the passage lasts
  ``ramp_time / 2`` longer.
* Refusals: a box its faces do not hold statically (dashpots alone), one line, exit 2.
* On 2 ranks the probe histories equal the same run alone (``@pytest.mark.mpi``).

The comparison with the steady state of the half-space is
``bench/moving_load_steady.py``.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE

from railvib_hpc.cli import run
from railvib_hpc.config import load_case

comm = MPI.COMM_WORLD

#: The coarse thesis soil without a track or a building (1.2 m cubes at refinement 0.5),
#: the thesis's faces (rollers, fixed base: statically held), no damping; one load of
#: 100 kN standing in equilibrium at x = 10 m, running up to 50 m/s over 20 ms, to
#: x = 11 m; a probe on the ground 3 m beside the path.
STATIC = ["mesh.refinement=0.5", "track.count=0", "building.present=false",
          "load.force=1e5", "load.speed=50", "load.x_start=10", "load.x_end=11",
          "load.start=static", "load.ramp_time=0.02", "load.half_width=2.4",
          "modal.lumped_mass=true", "transient.engine=explicit", "damping.model=none",
          "output.dt=0.001", "transient.checkpoint_interval=0", "output.stress_times=[]",
          "transient.f_max=100", "output.probes=[10.8, -3.0, 4.8]"]


def _stage(folder, comm_=MPI.COMM_SELF, *extra: str) -> dict:
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    return run_transient_stage(load_case(BASELINE, [*STATIC, *extra]), folder, comm_,
                               Reporter(comm_.rank))


def _probe(folder, name="user_1", what="velocity") -> np.ndarray:
    with h5py.File(folder / "probes.h5", "r") as f:
        for g in f["probes"].values():
            if str(g.attrs["name"]) == name:
                return g[what][()]
    raise KeyError(name)


@pytest.mark.skipif(comm.size > 1, reason="one rank (the 2-rank test below)")
@pytest.mark.parametrize("engine", [["transient.engine=explicit"],
                                    ["transient.engine=imex"],
                                    ["transient.engine=direct", "modal.lumped_mass=false"]],
                         ids=["explicit", "imex", "direct"])
def test_the_state_at_t0_is_static_equilibrium(tmp_path, engine):
    """``K u0 = f0`` within 1e-8 of ``|f0|`` (MUMPS at this size: measured ~1e-15),
    ``v0 = 0``, ``|M a0|`` within 1e-8 of ``|f0|``; the settlement beside the load is
    downwards. Measured: 2-3 s per engine."""
    from railvib_hpc.io.stage_protocol import StageContext
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.engines import initial_state
    from railvib_hpc.transient.integrate import add_sparse
    from railvib_hpc.transient.stage import _setup

    case = load_case(BASELINE, [*STATIC, *engine])
    init = _setup(StageContext(case, tmp_path, MPI.COMM_SELF, Reporter(1)))
    assert init["static_start"] is True
    state = initial_state(init, MPI.COMM_SELF, Reporter(1))
    system = init["system"]
    f0 = np.zeros(system.n_local)
    add_sparse(f0, system.r0, *init["prescribed"](0))
    assert f0.sum() == pytest.approx(-1e5, rel=1e-12)
    x, y = system.K.createVecRight(), system.K.createVecLeft()
    x.getArray()[:] = state.u
    system.K.mult(x, y)
    residual = np.abs(y.getArray() - f0).max() / np.abs(f0).max()
    x.getArray()[:] = state.a
    init["M"].mult(x, y)
    inertia = np.abs(y.getArray()).max() / np.abs(f0).max()
    print(f"{engine[0]}: |K u0 - f0| {residual:.1e}, |M a0| {inertia:.1e} of |f0|")
    assert residual < 1e-8 and inertia < 1e-8
    assert not np.any(state.v)
    assert state.u.min() < 0.0                                    # it settles
    for obj in (x, y):
        obj.destroy()
    init["solver"].destroy()
    system.destroy()


@pytest.mark.skipif(comm.size > 1, reason="one rank")
def test_a_load_at_rest_in_equilibrium_leaves_the_soil_at_rest(tmp_path):
    """The load barely moves (1 mm/s for 30 ms, 30 um): from the static start the probe 3 m
    away keeps its settlement within 1e-4 of it (the load's 30 um at 3 m change it by
    ~1e-5: measured 6.8e-6) and moves at under 1e-3 of the speed the same load switched
    on over 10 ms (``load.start = 'ramp'``) gives it, which is over 1e-4 m/s (measured:
    1.3e-8 m/s, the load's own step to 1 mm/s, against 7.1e-3). Measured: 3 s."""
    still = ["load.speed=0.001", "load.x_end=10.00003", "load.ramp_time=0"]
    _stage(tmp_path / "static", MPI.COMM_SELF, *still)
    u = _probe(tmp_path / "static", what="displacement")[:, 2]
    v = _probe(tmp_path / "static")[:, 2]
    print(f"static start, the load at rest: settlement {u[0]:.4e} m, changed by "
          f"{np.abs(u - u[0]).max() / abs(u[0]):.1e} of it")
    assert u[0] < 0 and np.abs(u - u[0]).max() < 1e-4 * abs(u[0])
    _stage(tmp_path / "ramp", MPI.COMM_SELF, *still[:2], "load.start=ramp",
           "load.ramp_time=0.01")
    ringing = np.abs(_probe(tmp_path / "ramp")[:, 2]).max()
    print(f"static start: |v| {np.abs(v).max():.1e} m/s; ramped start: {ringing:.1e} m/s")
    assert ringing > 1e-4 and np.abs(v).max() < 1e-3 * ringing


def test_the_run_up_moves_the_loads_and_lengthens_the_passage():
    from railvib_hpc.transient.surface_case import surface_passage
    from railvib_hpc.transient.surface_load import SurfaceLoadPath, run_up_distance

    case = load_case(BASELINE, STATIC)
    without = load_case(BASELINE, [*STATIC, "load.ramp_time=0"])
    assert surface_passage(case)["t_end"] == pytest.approx(
        surface_passage(without)["t_end"] + 0.01, rel=1e-12)
    t = np.array([0.0, 0.01, 0.02, 0.03])
    assert run_up_distance(t, 0.02) == pytest.approx([0.0, 0.01 / 2 - 0.02 / (2 * np.pi),
                                                      0.01, 0.02])
    path = SurfaceLoadPath(forces=np.array([1.0]), offsets=np.zeros(1), x_start=10.0, y=0.0,
                           speed=50.0, ramp_time=0.0, run_up=0.02)
    x = path.positions(t)[:, 0]
    assert x == pytest.approx(10.0 + 50.0 * run_up_distance(t, 0.02))
    assert np.all(path.amplitudes(t) == 1.0)          # the static start: the full force


@pytest.mark.skipif(comm.size > 1, reason="one rank")
def test_a_box_held_by_dashpots_alone_is_refused(tmp_path, one_line_refusal):
    faces = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")]
    out = tmp_path / "o"
    code = run(["transient", str(BASELINE), "--out", str(out),
                *(a for s in (*STATIC, *faces) for a in ("--set", s))])
    one_line_refusal(code, out, "load.start = 'static': solves K u0 = f0 at t = 0 and needs "
                                "the soil box held statically")


SERIAL_REFERENCES = {"static_start": (3.0, _stage)}


@pytest.mark.mpi
def test_the_static_start_agrees_on_1_and_2_ranks(shared_tmp, serial_refs):
    """The static start (the explicit engine's MUMPS factor of K, distributed) and the run
    up on ``comm.size`` ranks: the probe's velocity and displacement equal the run alone
    on one rank to round-off."""
    out = shared_tmp / f"static_start_{comm.size}"
    _stage(out, comm)
    if comm.rank == 0:
        for what in ("displacement", "velocity"):
            mine, alone = _probe(out, what=what), _probe(serial_refs["static_start"],
                                                        what=what)
            peak = np.abs(alone).max()
            worst = np.abs(mine - alone).max() / peak
            print(f"static start on {comm.size} rank(s) against 1, {what}: {worst:.2e}")
            assert peak > 0 and worst < 1e-9, worst
    comm.Barrier()
