"""Issue 26, the red team's ``railvib transient`` cases (items 1, 2, 5, 7, 9 and 16).

* 1: a Caughey layer damps the ground only, never the building or the track bed;
* 2: a Caughey layer that holds no element is refused in one line (exit 2);
* 5: faces that leave the soil box free to move as a rigid body give a warning;
* 7: an interrupted and resumed run gives the uninterrupted numbers bit for bit (the rail
  columns of the contact solve are computed in fixed blocks);
* 9: a run with too many steps (or histories beyond the memory) is refused in one line
  before anything is built;
* 16: ``--help`` and the docs say where ``transient`` writes: ``--out`` itself.

Each repro case is recorded in the fault suite's tally.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from faults import BASELINE, COARSE, ROOT, copy_results
from mpi4py import MPI

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.errors import UserError
from railvib_hpc.problem import Problem

ABSORBING = ROOT / "jobs" / "absorbing_boundaries.toml"
A = str(ABSORBING)
#: The COARSE overrides as ``key=value`` strings (for ``load_case``).
COARSE_SETS = [s for s in COARSE if s != "--set"]
MESH_FILES = ("mesh.h5", "mesh.msh", "mesh.xdmf", "mesh_report.json")
FACES = ("x_min", "x_max", "y_min", "y_max", "base")
#: The tiny full-order case of tests/transient (coarse thesis model, a wheelset).
TINY = ["mesh.refinement=0.25", "vehicle.x_start=2.7", "vehicle.x_end=4.2",
        "output.dt=0.002", "output.stress_times=[0.04]", "transient.checkpoint_interval=0",
        "transient.f_max=100"]


def _sets(*overrides: str) -> list[str]:
    return [arg for s in overrides for arg in ("--set", s)]


def _one_error(code: int, err: str) -> str | None:
    """The error line when the command failed cleanly (exit 2, one line), else None."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    if code == 2 and len(lines) == 1 and "Traceback" not in err:
        return lines[0]
    return None


@pytest.fixture(scope="module")
def meshed(tmp_path_factory) -> Path:
    """``railvib mesh`` of the absorbing job on the coarse model (once per module)."""
    path = tmp_path_factory.mktemp("meshed")
    assert run(["mesh", A, *COARSE, "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def mesh(meshed):
    from railvib_hpc.mesh.mesh_io import read_mesh_h5

    return read_mesh_h5(meshed / "mesh.h5")[0]


def _transient(capsys, meshed: Path, out: Path, *overrides: str) -> tuple[int, str, str]:
    """``railvib transient`` of the coarse absorbing job in process, on a copy of the
    prepared mesh (reused: no mesh build)."""
    copy_results(meshed, out, MESH_FILES)
    code = run(["transient", A, *COARSE, *_sets(*overrides), "--out", str(out)])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


# --------------------------------------------------------------------------- item 1
def test_caughey_layer_damps_the_ground_only(mesh, tally):
    """100 m reaches every element: only the subgrade gets a weight, not the building
    (0.87-0.95 before) nor the ballast and subballast (such a layer is refused by
    :func:`check_layers`, since it reaches the building; the weights alone are checked
    here); 3 m does not reach the footings, and its line names the parts left undamped."""
    from railvib_hpc.model.boundary import LAYER_PARTS, layer_line, layer_weights
    from railvib_hpc.schema import PART_ID

    case = load_case(ABSORBING, [*COARSE_SETS, "boundary.base=caughey",
                                 "boundary.layer_thickness=100"])
    w = layer_weights(mesh, Problem.from_case(case))
    ground = np.isin(mesh.hex_part, [PART_ID[p] for p in LAYER_PARTS])
    others = {p: float(w[mesh.hex_part == PART_ID[p]].max(initial=0.0))
              for p in ("footing", "column", "slab", "wall", "ballast", "subballast")}
    ok = all(v == 0.0 for v in others.values()) and bool(np.all(w[ground] > 0))
    tally.add("transient: caughey base layer 100 m over the building and the track bed",
              "correct" if ok else "silent wrong", str(others))
    assert ok, others
    side = load_case(ABSORBING, [*COARSE_SETS, "boundary.y_max=caughey",
                                 "boundary.layer_thickness=8"])
    line = layer_line(mesh, Problem.from_case(side))
    assert line.startswith("Caughey layers (8 m): y_max ")
    assert "ballast" in line and "are not damped" in line
    thin = load_case(ABSORBING, [*COARSE_SETS, "boundary.base=caughey",
                                 "boundary.layer_thickness=3"])
    weights = layer_weights(mesh, Problem.from_case(thin))
    assert weights[mesh.hex_part == PART_ID["footing"]].max() == 0.0


def test_caughey_layer_reaching_the_building_is_refused(mesh, meshed, tmp_path, capsys,
                                                        tally):
    """A base layer 20 x thicker than the 4.8 m of soil damped every ground element
    (about 27 % at the ground) with an info line; now it is refused in one line (exit 2)
    naming the key, the value and the range allowed, as the perfectly matched layers
    refuse a layer that reaches the building; a 1.5 m layer is accepted."""
    from railvib_hpc.model.boundary import check_layers

    code, out, err = _transient(capsys, meshed, tmp_path / "out", "boundary.base=caughey",
                                "boundary.layer_thickness=96")
    line = _one_error(code, err)
    tally.add("transient: caughey base layer 20 x the soil's depth, through the building",
              "clear error" if line else "silent wrong" if code == 0 else "unclear",
              line or err[-300:])
    assert line is not None, (code, err)
    assert line.startswith("railvib transient: error: boundary.layer_thickness = 96: the "
                           "Caughey layer of boundary.base reaches the building"), line
    assert "allowed: 0 < boundary.layer_thickness < " in line
    assert "[transient: assembly]" not in out
    thin = load_case(ABSORBING, [*COARSE_SETS, "boundary.base=caughey",
                                 "boundary.layer_thickness=1.5"])
    assert check_layers(mesh, Problem.from_case(thin))["base"]["elements"] > 0


# --------------------------------------------------------------------------- item 2
def test_caughey_layer_without_an_element_is_refused(mesh, meshed, tmp_path, capsys, tally):
    """3 m at y_min: the first centroids lie 6 m from the face; refused naming both."""
    from railvib_hpc.model.boundary import BoundaryError, check_layers

    code, out, err = _transient(capsys, meshed, tmp_path / "out", "boundary.y_min=caughey",
                                "boundary.layer_thickness=3")
    line = _one_error(code, err)
    tally.add("transient: caughey y_min layer of 3 m that holds no element",
              "clear error" if line else "silent wrong" if code == 0 else "unclear",
              line or err[-300:])
    assert line is not None, (code, err)
    assert line.startswith("railvib transient: error: boundary.layer_thickness = 3: the "
                           "Caughey layer of boundary.y_min holds no ground element"), line
    assert "allowed: more than 6 m" in line
    assert "[transient: assembly]" not in out          # refused before anything is assembled
    # just past the first centroids it is accepted
    ok = load_case(ABSORBING, [*COARSE_SETS, "boundary.y_min=caughey",
                               "boundary.layer_thickness=6.5"])
    assert check_layers(mesh, Problem.from_case(ok))["y_min"]["elements"] > 0
    with pytest.raises(BoundaryError, match="more than 6 m"):
        check_layers(mesh, Problem.from_case(load_case(ABSORBING, [
            *COARSE_SETS, "boundary.y_min=caughey", "boundary.layer_thickness=5.5"])))


# --------------------------------------------------------------------------- item 5
class _StopAfterSetupChecks(UserError):
    """Raised in place of the assembly: the setup's checks and warnings have run."""


def test_unsupported_box_is_warned(mesh, meshed, tmp_path, capsys, tally, monkeypatch):
    """All faces free: a warning naming the free motions and the faces (the run goes on;
    here it is stopped where the assembly would start)."""
    import railvib_hpc.model.petsc as modal_petsc
    from railvib_hpc.model.boundary import unsupported_motions

    def stop(*args, **kwargs):
        raise _StopAfterSetupChecks("stopped before the assembly (test)")

    monkeypatch.setattr(modal_petsc, "assemble", stop)
    code, out, err = _transient(capsys, meshed, tmp_path / "out",   # (no absorbing face:
                                "boundary.virtual_thickness=0",     # its springs are off)
                                *(f"boundary.{f}=free" for f in FACES))
    warned = [ln for ln in out.splitlines() if ln.startswith("warning: no truncation face")]
    tally.add("transient: every face free (the box floats)",
              "warning" if warned else "silent wrong", warned[0] if warned else out[-300:])
    assert warned, out[-2000:]
    assert code == 2 and "stopped before the assembly" in err, err
    assert "rigid-body motions (translations and rotations)" in warned[0]
    assert "base free" in warned[0]

    def free(**faces):
        return unsupported_motions(mesh, Problem.from_case(load_case(ABSORBING, [
            *COARSE_SETS, "boundary.virtual_thickness=0",
            *(f"boundary.{f}={faces.get(f, 'roller')}" for f in FACES)])))

    assert free(base="fixed") == []                       # the thesis faces
    assert free(base="free") == ["translation along z"]   # rollers hold nothing vertically
    assert free(x_min="absorbing", x_max="absorbing", y_min="absorbing", y_max="absorbing",
                base="absorbing") == []
    assert free(x_min="free", x_max="free", y_min="free", y_max="free", base="roller") == [
        "translation along x", "translation along y", "rotation about z"]


def test_supported_box_gives_no_warning(mesh):
    from railvib_hpc.model.boundary import support_warning

    assert support_warning(mesh, Problem.from_case(load_case(ABSORBING, COARSE_SETS))) is None


# --------------------------------------------------------------------------- item 7
@pytest.fixture(scope="module")
def tiny_setup(tmp_path_factory):
    """The tiny full-order case of tests/transient set up (mesh, factor), serial."""
    from railvib_hpc.io.stage_protocol import StageContext
    from railvib_hpc.log import Reporter
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.stage import _setup

    init_petsc([])
    init = _setup(StageContext(load_case(BASELINE, TINY), tmp_path_factory.mktemp("tiny"),
                               MPI.COMM_SELF, Reporter(0)))
    yield init
    init["solver"].destroy()
    init["system"].destroy()


@pytest.mark.slow
def test_rail_columns_are_the_same_bits_whenever_computed(tiny_setup):
    """A column is the same bits whether the wheels arrived step by step or start at that
    element (a resumed run's empty cache). Before: 16 of 48 columns differed (round-off of
    MUMPS multi-RHS blocks of another composition)."""
    from railvib_hpc.transient.integrate import RailColumns

    system, rails = tiny_setup["system"], tiny_setup["rails"]
    wheel_rail = np.array([0, 1])

    def dofs_at(e: int) -> np.ndarray:
        return np.stack([np.concatenate([rails.dofs[r, e], rails.dofs[r, e + 1]])
                         for r in wheel_rail])

    rolled = RailColumns(system, rails, 12)
    for m in range(0, 14):
        elem = np.array([m, m])
        rolled.require(dofs_at(m), wheel_rail, elem)
        if m in (1, 5, 13):
            fresh = RailColumns(system, rails, 12)
            fresh.require(dofs_at(m), wheel_rail, elem)
            common = set(rolled.cache) & set(fresh.cache)
            assert len(common) >= 16
            differ = [d for d in common if not np.array_equal(rolled.cache[d],
                                                              fresh.cache[d])]
            assert not differ, (m, len(differ), len(common))


#: A short passage of the coarse absorbing job (214 steps) whose resume at step 60 differed
#: from the uninterrupted run by 2.2e-9 relative in the building accelerations before.
RESUME_CASE = [*COARSE_SETS, "transient.checkpoint_interval=0", "output.stress_times=[]",
               "vehicle.x_start=8", "vehicle.x_end=12"]


#: Resumed against uninterrupted on several ranks, relative to the largest value: MUMPS's
#: parallel factorization differs from run to run by its round-off (two uninterrupted
#: 2-rank runs: 3.8e-9; resumed: 4.3e-9, 5.6e-9 measured, 8.7e-9 in the issue).
PARALLEL_RESUME_BOUND = 2e-8


def _coarse_resume(ref: Path, res: Path, comm) -> tuple[dict, dict]:
    """The short coarse passage uninterrupted into ``ref`` and interrupted at step 60 and
    resumed into ``res`` (collective); the histories of both (rank 0; None elsewhere)."""
    from railvib_hpc.log import Reporter
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.stage import Interrupted, run_transient_stage

    init_petsc([])

    def go(out: Path, **kw) -> dict:
        return run_transient_stage(load_case(ABSORBING, RESUME_CASE), out, comm,
                                   Reporter(comm.rank), **kw)

    go(ref)
    if comm.rank == 0:
        copy_results(ref, res, MESH_FILES)
    comm.Barrier()
    with pytest.raises(Interrupted):
        go(res, checkpoint_steps=60, stop_after=60)
    stats = go(res)
    assert 0 < stats["steps_run"] < stats["n_steps"]
    if comm.rank:
        return None, None
    return _resume_numbers(ref), _resume_numbers(res)


def _resume_numbers(out: Path) -> dict[str, np.ndarray]:
    with h5py.File(out / "probes.h5", "r") as f:
        h = {k: f[f"probes/{k}/acceleration"][()] for k in f["probes"]}
    with h5py.File(out / "transient.h5", "r") as f:
        h["contact_force"] = f["wheels/contact_force"][()]
        h["uz"] = f["rail/uz"][()]
    with h5py.File(out / "fields.h5", "r") as f:
        h["fields"] = f["fields/velocity"][()]
    return h


def _worst(a: dict, b: dict) -> float:
    return max(float(np.abs(a[k] - b[k]).max() / max(np.abs(a[k]).max(), 1e-300)) for k in a)


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one rank: bit for bit")
def test_interrupted_coarse_run_resumes_bit_identically(tmp_path, tally):
    a, b = _coarse_resume(tmp_path / "ref", tmp_path / "res", MPI.COMM_SELF)
    worst = _worst(a, b)
    same = all(np.array_equal(a[k], b[k]) for k in a)
    tally.add("transient: coarse absorbing run interrupted at step 60 and resumed",
              "resumed" if same else "silent wrong", f"largest relative difference {worst:.3g}")
    assert same, worst


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="several ranks (mpirun -n 2)")
def test_interrupted_coarse_run_on_two_ranks_resumes_within_the_bound(shared_tmp, tally):
    a, b = _coarse_resume(shared_tmp / "ref", shared_tmp / "res", MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank:
        return
    worst = _worst(a, b)
    tally.add(f"transient: coarse absorbing run on {MPI.COMM_WORLD.size} ranks interrupted "
              "and resumed", "resumed" if worst <= PARALLEL_RESUME_BOUND else "silent wrong",
              f"largest relative difference {worst:.3g}")
    assert worst <= PARALLEL_RESUME_BOUND


# --------------------------------------------------------------------------- item 9
SIZE_CASES = {
    "second train 1e6 s later": ("track.count=2", "geometry.ys0=12", "train2.t_start=1e6"),
    "vehicle.t_after = 1e5 s": ("vehicle.t_after=1e5",),
    "vehicle.speed = 0.001 m/s": ("vehicle.speed=0.001",),
    "transient.dt = 1e-7 s": ("transient.dt=1e-7",),
}


@pytest.mark.parametrize("name", list(SIZE_CASES))
def test_too_many_steps_are_refused_before_anything_is_built(name, tmp_path, capsys, tally):
    out = tmp_path / "out"
    code = run(["transient", A, *COARSE, *_sets(*SIZE_CASES[name]), "--out", str(out)])
    cap = capsys.readouterr()
    line = _one_error(code, cap.err)
    tally.add(f"transient: {name} (killed at 23 GB before)",
              "clear error" if line else "silent wrong" if code == 0 else "unclear",
              line or cap.err[-300:])
    assert line is not None, (code, cap.err[-2000:])
    assert "more than the limit of 200,000" in line and "transient.dt" in line, line
    assert not (out / "mesh.h5").exists()               # before the mesh


def test_histories_beyond_the_memory_are_refused(tmp_path, capsys, tally, monkeypatch):
    import railvib_hpc.resources as resources

    monkeypatch.setattr(resources, "available_memory_bytes", lambda: 1e6)   # 1 MB
    out = tmp_path / "out"
    code = run(["transient", A, *COARSE, "--out", str(out)])
    line = _one_error(code, capsys.readouterr().err)
    tally.add("transient: histories larger than the available memory",
              "clear error" if line else "unclear", line or "")
    assert line is not None
    assert "the transient histories (1.47e+03 steps) would need" in line, line
    assert not (out / "mesh.h5").exists()


# --------------------------------------------------------------------------- item 16
def test_help_and_docs_say_transient_writes_to_out_itself(tmp_path, tally):
    import argparse

    from railvib_hpc.cli import _out_dir, _parser
    from railvib_hpc.log import Reporter

    parser = _parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    text = sub.choices["transient"].format_help()
    docs = (ROOT / "docs" / "cli.md").read_text() + (ROOT / "docs" / "outputs.md").read_text()
    case = load_case(ABSORBING)
    given = parser.parse_args(["transient", A, "--out", str(tmp_path)])
    default = parser.parse_args(["transient", A])
    ok = ("<out>/transient" not in text + docs and "results in --out itself" in text
          and _out_dir(given, case, Reporter(0)) == tmp_path
          and _out_dir(default, case, Reporter(0)) == Path("results/absorbing_boundaries/"
                                                           "transient"))
    tally.add("transient: --help and docs/cli.md on the output folder",
              "correct" if ok else "unclear", " ".join(text.split())[:300])
    assert ok, text
    assert "results/<case.name>/transient" in " ".join(text.split())

