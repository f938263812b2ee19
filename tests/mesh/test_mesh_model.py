"""The generated thesis model: volumes, quality, connectivity, conformity, refinement."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.config import load_case
from railvib_hpc.mesh.gmsh_model import generate
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.mesh.search import locate
from railvib_hpc.schema import PART_ID

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"


def analytic_volumes(case) -> dict[str, float]:
    """Geometric volume of each solid part from the case parameters."""
    g, b, d = case["geometry"], case["building"], case["domain"]
    soil_len = g["x4"] - g["x1"] + 2 * d["extra_length"]
    soil_wid = g["ys0"] - g["ys4"] + d["extra_width"]
    depth = g["z1"] - g["z0"] + d["extra_depth"]
    side = g["x3"] - g["x2"]
    basement = g["z1"] - g["zbb"]
    toe, bb, bt = -g["ys1"], g["ballast_bottom_half_width"], g["ballast_top_half_width"]
    fs, fh, cs, wt = b["footing_size"], b["footing_height"], b["column_size"], b["wall_thickness"]
    bd, st = b["beam_depth"], b["slab_thickness"]
    inner = side - 2 * fs                      # clear length between footings
    span = side - fs - cs                      # clear length between columns
    ring = side**2 - (side - 2 * wt) ** 2      # wall ring area in plan
    col_h = (b["z_slab1_base"] - fh) + (b["z_slab2_base"] - b["z_slab1_base"] - st)
    return {
        "subgrade": soil_len * soil_wid * depth - side * side * basement,
        "subballast": soil_len * (g["z2"] - g["z1"]) * (toe + bb),
        "ballast": soil_len * (g["z3"] - g["z2"]) * (bb + bt),
        "footing": 4 * fs * fs * fh,
        "column": 4 * cs * cs * col_h,
        "slab": 2 * (side - fs + cs) ** 2 * st,
        "wall": ring * basement - 4 * (fs**2 - (fs - wt) ** 2) * fh,
        "beam": 4 * inner * cs * bd + 3 * 4 * span * cs * bd,
    }


def test_volume_per_part_equals_geometry(baseline_mesh):
    _, report = baseline_mesh
    case = load_case(BASELINE)
    expected = analytic_volumes(case)
    assert set(report["volume_per_part"]) == set(expected)
    for part, vol in expected.items():
        assert report["volume_per_part"][part] == pytest.approx(vol, rel=1e-12, abs=1e-9), part


def test_quality_and_conformity(baseline_mesh):
    mesh, report = baseline_mesh
    q = report["quality"]
    assert q["n_inverted"] == 0 and q["min_scaled_jacobian"] > 0.7
    assert np.all(mesh.hex_volumes() > 0)
    assert q["duplicate_nodes"] == 0 and q["unused_nodes"] == 0
    assert q["nonconformal_faces"] == 0
    # the thesis's model had 63,884 nodes; the issue asks for 45-65k at refinement 1
    assert 45_000 <= mesh.n_nodes <= 65_000


def _nodes_of(mesh, part):
    pid = PART_ID[part]
    conn = mesh.hexes[mesh.hex_part == pid] if pid in mesh.hex_part else \
        mesh.lines[mesh.line_part == pid]
    return np.unique(conn)


def test_rails_sleepers_pads_connect_as_specified(baseline_mesh):
    mesh, _ = baseline_mesh
    case = load_case(BASELINE)
    g, t = case["geometry"], case["track"]
    hg = t["gauge"] / 2
    p = mesh.points
    # flexible rails: 2 x 36 bays x 5 elements of 0.12 m at the rail height
    rail = mesh.lines[mesh.line_part == PART_ID["rail"]]
    assert len(rail) == 2 * 36 * 5
    seg = p[rail[:, 1]] - p[rail[:, 0]]
    assert np.allclose(np.abs(seg[:, 0]), 0.12) and np.allclose(seg[:, 1:], 0)
    assert np.allclose(p[rail][..., 2], g["z4"])
    assert np.allclose(np.abs(p[rail][..., 1]), hg)
    # rigid rails: 3 m at both ends of both rails, sharing the end nodes of the flexible rail
    rigid = mesh.lines[mesh.line_part == PART_ID["rigid_rail"]]
    assert len(rigid) == 4
    assert np.allclose(np.sort(np.abs(p[rigid[:, 1], 0] - p[rigid[:, 0], 0])), t["rigid_length"])
    assert len(np.intersect1d(np.unique(rigid), np.unique(rail))) == 4
    # sleepers: 37 x (2 + 4 + 2) elements on the ballast crest, nodes shared with the ballast
    sl = mesh.lines[mesh.line_part == PART_ID["sleeper"]]
    assert len(sl) == 37 * 8
    assert np.allclose(p[sl][..., 2], g["z3"])
    assert set(np.round(np.unique(p[sl][..., 0]), 6)) == \
        set(np.round(g["x1"] + 0.6 * np.arange(37), 6))
    assert np.all(np.isin(np.unique(sl), _nodes_of(mesh, "ballast")))
    # pads: three spring-dampers per rail/sleeper crossing, rail node above sleeper node
    for name in ("pad_x", "pad_y", "pad_z"):
        pad = mesh.lines[mesh.line_part == PART_ID[name]]
        assert len(pad) == 2 * 37
        top, bottom = pad[:, 0], pad[:, 1]
        assert np.allclose(p[top, 2], g["z4"]) and np.allclose(p[bottom, 2], g["z3"])
        assert np.allclose(p[top, :2], p[bottom, :2])
        assert np.all(np.isin(top, np.unique(np.r_[rail.ravel(), rigid.ravel()])))
        assert np.all(np.isin(bottom, np.unique(sl)))
    pads = [np.sort(mesh.lines[mesh.line_part == PART_ID[n]], axis=1) for n in
            ("pad_x", "pad_y", "pad_z")]
    assert np.array_equal(pads[0], pads[1]) and np.array_equal(pads[0], pads[2])


def test_building_shares_nodes_with_soil(baseline_mesh):
    mesh, _ = baseline_mesh
    case = load_case(BASELINE)
    g = case["geometry"]
    p = mesh.points
    soil = _nodes_of(mesh, "subgrade")
    building = np.unique(np.concatenate([_nodes_of(mesh, k) for k in
                                         ("footing", "beam", "wall", "column", "slab")]))
    # every building node on the excavation surface (bottom and the four sides) is a soil node
    x, y, z = p[building].T
    on_pit = (np.isclose(z, g["zbb"]) | (
        (z <= g["z1"] + 1e-9) & (np.isclose(x, g["x2"]) | np.isclose(x, g["x3"]) |
                                 np.isclose(y, g["ys2"]) | np.isclose(y, g["ys3"]))))
    interface = building[on_pit]
    assert len(interface) > 1000
    assert np.all(np.isin(interface, soil))
    # and the soil's excavation surface has no node that the building lacks (no hanging nodes)
    xs, ys, zs = p[soil].T
    inside_plan = (xs > g["x2"] - 1e-9) & (xs < g["x3"] + 1e-9) & \
        (ys > g["ys3"] - 1e-9) & (ys < g["ys2"] + 1e-9) & (zs > g["zbb"] - 1e-9)
    pit_soil = soil[inside_plan]
    footprint_in_building = np.isin(pit_soil, building)
    # soil nodes in the pit region are on its surface; those under the building's solid parts
    # are building nodes, the rest lie on the floor of the open basement interior
    open_floor = np.isclose(p[pit_soil[~footprint_in_building], 2], g["zbb"])
    assert np.all(open_floor)


def test_node_sets(baseline_mesh, baseline_layout):
    mesh, _ = baseline_mesh
    xmin, xmax, ymin, ymax, zmin, _ = baseline_layout.bounds
    p = mesh.points
    assert np.allclose(p[mesh.node_sets["bottom"], 2], zmin)
    assert np.sum(np.isclose(p[:, 2], zmin)) == len(mesh.node_sets["bottom"])
    xf = p[mesh.node_sets["x_faces"], 0]
    assert np.all(np.isclose(xf, xmin) | np.isclose(xf, xmax))
    solid_nodes = np.unique(mesh.hexes)
    on_x = solid_nodes[np.isclose(p[solid_nodes, 0], xmin) | np.isclose(p[solid_nodes, 0], xmax)]
    assert np.array_equal(np.sort(on_x), mesh.node_sets["x_faces"])
    yf = p[mesh.node_sets["y_faces"], 1]
    assert np.all(np.isclose(yf, ymin) | np.isclose(yf, ymax))


def test_probes_lie_in_the_model(baseline_mesh):
    mesh, _ = baseline_mesh
    names = list(mesh.probes)
    assert {"footing", "basement_wall", "slab1", "slab2"} <= set(names)
    assert sum(n.startswith("ground") for n in names) >= 3
    elem, _ = locate(np.array([mesh.probes[n] for n in names]), mesh)
    assert np.all(elem >= 0), dict(zip(names, elem))
    part_of = {n: mesh.hex_part[e] for n, e in zip(names, elem)}
    assert part_of["slab1"] == PART_ID["slab"] and part_of["slab2"] == PART_ID["slab"]
    assert part_of["footing"] in (PART_ID["footing"], PART_ID["column"])


@pytest.mark.slow
def test_refinement_increases_counts():
    counts = []
    for r in (0.5, 1.0, 2.0):
        mesh, _ = generate(build_layout(load_case(BASELINE, [f"mesh.refinement={r}"])))
        counts.append((mesh.n_nodes, mesh.counts_per_part()))
        assert mesh.quality()["n_inverted"] == 0
    for (n0, c0), (n1, c1) in zip(counts, counts[1:]):
        assert n1 > n0
        assert all(c1[p] >= c0[p] for p in c0)
        assert sum(c1.values()) > sum(c0.values())
    # refinement 2 halves the element size: ~8x the solid elements
    assert 6.0 < counts[2][1]["subgrade"] / counts[1][1]["subgrade"] <= 8.0


def test_domain_extensions_change_volumes_exactly():
    from railvib_hpc.mesh.stage import make_mesh

    case = load_case(BASELINE, ["domain.extra_depth=2.0", "domain.extra_width=6.0",
                                "domain.extra_length=2.0", "mesh.refinement=0.5"])
    _, report = make_mesh(case)
    expected = analytic_volumes(case)
    for part, vol in expected.items():
        assert report["volume_per_part"][part] == pytest.approx(vol, rel=1e-12), part
    assert report["quality"]["nonconformal_faces"] == 0
    assert report["quality"]["n_inverted"] == 0


def test_thesis_layout_reproduces_appendix_b_element_counts(baseline_mesh, baseline_layout):
    """Appendix B's element ranges: ballast 661-3348 (2,688), subballast 3349-6036 (2,688),
    subgrade 6037-18324 (12,288, the track zone), concrete 18547-22794 (4,248), subgrade
    22795-42762 (19,968, the building side): 41,880 hexahedra; rails 1-364, sleepers
    365-660, springs 18325-18546."""
    mesh, report = baseline_mesh
    case = load_case(BASELINE)
    assert case["mesh.layout"] == "thesis"
    counts = report["elements_per_part"]
    assert counts["ballast"] == 2688 and counts["subballast"] == 2688
    concrete = sum(counts[p] for p in ("footing", "column", "beam", "slab", "wall"))
    assert concrete == 4248
    sub = mesh.hex_part == PART_ID["subgrade"]
    yc = mesh.points[mesh.hexes[sub]][:, :, 1].mean(axis=1)
    ys1 = case["geometry.ys1"]
    assert np.sum(yc > ys1) == 12288 and np.sum(yc < ys1) == 19968
    assert len(mesh.hexes) == 41880
    from railvib_hpc.assess.thesis import THESIS_LAYOUT_NODES

    assert mesh.n_nodes == THESIS_LAYOUT_NODES == 51359
    assert counts["rail"] + counts["rigid_rail"] == 364 and counts["sleeper"] == 296
    assert counts["pad_x"] + counts["pad_y"] + counts["pad_z"] == 222
    # the divisions behind them (docs/thesis.md): 96 along x, 8 x 0.6 m in the subgrade,
    # 2 per embankment layer, 16 across the track zone, 3 + 24 + 5 on the building side
    lay = baseline_layout
    assert lay.nx.sum() == 32 + 48 + 16
    yb, ny = lay.yb, lay.ny
    track = (yb[:-1] >= ys1 - 1e-9)
    assert ny[track].sum() == 3 + 2 + 4 + 2 + 3 + 2
    beyond = yb[1:] <= case["geometry.ys3"] + 1e-9
    gap = (yb[:-1] >= case["geometry.ys2"] - 1e-9) & (yb[1:] <= ys1 + 1e-9)
    plan = ~track & ~beyond & ~gap
    assert (ny[beyond].sum(), ny[plan].sum(), ny[gap].sum()) == (3, 24, 5)
    below = [n for (z0, z1), n in lay.zdiv.items() if z1 <= case["geometry.z1"] + 1e-9]
    assert sum(below) == 8
    assert lay.zdiv[(4.8, 5.3)] == 2 and lay.zdiv[(5.3, 5.8)] == 2
    # clean: no inverted, duplicate, unused or non-conformal element
    q = report["quality"]
    assert q["n_inverted"] == 0 and q["nonconformal_faces"] == 0
    assert q["duplicate_nodes"] == 0 and q["unused_nodes"] == 0
    assert q["min_scaled_jacobian"] > 0.7


def test_refined_layout_keeps_its_counts():
    """The engineering layout (mesh.layout = 'refined') is unchanged: 52,056 hexahedra."""
    mesh, _ = generate(build_layout(load_case(BASELINE, ["mesh.layout=refined"])))
    c = mesh.counts_per_part()
    assert len(mesh.hexes) == 52056 and mesh.n_nodes == 63872
    assert (c["ballast"], c["subballast"], c["subgrade"]) == (1344, 1344, 45120)
    assert mesh.quality()["n_inverted"] == 0


def test_thesis_layout_rejects_refined_only_keys():
    from railvib_hpc.errors import CaseError

    with pytest.raises(CaseError, match=r"mesh\.size_far.*applies to mesh.layout = 'refined'"):
        load_case(BASELINE, ["mesh.size_far=0.3"])
    assert load_case(BASELINE, ["mesh.layout=refined", "mesh.size_far=0.3"])


def test_far_wall_probe_is_20_m_from_the_entry():
    """basement_wall_far: the far end (x = X3) of the track-side wall, the thesis's 20.2 m."""
    case = load_case(BASELINE)
    lay = build_layout(case)
    x, y, _ = lay.probes["basement_wall_far"]
    g = case["geometry"]
    assert (x, y) == (g["x3"], g["ys2"])
    far_rail = np.array([g["x1"], 0.5 * case["track.gauge"], g["z4"]])
    assert np.linalg.norm(np.array([x, y, g["zbb"]]) - far_rail) == pytest.approx(20.2, abs=0.02)
