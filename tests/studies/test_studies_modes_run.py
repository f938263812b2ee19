"""A tiny modal truncation study on 2 ranks: one shared modal solve, MBS per variant."""

from __future__ import annotations

import json
import os

import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD


@pytest.mark.slow
@pytest.mark.mpi
def test_modes_study_shares_the_modes_and_resumes(shared_tmp, capsys):
    args = ["study", "modes", str(BASELINE), *TINY, "--out", str(shared_tmp),
            "--study-set", "n_modes=[4, 8]", "--study-set", "tolerance=5"]
    assert run(args) == 0
    first = capsys.readouterr().out
    assert run(args) == 0
    second = capsys.readouterr().out
    if comm.rank == 0:
        root = shared_tmp / "modes"
        assert "VERDICT: modes needed to stay within 5 % of the reference (n8_corrected)" \
            in first
        assert second.count("finished earlier: skipping") == 4
        for name in ("n4_modal", "n4_corrected", "n8_modal", "n8_corrected"):
            link = root / name / "modes.h5"
            assert link.is_symlink() and os.readlink(link) == "../model/modes.h5"
            assert (root / name / "static.h5").is_symlink()
        assert first.count("eigensolve] done") == 1          # one modal solve only
        report = json.loads((root / "report.json").read_text())
        rows = {r["variant"]: r for r in report["analysis"]["rows"]}
        assert rows["n8_corrected"]["max_deviation"] == 0.0
        assert rows["n4_modal"]["max_deviation"] > 0.0
        # the static correction restores the rail's static flexibility
        d_plain = rows["n8_modal"]["quantities"]["max rail deflection"]
        d_corr = rows["n8_corrected"]["quantities"]["max rail deflection"]
        assert d_corr > 3 * d_plain
        assert set(report["analysis"]["modes_needed"]) == {"modal", "corrected"}
        assert (root / "figures" / "modes.png").exists()
        res = json.loads((root / "n4_modal" / "result.json").read_text())
        assert res["model"]["modes_used"] == 4 and res["model"]["modes_in_file"] == 8
    comm.Barrier()


@pytest.mark.slow
@pytest.mark.mpi
def test_modes_study_with_the_full_damping_matrix(shared_tmp, capsys):
    """modal.damping = 'full' (absorbing faces): every variant reads the shared
    modal_damping.h5, with and without the residual modes."""
    out = shared_tmp / "full"
    args = ["study", "modes", str(BASELINE), *TINY, "--out", str(out),
            "--set", "modal.damping=full", "--set", "boundary.base=absorbing",
            "--set", "boundary.virtual_thickness=20", "--study-set", "n_modes=[4, 8]"]
    assert run(args) == 0
    text = capsys.readouterr().out
    if comm.rank == 0:
        assert "modes study: 4 of 4 variants finished" in text
        for name in ("n4_modal", "n4_corrected", "n8_modal", "n8_corrected"):
            link = out / "modes" / name / "modal_damping.h5"
            assert link.is_symlink() and os.readlink(link) == "../model/modal_damping.h5"
    comm.Barrier()
