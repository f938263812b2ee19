"""``boundary.<face> = "pml"`` through ``railvib transient`` (issue 29): its bad input, and
the thesis model with perfectly matched layers on 1 and 2 ranks."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.io.files import TRANSIENT_CHECKPOINT_H5

comm = MPI.COMM_WORLD
#: The coarse thesis model, the wheelset rolling 0.2 m onto the flexible rail; explicit.
SHORT = ["mesh.refinement=0.25", "vehicle.x_start=2.7", "vehicle.x_end=2.9", "output.dt=0.001",
         "transient.checkpoint_interval=0", "transient.f_max=100", "modal.lumped_mass=true",
         "transient.engine=explicit", "output.stress_times=[]"]
#: Layers on four faces (the coarse mesh's far y_min elements are 16 m wide: dashpots
#: there), in soil added for them.
LAYERS = ["boundary.x_min=pml", "boundary.x_max=pml", "boundary.y_min=absorbing",
          "boundary.y_max=pml", "boundary.base=pml", "boundary.layer_thickness=5",
          "domain.extra_length=4", "domain.extra_depth=4", "geometry.ys0=12.25"]


def _sets(*items: str) -> list[str]:
    return [a for s in items for a in ("--set", s)]


def _refused(tmp_path, capsys, command: str, *overrides: str) -> str:
    code = run([command, str(BASELINE), "--out", str(tmp_path), *_sets(*SHORT, *overrides)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert len([line for line in err.splitlines() if "error" in line]) == 1, err
    assert not (tmp_path / "transient.h5").exists()
    assert not (tmp_path / "modes.h5").exists()
    return err


def _stage(folder, *overrides: str, comm_=MPI.COMM_SELF) -> dict:
    """``run_transient_stage`` of the short run with ``overrides`` (no assessment):
    ``{"stats": ..., "velocity": {probe: (steps + 1, 3)}}``."""
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    run_transient_stage(load_case(BASELINE, [*SHORT, *overrides]), folder, comm_,
                        Reporter(comm_.rank))
    with h5py.File(folder / "transient.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    return {"stats": stats, "velocity": _probes(folder)}


#: The ground probes, whose signals the 30 ms run resolves (the building's are ~1e-3 of
#: theirs, still rising).
GROUND = ("ground_toe", "ground_mid", "ground_opposite")


@pytest.mark.slow
def test_the_direct_engine_runs_the_thesis_model_with_layers_as_the_imex_engine(tmp_path):
    """The direct engine with the layers implicit (in K_eff, Cholesky) on the coarse thesis
    model, the wheelset rolling 0.9 m (30 ms): its step is its own accuracy step (5e-4 s,
    above the imex engine's explicit limit 4.9e-4 s), and the ground probes' peak
    velocities agree with the imex engine's within 1 % (measured: 0.02-0.06 %; with
    dashpots instead of layers both engines give ~22 % more there, the layers reaching
    within 1.7 m of the wheel)."""
    longer = "vehicle.x_end=3.6"
    direct = _stage(tmp_path / "direct", *LAYERS, longer, "transient.engine=direct")
    imex = _stage(tmp_path / "imex", *LAYERS, longer, "transient.engine=imex")
    assert direct["stats"]["engine"] == "direct" and direct["stats"]["pml_elements"] >= 2620
    assert direct["stats"]["dt"] == pytest.approx(5e-4, rel=1e-9)
    for name in GROUND:
        a, b = (np.abs(r["velocity"][name]).max() for r in (direct, imex))
        assert abs(a - b) < 1e-2 * b, (name, a, b)


def test_an_implicit_part_inside_a_layer_is_refused(tmp_path, capsys):
    """The imex engine with the subgrade implicit: its elements fill the layers, whose
    memory forces are explicit (unstable then, tests/transient/test_pml_imex.py)."""
    err = _refused(tmp_path, capsys, "transient", *LAYERS, "transient.engine=imex",
                   "transient.implicit_parts=[\"track\", \"subgrade\"]")
    assert "transient.implicit_parts = ['track', 'subgrade']: the part(s) subgrade" in err
    assert "allowed: implicit parts outside the layers" in err


def test_the_modal_path_refuses_pml(tmp_path, capsys):
    err = _refused(tmp_path, capsys, "modal", *LAYERS)
    assert "boundary.x_min" in err and "the modal path" in err
    assert "allowed here: fixed, roller, free, absorbing, caughey" in err


def test_pml_needs_a_thickness(tmp_path, capsys):
    err = _refused(tmp_path, capsys, "transient", *LAYERS, "boundary.layer_thickness=0")
    assert "boundary.layer_thickness = 0" in err and "must be > 0 m for the pml face(s)" in err


def test_a_pml_reflection_outside_0_1_is_refused(tmp_path, capsys):
    err = _refused(tmp_path, capsys, "transient", *LAYERS, "boundary.pml_reflection=1.5")
    assert "boundary.pml_reflection" in err


def test_a_layer_without_an_element_names_the_thickness_it_needs(tmp_path, capsys):
    err = _refused(tmp_path, capsys, "transient", *LAYERS, "boundary.layer_thickness=0.2")
    assert "boundary.layer_thickness = 0.2: the pml layer of boundary." in err
    assert "holds no element (the nearest Gauss point lies" in err and "allowed: more than" in err


def test_a_layer_that_reaches_the_building_is_refused(tmp_path, capsys):
    """The base layer of the thesis domain (no extra depth): the footings stand 2.4 m above
    the base."""
    err = _refused(tmp_path, capsys, "transient", *LAYERS, "domain.extra_depth=0",
                   "boundary.layer_thickness=3", "boundary.y_max=absorbing")
    assert "the pml layer of boundary.base reaches the building" in err


def test_the_classical_layer_and_the_unwritten_checkpoints_are_said(tmp_path, capsys):
    """``boundary.pml_alpha = 0`` (the classical layer: its memory never decays, and its
    energy was measured to grow from 7.4 s on) gets a warning naming the run's length, and
    ``transient.checkpoint_interval > 0`` with layers says that no checkpoint is written
    (the layers' memory is not in them); the default alpha warns of nothing."""
    _stage(tmp_path / "classical", *LAYERS, "transient.engine=imex", "boundary.pml_alpha=0",
           "transient.checkpoint_interval=1e-9")
    out = capsys.readouterr()
    text = out.out + out.err
    assert "warning: boundary.pml_alpha = 0: the classical layer's memory never decays" in text
    assert "this run lasts 0.00" in text
    # (the layers' memory is in the checkpoints now, test_pml_resume.py: they are written,
    # and the finished run deletes the last)
    assert "checkpoints: none written (the perfectly matched layers' memory" not in text
    assert not (tmp_path / "classical" / TRANSIENT_CHECKPOINT_H5).exists()
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.pml import pml_memory_warning

    shifted = Problem.from_case(load_case(BASELINE, [*SHORT, *LAYERS]))
    assert pml_memory_warning(shifted, 100.0) is None


@pytest.mark.slow
def test_the_pml_job_runs_end_to_end_and_is_assessed(tmp_path, capsys):
    """``jobs/pml_boundaries.toml`` (layers on all five faces, outside the thesis domain)
    through ``railvib transient`` and ``railvib assess``, coarse and short: the log names the
    five layers, the assessment reads the transient fields and writes its results (measured:
    2.5 min with the machine loaded, most of it the assessment's figures)."""
    from pathlib import Path

    job = Path(__file__).resolve().parents[2] / "jobs" / "pml_boundaries.toml"
    coarse = ["mesh.refinement=0.3", "vehicle.x_start=2.7",
              "vehicle.x_end=2.9", "output.dt=0.001", "transient.f_max=100",
              "output.stress_times=[]"]
    assert run(["transient", str(job), "--out", str(tmp_path), *_sets(*coarse)]) == 0
    text = capsys.readouterr().out
    assert "perfectly matched layers (4 m" in text
    assert all(f"{face} " in text for face in ("x_min", "x_max", "y_min", "y_max", "base"))
    with h5py.File(tmp_path / "transient.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    assert stats["engine"] == "imex" and stats["pml_elements"] > 0
    assert run(["assess", str(job), "--out", str(tmp_path), *_sets(*coarse)]) == 0
    report = json.loads((tmp_path / "assessment.json").read_text())
    assert report["solver"] == "transient" and report["complete"] is True
    assert {"footing", "slab1", "slab2"} <= set(report["results"])


#: The 2-rank runs' wheelset rolls 0.2 m from x = 2.95 m onto the flexible rail, which
#: starts at x = 3.0 m: from 2.7 to 2.9 m it never reached it with the layers' extra
#: soil, and every probe was exactly 0, so the 1- and 2-rank runs compared zeros.
ONTO = ["vehicle.x_start=2.95", "vehicle.x_end=3.15"]
#: The imex engine's short run with the layers.
IMEX = [*SHORT, *LAYERS, *ONTO, "transient.engine=imex"]


def _serial(overrides: list[str]):
    """A builder of ``serial_refs`` (tests/conftest.py): the short run with ``overrides``
    alone on ``MPI.COMM_SELF``."""
    def build(folder) -> None:
        from railvib_hpc.log import Reporter
        from railvib_hpc.transient.stage import run_transient_stage

        run_transient_stage(load_case(BASELINE, overrides), folder, MPI.COMM_SELF, Reporter(0))
    return build


#: The serial references the 2-rank tests below compare with (tests/conftest.py:
#: ``serial_refs``, computed side by side with the other modules'): name -> (seconds on one
#: rank, measured; builder).
SERIAL_REFERENCES = {"pml_explicit": (25.0, _serial([*SHORT, *LAYERS, *ONTO])),
                     "pml_imex": (8.0, _serial(IMEX))} if comm.size > 1 else {}


def _integrate(folder, overrides: list[str]) -> None:
    """``railvib transient``'s integration of ``overrides`` on every rank of ``comm``, its
    log on rank 0, without the assessment: the 2-rank tests below read the log,
    transient.h5 and probes.h5 only, and the assessment runs on rank 0 alone whatever the
    ranks (a pml case's: test_the_pml_job_runs_end_to_end_and_is_assessed); it cost ~6 s a
    run of these tests (measured: 6.2 s of the imex run's 8.6 s on one rank)."""
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    run_transient_stage(load_case(BASELINE, overrides), folder, comm, Reporter(comm.rank))


def _probes(folder) -> dict[str, np.ndarray]:
    with h5py.File(folder / "probes.h5", "r") as f:
        return {str(g.attrs["name"]): g["velocity"][()] for g in f["probes"].values()}


@pytest.mark.slow
@pytest.mark.mpi
def test_the_imex_engine_runs_the_thesis_model_with_layers_on_1_and_2_ranks(shared_tmp,
                                                                           serial_refs,
                                                                           capsys):
    """The same short run with the imex engine (the track and the building implicit): the
    layers' M_e1 and M_e2 are named among the implicit terms, the step is the explicit
    soil's (measured: 3.33e-4 s, 20 steps, against the explicit engine's ~2e-6 s for the
    rail),
    the probes are finite, and on 2 ranks they equal the same run alone on COMM_SELF
    (``serial_refs``) within 1e-9 of their peak."""
    out = shared_tmp / f"pml_imex_{comm.size}"
    _integrate(out, IMEX)
    text = capsys.readouterr().out
    if comm.rank == 0:
        assert "the layers M_e1, M_e2; explicit part stable up to" in text
        with h5py.File(out / "transient.h5", "r") as f:
            stats = json.loads(f.attrs["stats"])
        assert stats["engine"] == "imex" and stats["pml_elements"] >= 2620
        assert stats["dt"] > 1e-4, stats["dt"]
        velocities = _probes(out)
        assert all(np.isfinite(v).all() for v in velocities.values())
        assert all(np.abs(velocities[name]).max() > 0 for name in GROUND), velocities
        if comm.size > 1:
            alone = _probes(serial_refs["pml_imex"])
            for name, v in velocities.items():
                scale = max(np.abs(alone[name]).max(), 1e-30)
                assert np.abs(v - alone[name]).max() < 1e-9 * scale, name
    comm.Barrier()


@pytest.mark.slow
@pytest.mark.mpi
def test_the_thesis_model_with_layers_runs_and_agrees_on_1_and_2_ranks(shared_tmp, serial_refs,
                                                                       capsys):
    """The short explicit run with layers on four faces: the log names them and warns of
    the thin ones (the coarse mesh: 0.6-3.8 elements across), the statistics count the
    layer's elements; on 2 ranks the probe velocities equal the same run alone on
    MPI.COMM_SELF (``serial_refs``) to round-off (the layer's elements at the partition are
    computed on both ranks, their nodes' displacements gathered).

    Measured: 11 s of time integration on 1 rank (3112 steps), 2620 layer elements; on 2
    ranks against 1 the velocities differ by < 1e-12 of their peak."""
    out = shared_tmp / f"pml_{comm.size}"
    _integrate(out, [*SHORT, *LAYERS, *ONTO])
    text = capsys.readouterr().out
    if comm.rank == 0:
        assert "perfectly matched layers (5 m, R = 0.0001, p = 2): x_min " in text
        assert "warning: boundary.layer_thickness = 5 m gives the pml layer of" in text
        with h5py.File(out / "transient.h5", "r") as f:
            stats = json.loads(f.attrs["stats"])
        assert stats["engine"] == "explicit" and stats["pml_elements"] >= 2620
        velocities = _probes(out)
        assert all(np.isfinite(v).all() for v in velocities.values())
        assert all(np.abs(velocities[name]).max() > 0 for name in GROUND), velocities
        if comm.size > 1:
            alone = _probes(serial_refs["pml_explicit"])
            for name, v in velocities.items():
                scale = max(np.abs(alone[name]).max(), 1e-30)
                assert np.abs(v - alone[name]).max() < 1e-9 * scale, name
    comm.Barrier()
