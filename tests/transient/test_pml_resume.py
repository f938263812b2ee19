"""A run with perfectly matched layers killed mid-way resumes from its checkpoint (every
engine): the layers' memory is in the checkpoint (:meth:`~railvib_hpc.transient.engine.
Engine.state`, :meth:`~railvib_hpc.transient.pml.PmlLayer.memory`), so the resumed run's
probes and peaks equal the uninterrupted run's.

Bounds: on one rank the same state, factor and operations give the same numbers (0:
bit for bit, measured 0 on all three engines). On two ranks the resumed run lies within
:data:`RANKS_BOUND` of the uninterrupted 2-rank run (the round-off of MUMPS's parallel
factorization, ~4e-9 relative between two uninterrupted 2-rank runs, docs/transient.md;
the test of the rigid-ended tiny case, test_transient_stage.py, takes 1e-8 too), and a
2-rank checkpoint resumed on one rank within the same bound (the memory is stored by
global DOF and element).

The case: the coarse thesis model with layers on four faces (test_pml_stage.py), the
wheelset rolling 0.2 m onto the flexible rail (:data:`ONTO`).
"""

from __future__ import annotations

import shutil
from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI
from test_pml_stage import GROUND, LAYERS, SHORT, _probes
from transient_cases import BASELINE

from railvib_hpc.config import load_case
from railvib_hpc.io.files import TRANSIENT_CHECKPOINT_H5
from railvib_hpc.log import Reporter
from railvib_hpc.petsc_env import init_petsc

comm = MPI.COMM_WORLD
#: The wheelset rolls from the rigid rail onto the flexible one (which starts at x = 3 m
#: with the layers' extra soil): the probes move (at 2.7-2.9 m, test_pml_stage.py's run,
#: they stay at rest).
ONTO = ["vehicle.x_start=2.95", "vehicle.x_end=3.15"]
#: Checkpoint every this many steps and stop after the first at or after ``stop``, per
#: engine (about half the run).
STOPS = {"explicit": (200, 500), "imex": (4, 10), "direct": (3, 7)}
#: Largest difference of a resumed run's probe velocities from the uninterrupted run's,
#: relative to their largest value: on one rank (exact) and on two ranks.
SERIAL_BOUND = 0.0
RANKS_BOUND = 1e-8


def _run(engine: str, folder, c=MPI.COMM_SELF, **hooks) -> dict:
    from railvib_hpc.transient.stage import run_transient_stage

    init_petsc([])
    case = load_case(BASELINE, [*SHORT, *LAYERS, *ONTO, f"transient.engine={engine}"])
    return run_transient_stage(case, folder, c, Reporter(1 if c.rank else 0), **hooks)


def _interrupt(engine: str, folder, c=MPI.COMM_SELF) -> None:
    from railvib_hpc.transient.stage import Interrupted

    every, stop = STOPS[engine]
    with pytest.raises(Interrupted):
        _run(engine, folder, c, checkpoint_steps=every, stop_after=stop)


def _worst(new: dict, ref: dict) -> tuple[float, float]:
    """The largest difference of the probe velocities and of their peaks (max |v| per
    probe and component), each relative to the largest reference value."""
    scale = max(float(np.abs(v).max()) for v in ref.values())
    trace = max(float(np.abs(new[k] - ref[k]).max()) for k in ref) / scale
    peaks = max(float(np.abs(np.abs(new[k]).max(axis=0) - np.abs(ref[k]).max(axis=0)).max())
                for k in ref) / scale
    return trace, peaks


@pytest.fixture(scope="module")
def one_rank_runs(tmp_path_factory):
    """The one-rank runs the tests below share, each computed once per module (on one rank
    both tests ran each of them: the same case):

    * ``reference(engine)`` -> ``(folder, summary)``: the uninterrupted run;
    * ``checkpoint(engine)`` -> the folder of the run killed after its checkpoint
      (:data:`STOPS`), which a test copies before it resumes it (a resume removes the
      checkpoint)."""
    root = tmp_path_factory.mktemp("pml_resume")
    references: dict[str, tuple] = {}
    checkpoints: dict[str, object] = {}

    def reference(engine: str) -> tuple:
        if engine not in references:
            folder = root / f"{engine}_uninterrupted"
            references[engine] = (folder, _run(engine, folder))
        return references[engine]

    def checkpoint(engine: str):
        if engine not in checkpoints:
            folder = root / f"{engine}_killed"
            _interrupt(engine, folder)
            checkpoints[engine] = folder
        return checkpoints[engine]

    return SimpleNamespace(reference=reference, checkpoint=checkpoint)


@pytest.mark.skipif(comm.size > 1, reason="one rank (the 2-rank test below)")
@pytest.mark.parametrize("engine", ["explicit", "imex", "direct"])
def test_a_run_with_layers_resumes_to_the_uninterrupted_answer(one_rank_runs, tmp_path, engine,
                                                               capsys):
    ref_folder, ref = one_rank_runs.reference(engine)
    assert ref["pml_elements"] > 0
    out = tmp_path / "resume"
    shutil.copytree(one_rank_runs.checkpoint(engine), out, symlinks=True)
    assert (out / TRANSIENT_CHECKPOINT_H5).exists()
    capsys.readouterr()
    stats = _run(engine, out)
    assert "resuming from the checkpoint at step" in capsys.readouterr().out
    assert 0 < stats["steps_run"] < stats["n_steps"] == ref["n_steps"]
    assert not (out / TRANSIENT_CHECKPOINT_H5).exists()
    new, old = _probes(out), _probes(ref_folder)
    trace, peaks = _worst(new, old)
    print(f"{engine}: resumed - uninterrupted, probe velocities {trace:.2e}, peaks {peaks:.2e}"
          " of the largest")
    assert trace <= SERIAL_BOUND and peaks <= SERIAL_BOUND
    assert all(np.abs(old[g]).max() > 0 for g in GROUND)


@pytest.mark.mpi
@pytest.mark.parametrize("engine", ["explicit", "direct"])
def test_a_run_with_layers_resumes_on_two_ranks_or_one(one_rank_runs, shared_tmp, engine):
    """Killed on two ranks, resumed on two (and, from a copy of the checkpoint, on one):
    within :data:`RANKS_BOUND` of the uninterrupted 2-rank run. (In the one-rank pass the
    world is one rank: its uninterrupted run and its killed run are the one-rank test's,
    ``one_rank_runs``.)"""
    base = shared_tmp / engine
    if comm.size == 1:
        ref_folder = one_rank_runs.reference(engine)[0]
        shutil.copytree(one_rank_runs.checkpoint(engine), base / "two", symlinks=True)
    else:
        ref_folder = base / "ref"
        _run(engine, ref_folder, comm)
        _interrupt(engine, base / "two", comm)
    if comm.rank == 0:
        assert (base / "two" / TRANSIENT_CHECKPOINT_H5).exists()
        shutil.copytree(base / "two", base / "one", symlinks=True)
    comm.Barrier()
    stats = _run(engine, base / "two", comm)
    assert 0 < stats["steps_run"] < stats["n_steps"]
    if comm.rank == 0:
        one = _run(engine, base / "one")
        assert 0 < one["steps_run"] < one["n_steps"]
        ref = _probes(ref_folder)
        for folder in ("two", "one"):
            trace, peaks = _worst(_probes(base / folder), ref)
            print(f"{engine} on {comm.size} ranks, resumed on {folder}: probe velocities "
                  f"{trace:.2e}, peaks {peaks:.2e} of the largest")
            assert trace <= RANKS_BOUND and peaks <= RANKS_BOUND, folder
    comm.Barrier()
