"""The uncertainty study end to end on the coarse thesis model: a Saltelli design with a
random field, run as array tasks, resumed and merged; the statistics against the samples'
own results; the same statistics on 1 and 2 ranks for the same seeds."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from studies_tiny import BASELINE, TINY

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.log import Reporter
from railvib_hpc.studies.runner import execute_study

comm = MPI.COMM_WORLD
SHORT = ["--set", "vehicle.x_start=2.7", "--set", "vehicle.x_end=4.2", "--set",
         "vehicle.t_after=0.5", "--set", "output.dt=0.002"]
LAYERS = ('soil.layers=[{thickness = 1.5, c_s = 150.0, nu = 0.3, rho = 1800.0}, '
          '{thickness = 0.0, c_s = 250.0, nu = 0.3, rho = 1900.0}]')
PARAMS = ('uncertainty.parameter=[{key="soil.layers[1].c_s", distribution="lognormal", '
          'cov=0.25}, {key="pads.kz", distribution="uniform", low=3e9, high=1e10}]')
FIELD = ('uncertainty.field=[{layer=2, quantity="E", model="exponential", cov=0.2, '
         'len_h=4.0, len_v=1.0}]')


def _args(out, *more):
    return ["study", "uncertainty", str(BASELINE), *TINY, *SHORT, "--set", LAYERS,
            "--set", PARAMS, "--out", str(out), *more]


@pytest.mark.slow
def test_sobol_study_as_array_tasks_then_merge(tmp_path, capsys):
    base = _args(tmp_path, "--set", FIELD, "--set", "uncertainty.method=sobol",
                 "--set", "uncertainty.samples=2")
    assert run([*base, "--variant", "0"]) == 0                 # array task 0: no report
    first = capsys.readouterr().out
    assert "VERDICT" not in first
    assert run(base) == 0                                      # the rest, then the report
    out = capsys.readouterr().out
    assert out.count("finished earlier: skipping") == 1
    assert "[uncertainty] 8 of 8 samples: footing: P95 utilisation" in out
    assert "WARNING: the random field of soil_layer_2.E has a vertical correlation " \
           "length of 1 m" in out                          # the coarse mesh's elements
    root = tmp_path / "uncertainty"
    report = json.loads((root / "report.json").read_text())
    a = report["analysis"]
    assert report["complete"] and a["method"] == "sobol"
    assert a["parameters"] == ["soil.layers[1].c_s", "pads.kz"]
    # the statistics are those of the samples' own results (A and B rows: 0, 3, 4, 7)
    res = [json.loads((root / f"s{k:04d}" / "result.json").read_text()) for k in range(8)]
    din = [r["assessment"]["slab1"]["metrics"]["din4150-3"] for r in res]
    row = next(r for r in a["rows"] if r["probe"] == "slab1" and r["standard"] == "din4150-3")
    ab = [din[k]["value"] for k in (0, 3, 4, 7)]
    assert row["P50"]["value"] == pytest.approx(np.percentile(ab, 50))
    assert row["exceedance"]["k"] == sum(d["utilisation"] > 1 for k, d in enumerate(din)
                                         if k in (0, 3, 4, 7))
    # a softer top layer gives other modes: the samples differ
    assert len({r["model"]["frequencies_hz"][0] for r in res}) == 8
    sob = a["sobol"]["slab1"]["peak |a|"]
    assert set(sob) == {"soil.layers[1].c_s", "pads.kz"}
    assert all(np.isfinite(v["ST"]) for v in sob.values())
    # 2 base points: no estimates; the report leaves them out and says why (the raw
    # numbers above stay in report.json)
    md = (root / "report.md").read_text()
    assert "Sobol' indices of slab1 peak |a|" not in md and "Sobol' indices left out" in md
    assert "WARNING: Sobol' indices left out of the report" in out
    assert a["sobol_base_points"] == 2 and a["sobol_doubts"]["slab1"]["peak |a|"]
    bands = a["bands"]["slab1"]                  # the percentile bands of the spectra
    assert bands["bands_hz"] and np.all(np.diff([bands[q] for q in ("P5", "P50", "P95")],
                                                axis=0) >= 0)
    assert (root / "figures" / "uncertainty_bands.png").exists()
    with h5py.File(root / "uncertainty.h5") as f:
        assert f["design"].shape == (8, 2)
        assert np.allclose(f["slab1/peak_abs_a"][()],
                           [r["probes"]["slab1"]["acc_total"] for r in res])
    assert run([*base, "--merge"]) == 0                         # nothing recomputed
    assert "finished earlier" not in capsys.readouterr().out


def _three_samples():
    """The case of the 1-and-2-rank comparison: three samples."""
    args = _args("unused", "--set", "uncertainty.samples=3")
    return load_case(BASELINE, [args[i + 1] for i, a in enumerate(args) if a == "--set"])


def _serial_study(folder) -> None:
    """A builder of ``serial_refs`` (tests/conftest.py): the study alone on
    ``MPI.COMM_SELF``."""
    execute_study("uncertainty", _three_samples(), folder, MPI.COMM_SELF, Reporter(0))


#: The serial study the 2-rank test compares with (tests/conftest.py: ``serial_refs``,
#: computed side by side with the other modules' references): seconds on one rank, builder.
SERIAL_REFERENCES = {"uncertainty_three_samples": (39.0, _serial_study)}


@pytest.mark.slow
@pytest.mark.mpi
def test_same_statistics_on_one_and_two_ranks(shared_tmp, serial_refs):
    """The study on ``comm.size`` ranks and alone on ``MPI.COMM_SELF`` (``serial_refs``):
    the same design and statistics."""
    execute_study("uncertainty", _three_samples(), shared_tmp / "parallel", comm,
                  Reporter(comm.rank))
    if comm.rank == 0:
        one, two = (json.loads((d / "uncertainty" / "report.json").read_text())
                    for d in (serial_refs["uncertainty_three_samples"],
                              shared_tmp / "parallel"))
        assert one["analysis"]["design"] == two["analysis"]["design"]
        for r1, r2 in zip(one["analysis"]["rows"], two["analysis"]["rows"]):
            assert (r1["probe"], r1["standard"]) == (r2["probe"], r2["standard"])
            for q in ("P5", "P50", "P95"):
                assert r1[q]["value"] == pytest.approx(r2[q]["value"], rel=1e-5, abs=1e-12)
            assert r1["exceedance"] == r2["exceedance"]
        ranks = {json.loads((shared_tmp / "parallel" / "uncertainty" / "s0000" /
                             "result.json").read_text())["ranks"]}
        assert ranks == {2}
    comm.Barrier()
