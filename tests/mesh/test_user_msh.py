"""Bring your own mesh: a gmsh .msh with the project's physical-group names."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.errors import MeshError
from railvib_hpc.mesh.gmsh_model import generate, gmsh_session
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.mesh.stage import make_mesh
from railvib_hpc.schema import PART_ID

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"


def test_generated_msh_read_back_identically(tmp_path):
    case = load_case(BASELINE, ["mesh.refinement=0.5"])
    msh = tmp_path / "model.msh"
    mesh, _ = generate(build_layout(case), msh)
    user_case = load_case(BASELINE, ["mesh.refinement=0.5", f"mesh.file='{msh}'"])
    again, report = make_mesh(user_case)
    assert report["source"] == str(msh)
    assert again.n_nodes == mesh.n_nodes
    assert again.counts_per_part() == mesh.counts_per_part()
    assert np.allclose(np.sort(again.hex_volumes()), np.sort(mesh.hex_volumes()))


def _tiny_msh(path: Path, groups=("ballast", "subballast", "subgrade"), invert=False) -> None:
    """Three stacked unit hexes plus rails, sleeper and pads, as discrete gmsh entities."""
    with gmsh_session() as gmsh:
        gmsh.model.add("tiny")
        xy = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
        pts = np.concatenate([np.c_[xy, np.full(4, z)] for z in range(4)])
        top = np.array([[0.5, 0.5, 3.2], [1.5, 0.5, 3.2]])
        pts = np.r_[pts, top]
        gmsh.model.addDiscreteEntity(0, 1)
        gmsh.model.mesh.addNodes(0, 1, list(range(1, len(pts) + 1)), pts.ravel().tolist())
        for k, part in enumerate(groups):
            ent = gmsh.model.addDiscreteEntity(3)
            conn = np.r_[4 * k + np.arange(1, 5), 4 * (k + 1) + np.arange(1, 5)]
            if invert and k == 0:
                conn = np.r_[conn[4:], conn[:4]]
            gmsh.model.mesh.addElementsByType(ent, 5, [k + 1], conn.tolist())
            gmsh.model.addPhysicalGroup(3, [ent], PART_ID[part], name=part)
        lines = {"rail": [17, 18], "rigid_rail": [18, 17], "sleeper": [13, 14],
                 "pad_x": [17, 15], "pad_y": [17, 15], "pad_z": [17, 15]}
        for k, (part, conn) in enumerate(lines.items()):
            ent = gmsh.model.addDiscreteEntity(1)
            gmsh.model.mesh.addElementsByType(ent, 1, [100 + k], conn)
            gmsh.model.addPhysicalGroup(1, [ent], PART_ID[part], name=part)
        gmsh.write(str(path))


def test_tiny_user_mesh_is_accepted(tmp_path):
    msh = tmp_path / "tiny.msh"
    _tiny_msh(msh)
    mesh, report = make_mesh(load_case(BASELINE, [f"mesh.file='{msh}'"]))
    assert mesh.n_nodes == 18 and len(mesh.hexes) == 3
    assert report["volume_per_part"] == pytest.approx({"ballast": 1.0, "subballast": 1.0,
                                                       "subgrade": 1.0})


def test_any_subset_of_parts_is_a_mesh_but_none_is_a_clear_error(tmp_path):
    msh = tmp_path / "twolayers.msh"
    _tiny_msh(msh, groups=("ballast", "subgrade"))
    mesh, report = make_mesh(load_case(BASELINE, [f"mesh.file='{msh}'"]))
    assert len(mesh.hexes) == 2 and "subballast" not in report["parts"]
    with pytest.raises(MeshError, match=r"no physical group named after a part \(found: "
                                        r"'soil'\); allowed names: ballast, subballast"):
        _one_unknown_group(tmp_path / "unknown.msh")
        make_mesh(load_case(BASELINE, [f"mesh.file='{tmp_path / 'unknown.msh'}'"]))


def _one_unknown_group(path: Path) -> None:
    with gmsh_session() as gmsh:
        gmsh.model.add("unknown")
        pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float)
        gmsh.model.addDiscreteEntity(0, 1)
        gmsh.model.mesh.addNodes(0, 1, list(range(1, 9)), pts.ravel().tolist())
        ent = gmsh.model.addDiscreteEntity(3)
        gmsh.model.mesh.addElementsByType(ent, 5, [1], list(range(1, 9)))
        gmsh.model.addPhysicalGroup(3, [ent], 1, name="soil")
        gmsh.write(str(path))


def test_inverted_element_fails_mesh_command(tmp_path, capsys):
    msh = tmp_path / "inverted.msh"
    _tiny_msh(msh, invert=True)
    with pytest.raises(MeshError, match="1 inverted"):
        make_mesh(load_case(BASELINE, [f"mesh.file='{msh}'"]))
    code = run(["mesh", str(BASELINE), "--set", f"mesh.file='{msh}'", "--out",
                str(tmp_path / "out")])
    assert code == 2
    err = capsys.readouterr().err
    assert "inverted" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "mesh.h5").exists()


def test_shipped_example_mesh_reads():
    msh = Path(__file__).resolve().parents[2] / "meshes" / "tiny_user_mesh.msh"
    mesh, report = make_mesh(load_case(BASELINE, [f"mesh.file='{msh}'"]))
    assert len(mesh.hexes) == 3 and report["quality"]["n_inverted"] == 0


def test_coarse_preset_case():
    case = load_case(Path(__file__).resolve().parents[2] / "meshes" / "coarse.toml")
    assert case["mesh.refinement"] == 0.5
    mesh, _ = generate(build_layout(case))
    assert 5_000 < mesh.n_nodes < 15_000
