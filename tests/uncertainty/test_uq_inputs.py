"""Bad [uncertainty] input: one line naming the key, the value and what is allowed, exit
code 2; the samples of a study as case overrides."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.studies.common import variant_case
from railvib_hpc.studies.runner import make_plan
from railvib_hpc.studies.settings import study_settings
from railvib_hpc.studies.uncertainty import design, sample_overrides
from railvib_hpc.uncertain_inputs import marginals

LAYERS = [{"thickness": 2.0, "c_s": 150.0, "nu": 0.3, "rho": 1800.0},
          {"thickness": 0.0, "E": 3.0e8, "nu": 0.3, "rho": 1900.0}]


def _case(params=(), **more) -> Case:
    return Case.defaults().replace({"soil.layers": LAYERS,
                                    "uncertainty.parameter": list(params), **more})


def _refused(params=(), **more) -> str:
    with pytest.raises(CaseError) as exc:
        _case(params, **more)
    assert len(exc.value.problems) == 1
    return str(exc.value)


@pytest.mark.parametrize("key, hint", [
    ("pads.kzz", "did you mean 'pads.kz'?"),
    ("soil.layers[3].c_s", "the case gives 2 soil layer(s)"),
    ("soil.layers[2].c_s", "it gives: thickness, E, nu, rho, damping_ratio"),
    ("soil.layers[1].c_ss", "did you mean 'soil.layers[1].c_s'?"),
    ("modal.n_modes", "not a real-number key"),
])
def test_unknown_or_non_numeric_keys_are_refused(key, hint):
    msg = _refused([{"key": key, "distribution": "normal", "cov": 0.1}])
    assert f"uncertainty.parameter[1].key = '{key}'" in msg and hint in msg


@pytest.mark.parametrize("entry, needle", [
    ({"key": "pads.kz", "distribution": "lognormal", "cov": 0.0},
     "uncertainty.parameter[1].cov = 0.0: must be > 0"),
    ({"key": "pads.kz", "distribution": "normal", "cov": -0.1},
     "uncertainty.parameter[1].cov = -0.1: must be > 0"),
    ({"key": "building.rotation", "distribution": "normal", "cov": 0.1},
     "uncertainty.parameter[1].cov = 0.1: gives std = cov x mean = 0: the mean is 0"),
])
def test_a_zero_cov_names_cov(entry, needle):
    """The red team: ``cov = 0`` was refused as '...std = 0.0: must be > 0', naming a key
    the user did not give."""
    msg = _refused([entry])
    assert needle in msg and ".std" not in msg, msg


@pytest.mark.parametrize("entry, probability", [
    ({"key": "materials.subgrade.nu", "distribution": "normal", "std": 0.1}, "0.0241"),
    ({"key": "materials.subgrade.E", "distribution": "normal", "cov": 0.3}, "0.000429"),
    ({"key": "soil.layers[1].thickness", "distribution": "uniform", "low": 0.0,
      "high": 4.0}, "0.025"),
])
def test_distributions_outside_the_physical_range_are_refused_with_the_probability(
        entry, probability):
    msg = _refused([entry])
    assert f"puts probability {probability} outside the physical range" in msg


def test_physical_distributions_pass():
    c = _case([{"key": "materials.subgrade.nu", "distribution": "truncated_normal",
                "std": 0.1, "low": 0.1, "high": 0.45},
               {"key": "soil.layers[1].c_s", "distribution": "lognormal", "cov": 0.3},
               {"key": "soil.layers[2].E", "distribution": "lognormal", "cov": 0.5}])
    assert [m.params["mean"] for m in marginals(c)] == [0.2, 150.0, 3.0e8]


@pytest.mark.parametrize("more, text", [
    ({"uncertainty.correlation": [[1.0, 0.9, 0.9], [0.9, 1.0, -0.9], [0.9, -0.9, 1.0]]},
     "not positive definite (smallest eigenvalue"),
    ({"uncertainty.correlation": [[1.0, 0.5], [0.5, 1.0]]}, "must be 3 x 3"),
    ({"uncertainty.method": "sobol", "uncertainty.samples": 12},
     "needs a power of 2 (e.g. 16)"),
    ({"uncertainty.field": [{"layer": 4, "quantity": "E", "model": "gaussian", "cov": 0.2,
                             "len_h": 5.0, "len_v": 1.0}]}, "the case gives 2 soil layer(s)"),
    ({"uncertainty.field": [{"layer": 1, "quantity": "G", "model": "gaussian", "cov": 0.2,
                             "len_h": 5.0, "len_v": 1.0}]}, "allowed: E, rho"),
])
def test_bad_correlations_and_fields_are_refused(more, text):
    params = [{"key": k, "distribution": "lognormal", "cov": 0.2}
              for k in ("pads.kz", "materials.subgrade.E", "soil.layers[1].rho")]
    assert text in _refused(params, **more)


def test_sobol_needs_a_parameter():
    field = {"layer": 1, "quantity": "E", "model": "gaussian", "cov": 0.2, "len_h": 5.0,
             "len_v": 1.0}
    assert "Sobol' indices need at least one [[uncertainty.parameter]]" in _refused(
        **{"uncertainty.method": "sobol", "uncertainty.samples": 4,
           "uncertainty.field": [field]})


def test_the_command_line_exits_2_with_one_line(capsys, tmp_path):
    args = ["study", "uncertainty", "jobs/thesis_baseline.toml", "--list", "--out",
            str(tmp_path), "--set", 'uncertainty.parameter=[{key="pads.kzz",'
            'distribution="normal",cov=0.1}]']
    assert run(args) == 2
    err = capsys.readouterr()
    lines = [x for x in (err.out + err.err).splitlines() if "pads.kzz" in x]
    assert len(lines) == 1 and "did you mean 'pads.kz'?" in lines[0]
    assert "Traceback" not in err.err


def test_samples_become_variant_overrides():
    c = _case([{"key": "soil.layers[1].c_s", "distribution": "lognormal", "cov": 0.2},
               {"key": "pads.kz", "distribution": "uniform", "low": 3e9, "high": 9e9},
               {"key": "soil.layers[2].E", "distribution": "lognormal", "cov": 0.2}],
              **{"uncertainty.samples": 6, "uncertainty.field": [
                  {"layer": 2, "quantity": "E", "model": "matern", "cov": 0.2,
                   "len_h": 5.0, "len_v": 1.0}]})
    found, values = design(c)
    assert values.shape == (6, 3)
    ov = sample_overrides(c, [m.key for m in found], values[0])
    v = variant_case(c, ov)
    assert v["pads.kz"] == pytest.approx(values[0, 1])
    assert v["soil.layers"][0]["c_s"] == pytest.approx(values[0, 0])
    assert v["soil.layers"][1]["E"] == pytest.approx(values[0, 2])
    assert v["soil.layers"][1]["rho"] == LAYERS[1]["rho"]
    plan = make_plan("uncertainty", c, study_settings("uncertainty", case=c))
    assert [p.name for p in plan.variants] == [f"s{k:04d}" for k in range(6)]
    assert plan.variants[2].overrides[-1] == "uncertainty.realisation=3"
    again = make_plan("uncertainty", c, study_settings("uncertainty", case=c))
    assert again.variants == plan.variants                     # seeded: reproducible
    lhs = np.array([[p.parameter[m.name] for m in found] for p in plan.variants])
    assert np.allclose(lhs, values)


@pytest.mark.parametrize("method, first, more", [("mc", 3, 5), ("sobol", 2, 4)])
def test_a_grown_design_keeps_its_first_samples(method, first, more):
    params = [{"key": "pads.kz", "distribution": "lognormal", "cov": 0.3},
              {"key": "vehicle.speed", "distribution": "uniform", "low": 20.0, "high": 40.0}]

    def plan_of(n):
        c = _case(params, **{"uncertainty.method": method, "uncertainty.samples": n})
        return c, make_plan("uncertainty", c, study_settings("uncertainty", case=c))

    (c1, small), (c2, big) = plan_of(first), plan_of(more)
    k = len(small.variants)
    assert [v.overrides for v in big.variants[:k]] == [v.overrides for v in small.variants]
    one = variant_case(c1, small.variants[0].overrides)
    assert one["uncertainty.parameter"] == [] and one.digest() == \
        variant_case(c2, big.variants[0].overrides).digest()


def test_the_listing_shows_the_sampled_values_in_columns(capsys, tmp_path):
    """The red team: ``--list`` printed ~500 characters per row, four of them the design's
    own keys (``uncertainty.parameter=[] ...``) on every row. Now one column per
    parameter, one row per sample, the keys named once above."""
    assert run(["study", "uncertainty", "jobs/uncertainty_study.toml", "--list", "--out",
                str(tmp_path)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    head = next(ln for ln in lines if ln.startswith("index"))
    assert head.split() == ["index", "variant", "c_S", "layer", "1", "c_S", "layer", "2",
                            "damping", "layer", "1", "pad", "stiffness", "speed", "status"]
    assert "  c_S layer 1: soil.layers[1].c_s, lognormal" in lines
    assert "  speed: vehicle.speed, uniform" in lines
    rows = [ln for ln in lines if ln.split()[:2] and ln.split()[1].startswith("s0")]
    assert len(rows) == 28 and rows[0].split()[:2] == ["0", "s0000"]
    table = [ln for ln in lines if "folder" not in ln]  # the folder line carries tmp_path
    assert max(map(len, table)) < 100 and "uncertainty.parameter=[]" not in out
    speed = float(rows[0].split()[-2])
    assert 20.0 <= speed <= 40.0
