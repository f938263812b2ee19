"""The parametric building (``railvib_hpc.mesh.building``): volumes and masses against hand
counts, the thesis instance, probes per slab and bay, and bad input.

Hand counts: every member is a box, so its volume is a product of the case's sizes. The
example building is 12 m x 12 m in plan with 2 x 2 bays (spans (12 - 1.2)/2 = 5.4 m),
3 storeys, the thesis's member sizes (footing 1.2 m square and 0.6 m high, columns and
beams 0.6 m, slabs 0.2 m, wall 0.3 m, basement 2.4 m deep, slab undersides 4.2, 8.0 and
11.8 m above the base). The slabs reach the outer column faces: 12 - 1.2 + 0.6 = 11.4 m.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.mesh.building import Building, storey_of_probe
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.mesh.stage import predicted_hexes

ROOT = Path(__file__).resolve().parents[2]

#: The 12 m x 12 m, 2 x 2-bay, 3-storey building (the centre of its plan is the base point).
BIG = {"geometry.x2": 10.2, "geometry.x3": 22.2, "geometry.ys3": -21.9, "geometry.ys4": -33.9,
       "geometry.ybb": -15.9, "building.storeys": 3, "building.bays_x": 2, "building.bays_y": 2}


def thesis_case() -> Case:
    return Case.from_file(ROOT / "jobs" / "thesis_baseline.toml")


def part_volumes(case: Case) -> dict[str, float]:
    """Volume of every part of the case's layout blocks."""
    lay = build_layout(case)
    out: dict[str, float] = {}
    for b in lay.blocks:
        vol = (lay.xb[b.i + 1] - lay.xb[b.i]) * (lay.yb[b.j + 1] - lay.yb[b.j]) * (b.z1 - b.z0)
        out[b.part] = out.get(b.part, 0.0) + vol
    return out


def hand_counts(foundation: str) -> dict[str, float]:
    """Member volumes of the example building, member by member [m^3]."""
    n_col, extent, plan = 9, 11.4, 12.0
    # beams: 3 + 3 lines 0.6 m wide over the slab extent, less their 9 crossings (counted
    # twice) and the 9 columns standing there: 34.56 m^2 per beam level
    beam_plan = 6 * 0.6 * extent - 9 * 0.36 - 9 * 0.36
    ring = plan ** 2 - (plan - 2 * 0.3) ** 2                   # 14.04 m^2 of wall in plan
    vol = {
        "column": n_col * 0.36 * (11.8 - 0.6 - 2 * 0.2),     # footing top to top slab, less 2 slabs
        "slab": 3 * extent ** 2 * 0.2,
        # under the 3 slabs and the grade beams on the footings (below the ground the wall's
        # inner face is the outer column face: 0.3 = (1.2 - 0.6)/2)
        "beam": 4 * beam_plan * 0.6,
    }
    if foundation == "pad":
        vol["footing"] = n_col * 1.2 ** 2 * 0.6
        # grade beams between the pads: 6 lines of 12 m less 3 footings of 1.2 m
        vol["beam"] += 6 * (plan - 3 * 1.2) * 0.6 * 0.6
        # the wall, less the corner (1.2^2 - 0.9^2) and edge (1.2 x 0.3) pads it meets
        vol["wall"] = ring * 2.4 - (4 * (1.2 ** 2 - 0.9 ** 2) + 4 * 1.2 * 0.3) * 0.6
    elif foundation == "strip":
        vol["footing"] = (6 * 1.2 * plan - 9 * 1.2 ** 2) * 0.6
        vol["wall"] = ring * (2.4 - 0.6)                        # the outer strips carry it
    else:
        vol["footing"] = plan ** 2 * 0.6
        vol["wall"] = ring * (2.4 - 0.6)
    return vol


@pytest.mark.parametrize("foundation", ["pad", "strip", "raft"])
def test_building_volumes_and_mass_equal_the_hand_counts(foundation):
    case = thesis_case().replace({**BIG, "building.foundation": foundation})
    got = part_volumes(case)
    want = hand_counts(foundation)
    for part, v in want.items():
        assert got[part] == pytest.approx(v, rel=1e-12), part
    rho = case["materials.concrete.rho"]
    mass = rho * sum(got[p] for p in want)
    assert mass == pytest.approx(rho * sum(want.values()), rel=1e-12)


def test_the_thesis_building_is_the_one_bay_two_storey_instance():
    case = thesis_case()
    assert predicted_hexes(build_layout(case)) == 41_880
    got = part_volumes(case)
    # four pads, four columns 7.2 m high, two 6.6 m slabs, beams on four lines at three
    # levels plus the grade beams between the pads, the 2.4 m wall less the corner pads
    want = {"footing": 4 * 1.44 * 0.6, "column": 4 * 0.36 * (8.0 - 0.6 - 0.2),
            "slab": 2 * 6.6 ** 2 * 0.2,
            "beam": 3 * (4 * 0.6 * 6.6 - 8 * 0.36) * 0.6 + 4 * (7.2 - 2.4) * 0.6 * 0.6,
            "wall": (7.2 ** 2 - 6.6 ** 2) * 2.4 - 4 * (1.44 - 0.81) * 0.6}
    for part, v in want.items():
        assert got[part] == pytest.approx(v, rel=1e-12), part


def test_probes_per_slab_and_bay():
    case = thesis_case().replace(BIG)
    lay = build_layout(case)
    floors = [n for n, r in lay.probe_roles.items() if r == "floor"]
    assert len(floors) == 3 * (1 + 2 * 4)              # slab<k> plus mid and corner per bay
    assert {storey_of_probe(n) for n in floors} == {1, 2, 3}
    z3 = case["geometry.zbb"] + 11.8 + 0.2
    x, y, z = lay.probes["slab3_x2y1_mid"]
    assert (x, y, z) == pytest.approx((16.2 + 2.7, -9.9 - 0.6 - 2.7, z3))
    x, y, z = lay.probes["slab1_x1y2_corner"]
    assert (x, y) == pytest.approx((10.2 + 0.6 + 0.3, -9.9 - 0.6 - 5.4 - 0.3))
    assert storey_of_probe("slab12_x1y1_mid") == 12 and storey_of_probe("slabs") is None
    # every floor probe lies in a slab block's top face
    b = Building.of_case(case)
    for name in floors:
        px, py, pz = lay.probes[name]
        assert b.part(px, py, pz - 0.05) == "slab", name


def test_storeys_of_their_own_heights():
    """``building.slab_bases``: a 5.0 m ground storey under two of 3.2 m changes the
    columns (hand count) and the slab probes' levels, nothing else; the thesis's own levels
    given as a list reproduce its layout."""
    bases = [5.0, 8.2, 11.4]
    case = thesis_case().replace({**BIG, "building.slab_bases": bases})
    got, ref = part_volumes(case), hand_counts("pad")
    # footing top 0.6 to the top slab's underside, less the two lower slabs
    assert got["column"] == pytest.approx(9 * 0.36 * (11.4 - 0.6 - 2 * 0.2), rel=1e-12)
    for part in ("footing", "slab", "beam", "wall"):
        assert got[part] == pytest.approx(ref[part], rel=1e-12), part
    lay = build_layout(case)
    for k, z in enumerate(bases, start=1):
        assert lay.probes[f"slab{k}_x1y1_mid"][2] == pytest.approx(
            case["geometry.zbb"] + z + 0.2)
    same = thesis_case().replace({"building.slab_bases": [4.2, 8.0]})
    a, b = build_layout(same), build_layout(thesis_case())
    assert a.blocks == b.blocks and a.zdiv == b.zdiv and a.probes == b.probes


def test_unequal_spans_place_the_column_lines():
    case = thesis_case().replace({**BIG, "building.spans_x": [4.0, 6.8]})
    b = Building.of_case(case)
    assert b.cx.tolist() == pytest.approx([10.8, 14.8, 21.6])
    assert b.cy.tolist() == pytest.approx([-10.5, -15.9, -21.3])


@pytest.mark.parametrize("changes, key, words", [
    ({"building.spans_x": [3.0, 3.0]}, "building.spans_x", "one span per bay"),
    ({**BIG, "building.spans_x": [4.0, 4.0]}, "building.spans_x", "must add up to"),
    ({**BIG, "building.spans_y": [1.0, 9.8]}, "building.spans_y", "footings must fit"),
    ({"building.bays_x": 6}, "building.footing_size", "footings must fit"),
    ({"building.storeys": 0}, "building.storeys", "> 0"),
    ({"building.foundation": "piles"}, "building.foundation", "pad"),
    ({"geometry.ys2": -4.0}, "geometry.ys1", "YS4 < YS3 < YS2 < YS1"),
    ({"building.slab_bases": [4.2]}, "building.slab_bases", "2 entries (building.storeys)"),
    ({"building.slab_bases": [4.2, 4.5]}, "building.slab_bases",
     "storey-2 beam underside (3.9 m above ZBB) must be above slab 1 top (4.4 m)"),
    ({"building.slab_bases": [4.2, 8.0], "building.z_slab2_base": 9.0},
     "building.z_slab2_base", "applies to storeys of one height (building.slab_bases = [])"),
    ({"building.z_slab2_base": 4.5}, "building.z_slab2_base", "storey-2 beam underside"),
])
def test_bad_buildings_get_one_clear_line(changes, key, words):
    with pytest.raises(CaseError) as info:
        thesis_case().replace(changes)
    text = str(info.value)
    assert key in text and words in text
    assert "\n" not in text.strip()


def test_one_storey_has_no_second_slab():
    """One storey has no slab 2: its level ``z_slab2_base`` applies from two storeys on
    (one line when given), and the layout has no ``slab2``."""
    with pytest.raises(CaseError, match=r"building\.z_slab2_base = 1\.0: applies to "
                                        r"building\.storeys >= 2 only; here building\.storeys "
                                        r"= 1"):
        thesis_case().replace({"building.storeys": 1, "building.z_slab2_base": 1.0})
    case = thesis_case().replace({"building.storeys": 1})
    lay = build_layout(case)
    assert "slab2" not in lay.probes and "slab1" in lay.probes
    assert Building.of_case(case).top == pytest.approx(case["geometry.zbb"] + 4.2 + 0.2)
