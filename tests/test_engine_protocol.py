"""The time-domain engine protocol: every engine declared once
(:data:`railvib_hpc.time_engines.ENGINES`), built by the transient stage's setup, and a new
engine one module and one registry line (``example_engine.py``)."""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

import h5py
import pytest

import railvib_hpc as rv
from railvib_hpc import time_engines
from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.schema import PML_ENGINES, SCHEMA, TRANSIENT_ENGINES

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The coarse thesis model, the wheelset rolling 0.1 m; the explicit engine's settings.
SHORT = ["mesh.refinement=0.25", "vehicle.x_start=2.95", "vehicle.x_end=3.05",
         "output.dt=0.001", "transient.checkpoint_interval=0", "transient.f_max=100",
         "modal.lumped_mass=true", "output.stress_times=[]"]


#: ``SHORT`` run by the example engine, as ``--set`` arguments of the command line.
HALFSTEP_SETS = [a for s in [*SHORT, "transient.engine=halfstep"] for a in ("--set", s)]


@pytest.fixture
def halfstep(monkeypatch):
    """The example engine of ``example_engine.py``, registered with its one line."""
    import example_engine

    monkeypatch.setitem(time_engines.ENGINES, "halfstep", example_engine.DECLARATION)
    yield example_engine
    sys.modules.pop("example_engine", None)


@pytest.fixture(scope="module")
def halfstep_cli_run(tmp_path_factory):
    """``(folder, stdout)``: the uninterrupted ``halfstep`` run of ``SHORT`` from the command
    line (the engine registered for this run only), run once for the module: the run of the
    command-line test and the reference the checkpoint test resumes to (the same case;
    they ran it twice)."""
    import example_engine

    out = tmp_path_factory.mktemp("halfstep") / "cli"
    text = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(text):
        mp.setitem(time_engines.ENGINES, "halfstep", example_engine.DECLARATION)
        code = run(["transient", str(BASELINE), "--out", str(out), *HALFSTEP_SETS])
    sys.modules.pop("example_engine", None)
    assert code == 0, text.getvalue()
    return out, text.getvalue()


def test_the_schema_choices_and_the_checks_read_the_declarations(halfstep):
    assert tuple(TRANSIENT_ENGINES) == ("direct", "explicit", "imex", "halfstep")
    assert SCHEMA["transient"]["engine"].choices == TRANSIENT_ENGINES == PML_ENGINES
    assert "halfstep" in time_engines.needs_lumped_mass()
    from railvib_hpc.errors import CaseError

    with pytest.raises(CaseError, match=r"halfstep.*needs a diagonal mass"):
        load_case(BASELINE, [*SHORT, "transient.engine=halfstep", "modal.lumped_mass=false"])
    from railvib_hpc.assess.stage import _engine_text

    assert _engine_text({"engine": "halfstep"}).startswith("central differences at half")
    assert _engine_text({"rho_inf": 1.0}) == "generalized-alpha rho_inf 1.0, "


def test_every_engine_builds_from_its_declaration():
    from railvib_hpc.transient.engine import engine_class

    for name, spec in time_engines.ENGINES.items():
        cls = engine_class(name)
        assert cls.name == name, spec.factory
        for method in ("stable_step", "factor", "make_solver", "initial_acceleration", "step",
                       "state", "restore", "describe", "destroy"):
            assert callable(getattr(cls, method)), (name, method)


def test_a_new_engine_is_one_module_and_one_registry_line(halfstep, halfstep_cli_run,
                                                          tmp_path):
    """``halfstep`` from the command line (``halfstep_cli_run``) and the API: the run takes
    half the explicit engine's step, says so, records its engine and is reused by the next
    call."""
    out, text = halfstep_cli_run
    assert "central differences at half the stable step (example), stable up to" in text
    with h5py.File(out / "transient.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    assert stats["engine"] == "halfstep" and stats["steps_run"] == stats["n_steps"]
    case = load_case(BASELINE, [*SHORT, "transient.engine=halfstep"])
    api = rv.Pipeline(case, tmp_path / "api").stage("transient")
    assert api.summary["engine"] == "halfstep" and not api.reused
    assert api.summary["dt"] == pytest.approx(stats["dt"], rel=1e-12)
    assert api.summary["n_steps"] == stats["n_steps"]
    explicit = rv.Pipeline(case.replace({"transient.engine": "explicit"}),
                           tmp_path / "explicit").stage("transient")
    assert api.summary["dt"] == pytest.approx(0.5 * explicit.summary["dt"], rel=1e-9)
    again = rv.Pipeline(case, tmp_path / "api").stage("transient")
    assert again.reused is True and again.summary["engine"] == "halfstep"


def test_the_new_engine_checkpoints_and_resumes(halfstep, halfstep_cli_run, tmp_path,
                                                capsys):
    """Killed after a checkpoint, ``halfstep`` resumes through the command line to the
    uninterrupted answer (``halfstep_cli_run``), bit for bit (one rank)."""
    from mpi4py import MPI

    from railvib_hpc.log import Reporter
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.stage import Interrupted, run_transient_stage

    init_petsc([])
    case = load_case(BASELINE, [*SHORT, "transient.engine=halfstep"])
    ref_folder = halfstep_cli_run[0]
    with pytest.raises(Interrupted):
        run_transient_stage(case, tmp_path / "resume", MPI.COMM_SELF, Reporter(0),
                            checkpoint_steps=400, stop_after=400)
    capsys.readouterr()
    assert run(["transient", str(BASELINE), "--out", str(tmp_path / "resume"),
                *HALFSTEP_SETS]) == 0
    assert "resuming from the checkpoint at step 400" in capsys.readouterr().out
    with h5py.File(ref_folder / "probes.h5", "r") as a, \
            h5py.File(tmp_path / "resume" / "probes.h5", "r") as b:
        for name in a["probes"]:
            ref, new = a[f"probes/{name}/velocity"][()], b[f"probes/{name}/velocity"][()]
            assert (new == ref).all(), name
