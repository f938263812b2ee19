"""A tiny speed sweep on 2 ranks, run like a batch array: prepare, variants, merge;
a failing variant is recorded and reported."""

from __future__ import annotations

import json

import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run
from railvib_hpc.errors import UserError

comm = MPI.COMM_WORLD


@pytest.mark.mpi
def test_speed_study_as_array_jobs_then_merge(shared_tmp, capsys, monkeypatch):
    base = ["study", "speed", str(BASELINE), *TINY, "--out", str(shared_tmp),
            "--study-set", "speeds=[20, 60]"]
    assert run([*base, "--prepare"]) == 0                      # the shared modes
    assert run([*base, "--variant", "0"]) == 0                 # array task 0
    assert run([*base, "--variant", "v60"]) == 0               # array task 1
    runs = capsys.readouterr().out
    assert run([*base, "--list"]) == 0
    listing = capsys.readouterr().out
    assert run([*base, "--merge"]) == 0
    merged = capsys.readouterr().out
    root = shared_tmp / "speed"
    if comm.rank == 0:
        assert "VERDICT" not in runs                             # variants only: no report
        assert runs.count("eigensolve] done") == 1
        assert listing.count("finished") == 2
        assert "VERDICT: largest building acceleration at" in merged
        report = json.loads((root / "report.json").read_text())
        assert report["complete"]
        rows = report["analysis"]["rows"]
        assert [r["speed"] for r in rows] == [20.0, 60.0]
        assert rows[1]["duration"] < rows[0]["duration"]        # faster: shorter passage
        assert all(r["passed"] is not None for r in rows)
    comm.Barrier()

    # a variant whose MBS fails: failed.json, exit code 2, listed in the report
    def broken(*args, **kwargs):
        raise UserError("simulated failure")

    monkeypatch.setattr("railvib_hpc.mbs.stage.simulate_case", broken)
    more = [*base[:-1], "speeds=[20, 40, 60]"]
    assert run(more) == 2
    out = capsys.readouterr().out
    if comm.rank == 0:
        assert "[speed/v40] FAILED: simulated failure" in out
        assert out.count("finished earlier: skipping") == 2
        assert "2 of 3 variants finished" in out
        assert json.loads((root / "v40" / "failed.json").read_text())["error"] == \
            "simulated failure"
        report = json.loads((root / "report.json").read_text())
        assert not report["complete"]
        assert [v["status"] for v in report["variants"]] == ["finished", "failed",
                                                              "finished"]
    comm.Barrier()
