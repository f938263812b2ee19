"""A building turned against the track (``building.rotation``, ``railvib_hpc.mesh.turn``).

Whole quarter turns are exact: the building's parts and probes are the unturned ones
turned, and no soil twists. The rest twists the soil round the building. The twist keeps
every circle round the plan centre and every area, so: the building and every part keep
their volume to round-off, the building's nodes are its unturned nodes rotated rigidly,
nothing beyond the ring moves (track, embankment, domain faces), no element folds, the mesh
stays conformal, and it still passes the patch test (a linear displacement field leaves no
residual at interior nodes). Bad input gets one line.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError, MeshError
from railvib_hpc.fem import assemble_matrix, element_dofs, hex8_stiffness
from railvib_hpc.mesh.building import Building
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.mesh.search import boundary_faces
from railvib_hpc.mesh.stage import format_report, make_mesh
from railvib_hpc.mesh.turn import (
    MIN_TWISTED_JACOBIAN,
    TwistMap,
    quad_jacobians,
    relax,
    twist,
    twist_weight,
)
from railvib_hpc.schema import BUILDING_PARTS, PART_ID
from railvib_hpc.site import (
    MAX_TWIST_SHEAR,
    BuildingTurn,
    building_turn,
    placed_plan,
    turn_quarters,
)

ROOT = Path(__file__).resolve().parents[2]
EPS = np.finfo(float).eps
ANGLE = 15.0


def thesis_case(**changes) -> Case:
    return Case.from_file(ROOT / "jobs" / "thesis_baseline.toml").replace(changes)


@pytest.fixture(scope="module")
def meshes():
    """The thesis mesh turned by ANGLE degrees and its straight twin (the same layout, with
    the ring's extra divisions, not twisted), with their reports."""
    case = thesis_case(**{"building.rotation": ANGLE})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("railvib_hpc.mesh.stage.turn_map", lambda *args: None)
        mp.setattr("railvib_hpc.mesh.stage.turn_building", lambda mesh, *args: mesh)
        straight = make_mesh(case)
    turned = make_mesh(case)
    return straight, turned


@pytest.mark.slow
def test_the_ring_is_divided_in_proportion_to_the_twist():
    """The unturned thesis mesh is the thesis's (41,880 hexahedra); a twist divides the
    soil across its ring more finely, the more the larger the twist; quarter turns do not."""
    counts = {a: make_mesh(thesis_case(**{"building.rotation": a, "mesh.refinement": 1.0})
                           )[1]["quality"]["n_hexes"] for a in (0.0, 90.0, 15.0, 30.0)}
    assert counts[0.0] == counts[90.0] == 41880
    assert 41880 < counts[15.0] < counts[30.0]


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
    """w is 1 inside, 0 outside, continuous; its shear r |w'(r)| is the same all across the
    ring and equals the closed form 1 / ln(r_out / r_in)."""
    r_in, r_out = 5.0, 9.0
    r = np.linspace(0, 12, 240001)
    w = twist_weight(r, r_in, r_out)
    assert np.all(w[r <= r_in] == 1) and np.all(w[r >= r_out] == 0)
    assert np.abs(np.diff(w)).max() < 1e-3
    ring = (r > r_in + 1e-3) & (r < r_out - 1e-3)
    shear = (r * np.abs(np.gradient(w, r)))[ring]
    turn = BuildingTurn((0.0, 0.0), 1.0, r_in, r_out, "x")
    assert np.allclose(shear, turn.shear_per_radian, rtol=1e-6)
    assert turn.shear_per_radian == pytest.approx(1 / math.log(r_out / r_in), rel=1e-15)
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


# a trench whose far face is 7 m from the building's centre: the ring is 5.09-7 m
NEAR_TRENCH = {"trench.type": "open", "trench.distance": 4.5, "trench.width": 2.0,
               "trench.depth": 1.0}


@pytest.mark.parametrize(("changes", "needle"), [
    ({"building.rotation": 44.0, **NEAR_TRENCH},
     "building.rotation = 44.0: +44 deg from the nearest whole quarter turn, 0 deg, twists "
     "the soil; at most +-39.1 deg here: the soil between the building's corners (5.091 m "
     "from its centre) and the trench's far face (7 m from it)"),
    ({"building.rotation": -50.0, **NEAR_TRENCH},
     "building.rotation = -50.0: +40 deg from the nearest whole quarter turn, 270 deg, "
     "twists the soil; at most +-39.1 deg here"),
    ({"building.rotation": 10.0, "trench.type": "open", "trench.distance": 5.0,
      "trench.width": 3.5, "trench.depth": 1.0},
     "building.rotation = 10.0: +10 deg from the nearest whole quarter turn, 0 deg, twists "
     "the soil, and there is no room for it: the building's corners (5.091 m from its "
     "centre) reach the trench's far face (5 m from it)"),
    ({"building.rotation": 5.0, "mesh.file": "../meshes/tiny_user_mesh.msh"},
     "building.rotation = 5.0: turns the generated mesh's building"),
    ({"building.rotation": 90.0, "geometry.x2": 3.6, "geometry.x3": 24.0,
      "geometry.xbb": 13.8},
     "building.rotation = 90.0: the plan turned by 1 quarter turn (7.2 x 20.4 m about its "
     "centre) must lie inside the soil and clear of the embankment: its face comes to 3.3 m "
     "from the track, within the embankment toe at 4.25 m"),
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


@pytest.mark.slow
def test_the_elements_bound_the_twist(tmp_path):
    """45 deg passes the ring's shear bound on the thesis site (1.57 <= 2.14) but not its
    mesh: its soil elements by the building's corners would shear past corner angles of
    25-155 deg, also with the ring relaxed (the domain's end is 4.8 m from the building).
    One line with the largest twist the elements allow, exit code 2, and no mesh.msh left
    behind; that largest twist meshes."""
    case = thesis_case(**{"building.rotation": 45.0})
    assert building_turn(case).shear < MAX_TWIST_SHEAR
    with pytest.raises(MeshError) as err:
        make_mesh(case)
    text = str(err.value)
    assert text.startswith("building.rotation = 45.0: twisting the soil by +45 deg from 0 deg")
    assert "\n" not in text
    largest = float(text.split("allow at most ")[1].split(" deg")[0])
    assert 35.0 < largest < 45.0
    _, rep = make_mesh(thesis_case(**{"building.rotation": largest}))
    assert rep["quality"]["min_scaled_jacobian"] >= MIN_TWISTED_JACOBIAN
    # the command line: one line, exit code 2, nothing half-written
    proc = subprocess.run([sys.executable, "-m", "railvib_hpc", "mesh",
                           str(ROOT / "jobs" / "thesis_baseline.toml"), "--out", str(tmp_path),
                           "--set", "building.rotation=45"], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 2
    assert [ln for ln in proc.stderr.splitlines() if "error" in ln] == [
        f"railvib mesh: error: {text}"]
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "mesh.msh").exists() and not (tmp_path / "mesh.h5").exists()


# a rectangular building with unequal spans, 2 x 1 bays: quarter turns exchange its length
# and width, so the layout around it changes, but its parts and probes must be the
# unturned ones turned
OBLONG = {"geometry.x3": 22.2, "geometry.xbb": 17.4, "building.bays_x": 2,
          "building.spans_x": [3.0, 5.4], "mesh.refinement": 0.5}


@pytest.fixture(scope="module")
def oblong():
    return {deg: make_mesh(thesis_case(**OBLONG, **{"building.rotation": deg}))[0]
            for deg in (0.0, 90.0, 180.0, 270.0, 100.0)}


@pytest.mark.parametrize("quarters", [1, 2, 3])
def test_quarter_turns_are_exact(oblong, quarters):
    """Every building element of the turned mesh, turned back, lies in the unturned
    building's part of the same name; every part keeps its volume; the building's probes
    are the unturned ones turned; the plan's length and width are exchanged."""
    case = thesis_case(**OBLONG, **{"building.rotation": 90.0 * quarters})
    m0, m1 = oblong[0.0], oblong[90.0 * quarters]
    own = Building.of_case(thesis_case(**OBLONG))
    centre = own.centre
    ids = {PART_ID[p]: p for p in BUILDING_PARTS}
    in_building = np.isin(m1.hex_part, list(ids))
    centroids = m1.points[m1.hexes[in_building]].mean(axis=1)
    x, y = turn_quarters(centroids[:, 0], centroids[:, 1], -quarters, centre)
    parts = [own.part(a, b, c) for a, b, c in zip(x, y, centroids[:, 2])]
    assert parts == [ids[i] for i in m1.hex_part[in_building]]
    for pid, name in ids.items():
        v = [float(np.sum(_volumes(m.points[m.hexes[m.hex_part == pid]]))) for m in (m0, m1)]
        assert v[1] == pytest.approx(v[0], rel=1e-12), name
    for name, p in m0.probes.items():
        if name.startswith(("slab", "footing", "basement")):
            expect = turn_quarters(p[0], p[1], quarters, centre)
            assert np.allclose(m1.probes[name][:2], expect, atol=1e-12, rtol=0), name
            assert m1.probes[name][2] == p[2]
    x_lo, x_hi, y_lo, y_hi = placed_plan(case)
    if quarters % 2:
        assert (x_hi - x_lo, y_hi - y_lo) == pytest.approx((7.2, 9.6), abs=1e-12)
    assert m1.probes["ground_building"][1] == pytest.approx(y_hi, abs=1e-12)


def test_a_quarter_turn_and_a_rest(oblong):
    """100 deg: the 90 deg mesh's building twisted rigidly by 10 deg."""
    m90, m100 = oblong[90.0], oblong[100.0]
    turn = building_turn(thesis_case(**OBLONG, **{"building.rotation": 100.0}))
    assert turn.angle == pytest.approx(math.radians(10.0), rel=1e-15)
    ids = [PART_ID[p] for p in BUILDING_PARTS]
    b90 = m90.points[np.unique(m90.hexes[np.isin(m90.hex_part, ids)])]
    b100 = m100.points[np.unique(m100.hexes[np.isin(m100.hex_part, ids)])]
    assert np.abs(sorted_rows(rotation(10.0, turn.centre)(b90)) - sorted_rows(b100)).max() \
        < 64 * EPS * 30


def _volumes(x: np.ndarray) -> np.ndarray:
    """Volumes of hexahedra (n, 8, 3) that are boxes (the straight building's)."""
    span = x.max(axis=1) - x.min(axis=1)
    return span.prod(axis=1)


def test_relax_raises_the_worst_cell_and_moves_only_free_nodes():
    """A plan grid sheared until a cell folds: the relaxation untangles it (every cell's
    corner angles within 30-150 deg, its target) and leaves the held nodes bit for bit."""
    gx, gy = np.meshgrid(np.linspace(0, 6, 13), np.linspace(0, 4, 9), indexing="ij")
    p = np.stack([gx + 1.5 * np.sin(np.pi * gy / 4) * np.exp(-(gx - 3) ** 2), gy], axis=-1)
    free = np.zeros(gx.shape, bool)
    free[1:-1, 1:-1] = True
    assert quad_jacobians(p).min() < 0
    q = relax(p, free)
    assert quad_jacobians(q).min() >= math.sin(math.radians(30))
    assert np.array_equal(q[~free], p[~free])


@pytest.fixture(scope="module")
def relaxed():
    """The thesis building turned by 45 deg in a domain 6 m longer and wider (the ring
    relaxed), and its straight twin."""
    case = thesis_case(**{"building.rotation": 45.0, **WIDER})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("railvib_hpc.mesh.stage.turn_map", lambda *args: None)
        mp.setattr("railvib_hpc.mesh.stage.turn_building", lambda mesh, *args: mesh)
        straight = make_mesh(case)
    return case, straight, make_mesh(case)


WIDER = {"domain.extra_length": 6.0, "domain.extra_width": 6.0}


def test_a_relaxed_ring_turns_by_45_degrees(relaxed, tmp_path):
    """Every angle is within 45 deg of a quarter turn: with room (a domain 6 m longer and
    wider on the thesis site) 45 deg meshes once the ring is relaxed. The building still
    turns rigidly, nothing beyond the ring moves, every part keeps its volume (the ring's
    boundary is held and the soil moves in plan only), corner angles stay within 25-155
    deg, the elements, parts and node sets are the twin's."""
    case, (m0, rep0), (m1, rep1) = relaxed
    turn = building_turn(case)
    layout = build_layout(case)
    assert TwistMap(case, layout).relaxed
    q = rep1["quality"]
    assert q["n_inverted"] == 0 and q["nonconformal_faces"] == 0 and q["duplicate_nodes"] == 0
    assert q["min_scaled_jacobian"] >= MIN_TWISTED_JACOBIAN
    assert rep1["elements_per_part"] == rep0["elements_per_part"]
    assert rep1["node_sets"] == rep0["node_sets"]
    for part, v0 in rep0["volume_per_part"].items():
        n = rep0["elements_per_part"][part]
        assert rep1["volume_per_part"][part] == pytest.approx(v0, rel=100 * EPS * n, abs=1e-12)
    ids = [PART_ID[p] for p in BUILDING_PARTS]
    b0 = m0.points[np.unique(m0.hexes[np.isin(m0.hex_part, ids)])]
    b1 = m1.points[np.unique(m1.hexes[np.isin(m1.hex_part, ids)])]
    assert np.abs(sorted_rows(rotation(45.0, turn.centre)(b0)) - sorted_rows(b1)).max() \
        < 64 * EPS * 30
    assert np.array_equal(sorted_rows(m0.points[np.unique(m0.lines)]),
                          sorted_rows(m1.points[np.unique(m1.lines)]))
    z0, z1 = np.unique(m0.points[:, 2]), np.unique(m1.points[:, 2])
    assert np.array_equal(z0, z1)                  # the soil moves in plan only
    assert "building turned 45 deg" in format_report(rep1)
    assert "the ring's soil relaxed" in format_report(rep1)
    assert "relaxed" not in format_report(make_mesh(thesis_case(
        **{"building.rotation": ANGLE, "mesh.refinement": 0.5}))[1])


@pytest.mark.slow
def test_the_written_msh_carries_the_relaxed_ring(tmp_path):
    """mesh.msh gets the same map as the mesh (the relaxed ring, not the bare twist)."""
    from railvib_hpc.mesh.gmsh_model import read_msh

    case = thesis_case(**{"building.rotation": 45.0, **WIDER, "mesh.refinement": 0.5})
    mesh, _ = make_mesh(case, tmp_path / "mesh.msh")
    back = read_msh(tmp_path / "mesh.msh")
    assert np.abs(sorted_rows(back.points) - sorted_rows(mesh.points)).max() < 1e-12
