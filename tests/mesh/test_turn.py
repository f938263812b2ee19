"""A building turned against the track (``building.rotation``, ``railvib_hpc.mesh.turn``).

The twist keeps every circle round the plan centre and every area, so: the building and
every part keep their volume to round-off, the building's nodes are its unturned nodes
rotated rigidly, nothing beyond the ring moves (track, embankment, domain faces), no
element folds, the mesh stays conformal, and it still passes the patch test (a linear
displacement field leaves no residual at interior nodes). Bad input gets one line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.config import MAX_TWIST_SHEAR, BuildingTurn, Case, building_turn, twist_weight
from railvib_hpc.errors import CaseError
from railvib_hpc.fem import assemble_matrix, element_dofs, hex8_stiffness
from railvib_hpc.mesh.search import boundary_faces
from railvib_hpc.mesh.stage import format_report, make_mesh
from railvib_hpc.mesh.turn import twist
from railvib_hpc.schema import BUILDING_PARTS, PART_ID

ROOT = Path(__file__).resolve().parents[2]
EPS = np.finfo(float).eps
ANGLE = 15.0


def thesis_case(**changes) -> Case:
    return Case.from_file(ROOT / "jobs" / "thesis_baseline.toml").replace(changes)


@pytest.fixture(scope="module")
def meshes():
    """The thesis mesh unturned and turned by ANGLE degrees, with their reports."""
    straight = make_mesh(thesis_case())
    turned = make_mesh(thesis_case(**{"building.rotation": ANGLE}))
    return straight, turned


def rotation(deg: float, centre) -> np.ndarray:
    """Points (n, 3) -> rotated about the vertical through ``centre``."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))

    def apply(p: np.ndarray) -> np.ndarray:
        out = p.copy()
        dx, dy = p[:, 0] - centre[0], p[:, 1] - centre[1]
        out[:, 0], out[:, 1] = centre[0] + c * dx - s * dy, centre[1] + s * dx + c * dy
        return out
    return apply


def sorted_rows(p: np.ndarray) -> np.ndarray:
    key = np.round(p, 9)
    return p[np.lexsort(key.T[::-1])]


def test_twist_weight_and_shear_bound():
    """w is 1 inside, 0 outside, C1 at both ends; the closed-form largest shear equals the
    sampled max of r |w'(r)|."""
    r_in, r_out = 5.0, 9.0
    r = np.linspace(0, 12, 240001)
    w = twist_weight(r, r_in, r_out)
    assert np.all(w[r <= r_in] == 1) and np.all(w[r >= r_out] == 0)
    dw = np.gradient(w, r)
    assert abs(dw[np.searchsorted(r, r_in)]) < 1e-3 and abs(dw[np.searchsorted(r, r_out)]) < 1e-3
    turn = BuildingTurn((0.0, 0.0), 1.0, r_in, r_out, "x")
    assert turn.shear_per_radian == pytest.approx(np.max(r * np.abs(dw)), rel=1e-6)
    assert turn.max_angle * turn.shear_per_radian == pytest.approx(MAX_TWIST_SHEAR)


def test_twist_keeps_circles_and_areas():
    """|p - c| is kept; the Jacobian determinant of the map is 1 (finite differences)."""
    turn = BuildingTurn((1.0, -2.0), math.radians(30), 2.0, 5.0, "x")
    rng = np.random.default_rng(3)
    p = np.c_[rng.uniform(-6, 8, (500, 2)), rng.uniform(0, 1, 500)]
    q = twist(p, turn)
    c = np.array([1.0, -2.0])
    assert np.allclose(np.hypot(*(q[:, :2] - c).T), np.hypot(*(p[:, :2] - c).T), atol=1e-12)
    assert np.array_equal(q[:, 2], p[:, 2])
    h = 1e-6
    jx = (twist(p + [h, 0, 0], turn) - twist(p - [h, 0, 0], turn))[:, :2] / (2 * h)
    jy = (twist(p + [0, h, 0], turn) - twist(p - [0, h, 0], turn))[:, :2] / (2 * h)
    det = jx[:, 0] * jy[:, 1] - jx[:, 1] * jy[:, 0]
    assert np.allclose(det, 1.0, atol=1e-7)


def test_turned_thesis_mesh(meshes):
    (m0, rep0), (m1, rep1) = meshes
    turn = building_turn(thesis_case(**{"building.rotation": ANGLE}))
    q = rep1["quality"]
    # the same elements, parts and node sets; conformal, nothing folded
    assert (q["n_hexes"], q["n_nodes"]) == (rep0["quality"]["n_hexes"], rep0["quality"]["n_nodes"])
    assert rep1["elements_per_part"] == rep0["elements_per_part"]
    assert rep1["node_sets"] == rep0["node_sets"]
    assert q["n_inverted"] == 0 and q["nonconformal_faces"] == 0 and q["duplicate_nodes"] == 0
    # a square sheared by gamma keeps a scaled Jacobian of 1/sqrt(1 + gamma^2); the
    # straight mesh's least is that of its shoulder blocks
    gamma = turn.shear
    assert 0 < gamma <= MAX_TWIST_SHEAR
    assert q["min_scaled_jacobian"] >= 0.5 * rep0["quality"]["min_scaled_jacobian"]
    # every part keeps its volume (area-preserving map, rigid inside, identity outside):
    # round-off of the sum of the part's element volumes
    for part, v0 in rep0["volume_per_part"].items():
        n = rep0["elements_per_part"][part]
        assert rep1["volume_per_part"][part] == pytest.approx(v0, rel=10 * EPS * n, abs=1e-12)
    # the building's nodes are its unturned nodes rotated rigidly
    turn_pts = rotation(ANGLE, turn.centre)
    ids = [PART_ID[p] for p in BUILDING_PARTS]
    b0 = m0.points[np.unique(m0.hexes[np.isin(m0.hex_part, ids)])]
    b1 = m1.points[np.unique(m1.hexes[np.isin(m1.hex_part, ids)])]
    assert np.abs(sorted_rows(turn_pts(b0)) - sorted_rows(b1)).max() < 64 * EPS * 30
    # beyond the ring nothing moves: the rails, sleepers and pads (line elements) exactly
    assert np.array_equal(sorted_rows(m0.points[np.unique(m0.lines)]),
                          sorted_rows(m1.points[np.unique(m1.lines)]))
    far = np.hypot(m0.points[:, 0] - turn.centre[0], m0.points[:, 1] - turn.centre[1]) \
        >= turn.r_out
    assert np.array_equal(sorted_rows(m0.points[far]),
                          sorted_rows(m1.points[np.hypot(m1.points[:, 0] - turn.centre[0],
                                                         m1.points[:, 1] - turn.centre[1])
                                                >= turn.r_out]))
    # the building's probes turn with it, the ground's far from it stay
    for name, p in m0.probes.items():
        expect = turn_pts(np.array([p]))[0] if name.startswith(("slab", "footing", "basement")) \
            else twist(np.array([p]), turn)[0]
        assert np.allclose(m1.probes[name], expect, atol=1e-12)
    assert m1.probes["ground_toe"] == m0.probes["ground_toe"]
    assert "building turned 15 deg" in format_report(rep1)


def test_the_written_msh_is_turned_too(tmp_path):
    """mesh.msh (gmsh's own file) carries the turned nodes: read back, its points are the
    turned mesh's."""
    from railvib_hpc.mesh.gmsh_model import read_msh

    case = thesis_case(**{"building.rotation": ANGLE, "mesh.refinement": 0.5})
    mesh, _ = make_mesh(case, tmp_path / "mesh.msh")
    back = read_msh(tmp_path / "mesh.msh")
    assert np.abs(sorted_rows(back.points) - sorted_rows(mesh.points)).max() < 1e-12


def test_turned_mesh_passes_the_patch_test(meshes):
    """K u = 0 at interior nodes for u linear: the twisted elements still fit together."""
    _, (m1, _) = meshes
    pts, hexes = m1.points, m1.hexes
    ke = hex8_stiffness(pts[hexes], 1.0e8, 0.3)
    dofs = element_dofs(hexes, 3)
    K = assemble_matrix(dofs, ke, 3 * len(pts))
    rng = np.random.default_rng(7)
    grad_u = rng.normal(size=(3, 3)) * 1e-3
    u = (pts @ grad_u.T).ravel()
    r = (K @ u).reshape(-1, 3)
    on_boundary = np.zeros(len(pts), bool)
    on_boundary[np.unique(boundary_faces(hexes))] = True
    inside = ~on_boundary
    assert inside.sum() > 10000
    # round-off of a row sum over <= 81 neighbour DOFs
    tol = 81 * 10 * EPS * abs(K).max() * np.abs(u).max()
    assert np.abs(r[inside]).max() < tol
    # and it is not trivially so: the boundary rows carry the tractions
    assert np.abs(r[on_boundary]).max() > 1e3 * tol


@pytest.mark.parametrize(("changes", "needle"), [
    ({"building.rotation": 30.0}, "building.rotation = 30.0: at most +-18.5 deg here"),
    ({"building.rotation": 10.0, "trench.type": "open", "trench.distance": 5.0,
      "trench.width": 3.5, "trench.depth": 1.0},
     "building.rotation = 10.0: no room to turn the building: its corners (5.091 m from its "
     "centre) reach the trench's far face (5 m from it)"),
    ({"building.rotation": 5.0, "mesh.file": "../meshes/tiny_user_mesh.msh"},
     "building.rotation = 5.0: turns the generated mesh's building"),
])
def test_bad_turns_get_one_line(changes, needle):
    with pytest.raises(CaseError) as err:
        thesis_case(**changes)
    assert needle in str(err.value)
    assert "\n" not in str(err.value).strip()


def test_room_grows_with_the_domain():
    """A longer domain lets the building turn further (the ring widens)."""
    small = building_turn(thesis_case(**{"building.rotation": 10.0}))
    big = building_turn(thesis_case(**{"building.rotation": 10.0, "domain.extra_length": 12.0}))
    assert big.r_out > small.r_out and big.max_angle > small.max_angle
