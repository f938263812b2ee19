"""A site without a building (``building.present = false``): the free field alone.

* The layout has no building part, none of the building's lines or levels, and no
  building probe; the ground probes and the probe lines stay (with and without a track).
* Every building-only key is refused at another value by the one rule of the keys of a
  feature that is off (``tests/reliability/test_redteam_feature_keys.py`` sets each in a
  case with ``building.present = false``); here one line and exit 2 through the CLI.
* ``railvib check`` says there is none, and the site keys that place the building set
  nothing of it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.schema import BUILDING_PARTS

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
NONE = ["building.present=false"]
LINE = "probes.line=[{name = 'ff', distances = [5.0, 20.0]}]"


@pytest.mark.parametrize("track", [[], ["track.count=0", "load.force=1e5"]],
                         ids=["track", "bare_soil"])
def test_the_layout_has_no_building(track):
    with_building = build_layout(load_case(BASELINE, [*track, LINE]))
    lay = build_layout(load_case(BASELINE, [*NONE, *track, LINE]))
    assert not {b.part for b in lay.blocks} & set(BUILDING_PARTS)
    assert {b.part for b in with_building.blocks} & set(BUILDING_PARTS)
    # no building line along x or y, no level above the ground
    if track:                          # (with a track the sleepers are x lines too)
        assert not {12.6, 12.9, 19.5, 19.8} & set(np.round(lay.xb, 6))
    assert -9.9 not in np.round(lay.yb, 6) and -17.1 not in np.round(lay.yb, 6)
    assert max(b.z1 for b in lay.blocks) <= 6.0 + 1e-9            # the track bed's top
    building = {"footing", "basement_wall", "basement_wall_far", "slab1", "slab2"}
    assert building <= set(with_building.probes) and not building & set(lay.probes)
    assert not any(k.startswith("slab") for k in lay.probes)
    assert set(lay.probes) == ({"ground_mid", "ground_opposite"}
                               | ({"ground_toe"} if not track else set()))
    assert set(lay.probe_roles.values()) == {"ground"}
    z1 = 4.8
    assert all(abs(p[2] - z1) < 1e-12 for p in lay.probes.values())


def test_the_soil_keeps_its_sizes_without_the_building():
    """The refined layout's soil above the building base took the building's vertical
    size (mesh.size_building_z); without a building the whole soil takes mesh.size_deep."""
    lay = build_layout(load_case(BASELINE, [*NONE, "mesh.layout=refined",
                                            "mesh.size_deep=1.2"]))
    sizes = {(z0, z1): (z1 - z0) / n for (z0, z1), n in lay.zdiv.items() if z1 <= 4.8 + 1e-9}
    assert all(abs(h - 1.2) <= 0.6 for h in sizes.values()), sizes


@pytest.mark.parametrize(("sets", "needle"), [
    (["building.storeys=3"], "building.storeys = 3: applies to a building "
                             "(building.present = True) only; here building.present = "
                             "False"),
    (["site.building_distance=20"], "site.building_distance = 20.0: applies to a building"),
    (["materials.concrete.E=3e10"], "materials.concrete.E = 30000000000.0: applies to a "
                                    "building"),
    (["isolation.modulus=1e8"], "isolation.modulus = 100000000.0: applies to a building"),
    (["mesh.size_building_y=0.5"], "mesh.size_building_y = 0.5: applies to a building"),
])
def test_a_building_key_without_a_building_is_one_line(tmp_path, capsys, sets, needle):
    argv = ["check", str(BASELINE), "--set", NONE[0]]
    for s in sets:
        argv += ["--set", s]
    code = run(argv)
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code == 2 and len(err) == 1, err
    assert needle in err[0], err[0]


def test_check_says_there_is_no_building(capsys):
    assert run(["check", str(BASELINE), "--set", NONE[0], "--set", "site.track_length=30",
                "--set", "track.rail_length=30", "--set", "geometry.x4=33"]) == 0
    out = capsys.readouterr().out
    assert "building: none (building.present = false: the free field alone)" in out
    site = next(ln for ln in out.splitlines() if ln.strip().startswith("site:"))
    assert "x2" not in site and "xbb" not in site, site
