"""The study protocol: a new study is one module (``tests/example_study.py``) and one line of
the registry, and runs end to end through the command line and the API; the package's seven
studies are declared the same way, and the command line takes its choices and help from
the one registry."""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

import railvib_hpc as rv
from railvib_hpc.cli import run
from railvib_hpc.studies import registry
from railvib_hpc.studies.settings import StudySettingsError

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one rank")


@pytest.fixture
def example(monkeypatch):
    """The example study of ``example_study.py``, registered with its one line."""
    monkeypatch.setitem(registry.STUDIES, "example", "example_study")
    yield registry.study("example")
    sys.modules.pop("example_study", None)


def _shear_speed(case: rv.Case, modulus: float) -> float:
    """c_S = sqrt(E / (2 (1 + nu) rho)) of the subgrade at Young's modulus ``modulus``."""
    sub = case["materials"]["subgrade"]
    return math.sqrt(modulus / (2.0 * (1.0 + sub["nu"]) * sub["rho"]))


def test_a_new_study_is_one_module_and_one_registry_line(example, tmp_path, capsys):
    out = tmp_path / "out"
    sets = ["--study-set", "moduli=[4e8, 1e8]", "--study-set", "max_shear_speed=250"]
    # the command line: its name is a choice of `railvib study`, its help line is there
    with pytest.raises(SystemExit):
        run(["study", "--help"])
    assert re.search(r"\n  example +the subgrade's wave speeds against its Young's modulus\n",
                     capsys.readouterr().out)
    assert run(["study", "example", str(BASELINE), "--out", str(out), *sets]) == 0
    text = capsys.readouterr().out
    case = rv.Case.from_file(BASELINE)
    fast, slow = _shear_speed(case, 4e8), _shear_speed(case, 1e8)
    assert slow < 250.0 < fast                  # the limit between the two: the verdict fails
    assert f"VERDICT: shear-wave speed up to {fast:.1f} m/s (E = 4e+08 Pa); above 250 m/s " \
           "at E4e+08" in text
    root = out / "example"
    report = json.loads((root / "report.json").read_text())
    assert report["complete"] and report["verdict"]["ok"] is False
    assert [r["variant"] for r in report["analysis"]["rows"]] == ["E1e+08", "E4e+08"]  # sorted
    result = json.loads((root / "E1e+08" / "result.json").read_text())
    assert result["study"] == "example" and result["parameter"] == {"E": 1e8}
    assert result["wave_speeds"]["c_S"] == pytest.approx(slow, rel=1e-12)
    assert (root / "figures" / "example.png").exists() and (root / "report.md").exists()
    # a rerun skips the finished variants (their result.json is current for them)
    assert run(["study", "example", str(BASELINE), "--out", str(out), *sets, "--list"]) == 0
    assert text.count("running:") == 2 and "finished" in capsys.readouterr().out
    assert run(["study", "example", str(BASELINE), "--out", str(out), *sets]) == 0
    assert capsys.readouterr().out.count("finished earlier: skipping") == 2
    # its settings are checked by the schema's engine, one line each
    assert run(["study", "example", str(BASELINE), "--out", str(out), "--study-set",
                "moduli=[-1]"]) == 2
    assert "study.example.moduli = [-1]" in capsys.readouterr().err
    # the Python API: the same study, its typed result
    res = rv.run_study("example", case, tmp_path / "api", MPI.COMM_SELF, quiet=True,
                       settings={"moduli": [1e8, 2e8]})
    assert res.ok and res.merged and res.kind == "example" and res.verdict["ok"] is True
    assert [r["c_S"] for r in res.rows] == pytest.approx(
        [slow, _shear_speed(case, 2e8)], rel=1e-12)
    assert res.tables[0].as_dicts()[0]["variant"] == "E1e+08"


def test_the_registry_declares_every_study_and_the_cli_derives_from_it(capsys):
    import railvib_hpc.studies as studies
    from railvib_hpc.studies.runner import trackless_kinds

    declared = {name: registry.study(name) for name in registry.STUDIES}
    assert list(declared) == ["convergence", "modes", "reflection", "speed", "thesis",
                              "mitigation", "uncertainty"]
    for name, study in declared.items():
        assert study.name == name and study.help and study.title and study.in_schema
        assert set(study.settings) == set(rv.Case.defaults().section(f"study.{name}"))
        assert studies.STUDY_MODULES[name].STUDY is study
    assert trackless_kinds() == ("convergence", "mitigation", "reflection", "speed")
    with pytest.raises(SystemExit):
        run(["study", "--help"])
    helps = capsys.readouterr().out
    assert all(re.search(rf"\n  {name} +{re.escape(s.help)}\n", helps)
               for name, s in declared.items())
    with pytest.raises(StudySettingsError, match="study = 'nope': allowed: convergence, "
                                                 "modes, reflection"):
        rv.run_study("nope", rv.Case.defaults(), "unused", MPI.COMM_SELF, quiet=True)
    with pytest.raises(registry.UnknownStudy, match="unknown study 'nope'"):
        registry.study("nope")
