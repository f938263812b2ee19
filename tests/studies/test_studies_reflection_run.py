"""A tiny boundary reflection study on 2 ranks: two domains, peaks and spectra compared."""

from __future__ import annotations

import json

import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD


@pytest.mark.slow
@pytest.mark.mpi
def test_reflection_study_compares_domains_and_resumes(shared_tmp, capsys):
    args = ["study", "reflection", str(BASELINE), *TINY, "--out", str(shared_tmp),
            "--study-set", "domains=[[0, 0, 0], [1.2, 1.2, 3]]",
            "--study-set", "names=[small, big]", "--study-set", "threshold=10"]
    assert run(args) == 0
    first = capsys.readouterr().out
    assert run(args) == 0
    second = capsys.readouterr().out
    if comm.rank == 0:
        root = shared_tmp / "reflection"
        assert "VERDICT: boundary reflections" in first
        assert "for the small domain" in first and "reference domain big" in first
        assert second.count("finished earlier: skipping") == 2
        report = json.loads((root / "report.json").read_text())
        rows = {r["variant"]: r for r in report["analysis"]["rows"]}
        assert rows["big"]["n_dofs"] > rows["small"]["n_dofs"]
        assert rows["big"]["extra_width"] == 3.0
        dev = rows["small"]["max_deviation"]
        assert report["verdict"]["reflections_matter"] is (dev > 0.10)
        assert set(rows["small"]["spectrum_db"]) == {"footing", "basement_wall", "slab1",
                                                      "slab2"}
        res = json.loads((root / "big" / "result.json").read_text())
        assert res["spectra"]["slab1"]["bands_hz"][0] >= 1.0
        for png in ("reflection_peaks.png", "reflection_spectra.png"):
            assert (root / "figures" / png).exists()
    comm.Barrier()


@pytest.mark.slow
@pytest.mark.mpi
def test_reflection_study_with_a_band_uses_band_sliced_modes(shared_tmp, capsys):
    """band_hz: every domain gets all its modes below the band (modal.f_max, inertia
    counted), one solve each, and the MBS uses them all."""
    args = ["study", "reflection", str(BASELINE), *TINY, "--out", str(shared_tmp),
            "--study-set", "domains=[[0, 0, 0], [1.2, 1.2, 3]]",
            "--study-set", "names=[small, big]", "--study-set", "band_hz=13"]
    assert run(args) == 0
    out = capsys.readouterr().out
    if comm.rank == 0:
        assert out.count("modes below the band limit 13 Hz (inertia-checked band solve)") == 2
        counts = {}
        for name in ("small", "big"):
            res = json.loads((shared_tmp / "reflection" / name / "result.json").read_text())
            f = res["model"]["frequencies_hz"]
            assert max(f) < 13.0 and res["model"]["f_max_hz"] < 13.0
            counts[name] = len(f)
        assert counts["big"] >= counts["small"] >= 1
    comm.Barrier()


@pytest.mark.slow
def test_reflection_study_with_boundary_types_and_the_direct_solver(shared_tmp, capsys):
    """Boundary type as a dimension, every variant by the full-order time integration."""
    short = ["--set", "vehicle.x_start=2.7", "--set", "vehicle.x_end=4.2", "--set",
             "output.dt=0.002", "--set", "output.stress_times=[]", "--set",
             "transient.checkpoint_interval=0"]
    args = ["study", "reflection", str(BASELINE), *TINY, *short, "--out", str(shared_tmp),
            "--study-set", "domains=[[0, 0, 0], [1.2, 1.2, 3]]",
            "--study-set", "names=[small, big]", "--study-set", "boundaries=[thesis,absorbing]",
            "--study-set", "solver=direct"]
    assert run(args) == 0
    out = capsys.readouterr().out
    if comm.rank == 0:
        root = shared_tmp / "reflection"
        report = json.loads((root / "report.json").read_text())
        rows = {r["variant"]: r for r in report["analysis"]["rows"]}
        assert set(rows) == {"thesis-small", "thesis-big", "absorbing-small", "absorbing-big"}
        groups = report["verdict"]["groups"]
        assert [g["boundary"] for g in groups] == ["thesis", "absorbing"]
        assert [g["reference"] for g in groups] == ["thesis-big", "absorbing-big"]
        assert "with thesis boundaries" in out and "with absorbing boundaries" in out
        res = json.loads((root / "absorbing-small" / "result.json").read_text())
        assert res["model"]["solver"] == "direct"
        assert "boundary.base=absorbing" in res["overrides"]
        assert (root / "absorbing-small" / "transient.h5").exists()
    comm.Barrier()


def test_reflection_settings_reject_unknown_boundaries_and_solvers():
    from railvib_hpc.studies.settings import StudySettingsError, study_settings

    with pytest.raises(StudySettingsError, match=r"boundaries.*unknown entries \['sponge'\]"):
        study_settings("reflection", ["boundaries=[thesis,sponge]"])
    with pytest.raises(StudySettingsError,
                       match=r"solver = 'fast': allowed values: 'modal', 'direct'"):
        study_settings("reflection", ["solver=fast"])
