"""The runner owns the stage graph: stages declare the stages they need and get their products
through the context, declare their refusals (checked before anything runs) and their case
keys on their products' rows; no stage module imports another's or builds a context
(``tools/stage_rules.py``, run by ``make lint`` too)."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

import railvib_hpc as rv
from railvib_hpc import pipeline
from railvib_hpc.errors import CaseError, StaleInputError
from railvib_hpc.io.products import STAGE_FILES, StageFile, inputs_hash, spec
from railvib_hpc.io.stage_checks import CHECKS
from railvib_hpc.io.stage_protocol import Stage, StageInput, StageOutput, StageRunner
from railvib_hpc.log import Reporter
from railvib_hpc.validation import command_problems

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
sys.path.insert(0, str(ROOT / "tools"))
import stage_rules  # noqa: E402

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one rank")


def test_the_graph_of_the_registered_stages():
    """Every need is a registered stage, the needs form no cycle, and every file a stage
    reads is a product of a stage it needs."""
    graph = pipeline.stage_graph()
    assert graph == {"mesh": (), "modal": ("mesh",), "mbs": ("modal",),
                     "reconstruct": ("modal", "mbs"), "transient": ("mesh",),
                     "assess": ("modal", "mbs", "reconstruct", "transient")}
    order = list(graph)
    for name, needs in graph.items():
        assert all(order.index(n) < order.index(name) for n in needs)
        stage = pipeline.stage(name)
        given = {p for n in needs for p in pipeline.stage(n).products}
        assert set(stage.reads) <= given, (name, set(stage.reads) - given)
    assert pipeline.stage("mesh").provide is not None        # built on demand; others verified
    assert all(pipeline.stage(n).provide is None for n in graph if n != "mesh")


def test_a_cycle_or_an_unknown_need_is_refused(monkeypatch):
    stages = {"a": Stage("a", "x", compute=None, needs=("b",)),
              "b": Stage("b", "x", compute=None, needs=("a",))}
    monkeypatch.setattr(pipeline, "STAGES", dict.fromkeys(stages, ""))
    monkeypatch.setattr(pipeline, "stage", stages.__getitem__)
    with pytest.raises(ValueError, match="the stages' needs form a cycle: a -> b -> a"):
        pipeline.stage_graph()
    stages["b"] = Stage("b", "x", compute=None, needs=("nope",))
    with pytest.raises(ValueError, match="stage b needs 'nope', which is not a stage"):
        pipeline.stage_graph()


def test_the_case_keys_are_declared_on_the_products():
    """A row adds its own keys to those of the products it extends; the cumulative
    selection is that of its upstream products and its own (no key chained by import)."""
    for name in STAGE_FILES:
        row = spec(name)
        for upstream in row.extends:
            assert all(k in row.inputs for k in spec(upstream).inputs), (name, upstream)
        assert all(k in row.inputs for k in row.keys)
    assert spec("modes.h5").extends == ("mesh.h5",)
    assert spec("mbs.h5").extends == ("modes.h5",)
    assert spec("fields.h5").extends == ("mbs.h5",)
    assert spec("transient.h5").extends == ("mesh.h5",)
    case = rv.Case.from_file(BASELINE)
    faster = case.replace({"vehicle.speed": 20.0})        # mbs.h5 on: not the modes
    assert inputs_hash(case, "modes.h5") == inputs_hash(faster, "modes.h5")
    assert inputs_hash(case, "mbs.h5") != inputs_hash(faster, "mbs.h5")
    assert inputs_hash(case, "fields.h5") != inputs_hash(faster, "fields.h5")
    damped = case.replace({"modal.damping_ratio": 0.05})   # the passage's, not the modes'
    assert inputs_hash(case, "modes.h5") == inputs_hash(damped, "modes.h5")
    assert inputs_hash(case, "mbs.h5") != inputs_hash(damped, "mbs.h5")


def test_each_stage_declares_its_refusals_and_the_command_collects_them():
    case = rv.Case.from_file(BASELINE)
    assert all(pipeline.stage(n).refusals(case) == [] for n in pipeline.STAGES)
    bare = case.replace({"track.count": 0, "load.force": 1e5})
    for command in ("run", "modal", "mbs", "reconstruct"):
        (key, value, allowed), = command_problems(bare, command)
        assert (key, value) == ("track.count", 0)
        assert allowed.startswith(f"railvib {command} needs a track")
    for command in ("mesh", "transient", "assess", "check", "study"):
        assert command_problems(bare, command) == []
    pml = case.replace({"boundary.x_max": "pml", "boundary.layer_thickness": 2.0})
    # railvib run: the modal stage's refusal, before the mesh is built (the first stage)
    assert [p[0] for p in command_problems(pml, "run")] == ["boundary.x_max"]
    assert command_problems(pml, "mbs") == [] and command_problems(pml, "transient") == []
    ends = case.replace({"track.ends": "supported", "boundary.x_max": "pml",
                         "boundary.layer_thickness": 2.0})
    # one line: the first refusal in the order the stage checks them
    assert [p[0] for p in command_problems(ends, "modal")] == ["modal.damping"]


@pytest.fixture
def graph():
    """Two test-only stages in a graph of their own: ``up`` provides its product, ``down``
    needs it; ``late`` needs ``down``, whose product it verifies."""
    calls = []
    rows = [StageFile("up.json", "up", 1, (("vehicle.speed", ()),)),
            StageFile("down.json", "down", 1, (("vehicle.x_start", ()),),
                      extends=("up.json",))]

    def provide(ctx):
        calls.append(ctx.stage.name)
        return StageInput("up", {"up.json": "0" * 64}, {"up.json": ctx.path("up.json")},
                          value=ctx.case["vehicle.speed"])

    def down(ctx):
        given = ctx.input("up")
        return StageOutput(reused=False, summary={"speed": given.value, "sha": given.sha256})

    def late(ctx):
        ctx.input("down")                                  # verified: down.json must be there
        return StageOutput(reused=False, summary={})

    def stray(ctx):
        return ctx.input("up")                             # not declared in its needs

    stages = {"up": Stage("up", "x", compute=None, products=(rows[0],), provide=provide),
              "down": Stage("down", "x", compute=down, products=(rows[1],), needs=("up",),
                            reads=("up.json",),
                            refuse=lambda case, command: [("vehicle.speed", 20.0, "not 20")]
                            if case["vehicle.speed"] == 20.0 else []),
              "late": Stage("late", "x", compute=late, needs=("down",), reads=("down.json",)),
              "stray": Stage("stray", "x", compute=stray)}
    yield stages, calls
    for name in ("up.json", "down.json"):
        STAGE_FILES.pop(name, None)
        CHECKS.pop(name, None)


def test_the_runner_hands_a_stage_its_upstream_products(graph, tmp_path):
    stages, calls = graph
    case = rv.Case.from_file(BASELINE)
    runner = StageRunner(tmp_path, MPI.COMM_SELF, Reporter(0, io.StringIO()), command="t",
                         stages=stages.__getitem__)
    done = runner.run(stages["down"], case, record=False).result
    assert done.summary == {"speed": 30.0, "sha": "0" * 64} and calls == ["up"]
    assert spec("down.json").inputs == (("vehicle.speed", ()), ("vehicle.x_start", ()))
    # a product that is no provider's is verified: missing -> one line naming the command
    with pytest.raises(StaleInputError, match=r"down.json not found: run 'railvib down' first"):
        runner.run(stages["late"], case, record=False)
    with pytest.raises(ValueError, match="stage stray reads the products of stage 'up', "
                                         "which it does not declare"):
        runner.run(stages["stray"], case, record=False)
    # the refusal comes before the lock and before anything runs
    fresh = StageRunner(tmp_path / "fresh", MPI.COMM_SELF, Reporter(0, io.StringIO()),
                        command="t", stages=stages.__getitem__)
    with pytest.raises(CaseError, match=r"vehicle.speed = 20.0: not 20"):
        fresh.run(stages["down"], case.replace({"vehicle.speed": 20.0}))
    assert calls == ["up"] and not (tmp_path / "fresh").exists()


def test_the_stage_modules_import_no_other_stage_and_build_no_context(tmp_path):
    assert stage_rules.violations() == []
    pkg = tmp_path / "railvib_hpc" / "newstage"
    pkg.mkdir(parents=True)
    (pkg / "stage.py").write_text(
        "from ..mesh.stage import build_or_reuse_mesh\n"
        "from ..modal import stage\n"
        "import railvib_hpc.mbs.stage\n"
        "from .stage import STAGE\n"                       # its own: allowed
        "from ..io.stage_protocol import StageContext\n"
        "ctx = StageContext(None, '.')\n")
    found = stage_rules.violations(tmp_path)
    assert len(found) == 4, found
    assert "imports railvib_hpc.mesh.stage" in found[0]
    assert "imports railvib_hpc.modal.stage" in found[1]
    assert "imports railvib_hpc.mbs.stage" in found[2]
    assert "builds a StageContext" in found[3]
