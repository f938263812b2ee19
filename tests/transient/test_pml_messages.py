"""The refusals of a perfectly matched layer name what takes it and the keys that move it:
the modal path before it meshes, every engine of ``railvib transient`` by name, the real
``domain.extra_*`` keys."""

from __future__ import annotations

import pytest
from mpi4py import MPI
from transient_cases import BASELINE

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.schema import PML_ENGINES, SCHEMA
from railvib_hpc.validation import command_problems

#: The red team's coarse settings.
COARSE = ["mesh.refinement=0.5", "modal.n_modes=20", "output.dt=0.01"]


def _sets(*items: str) -> list[str]:
    return [a for s in items for a in ("--set", s)]


def test_every_engine_takes_the_layer():
    """The refusals name :data:`~railvib_hpc.schema.PML_ENGINES`: every engine of
    ``transient.engine`` (each one's layer is tested in test_pml_coarse_layers.py)."""
    assert SCHEMA["transient"]["engine"].choices == PML_ENGINES
    case = load_case(BASELINE, ["boundary.y_min=pml", "boundary.layer_thickness=4"])
    for engine in PML_ENGINES:
        ok = case.replace({"transient.engine": engine, "modal.lumped_mass": True})
        assert command_problems(ok, "transient") == []


@pytest.mark.parametrize("command", ["run", "modal"])
def test_the_modal_path_refuses_a_layer_before_it_meshes(tmp_path, one_line_refusal,
                                                         command):
    """``railvib run B $C --set boundary.y_min=pml --set boundary.layer_thickness=4``: one
    line naming the three engines (it named the explicit one alone), exit 2, and nothing
    in the output folder (it meshed first)."""
    out = tmp_path / "out"
    code = run([command, str(BASELINE), "--out", str(out),
                *_sets(*COARSE, "boundary.y_min=pml", "boundary.layer_thickness=4")])
    if MPI.COMM_WORLD.rank == 0:              # (rank 0 prints the line)
        one_line_refusal(code, out, "boundary.y_min = 'pml'")
    assert code == 2 and (not out.exists() or not any(out.iterdir()))


def test_the_modal_refusal_names_every_engine():
    case = load_case(BASELINE, ["boundary.y_min=pml", "boundary.layer_thickness=4"])
    (key, value, text), = command_problems(case, "run")
    assert (key, value) == ("boundary.y_min", "pml")
    assert "transient.engine = 'direct', 'explicit' or 'imex'" in text
    assert "allowed here: fixed, roller, free, absorbing, caughey" in text


def test_a_layer_that_reaches_the_building_names_the_domain_keys(tmp_path, capsys):
    """``railvib transient B $C --set transient.dt=0.005 --set boundary.base=pml --set
    boundary.layer_thickness=50``: the hint names ``domain.extra_depth``, ``_length`` and
    ``_width`` (it said "([domain], case.extra_*)")."""
    code = run(["transient", str(BASELINE), "--out", str(tmp_path),
                *_sets(*COARSE, "transient.dt=0.005", "boundary.base=pml",
                       "boundary.layer_thickness=50")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    if MPI.COMM_WORLD.rank > 0:               # (rank 0 prints the line)
        return
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert len(lines) == 1, err
    assert "the pml layer of boundary.base reaches the building" in lines[0]
    assert "(domain.extra_depth, domain.extra_length, domain.extra_width)" in lines[0]
    assert "case.extra" not in lines[0]
