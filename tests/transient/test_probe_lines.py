"""Probe lines through the full-order solution into the assessment (issue 28, item 4)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE, TINY, tiny_case

from railvib_hpc.cli import run
from railvib_hpc.log import Reporter
from railvib_hpc.petsc_env import init_petsc

LINES = ('probes.line=[{name = "ff", distances = [5.0, 20.0]}, '
         '{name = "opp", distances = [6.0], side = "away", x = 10.0}]')


def test_a_probe_line_is_recorded_as_free_field_probes(tmp_path):
    """The tiny moving-force run: the line's points are probes of probes.h5 where the case
    puts them, with the role free_field, and the free-field metrics are theirs."""
    init_petsc([])
    from railvib_hpc.assess.free_field import free_field_summary
    from railvib_hpc.reconstruct.probes import read_probes
    from railvib_hpc.site import line_probes
    from railvib_hpc.transient.stage import run_transient_stage

    case = tiny_case("vehicle.type=moving_force", LINES)
    run_transient_stage(case, tmp_path, MPI.COMM_SELF, Reporter(0))
    hist = read_probes(tmp_path / "probes.h5")
    lines = line_probes(case)
    for name, point in lines.items():
        assert hist[name]["role"] == "free_field"
        assert np.allclose(hist[name]["coords"], point.point)
    assert hist["ground_mid"]["role"] == "ground"
    with h5py.File(tmp_path / "probes.h5", "r") as f:
        assert {f[f"probes/{g}"].attrs["name"] for g in f["probes"]} >= set(lines)
    out = free_field_summary(hist, lines)
    assert list(out["probes"]) == list(lines)
    for name, p in out["probes"].items():
        v = hist[name]["velocity"]
        assert p["ppv_vertical"] == pytest.approx(np.abs(v[:, 2]).max(), rel=1e-12)
        assert p["ppv_resultant"] == pytest.approx(np.linalg.norm(v, axis=1).max(), rel=1e-12)
        assert p["rms_max_vertical"] <= p["ppv_vertical"]
    # the nearer point of the line moves more than the farther one
    assert out["probes"]["ff_5m"]["ppv_resultant"] > 10 * out["probes"]["ff_20m"]["ppv_resultant"]


@pytest.mark.slow
def test_a_probe_line_reaches_the_report(tmp_path, capsys):
    """railvib transient (and its assessment): the free-field table in the report, the
    numbers in assessment.json and report.json."""
    sets = [a for s in [*TINY, "vehicle.type=moving_force", LINES] for a in ("--set", s)]
    assert run(["transient", str(BASELINE), "--out", str(tmp_path), *sets]) == 0
    text = capsys.readouterr().out
    assert "free field (probe lines), unweighted velocity" in text
    report = (tmp_path / "report.md").read_text()
    assert "## Free field (probe lines)" in report and "opp_6m" in report
    doc = json.loads((tmp_path / "assessment.json").read_text())
    ff = doc["free_field"]["probes"]
    assert list(ff) == ["ff_5m", "ff_20m", "opp_6m"]
    with h5py.File(tmp_path / "probes.h5", "r") as f:
        group = next(g for g in f["probes"].values() if g.attrs["name"] == "ff_5m")
        vz = group["velocity"][()][:, 2]
    assert ff["ff_5m"]["ppv_vertical"] == pytest.approx(np.abs(vz).max(), rel=1e-12)
    assert ff["ff_5m"]["distance"] == 5.0 and ff["opp_6m"]["side"] == "away"
    assert "free_field" in json.loads((tmp_path / "report.json").read_text())
    assert doc["results"]["ff_5m"]["standards"]           # assessed like every probe
