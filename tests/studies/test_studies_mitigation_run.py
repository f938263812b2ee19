"""A tiny mitigation study on 2 ranks: baseline, soft pads, an open trench with its same-mesh
reference; the report ranks the measures and the rerun reuses every variant."""

from __future__ import annotations

import json
import math

import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD


@pytest.mark.slow
@pytest.mark.mpi
def test_mitigation_study_ranks_the_measures(shared_tmp, capsys):
    measures = ("measures=['soft: pads.kz=1.2e8', 'trench: trench.type=open; "
                "trench.distance=6.0; trench.width=1.2; trench.depth=3.0']")
    base = ["study", "mitigation", str(BASELINE), *TINY, "--out", str(shared_tmp),
            "--study-set", measures]
    assert run(base) == 0
    out = capsys.readouterr().out
    assert run(base) == 0                                   # rerun: every variant reused
    again = capsys.readouterr().out
    if comm.rank == 0:
        assert "VERDICT: best measure:" in out
        report = json.loads((shared_tmp / "mitigation" / "report.json").read_text())
        assert report["complete"]
        rows = {r["measure"]: r for r in report["analysis"]["rows"]}
        assert set(rows) == {"soft", "trench"}
        assert rows["soft"]["reference"] == "baseline"
        assert rows["trench"]["reference"] == "ref-trench"
        assert sorted(r["rank"] for r in rows.values()) == [1, 2]
        for r in rows.values():
            assert all(math.isfinite(x) for x in r["il_peak_db"].values())
            assert r["utilisation_after"] is not None
        assert (shared_tmp / "mitigation" / "figures" / "mitigation_insertion_loss.png").exists()
        assert again.count("finished earlier: skipping") == 4
    comm.Barrier()
