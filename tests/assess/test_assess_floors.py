"""The assessment per floor (``railvib_hpc.assess.floors``) on known verdicts."""

from __future__ import annotations

from railvib_hpc.assess.floors import BASEMENT, OTHER, floor_summary, format_floor_table


def result(u: float, limit_ok: bool = True) -> dict:
    return {"passed": limit_ok, "standards": {"DIN4150-3": {"utilisation": u,
                                                             "passed": limit_ok}}}


def test_floors_gather_their_probes_and_keep_the_largest_utilisation():
    results = {"footing": result(0.1), "basement_wall": result(0.3),
               "slab1": result(0.2), "slab1_x1y1_mid": result(0.5),
               "slab1_x2y1_corner": result(0.4), "slab2_x1y1_mid": result(1.2, False),
               "slab2": result(0.7), "lab_floor": result(0.05), "ground_mid": result(9.0)}
    roles = {n: "floor" for n in results}
    roles.update(footing="foundation", basement_wall="wall", ground_mid="ground")
    floors = floor_summary(results, roles)
    assert list(floors) == [BASEMENT, "floor 1", "floor 2", OTHER]   # ground left out
    f1 = floors["floor 1"]["standards"]["DIN4150-3"]
    assert (f1["utilisation"], f1["governing_probe"], f1["passed"]) == (0.5, "slab1_x1y1_mid",
                                                                         True)
    assert floors[BASEMENT]["standards"]["DIN4150-3"]["governing_probe"] == "basement_wall"
    assert floors["floor 2"]["passed"] is False and floors["floor 1"]["passed"] is True
    assert floors["floor 2"]["standards"]["DIN4150-3"]["utilisation"] == 1.2
    text = format_floor_table(floors)
    assert "FAIL 1.200 (slab2_x1y1_mid)" in text and "floor 10" not in text
    # floors sort numerically, not as text
    many = floor_summary({f"slab{k}": result(0.1) for k in (10, 2, 1)},
                         {f"slab{k}": "floor" for k in (10, 2, 1)})
    assert list(many) == ["floor 1", "floor 2", "floor 10"]
