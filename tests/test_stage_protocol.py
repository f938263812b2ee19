"""The stage protocol: every stage declared once, run by one runner, and the rule that keeps
the stage modules off the reuse, provenance and lock layer (``make lint`` runs it too)."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import pytest

import railvib_hpc as rv
from railvib_hpc import pipeline
from railvib_hpc.io.locks import holds_lock
from railvib_hpc.io.products import STAGE_FILES
from railvib_hpc.io.provenance import read_provenance
from railvib_hpc.io.stage_checks import CHECKS
from railvib_hpc.io.stage_protocol import StageRunner
from railvib_hpc.log import Reporter

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
sys.path.insert(0, str(ROOT / "tools"))
import stage_rules  # noqa: E402


@pytest.fixture
def example(monkeypatch):
    """The example stage of ``example_stage.py``, registered with its one line."""
    monkeypatch.setitem(pipeline.STAGES, "example", "example_stage")
    yield pipeline.stage("example")
    STAGE_FILES.pop("example.json", None)
    CHECKS.pop("example.json", None)
    sys.modules.pop("example_stage", None)


def test_a_new_stage_is_one_module_and_one_registry_line(example, tmp_path, capsys):
    case = rv.Case.from_file(BASELINE)
    out = tmp_path / "out"
    pipe = rv.Pipeline(case, out)
    first = pipe.stage("example")
    assert first.reused is False and first.summary["speed_squared"] == 30.0**2
    assert not holds_lock(out) and (out / ".railvib" / "lock").exists()
    assert read_provenance(out / "example.json")["inputs_sha256"]
    second = pipe.stage("example")
    text = capsys.readouterr().out
    assert second.reused is True and second.summary["speed_squared"] == 900.0
    assert f"reusing {out / 'example.json'} (same vehicle speed)" in text
    record = pipe.run_record()
    assert [(c["stage"], c["reused"], c["status"]) for c in record["calls"]] == [
        ("example", False, "ok"), ("example", True, "ok")]
    # a changed key recomputes it, saying why, as every stage does
    slower = rv.Pipeline(case.replace({"vehicle.speed": 20.0}), out).stage("example")
    assert slower.reused is False and slower.summary["speed_squared"] == 400.0
    assert (f"recomputing {out / 'example.json'}: it was computed with vehicle.speed = 30, "
            "the case says 20") in capsys.readouterr().out
    # ... and the command line has it: its command and help line come from the registry
    from railvib_hpc.cli import run

    assert run(["example", str(BASELINE), "--out", str(out)]) == 0
    assert f"reusing {out / 'example.json'}" not in capsys.readouterr().out   # 30 m/s again
    assert json.loads((out / "run.json").read_text())["stages"]["example"]["command"] \
        .startswith("railvib example")
    with pytest.raises(SystemExit):
        run(["--help"])
    assert "write example.json: the vehicle's speed squared" in capsys.readouterr().out


def test_the_runner_takes_the_lock_once_and_records_each_call(example, tmp_path):
    case = rv.Case.from_file(BASELINE)
    from mpi4py import MPI

    runner = StageRunner(tmp_path, MPI.COMM_SELF, Reporter(0, io.StringIO()), command="t")
    with runner.session() as unused:
        assert holds_lock(tmp_path)
        runs = pipeline.run_stages(runner, ["example", "example"], case)
    assert unused == [] and not holds_lock(tmp_path)
    assert runs["example"].result.reused is True and runs["example"].seconds >= 0
    calls = rv.read_run_record(tmp_path)["calls"]
    assert [c["reused"] for c in calls] == [False, True]
    with pytest.raises(ValueError, match="unknown stage 'nope'"):
        pipeline.run_stages(runner, ["example", "nope"], case)
    assert len(rv.read_run_record(tmp_path)["calls"]) == 2       # refused before anything


def test_every_stage_is_declared_once_with_its_products():
    """Each product row of the table belongs to exactly one registered stage, whose
    declaration names it, and every file a product is computed from is one the stage reads
    or writes."""
    declared = {name: pipeline.stage(name) for name in pipeline.STAGES}
    owners: dict[str, str] = {}
    for name, stage in declared.items():
        assert stage.name == name and stage.help
        for product in stage.products:
            assert product not in owners, f"{product}: {owners[product]} and {name}"
            owners[product] = name
        for row in stage.rows:
            assert set(row.upstream) <= set(stage.reads) | set(stage.products), row.name
            assert row.inputs and all(k in stage.case_keys for k in row.inputs)
    written = {n for n, row in STAGE_FILES.items() if row.stage in declared}
    assert written == set(owners)
    for pipe in pipeline.PIPELINES.values():
        assert set(pipe) <= set(declared)


def test_stage_modules_leave_reuse_provenance_and_locks_to_the_runner():
    assert stage_rules.stage_modules() and stage_rules.violations() == []


def test_the_stage_rule_finds_a_direct_import(tmp_path):
    pkg = tmp_path / "railvib_hpc" / "newstage"
    pkg.mkdir(parents=True)
    (pkg / "stage.py").write_text(
        "from ..io.atomic import ensure_space\n"
        "from ..io.provenance import examine\n"
        "from ..io import run_record\n"
        "import railvib_hpc.io.locks as locks\n")
    found = stage_rules.violations(tmp_path)
    assert len(found) == 3 and "imports examine" in found[0]
    assert all(line.startswith("railvib_hpc/newstage/stage.py") for line in found)


def test_the_stage_rule_covers_the_helpers_of_a_stage_package(tmp_path):
    """A helper split out of a stage (here ``newstage/helper.py``, like
    ``mbs/damping_model.py``) may not reach the provenance layer either; a package without a
    ``stage.py`` is not a stage's."""
    pkg = tmp_path / "railvib_hpc" / "newstage"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "stage.py").write_text("from ..io.stage_protocol import Stage\n")
    (pkg / "helper.py").write_text("from ..io.provenance import require_inputs\n")
    (pkg / "sub" / "deep.py").write_text("from ...io.digests import forget\n")
    other = tmp_path / "railvib_hpc" / "studies"
    other.mkdir()
    (other / "common.py").write_text("from ..io.provenance import examine\n")
    found = stage_rules.violations(tmp_path)
    assert len(found) == 2
    assert found[0].startswith("railvib_hpc/newstage/helper.py: line 1: imports require_inputs")
    assert found[1].startswith("railvib_hpc/newstage/sub/deep.py: line 1: imports forget")
