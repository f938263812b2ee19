"""A tiny mesh convergence study on 2 ranks: table, Richardson, verdict, resume."""

from __future__ import annotations

import json

import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD


@pytest.mark.slow
@pytest.mark.mpi
def test_convergence_study_reports_and_resumes(shared_tmp, capsys):
    args = ["study", "convergence", str(BASELINE), *TINY, "--out", str(shared_tmp),
            "--study-set", "levels=[0.25, 0.35, 0.5]", "--study-set", "n_frequencies=3"]
    assert run(args) == 0
    first = capsys.readouterr().out
    assert run(args) == 0                     # second run: every level is skipped
    second = capsys.readouterr().out
    if comm.rank == 0:
        root = shared_tmp / "convergence"
        assert "VERDICT: converged within" in first or "VERDICT: NOT converged" in first
        assert "Richardson" in first and "r0.35→r0.5" in first
        assert second.count("finished earlier: skipping") == 3
        assert "[modal" not in second and "eigensolve" not in second
        report = json.loads((root / "report.json").read_text())
        assert report["complete"] and [v["status"] for v in report["variants"]] == \
            ["finished"] * 3
        levels = report["analysis"]["levels"]
        assert [lv["refinement"] for lv in levels] == [0.25, 0.35, 0.5]
        assert levels[0]["n_dofs"] < levels[1]["n_dofs"] < levels[2]["n_dofs"]
        q = levels[-1]["quantities"]
        assert set(q) >= {"f1 [Hz]", "f3 [Hz]", "slab1 a_z", "slab2 |a|",
                          "basement_wall |a|", "footing a_z", "peak contact force"}
        rich = report["analysis"]["richardson"]
        assert rich["f3 [Hz]"]["basis"] in ("observed", "unreliable")
        v = report["verdict"]
        assert v["error"] == pytest.approx(max(e["error"] for e in rich.values()))
        assert v["text"] in first
        md = (root / "report.md").read_text()
        assert "## Quantities per level" in md and "figures/convergence.png" in md
        assert (root / "figures" / "convergence.png").stat().st_size > 10_000
        res = json.loads((root / "r0.5" / "result.json").read_text())
        assert res["complete"] and res["model"]["modes_in_file"] == 8
        assert res["ranks"] == comm.size and (root / "r0.5" / "probes.h5").exists()
        assert not (root / "r0.5" / "fields.h5").exists()     # no full reconstruction
    comm.Barrier()
