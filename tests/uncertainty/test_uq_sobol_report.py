"""Sobol' indices are reported only when they are estimates: a Saltelli design of at least
:data:`~railvib_hpc.uncertainty.statistics.MIN_SOBOL_BASE_SAMPLES` base points, every index
in [0, 1] within its bootstrap interval. The red team's two-parameter design of 2 base
points gave 15 of 16 (S1, ST) pairs outside [0, 1] (speed S1 = 1.411 ± 0.210, ST = 2.090 ±
0.158, pads.kz S1 = -0.171 ± 0.082) as precise values, with no warning. The analysis runs
here on synthetic sample results (no model is solved)."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.config import Case
from railvib_hpc.studies.settings import study_settings
from railvib_hpc.studies.uncertainty import analyse, plan
from railvib_hpc.uncertainty.statistics import MIN_SOBOL_BASE_SAMPLES, sobol_doubts

#: The red team's parameters: pad stiffness lognormal (cov 0.5), speed uniform 20-40 m/s.
PARAMS = [{"key": "pads.kz", "distribution": "lognormal", "cov": 0.5},
          {"key": "vehicle.speed", "distribution": "uniform", "low": 20.0, "high": 40.0}]
PROBES = ["footing", "slab1"]


def _analysis(samples: int) -> dict:
    """The study's analysis of a Saltelli design whose outputs are a smooth function of the
    inputs: mostly the speed, a little the pads."""
    case = Case.defaults().replace({"uncertainty.parameter": PARAMS,
                                    "uncertainty.method": "sobol",
                                    "uncertainty.samples": samples})
    settings = study_settings("uncertainty", case=case) | {"probes": PROBES}
    p = plan(case, settings)
    results = {}
    for v in p.variants:
        kz, speed = v.parameter["pads.kz"], v.parameter["vehicle.speed"]
        peak = 1e-3 * speed + 1e-14 * kz
        results[v.name] = {
            "probes": {q: {"acc_total": peak} for q in PROBES},
            "assessment": {q: {"max_utilisation": 10 * peak, "metrics": {"din4150-3": {
                "metric": "PPV", "unit": "mm/s", "value": 100 * peak, "utilisation":
                10 * peak, "limit": 5.0, "comparison_only": False}}} for q in PROBES},
            "spectra": {}}
    return analyse(p, results, settings)


def test_the_red_teams_indices_are_doubted():
    red = {"vehicle.speed": {"S1": 1.411, "S1_conf": 0.210, "ST": 2.090, "ST_conf": 0.158},
           "pads.kz": {"S1": -0.171, "S1_conf": 0.082, "ST": 0.05, "ST_conf": 0.1}}
    doubts = sobol_doubts(red, 2)
    assert doubts[0].startswith("the design has N = 2 base points, fewer than 64")
    assert "vehicle.speed S1 = 1.411 ± 0.210 lies outside [0, 1]" in doubts[1]
    assert any("pads.kz S1 = -0.171 ± 0.082" in d for d in doubts)
    # inside [0, 1] within the interval, with enough base points: an estimate
    fine = {"x": {"S1": -0.02, "S1_conf": 0.03, "ST": 1.02, "ST_conf": 0.05}}
    assert sobol_doubts(fine, MIN_SOBOL_BASE_SAMPLES) == []
    assert sobol_doubts({"x": {"S1": np.nan, "S1_conf": 0.1, "ST": 0.5, "ST_conf": 0.1}},
                        128)


def test_a_two_point_design_leaves_the_indices_out_and_warns():
    a = _analysis(2)
    titles = [t["title"] for t in a["tables"]]
    assert not any(t.startswith("Sobol' indices of") for t in titles), titles
    left = next(t for t in a["tables"] if t["title"] == "Sobol' indices left out")
    assert {(r[0], r[1]) for r in left["rows"]} == {(p, q) for p in PROBES
                                                    for q in ("peak |a|", "max utilisation")}
    assert all("N = 2 base points" in r[2] for r in left["rows"])
    assert len(a["warnings"]) == 1 and "left out of the report for 4 of 4 outputs" \
        in a["warnings"][0]
    assert "driven by" not in a["verdict"]["text"]
    assert a["sobol"]["slab1"]["peak |a|"]          # the raw numbers stay in report.json


@pytest.mark.parametrize("samples", [MIN_SOBOL_BASE_SAMPLES])
def test_a_large_enough_design_reports_the_indices(samples):
    a = _analysis(samples)
    table = next(t for t in a["tables"] if t["title"] == "Sobol' indices of slab1 peak |a|")
    assert table["rows"][0][1] == "vehicle.speed"              # ranked first by ST
    assert a["warnings"] == [] and "driven by vehicle.speed (footing)" in a["verdict"]["text"]
    idx = a["sobol"]["slab1"]["peak |a|"]["vehicle.speed"]
    assert idx["ST"] == pytest.approx(1.0, abs=0.05)
