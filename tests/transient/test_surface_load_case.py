"""The moving load on the bare soil through the case file (issue 28, item 5): ``track.count
= 0`` with ``[load]`` through ``railvib transient``.

* The stage's run equals, to round-off, the hand-built model of
  :mod:`moving_load_cases` (the library's :class:`MovingSurfaceLoad` on the explicit engine,
  the same calls) on the stage's own mesh and step: every node's velocity at every output
  step of ``fields.h5``. The load acts: after the switch-on its nodal forces sum to the full
  downward force, and the ground beside the path moves.
* Bad input: one line naming the key, the value and what is allowed, exit code 2, nothing
  written.
* On 2 ranks the probe histories equal the same run alone on one rank
  (``@pytest.mark.mpi``).
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE

from railvib_hpc.cli import run
from railvib_hpc.config import load_case

comm = MPI.COMM_WORLD

#: The coarse thesis site without its track (the building stays): the explicit engine, no
#: damping, the thesis's faces (rollers, fixed base; no dashpots, so that C = 0 as in the
#: hand-built model), one point load of 100 kN at 50 m/s on y = 0 from x = 3 m (the soil's
#: start) to x = 4.5 m, switched on over 10 ms; 30 ms in 1 ms output steps, a probe on the
#: ground 2 m beside the path.
LOAD = ["mesh.refinement=0.25", "track.count=0", "load.force=1e5", "load.speed=50",
        "load.x_start=3", "load.x_end=4.5", "load.ramp_time=0.01", "modal.lumped_mass=true",
        "transient.engine=explicit", "damping.model=none", "output.dt=0.001",
        "transient.checkpoint_interval=0", "output.stress_times=[]", "transient.f_max=100",
        "output.probes=[4.2, -2.0, 4.8]"]


def _sets(*items: str) -> list[str]:
    return [a for s in items for a in ("--set", s)]


def _fields(folder) -> tuple[np.ndarray, np.ndarray]:
    with h5py.File(folder / "fields.h5", "r") as f:
        return f["steps"][()], f["fields/velocity"][()]


def _probes(folder) -> dict[str, np.ndarray]:
    with h5py.File(folder / "probes.h5", "r") as f:
        return {str(g.attrs["name"]): g["velocity"][()] for g in f["probes"].values()}


def hand_built(folder, case, steps: np.ndarray) -> tuple[np.ndarray, object]:
    """The model of :func:`moving_load_cases.run_moving_load` (assemble, ExplicitSystem,
    MovingSurfaceLoad, ExplicitSolver, initial_acceleration) on the stage's mesh
    (``mesh.h5`` of ``folder``) with its step: the nodes' velocities (len(steps), nodes, 3)
    at ``steps``, and the load."""
    from railvib_hpc.mesh.mesh_io import read_mesh_h5
    from railvib_hpc.model.boundary import problem_dofmap
    from railvib_hpc.model.petsc import assemble
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        initial_acceleration,
    )
    from railvib_hpc.transient.integrate import State
    from railvib_hpc.transient.surface_load import MovingSurfaceLoad, SurfaceLoadPath

    init_petsc([])
    with h5py.File(folder / "transient.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    dt, nt = stats["dt"], stats["n_steps"]
    mesh, _ = read_mesh_h5(folder / "mesh.h5")
    problem = Problem.from_case(case)
    self_comm = MPI.COMM_SELF
    dofmap = problem_dofmap(mesh, problem, 1)
    K, M, _ = assemble(mesh, problem, dofmap, self_comm, mass="diagonal")
    system = ExplicitSystem(K, M, None, dt, self_comm)
    ld = case["load"]
    path = SurfaceLoadPath(forces=np.array([ld["force"]]), offsets=np.zeros(1),
                           x_start=ld["x_start"], y=ld["y"], speed=ld["speed"],
                           ramp_time=ld["ramp_time"])
    load = MovingSurfaceLoad(mesh, dofmap.index, path, dt, nt, ground=case["geometry.z1"])
    solver = ExplicitSolver(system, load)
    n = system.r1 - system.r0
    st = State(0, np.zeros(n), np.zeros(n), np.zeros(n))
    initial_acceleration(system, st, [load(0)])
    solver.start(st)
    idx = dofmap.index[:, :3]
    out = np.zeros((steps.size, mesh.n_nodes, 3))

    def put(k: int) -> None:
        ok = idx >= 0
        out[k][ok] = st.v[idx[ok]]

    want = {int(s): k for k, s in enumerate(steps)}
    if 0 in want:
        put(want[0])
    for _ in range(nt):
        solver.step(st)
        if st.step in want:
            put(want[st.step])
    solver.destroy()
    system.destroy()
    K.destroy()
    M.destroy()
    return out, load


def _stage(folder, comm_=MPI.COMM_SELF, *extra: str, **hooks) -> dict:
    """``run_transient_stage`` of :data:`LOAD` and ``extra`` overrides (no assessment)."""
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    return run_transient_stage(load_case(BASELINE, [*LOAD, *extra]), folder, comm_,
                               Reporter(comm_.rank), **hooks)


@pytest.mark.slow
@pytest.mark.skipif(comm.size > 1, reason="one rank")
def test_an_interrupted_surface_load_run_resumes_to_the_same_answer(tmp_path):
    """Checkpointed at step 300, stopped, resumed: the probes are those of the run straight
    through, bit for bit; a changed load key is a new run, not a reuse (the inputs digest
    holds [load]). Measured: 15 s (four runs)."""
    from railvib_hpc.transient.stage import Interrupted

    ref = tmp_path / "ref"
    _stage(ref)
    out = tmp_path / "resume"
    with pytest.raises(Interrupted):
        _stage(out, checkpoint_steps=300, stop_after=300)
    assert (out / "transient_checkpoint.h5").exists()
    stats = _stage(out)
    assert 0 < stats["steps_run"] < stats["n_steps"]
    a, b = _probes(ref), _probes(out)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert _stage(ref)["reused"] is True
    assert _stage(ref, MPI.COMM_SELF, "load.force=2e5")["reused"] is False
    assert np.abs(_probes(ref)["user_1"]).max() == pytest.approx(
        2 * np.abs(a["user_1"]).max(), rel=1e-9)                 # linear in the force


@pytest.mark.skipif(comm.size > 1, reason="one rank (the 2-rank test below)")
def test_the_case_route_equals_the_hand_built_model(tmp_path):
    """Measured: 6.0 s in all on the soil's own grid (2.4 m cubes at refinement 0.25; 6.7 s
    on the notional track's grid before); the fields are the same bits (difference 0 of
    the peak 0.0817 m/s; 0.0866 before). The hand-built route is the one
    tests/transient/test_moving_load_halfspace.py checks against the half-space's steady
    state (within 5 % at 4-12 m from the path)."""
    out = tmp_path / "load"
    _stage(out)
    with h5py.File(out / "transient.h5", "r") as f:
        assert f["wheels/contact_force"].shape[1] == 0
        assert f["vehicle"].attrs["type"] == "surface_load"
    with h5py.File(out / "probes.h5", "r") as f:
        assert "rail" not in f
    steps, v_stage = _fields(out)
    case = load_case(BASELINE, LOAD)
    v_hand, load = hand_built(out, case, steps)
    peak = np.abs(v_hand).max()
    err = np.abs(v_stage - v_hand).max() / peak
    print(f"surface load through the case: max |v| {peak:.3e} m/s, stage against the "
          f"hand-built model {err:.2e} of it")
    assert peak > 1e-5                                    # the load acts
    assert err < 1e-9, err
    # at the end, switched on, the whole load stands on the ground, downwards
    assert load.total_force(load.x.shape[0] - 1) == pytest.approx(-1e5, rel=1e-12)
    # the ground beside the path moves, and the probe there sees it
    v_probe = _probes(out)["user_1"]
    assert np.abs(v_probe[:, 2]).max() > 0.05 * peak


@pytest.mark.skipif(comm.size > 1, reason="one rank")
def test_every_engine_runs_the_surface_load(tmp_path):
    """The direct and imex engines (at the band's step, 5e-4 s, 60 steps; the explicit
    engine at its stable step) give the probe beside the path the same peak vertical
    velocity within 1 % (measured on the soil's own grid: 0.010283, 0.010231, 0.010296
    m/s, 0.6 %; on the notional track's grid before: 0.01561, 0.01557, 0.01559). One
    folder: the mesh is built once. Measured: 6.8 s."""
    out = tmp_path / "engines"
    peaks = {}
    for engine in ("explicit", "direct", "imex"):
        stats = _stage(out, MPI.COMM_SELF, f"transient.engine={engine}")
        assert stats["engine"] == engine and stats["reused"] is False
        peaks[engine] = np.abs(_probes(out)["user_1"][:, 2]).max()
    print("surface load, peak vertical velocity at user_1 [m/s]: " + ", ".join(
        f"{k} {v:.5g}" for k, v in peaks.items()))
    assert peaks["explicit"] > 1e-3
    for engine in ("direct", "imex"):
        assert peaks[engine] == pytest.approx(peaks["explicit"], rel=0.01), peaks


def test_the_bare_soil_layout_has_no_track():
    """``track.count = 0``: no embankment block, rail, sleeper or pad, and none of their
    grid lines: the soil outside the building is a grid of its own size (the thesis
    layout's 0.6 m cubes, :func:`~railvib_hpc.mesh.layout.bare_soil_size`) with the load's
    path on a line of nodes; the building's blocks are the track case's; the named probes
    stay; the probe lines may start at the path."""
    from railvib_hpc.mesh.layout import bare_soil_size, build_layout
    from railvib_hpc.site import line_ranges

    with_track = build_layout(load_case(BASELINE, []))
    case = load_case(BASELINE, ["track.count=0", "load.force=1e5", "load.y=1.5"])
    bare = build_layout(case)
    track_parts = {"ballast", "subballast", "fill"}
    assert {b.part for b in with_track.blocks} & track_parts
    assert not {b.part for b in bare.blocks} & track_parts
    assert bare.rail_y == () and bare.sleeper_y.shape == (0, 4)
    assert not set(np.round(with_track.yb, 6)) - {-4.25, 4.25} <= set(np.round(bare.yb, 6))
    from railvib_hpc.mesh.building import Building

    lines = Building.of_case(case).x_lines()        # x: the soil's ends and the building's
    assert np.allclose(bare.xb, np.unique(np.round([3.0, 24.6, *lines], 9)))
    assert 1.5 in bare.yb and len(bare.xb) < len(with_track.xb)
    building = {"footing", "column", "beam", "slab", "wall"}

    def volumes(lay):                  # of each building part (the track splits blocks)
        out: dict[str, float] = {}
        for b in lay.blocks:
            if b.part in building:
                v = np.diff(lay.xb)[b.i] * np.diff(lay.yb)[b.j] * (b.z1 - b.z0)
                out[b.part] = round(out.get(b.part, 0.0) + v, 6)
        return out

    assert volumes(bare) == volumes(with_track)
    h = bare_soil_size(case)
    assert h == 0.6
    sizes = np.concatenate([np.diff(bare.yb) / bare.ny, np.diff(bare.xb) / bare.nx])
    x2, x3, ys3, ys2 = 12.6, 19.8, -17.1, -9.9
    outside = np.concatenate([
        [not (ys3 - 1e-9 <= a and b <= ys2 + 1e-9) for a, b in zip(bare.yb[:-1], bare.yb[1:])],
        [not (x2 - 1e-9 <= a and b <= x3 + 1e-9) for a, b in zip(bare.xb[:-1], bare.xb[1:])]])
    assert np.all(np.abs(sizes[outside] - h) <= 0.5 * h), sizes[outside]
    assert bare.probes == with_track.probes
    assert line_ranges(case, 13.8, "building")[0][0] == 0.0
    assert line_ranges(load_case(BASELINE, []), 13.8, "building")[0][0] == 4.25


@pytest.mark.slow
@pytest.mark.skipif(comm.size > 1, reason="one rank")
def test_the_surface_load_case_runs_and_is_assessed(tmp_path, capsys):
    """``railvib transient`` of the case, its assessment included: the log says there is
    no track, the assessment reads the results unchanged and leaves out what belongs to a
    train (the contact-force figure, the thesis comparison). Measured: 31 s (24 s of it
    the assessment's figures)."""
    out = tmp_path / "load"
    assert run(["transient", str(BASELINE), "--out", str(out), *_sets(*LOAD)]) == 0
    text = capsys.readouterr().out
    assert "track: none (track.count = 0): the bare soil under 1 moving load(s)" in text
    report = json.loads((out / "assessment.json").read_text())
    assert report["solver"] == "transient" and report["complete"] is True
    assert {"footing", "slab1", "ground_toe", "user_1"} <= set(report["results"])
    assert not (out / "figures" / "contact.png").exists()
    assert "Comparison with the thesis" not in (out / "report.md").read_text()
    # assess on its own reads them again
    assert run(["assess", str(BASELINE), "--out", str(out), *_sets(*LOAD)]) == 0


@pytest.mark.skipif(comm.size > 1, reason="one rank")
@pytest.mark.parametrize(("overrides", "needle"), [
    (["track.count=0"], "track.count = 0: 0 (no track) needs the moving surface load"),
    (["load.force=1e5"], "load.force = 100000.0: applies to the moving load on the bare "
                         "soil (track.count = 0) only; here track.count = 1"),
    (["track.count=3"], "track.count = 3: must be 1 or 2, or 0 (no track"),
    (["track.count=-1"], "track.count = -1: must be >= 0"),
    (["track.count=0", "load.force=1e5", "load.speed=0"], "load.speed = 0"),
    (["track.count=0", "load.force=-5"], "load.force = -5"),
    (["track.count=0", "load.force=1e5", "load.offsets=[0, 2]"],
     "load.offsets = [0.0, 2.0]: must be a non-empty list of offsets <= 0"),
    (["track.count=0", "load.force=1e5", "load.y=500"], "load.y = 500.0: the path must run "
                                                        "on the soil"),
    (["track.count=0", "load.force=1e5", "load.x_start=10", "load.x_end=5"],
     "load.x_end = 5.0: must lie beyond the last load's start 10 m"),
    (["track.count=0", "load.force=1e5", "load.frequency=100"],
     "load.frequency = 100.0: must be <= transient.f_max = 80 Hz"),
    (["track.count=0", "load.force=1e5", "load.frequency=-1"], "load.frequency = -1"),
    (["load.frequency=5"], "load.frequency = 5.0: applies to the moving load on the bare "
                           "soil (track.count = 0) only"),
    (["track.count=0", "load.force=1e5", "load.speed=250"],
     "load.speed = 250.0: is at or above the ground's Rayleigh speed"),
    (["track.count=0", "load.force=1e5", "vehicle.speed=40"],
     "vehicle.speed = 40.0: applies to a case with a track (track.count > 0) only"),
    (["track.count=0", "load.force=1e5", "track.embankment_height=3"],
     "track.embankment_height = 3.0: applies to a case with a track"),
    (["track.count=0", "load.force=1e5", "track.ends=supported"],
     "track.ends = 'supported': applies to a case with a track"),
])
def test_bad_surface_load_input_is_one_line(tmp_path, one_line_refusal, overrides, needle):
    out = tmp_path / "o"
    code = run(["transient", str(BASELINE), "--out", str(out), *_sets(*overrides)])
    one_line_refusal(code, out, needle)


@pytest.mark.skipif(comm.size > 1, reason="one rank")
@pytest.mark.parametrize("command", ["run", "modal", "mbs"])
def test_the_modal_path_refuses_the_bare_soil(tmp_path, capsys, command):
    out = tmp_path / "o"
    code = run([command, str(BASELINE), "--out", str(out),
                *_sets("track.count=0", "load.force=1e5")])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert f"track.count = 0: railvib {command} needs a track" in lines[0], lines[0]
    assert not out.exists() or not any(out.iterdir())


def test_the_api_refuses_the_modal_stages_of_the_bare_soil(tmp_path):
    from railvib_hpc.api import Pipeline
    from railvib_hpc.errors import CaseError

    pipe = Pipeline(load_case(BASELINE, ["track.count=0", "load.force=1e5"]), tmp_path / "o",
                    MPI.COMM_SELF, quiet=True)
    with pytest.raises(CaseError, match=r"track\.count = 0: railvib modal needs a track"):
        pipe.stage("modal")
    with pytest.raises(CaseError, match="railvib mbs needs a track"):
        pipe.run_stages(["mesh", "mbs"])
    assert not (tmp_path / "o" / "mesh.h5").exists()


@pytest.mark.skipif(comm.size > 1, reason="one rank")
def test_the_load_frequency_reaches_the_load_and_the_check_line(monkeypatch, capsys):
    """``load.frequency`` goes to the load's path (:func:`surface_load`) and into
    ``railvib check``'s description of the load."""
    from railvib_hpc.transient import surface_case

    seen = {}
    monkeypatch.setattr(surface_case, "MovingSurfaceLoad",
                        lambda mesh, index, path, dt, nt, ground: seen.setdefault("p", path))
    case = load_case(BASELINE, [*LOAD, "load.frequency=12.5"])
    surface_case.surface_load(case, None, None, 1e-3, 10)
    assert seen["p"].frequency == 12.5
    assert run(["check", str(BASELINE), *_sets(*LOAD, "load.frequency=12.5")]) == 0
    assert "harmonic at 12.5 Hz" in capsys.readouterr().out


def test_the_keys_of_load_leave_the_digests_of_other_cases_alone():
    """``[load]`` at its defaults enters no inputs digest (the golden record stands); a
    given load changes the transient products' digest, not the mesh's."""
    from railvib_hpc.io.products import inputs_hash

    base = load_case(BASELINE, [])
    same = load_case(BASELINE, ["load.speed=30"])         # the default, given
    assert inputs_hash(base, "transient.h5") == inputs_hash(same, "transient.h5")
    a = load_case(BASELINE, ["track.count=0", "load.force=1e5"])
    b = load_case(BASELINE, ["track.count=0", "load.force=2e5"])
    assert inputs_hash(a, "transient.h5") != inputs_hash(b, "transient.h5")
    assert inputs_hash(a, "mesh.h5") == inputs_hash(b, "mesh.h5")


#: The serial run the 2-rank test compares with (tests/conftest.py: ``serial_refs``,
#: computed side by side with the other modules' references): seconds on one rank, builder.
SERIAL_REFERENCES = {"surface_load": (5.0, _stage)}


@pytest.mark.slow
@pytest.mark.mpi
def test_the_surface_load_case_agrees_on_1_and_2_ranks(shared_tmp, serial_refs):
    """The same case on ``comm.size`` ranks: its probe histories equal the same run alone
    on MPI.COMM_SELF (``serial_refs``) to round-off (measured on 2 ranks: 14 s, the two
    runs; they differ by 3.6e-18 of the peak)."""
    out = shared_tmp / f"surface_load_{comm.size}"
    _stage(out, comm)
    if comm.rank == 0:
        velocities = _probes(out)
        alone = _probes(serial_refs["surface_load"])
        assert set(velocities) == set(alone)
        peak = max(np.abs(v).max() for v in alone.values())
        assert peak > 0
        worst = max(np.abs(v - alone[name]).max() for name, v in velocities.items()) / peak
        print(f"surface load on {comm.size} rank(s) against 1: {worst:.2e} of the peak")
        assert worst < 1e-9, worst
    comm.Barrier()
