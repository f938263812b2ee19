"""A tiny thesis-comparison study on 2 ranks: count vs band, with and without the drop."""

from __future__ import annotations

import json

import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD


@pytest.mark.slow
@pytest.mark.mpi
def test_thesis_study_count_band_and_drop(shared_tmp, capsys):
    # modal.n_modes >= 10: SLEPc's spectrum slicing (modal.f_max) refuses nev < 10
    args = ["study", "thesis", str(BASELINE), *TINY, "--set", "modal.n_modes=12",
            "--out", str(shared_tmp),
            "--study-set", "band_hz=16", "--study-set", "n_modes=4",
            "--study-set", "drop_heights=[0, 1e-4]"]
    assert run(args) == 0
    out = capsys.readouterr().out
    if comm.rank == 0:
        root = shared_tmp / "thesis"
        assert "VERDICT: The first 4 modes" in out and "The 16 Hz band" in out
        report = json.loads((root / "report.json").read_text())
        rows = {r["variant"]: r for r in report["analysis"]["rows"]}
        assert set(rows) == {"n4_drop0mm", "n4_drop0.1mm", "band_drop0mm", "band_drop0.1mm"}
        assert rows["n4_drop0mm"]["modes_used"] == 4
        band = rows["band_drop0mm"]
        assert band["modes_used"] > 4 and band["f_top_hz"] <= 16.0
        # the drop: a Hertz impact of 45-55 kN (the energy solution on a rigid rail gives
        # 47.7 kN for 0.1 mm; dt = auto), against 7.69 kN static without it
        assert rows["n4_drop0mm"]["peak_contact_force"] == pytest.approx(7691, rel=0.02)
        assert 40e3 < rows["band_drop0.1mm"]["peak_contact_force"] < 56e3
        # every variant shares one modal solve
        res = json.loads((root / "band_drop0.1mm" / "result.json").read_text())
        assert res["reused"]["modes"] is True
        assert (root / "figures" / "thesis_comparison.png").exists()
    comm.Barrier()
