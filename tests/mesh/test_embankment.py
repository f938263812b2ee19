"""A fill embankment under the track bed (``track.embankment_height``, ``_slope``).

The fill lifts the subballast, ballast, sleepers and rails by its height; its sides slope
from the subballast's base (half-width |YS1|) down to the ground. The thesis's track bed
on the ground (height 0) is a track at grade and keeps its mesh.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.mesh.stage import make_mesh, predicted_hexes

ROOT = Path(__file__).resolve().parents[2]


def thesis_case(**changes) -> Case:
    return Case.from_file(ROOT / "jobs" / "thesis_baseline.toml").replace(changes)


@pytest.mark.slow
def test_fill_lifts_the_track_and_has_the_trapezoid_volume():
    h, slope = 2.0, 1.5
    case = thesis_case(**{"mesh.refinement": 0.5, "track.embankment_height": h,
                          "track.embankment_slope": slope})
    mesh, report = make_mesh(case)
    vol = report["volume_per_part"]
    length = case["geometry.x4"] - case["geometry.x1"]
    top = 2 * -case["geometry.ys1"]                              # 8.5 m: the subballast's base
    assert vol["fill"] == pytest.approx(length * h * (top + top + 2 * slope * h) / 2, rel=1e-12)
    # the track bed keeps its volumes, lifted
    _, plain_report = make_mesh(thesis_case(**{"mesh.refinement": 0.5}))
    for part in ("ballast", "subballast"):
        assert vol[part] == pytest.approx(plain_report["volume_per_part"][part], rel=1e-12)
    rails = mesh.rail_nodes()
    assert mesh.points[rails, 2] == pytest.approx(case["geometry.z4"] + h)
    q = report["quality"]
    assert q["n_inverted"] == 0 and q["nonconformal_faces"] == 0 and q["duplicate_nodes"] == 0
    # the ground probe at the toe moves out with the embankment's base
    lay = build_layout(case)
    assert lay.probes["ground_toe"][1] == pytest.approx(case["geometry.ys1"] - slope * h)


def test_at_grade_is_the_thesis_mesh():
    assert predicted_hexes(build_layout(thesis_case())) == 41_880
    assert "fill" not in {b.part for b in build_layout(thesis_case()).blocks}


@pytest.mark.parametrize("changes, key, words", [
    ({"track.embankment_height": 4.0}, "track.embankment_height", "reaches the building face"),
    ({"track.embankment_height": 1.0, "trench.type": "open", "trench.distance": 5.0,
      "trench.width": 0.6, "trench.depth": 2.0}, "trench.distance", "beyond the embankment toe"),
    ({"track.embankment_height": -1.0}, "track.embankment_height", ">= 0"),
])
def test_bad_embankments_get_one_clear_line(changes, key, words):
    with pytest.raises(CaseError) as info:
        thesis_case(**changes)
    text = str(info.value)
    assert key in text and words in text and "\n" not in text.strip()


def test_wave_arrivals_measure_from_the_lifted_rail():
    from railvib_hpc.site import track_lift

    case = thesis_case(**{"track.embankment_height": 1.0})
    assert track_lift(case) == 1.0
    assert np.isclose(build_layout(case).rail_z, case["geometry.z4"] + 1.0)
