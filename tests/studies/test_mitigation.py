"""The mitigation study: measures parsed, variants planned (same-mesh references), insertion
losses and the ranking from known responses."""

from __future__ import annotations

import math

import pytest

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.studies import study_settings
from railvib_hpc.studies.mitigation import (
    BASELINE,
    analyse,
    band_insertion_loss,
    insertion_loss_db,
    parse_measure,
    plan,
    reference_overrides,
)
from railvib_hpc.studies.runner import make_plan

PROBES = ["footing", "slab1"]
BANDS = [4.0, 8.0, 16.0, 31.5]


def result(scale: float, utilisation: float) -> dict:
    """A variant result whose accelerations are ``scale`` times the baseline's."""
    spec = {"bands_hz": BANDS, "acc_rms": {c: [scale * 1e-3 * (k + 1) for k in range(4)]
                                           for c in ("x", "y", "z", "total")}}
    return {"probes": {p: {"acc_vertical": scale * 0.01, "acc_total": scale * 0.02}
                       for p in PROBES},
            "mbs": {"peak_contact_force": 9000.0},
            "assessment": {p: {"passed": utilisation <= 1.0, "max_utilisation": utilisation,
                               "utilisation": {"din4150_2": utilisation}} for p in PROBES},
            "spectra": {p: spec for p in PROBES}, "timings": {"total": 1.0}}


def test_measures_parse_and_bad_ones_get_one_line():
    assert parse_measure("soft: pads.kz=1e8; pads.ky=2e8") == ("soft", ("pads.kz=1e8",
                                                                         "pads.ky=2e8"))
    for bad, words in (("soft pads.kz=1e8", "must look like 'name: key=value"),
                       ("baseline: pads.kz=1e8", "not 'baseline'"),
                       ("soft:", "sets no key"), ("soft: pads.kz", "is not key=value")):
        with pytest.raises(CaseError) as info:
            parse_measure(bad)
        assert str(info.value).count("\n") == 0 and words in str(info.value)
        assert "study.mitigation.measures" in str(info.value)


def test_geometric_measures_get_a_reference_on_their_own_mesh():
    ov = ("trench.type=open", "trench.distance=6.0", "trench.width=0.6", "trench.depth=3.0")
    assert reference_overrides(ov) == ("trench.distance=6.0", "trench.width=0.6",
                                       "trench.depth=3.0", "trench.type=none")
    assert reference_overrides(("pads.kz=1e8",)) is None
    settings = study_settings("mitigation")
    p = plan(Case.defaults(), settings)
    names = [v.name for v in p.variants]
    assert names == [BASELINE, "soft_pads", "ref-open_trench", "open_trench", "filled_trench",
                     "ref-wib", "wib"]
    by = {v.name: v for v in p.variants}
    assert by["soft_pads"].parameter["reference"] == BASELINE
    # open and filled trench have the same geometry: one shared reference
    assert by["filled_trench"].parameter["reference"] == "ref-open_trench"
    without = plan(Case.defaults(), {**settings, "same_mesh": False})
    assert all(v.parameter["reference"] in (None, BASELINE) for v in without.variants)


def test_every_default_variant_is_a_valid_case():
    p = make_plan("mitigation", Case.defaults(), study_settings("mitigation"))
    assert len(p.variants) == 7


def test_a_measure_with_a_bad_key_is_refused_before_anything_runs():
    settings = study_settings("mitigation", ["measures=['deep: trench.type=open; "
                                             "trench.distance=6; trench.width=0.6; "
                                             "trench.depth=9']"])
    with pytest.raises(CaseError, match=r"trench\.depth = 9"):
        make_plan("mitigation", Case.defaults(), settings)


def test_insertion_loss_and_ranking():
    assert insertion_loss_db(2.0, 1.0) == pytest.approx(20 * math.log10(2))
    assert insertion_loss_db(1.0, 0.0) is None
    half = band_insertion_loss(result(1.0, 1.0)["spectra"]["slab1"],
                               result(0.5, 1.0)["spectra"]["slab1"])
    assert list(half) == BANDS and all(x == pytest.approx(6.0206, abs=1e-4)
                                       for x in half.values())
    settings = {**study_settings("mitigation"), "probes": PROBES,
                "measures": ["good: pads.kz=1e8", "better: pads.kz=5e7", "worse: pads.kz=1e10"]}
    p = plan(Case.defaults(), settings)
    results = {BASELINE: result(1.0, 1.4), "good": result(0.8, 1.12),
               "better": result(0.5, 0.7), "worse": result(1.25, 1.75)}
    out = analyse(p, results, settings)
    assert [d["measure"] for d in out["rows"]] == ["better", "good", "worse"]
    best = out["rows"][0]
    assert best["mean_il_total_db"] == pytest.approx(6.0206, abs=1e-4)
    assert out["rows"][2]["mean_il_total_db"] == pytest.approx(-1.9382, abs=1e-4)
    assert best["utilisation_before"] == 1.4 and best["utilisation_after"] == 0.7
    assert out["verdict"]["passing"] == ["better"] and out["verdict"]["best"] == "better"
    assert "the baseline FAILS" in out["verdict"]["text"]
    assert out["tables"][0]["rows"][0][:2] == ["1", "better"]
