"""The red team's geometry findings of the fourth round: a surface load's path through the
building's plan (silently wrong: the load stood in the basement wall and on nothing over the
basement), and a building too narrow for its frame blamed on the footings with a negative
span. Each repro is one tally entry; all are refused before the mesh."""

from __future__ import annotations

import pytest
from faults import BASELINE

from railvib_hpc.cli import run
from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError

B = str(BASELINE)
#: The red team's coarse settings (``$C``).
C = ["mesh.refinement=0.5", "modal.n_modes=20", "output.dt=0.01"]
BARE = ["track.count=0", "load.force=1e5"]


def _cli(tally, fault: str, command: str, sets: list[str], capsys, tmp_path=None,
         valid: bool = False) -> tuple[int, str]:
    """``railvib COMMAND`` on the baseline with ``--set`` entries; records the outcome
    (``valid``: the case is right, exit 0 is the correct outcome)."""
    argv = [command, B, *(["--out", str(tmp_path)] if tmp_path is not None else [])]
    for s in sets:
        argv += ["--set", s]
    code = run(argv)
    cap = capsys.readouterr()
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    tb = "Traceback" in cap.err + cap.out or "internal error" in cap.err
    outcome = ("traceback" if tb else "clear error" if code == 2 and len(lines) == 1
               else "ok" if code == 0 else "unclear")
    line = lines[0] if lines else ""
    if valid:
        outcome = "correct" if outcome == "ok" else outcome
    tally.add(fault, "silent wrong" if outcome == "ok" else outcome, line)
    return code, line


def _refused(changes: dict, base: Case | None = None) -> list[tuple]:
    with pytest.raises(CaseError) as info:
        (base or Case.from_file(B)).replace(changes)
    return info.value.problems


# ------------------------------------------------------ a load's path through the building
@pytest.mark.parametrize("sets, needle", [
    (["load.y=-13"], "load.y = -13.0: the load's path y = -13 m runs through the building's "
                     "plan (x 12.6 to 19.8 m, y -17.1 to -9.9 m"),
    (["load.y=-10"], "allowed: load.y <= -17.1 or >= -9.9 m"),
    (["load.y=-13", "building.rotation=90"], "runs through the building's plan"),
    (["load.y=-7", "trench.type=open", "trench.distance=6", "trench.width=2",
      "trench.depth=2"], "load.y = -7.0: the load's path runs along the open trench (y = -8 "
                         "to -6 m"),
])
def test_a_load_path_through_the_building_is_refused_before_meshing(sets, needle, tally,
                                                                    capsys, tmp_path):
    """It ran (exit 0): in the wall at x = 12.75 and 19.5 m, nothing over the basement."""
    for command in ("check", "transient"):
        out = tmp_path / command
        code, line = _cli(tally, f"surface load {' '.join(sets)}: {command}", command,
                          [*C, *BARE, *sets], capsys, out if command != "check" else None)
        assert code == 2 and needle in line, line
        assert not out.exists() or not any(out.iterdir())        # nothing meshed, written


@pytest.mark.parametrize("sets", [["load.y=-9.9"], ["load.y=-17.1"], ["load.y=-5"],
                                  ["load.y=-13", "load.x_end=10"]])
def test_a_load_path_beside_the_building_or_stopping_before_it_runs(sets, tally, capsys):
    code, line = _cli(tally, f"surface load {' '.join(sets)} (beside the plan)", "check",
                      [*C, *BARE, *sets], capsys, valid=True)
    assert code == 0, line


# ---------------------------------------------------- the building's width, cov = 0
@pytest.mark.parametrize("sets, needle", [
    (["site.building_width=0.01"], "site.building_width = 0.01: must be > 2.4 m: the "
                                   "building's frame across the track needs 2 column lines"),
    (["site.building_length=2"], "site.building_length = 2.0: must be > 2.4 m"),
    (["site.building_width=20", "building.bays_y=2", "building.spans_y=[5, 5]"],
     "site.building_width = 20.0: must be 11.2 m: building.spans_y add up to 10 m"),
])
def test_a_building_too_small_for_its_frame_names_the_site_key(sets, needle, tally, capsys):
    """It blamed building.footing_size with a negative span (-1.19 m)."""
    argv = ["check", "jobs/free_field_site.toml"]
    for s in sets:
        argv += ["--set", s]
    code = run(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    tally.add(f"free_field_site {' '.join(sets)}", "clear error" if code == 2 and
              len(lines) == 1 else "unclear", err.strip())
    assert code == 2 and len(lines) == 1 and needle in lines[0], err
    assert "-1.19" not in err and "footing_size = 1.2 m must be" not in err


def test_a_plan_given_by_its_coordinates_is_blamed_not_the_footings():
    (key, _, text), = _refused({"geometry.ys3": -11.0})
    assert key == "geometry.ys3" and "YS2 - YS3 = 1.1 m, too small for its frame: it must " \
        "be > 2.4 m" in text
    (key, _, text), = _refused({"building.footing_size": 2.0, "building.bays_x": 3})
    assert key == "building.footing_size" and "must be < (X3 - X2) / (bays_x + 1) = 1.8 m" \
        in text, text


