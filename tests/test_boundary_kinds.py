"""The boundary kinds as registered objects: the schema's choices, the validation, the modal
path's refusal and the reflection study's variants derive from the registry, and a new kind
(``example_boundary.py``) is one module and one registry line that runs end to end."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

import railvib_hpc as rv
from railvib_hpc.boundary_registry import BOUNDARY_KINDS, boundary_kind, boundary_kinds
from railvib_hpc.config import load_case
from railvib_hpc.errors import CaseError
from railvib_hpc.schema import BOUNDARY_FACES, BOUNDARY_TYPES, SCHEMA

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The coarse thesis model of the modal tests.
COARSE = {"mesh.refinement": 0.25, "modal.n_modes": 8, "modal.block_size": 8}


@pytest.fixture
def winkler(monkeypatch):
    """The example kind of ``example_boundary.py``, registered with its one line."""
    monkeypatch.setitem(BOUNDARY_KINDS, "winkler", "example_boundary")
    yield boundary_kind("winkler")
    sys.modules.pop("example_boundary", None)


def test_the_schema_choices_are_the_registry():
    assert tuple(BOUNDARY_TYPES) == ("fixed", "roller", "free", "absorbing", "caughey", "pml")
    assert [k.name for k in boundary_kinds()] == list(BOUNDARY_KINDS)
    for face in BOUNDARY_FACES:
        assert tuple(SCHEMA["boundary"][face].choices) == tuple(BOUNDARY_KINDS)
    with pytest.raises(ValueError, match="unknown boundary kind 'sponge'"):
        boundary_kind("sponge")


def test_the_kinds_declare_what_the_faces_did():
    """The declarations reproduce the rules the switches held: constrained DOFs, the
    components held, the layers and the paths."""
    full = ("ux", "uy", "uz", "rx", "ry", "rz")
    assert {k.name: k.constrained("y_min") for k in boundary_kinds()} == {
        "fixed": full, "roller": ("uy",), "free": (), "absorbing": (), "caughey": full,
        "pml": full}
    assert {k.name: k.restrained("base") for k in boundary_kinds()} == {
        "fixed": (0, 1, 2), "roller": (2,), "free": (), "absorbing": (0, 1, 2),
        "caughey": (0, 1, 2), "pml": (0, 1, 2)}
    springs, dashpots = {"virtual_thickness": 1.0}, {"virtual_thickness": 0.0}
    assert boundary_kind("absorbing").statically_held("base", springs) == (0, 1, 2)
    assert boundary_kind("absorbing").statically_held("base", dashpots) == ()
    assert [k.name for k in boundary_kinds() if k.has_layer] == ["caughey", "pml"]
    assert [k.name for k in boundary_kinds() if not k.modal] == ["pml"]


def test_the_modal_refusal_of_a_layer_is_derived_from_the_kinds():
    from railvib_hpc.modal.refusals import no_pml

    case = load_case(BASELINE, ["boundary.y_min=pml", "boundary.layer_thickness=2"])
    assert no_pml(case) == [(
        "boundary.y_min", "pml",
        "a perfectly matched layer is frequency dependent (its stretching 1 + d / (i omega)), "
        "so the modal path (modal, mbs, run and the modal studies) has no modes of it; it is "
        "for railvib transient with transient.engine = 'direct', 'explicit' or 'imex'; "
        "allowed here: fixed, roller, free, absorbing, caughey")]


def test_the_layer_checks_come_from_the_kinds():
    with pytest.raises(CaseError) as err:
        load_case(BASELINE, ["boundary.x_min=caughey", "boundary.base=pml",
                             "boundary.layer_thickness=0"])
    keys = [p[0] for p in err.value.problems]
    assert keys == ["boundary.layer_thickness", "boundary.layer_thickness"]
    text = str(err.value)
    assert "for the caughey face(s) x_min" in text and "for the pml face(s) base" in text


def test_the_reflection_variants_come_from_the_kinds():
    from railvib_hpc.studies import reflection
    from railvib_hpc.studies.settings import StudySettingsError

    assert tuple(SCHEMA["study"]["reflection"]["boundaries"].choices) == (
        "case", "thesis", *reflection.variant_kinds())
    five = ("x_min", "x_max", "y_min", "y_max", "base")
    assert reflection.boundary_overrides("absorbing") == tuple(
        f"boundary.{f}=absorbing" for f in five)
    assert reflection.boundary_overrides("pml") == (
        *(f"boundary.{f}=pml" for f in five), "modal.lumped_mass=true")
    case = load_case(BASELINE)
    settings = {"domains": [[0.0, 0.0, 0.0]], "names": ["model1"], "band_hz": 0.0,
                "pml_thickness": 4.0, "boundaries": ["thesis", "pml"], "solver": "direct"}
    plan = reflection.plan(case, settings)
    pml = next(v for v in plan.variants if v.parameter["boundary"] == "pml")
    assert "boundary.layer_thickness=4.0" in pml.overrides      # the layer outside the domain
    with pytest.raises(StudySettingsError, match="'pml' needs study.reflection.solver = "
                                                 r"'direct' \(the layers are time-domain only"):
        reflection.plan(case, {**settings, "solver": "modal"})


def test_a_new_kind_is_one_module_and_one_registry_line(winkler, tmp_path):
    """``winkler`` (springs under the base): allowed by the schema once registered, it
    runs the modal path through the API; the springs are softer than a fixed base."""
    assert "winkler" in SCHEMA["boundary"]["base"].choices
    case = rv.Case.from_file(BASELINE).replace(COARSE)
    fixed = rv.Pipeline(case, tmp_path / "fixed").stage("modal")
    springs = rv.Pipeline(case.replace({"boundary.base": "winkler"}),
                          tmp_path / "winkler").stage("modal")
    assert springs.n_dofs > fixed.n_dofs                    # the base's DOFs are free
    assert 0.0 < springs.frequencies_hz[0] < fixed.frequencies_hz[0]


def test_an_unregistered_kind_is_refused():
    with pytest.raises(CaseError, match=r"boundary.base = 'winkler'"):
        load_case(BASELINE, ["boundary.base=winkler"])


@pytest.mark.slow
def test_the_new_kind_runs_both_paths_from_the_command_line(winkler, tmp_path, capsys):
    """``railvib modal`` and ``railvib transient`` on the coarse model with a winkler base."""
    from railvib_hpc.cli import run

    sets = [a for s in (f"{k}={v}" for k, v in COARSE.items()) for a in ("--set", s)]
    assert run(["modal", str(BASELINE), "--out", str(tmp_path / "m"), *sets,
                "--set", "boundary.base=winkler"]) == 0
    assert (tmp_path / "m" / "modes.h5").exists()
    short = ["mesh.refinement=0.25", "vehicle.x_start=2.7", "vehicle.x_end=3.2",
             "output.dt=0.002", "output.stress_times=[]", "transient.checkpoint_interval=0",
             "transient.f_max=100", "boundary.base=winkler"]
    out = tmp_path / "t"
    assert run(["transient", str(BASELINE), "--out", str(out),
                *[a for s in short for a in ("--set", s)]]) == 0
    text = capsys.readouterr().out
    assert "winkler" in text
    assert json.loads((out / "run.json").read_text())["stages"]["transient"]["command"] \
        .startswith("railvib transient")
