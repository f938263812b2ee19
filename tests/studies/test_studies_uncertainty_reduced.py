"""The uncertainty study with the parametric reduced model on the coarse thesis model:
reduced samples against their full reference solves (frequencies and response peaks
within the residual), the fallback to full solves, a random field judged by its residual,
and the same reduced results on 1 and 2 ranks."""

from __future__ import annotations

import json

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
FIELD = ('uncertainty.field=[{layer=1, quantity="E", model="exponential", cov=0.5, '
         'len_h=4.0, len_v=1.0}]')


def _args(out, *more):
    return ["study", "uncertainty", str(BASELINE), *TINY, *SHORT, "--set", LAYERS,
            "--set", PARAMS, "--set", "uncertainty.model=reduced", "--set",
            "uncertainty.samples=4", "--out", str(out), *more]


def _report(out):
    return json.loads((out / "uncertainty" / "report.json").read_text())["analysis"]


@pytest.mark.slow
def test_reduced_samples_against_full_solves_and_the_fallback(tmp_path):
    out = tmp_path / "accept"
    assert run(_args(out, "--set", "uncertainty.reduced_tol=1", "--set",
                     "uncertainty.reduced_checks=2")) == 0
    rom = _report(out)["reduced"]
    assert rom["accepted"] == 4 and not rom["fallback"] and len(rom["references"]) == 2
    for name, ref in rom["references"].items():
        e, res = ref["errors"], ref["max_residual"]
        assert ref["reduced_used"]
        # a Ritz frequency's error is second order: far below the residual
        assert 0 <= e["frequency"] <= res ** 2
        for p in ("footing", "slab1", "slab2"):       # peaks within the residual
            assert e[f"{p} peak |a|"] <= res, (name, p, e[f"{p} peak |a|"], res)
    # the same design with a tolerance below every residual: all solved in full
    out2 = tmp_path / "strict"
    assert run(_args(out2, "--set", "uncertainty.reduced_tol=1e-4", "--set",
                     "uncertainty.reduced_checks=0")) == 0
    strict = _report(out2)["reduced"]
    assert strict["accepted"] == 0 and len(strict["fallback"]) == 4
    assert all("> uncertainty.reduced_tol = 0.0001" in f["reason"] for f in strict["fallback"])
    text = (out2 / "uncertainty" / "report.md").read_text()
    assert "Reduced model: error control" in text


@pytest.mark.slow
def test_a_random_field_is_judged_by_its_residual(tmp_path):
    assert run(_args(tmp_path, "--set", FIELD, "--set", "uncertainty.reduced_checks=0")) == 0
    root = tmp_path / "uncertainty"
    tol = 3e-2
    for k in range(4):
        red = json.loads((root / f"s{k:04d}" / "result.json").read_text())["model"]["modal"][
            "reduced"]
        assert red["projection"] == "galerkin"
        if red["used"]:
            assert red["max_residual"] <= tol
        else:
            assert "random field is not represented" in red["reason"]


def _one_check():
    """The case of the 1-and-2-rank comparison: one full-solve check."""
    args = _args("unused", "--set", "uncertainty.reduced_tol=1", "--set",
                 "uncertainty.reduced_checks=1")
    return load_case(BASELINE, [args[i + 1] for i, a in enumerate(args) if a == "--set"])


def _serial_study(folder) -> None:
    """A builder of ``serial_refs`` (tests/conftest.py): the study alone on
    ``MPI.COMM_SELF``."""
    execute_study("uncertainty", _one_check(), folder, MPI.COMM_SELF, Reporter(0))


#: The serial study the 2-rank test compares with (tests/conftest.py: ``serial_refs``,
#: computed side by side with the other modules' references): seconds on one rank, builder.
SERIAL_REFERENCES = {"uncertainty_reduced_one_check": (35.0, _serial_study)}


@pytest.mark.slow
@pytest.mark.mpi
def test_same_reduced_model_on_one_and_two_ranks(shared_tmp, serial_refs):
    """The reduced study on ``comm.size`` ranks and alone on ``MPI.COMM_SELF``
    (``serial_refs``): the same reduced model and samples."""
    execute_study("uncertainty", _one_check(), shared_tmp / "parallel", comm,
                  Reporter(comm.rank))
    if comm.rank == 0:
        for k in range(4):
            one, two = (json.loads((d / "uncertainty" / f"s{k:04d}" /
                                    "result.json").read_text())
                        for d in (serial_refs["uncertainty_reduced_one_check"],
                                  shared_tmp / "parallel"))
            assert two["ranks"] == 2
            r1, r2 = one["model"]["modal"]["reduced"], two["model"]["modal"]["reduced"]
            assert r1["used"] and r2["used"]
            assert r1["frequencies_hz"] == pytest.approx(r2["frequencies_hz"], rel=1e-8)
            assert r1["max_residual"] == pytest.approx(r2["max_residual"], rel=1e-4)
            assert one["probes"]["slab1"]["acc_total"] == pytest.approx(
                two["probes"]["slab1"]["acc_total"], rel=1e-5)
    comm.Barrier()
