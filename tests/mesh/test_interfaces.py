"""Elastic interfaces (``railvib_hpc.mesh.interfaces``): under-sleeper pads, ballast mats,
base isolation.

* The cut: the side above gets its own nodes, joined by three springs per pair; the
  tributary areas add up to the interface's area (hand counts below).
* Physics: a stiff block on a ballast mat bounces at sqrt(k'' A / m) / 2 pi, the
  frequency of a rigid mass on a continuous elastic layer of bedding modulus k''.
* The generated mesh keeps its counts and stays free of unintended duplicates and
  non-conformal faces; the interface's damping ratio is half its loss factor.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
from fem_tools import box_mesh

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.fem.assemble_serial import assemble_matrix
from railvib_hpc.mesh.interfaces import split_interfaces, tributary_areas
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.mesh.stage import make_mesh
from railvib_hpc.model.elements import element_batches, group_damping_ratio
from railvib_hpc.problem import Problem
from railvib_hpc.schema import INTERFACE_PARTS, PART_ID

ROOT = Path(__file__).resolve().parents[2]
ALL = {"usp.modulus": 1e8, "ballast_mat.modulus": 5e7, "isolation.modulus": 1e8}


def thesis_case(**changes) -> Case:
    return Case.from_file(ROOT / "jobs" / "thesis_baseline.toml").replace(
        {"mesh.refinement": 0.5, **changes})


@pytest.fixture(scope="module")
def meshes():
    """The coarse thesis mesh without and with all three interfaces (ground-level bearings),
    and with the bearings under the footings."""
    plain, _ = make_mesh(thesis_case())
    cut, report = make_mesh(thesis_case(**ALL))
    base, _ = make_mesh(thesis_case(**{"isolation.modulus": 1e8,
                                       "isolation.level": "footings"}))
    return plain, cut, report, base


def springs(mesh: Mesh, kind: str) -> np.ndarray:
    return mesh.lines[mesh.line_part == PART_ID[INTERFACE_PARTS[kind][2]]]


def test_tributary_areas_add_up_to_the_interfaces(meshes):
    _, cut, _, base = meshes
    # usp: 37 sleepers x 2.5 m x 0.27 m bearing width
    assert tributary_areas(cut, "usp", 0.27).sum() == \
        pytest.approx(37 * 2.5 * 0.27, rel=1e-12)
    # the mat: the ballast's underside, 21.6 m x 2 x 3.75 m
    assert tributary_areas(cut, "ballast_mat").sum() == \
        pytest.approx(21.6 * 7.5, rel=1e-12)
    # bearings at the ground: under the 4 columns, 0.6 m square
    assert tributary_areas(cut, "isolation").sum() == \
        pytest.approx(4 * 0.36, rel=1e-12)
    # under the footings: the 4 pads (5.76 m^2), the wall between them (8.28 - 4 x 0.63) and
    # the grade beams between the pads (4 x 4.8 m x 0.6 m)
    assert tributary_areas(base, "isolation").sum() == \
        pytest.approx(4 * 1.44 + (7.2 ** 2 - 6.6 ** 2 - 4 * 0.63) + 4 * 4.8 * 0.6, rel=1e-12)


def test_the_cut_separates_the_sides(meshes):
    plain, cut, report, _ = meshes
    assert len(cut.hexes) == len(plain.hexes)
    n_pairs = sum(len(springs(cut, k)) for k in INTERFACE_PARTS)
    assert cut.n_nodes == plain.n_nodes + n_pairs
    q = report["quality"]
    assert q["duplicate_nodes"] == 0 and q["nonconformal_faces"] == 0 and q["unused_nodes"] == 0
    # every pair coincides; the sleepers no longer touch the ballast, the ballast no
    # longer touches the subballast
    for kind in INTERFACE_PARTS:
        pairs = springs(cut, kind)
        assert np.array_equal(cut.points[pairs[:, 0]], cut.points[pairs[:, 1]])
    sleeper_nodes = np.unique(cut.lines[cut.line_part == PART_ID["sleeper"]])
    ballast_nodes = np.unique(cut.hexes[cut.hex_part == PART_ID["ballast"]])
    sub_nodes = np.unique(cut.hexes[cut.hex_part == PART_ID["subballast"]])
    assert not np.intersect1d(sleeper_nodes, ballast_nodes).size
    assert not np.intersect1d(ballast_nodes, sub_nodes).size
    # the nodes stay numbered along the track (the parallel split relies on it)
    assert np.all(np.diff(np.round(cut.points[:, 0], 7)) >= 0)


def test_block_on_a_mat_bounces_at_the_rigid_mass_frequency():
    """A 2 m x 2 m x 0.5 m block (ballast, E = 1e14 Pa: rigid beside the mat) on a mat of
    bedding modulus 5e7 N/m^3 over a fixed subballast slab."""
    case = thesis_case(**{"ballast_mat.modulus": 5e7, "materials.ballast.E": 1e14})
    z2 = case["geometry.z2"]
    pts, hexes = box_mesh(4, 4, 3, 2.0, 2.0, 1.5)
    pts[:, 2] += z2 - 1.0                                     # 1 m below Z2, 0.5 m above
    part = np.where(pts[hexes, 2].mean(axis=1) > z2, PART_ID["ballast"], PART_ID["subballast"])
    mesh = Mesh(points=pts, hexes=hexes, hex_part=part.astype(np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets={})
    mesh = split_interfaces(mesh, case)
    assert len(springs(mesh, "ballast_mat")) == 25
    n = 3 * mesh.n_nodes
    K, M = sp.csr_matrix((n, n)), sp.csr_matrix((n, n))
    index = np.arange(n).reshape(-1, 3)
    for b in element_batches(mesh, Problem.from_case(case)):
        dofs = b.dofs(index)
        K = K + assemble_matrix(dofs, b.K, n)
        if b.M is not None:
            M = M + assemble_matrix(dofs, b.M, n)
    # the subballast is held (its nodes fixed); the block moves on the mat only
    sub = np.unique(mesh.hexes[mesh.hex_part == PART_ID["subballast"]])
    free = np.setdiff1d(np.arange(n), (3 * sub[:, None] + np.arange(3)).ravel())
    k, m = K[free][:, free].toarray(), M[free][:, free].toarray()
    lam, phi = la.eigh(k, m, subset_by_index=[0, 5])
    uz = phi[2::3]
    vertical = int(np.argmax(np.abs(uz).sum(axis=0) / np.abs(phi).sum(axis=0)))
    mass = 2.0 * 2.0 * 0.5 * case["materials.ballast.rho"]
    exact = np.sqrt(5e7 * 4.0 / mass)
    # the block's own stiffness (E A / h ~ 1e15 N/m against the mat's 2e8) moves it < 1e-6
    assert np.sqrt(lam[vertical]) == pytest.approx(exact, rel=1e-5)


def test_interface_damping_is_half_the_loss_factor():
    case = thesis_case(**{"usp.modulus": 1e8, "usp.loss_factor": 0.16})
    problem = Problem.from_case(case)
    assert group_damping_ratio(problem, "usp") == pytest.approx(0.08)
    assert group_damping_ratio(problem, "subgrade") == case["materials.subgrade.damping_ratio"]


@pytest.mark.parametrize("changes, key, words", [
    ({"usp.modulus": -1.0}, "usp.modulus", ">= 0"),
    ({"ballast_mat.modulus": 1e7, "ballast_mat.shear_ratio": 0.0},
     "ballast_mat.shear_ratio", "> 0"),
    ({"isolation.modulus": 1e8, "isolation.level": "roof"}, "isolation.level", "ground"),
])
def test_bad_interfaces_get_one_clear_line(changes, key, words):
    with pytest.raises(CaseError) as info:
        thesis_case(**changes)
    text = str(info.value)
    assert key in text and words in text and "\n" not in text.strip()
