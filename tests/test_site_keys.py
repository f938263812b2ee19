"""The site as an engineer gives it (issue 28, item 4): ``[site]`` keys, derived geometry
keys computed instead of hand-kept, probe lines and their refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.config import Case, load_case
from railvib_hpc.errors import CaseError
from railvib_hpc.io.products import STAGE_FILES, inputs_hash
from railvib_hpc.site import line_probes

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The thesis's derived keys as the baseline gave them by hand before issue 28.
HAND_KEPT = {"geometry.x4": 24.6, "track.rail_length": 21.6, "track.n_sleepers": 37,
             "geometry.xbb": 16.2, "geometry.ybb": -13.5}
LINES = [{"name": "ff", "distances": [5.0, 20.0]},
         {"name": "opp", "distances": [6.0], "side": "away", "x": 10.0}]


def _problems(changes):
    with pytest.raises(CaseError) as info:
        Case.defaults().replace(changes)
    return info.value.problems


def test_the_thesis_keys_give_the_old_values():
    """The baseline leaves the derived keys out (commented); they come out bit for bit as
    the APDL script's, so the thesis mesh and its digests are unchanged."""
    text = BASELINE.read_text()
    assert "\n# x4 = 24.6  # derived: geometry.x1 + track.rail_length" in text
    assert "\nx4 =" not in text and "\nn_sleepers =" not in text
    new, old = load_case(BASELINE), Case.from_dict(HAND_KEPT)
    assert new.data == old.data == Case.defaults().data
    assert {k: new[k] for k in HAND_KEPT} == HAND_KEPT
    for name in ("mesh.h5", "assessment.json", "transient:probes.h5"):
        assert inputs_hash(new, name) == inputs_hash(old, name)


def test_site_and_probes_at_their_defaults_leave_the_digests_as_they_were():
    """The digest of the thesis case equals the one without the [site] and [probes]
    sections (as before they existed); a probe line changes the probe files' digests."""
    case = Case.defaults()
    before = Case(data={k: v for k, v in case.data.items() if k not in ("site", "probes")})
    for name in STAGE_FILES:
        assert inputs_hash(case, name) == inputs_hash(before, name), name
    given = case.replace({"site.soil_depth": 4.8})          # the thesis's depth, given
    assert given.data["domain"] == case.data["domain"]
    assert inputs_hash(given, "mesh.h5") == inputs_hash(case, "mesh.h5")
    assert inputs_hash(given, "assessment.json") != inputs_hash(case, "assessment.json")
    lined = case.replace({"probes.line": LINES})
    assert inputs_hash(lined, "transient:probes.h5") != inputs_hash(case, "transient:probes.h5")
    assert inputs_hash(lined, "probes.h5") != inputs_hash(case, "probes.h5")
    assert inputs_hash(lined, "mesh.h5") == inputs_hash(case, "mesh.h5")


def test_one_length_moves_the_end_of_the_soil_and_the_sleepers():
    """rail_length alone: X4 and the sleepers follow; X4 alone: the rail length follows;
    a new sleeper spacing: the count follows."""
    from railvib_hpc.mesh.layout import build_layout

    long = Case.defaults().replace({"track.rail_length": 30.0})
    assert (long["geometry.x4"], long["track.n_sleepers"]) == (33.0, 51)
    lay = build_layout(long)
    assert lay.sleeper_x.size == 51 and lay.sleeper_x[-1] == pytest.approx(33.0)
    assert lay.bounds[1] == pytest.approx(33.0)
    by_x4 = Case.from_dict({"geometry.x4": 27.0})
    assert (by_x4["track.rail_length"], by_x4["track.n_sleepers"]) == (24.0, 41)
    assert Case.defaults().replace({"track.sleeper_spacing": 0.72})["track.n_sleepers"] == 31
    moved = Case.from_dict({"geometry.x2": 9.0, "geometry.x3": 16.2})
    assert moved["geometry.xbb"] == 12.6


def test_site_keys_set_the_geometry():
    c = Case.from_dict({"site.building_distance": 15.0, "site.building_width": 12.0,
                        "site.building_length": 12.0, "site.track_length": 60.0,
                        "site.soil_depth": 20.0})
    g = c["geometry"]
    assert (g["ys2"], g["ys3"], g["ybb"], g["ys4"]) == (-15.0, -27.0, -21.0, -39.0)
    assert (c["track.rail_length"], g["x4"], c["track.n_sleepers"]) == (60.0, 63.0, 101)
    # centred on the track's middle x = 33 m, its start on a sleeper
    assert (g["x2"], g["x3"], g["xbb"]) == (27.0, 39.0, 33.0)
    assert (g["z0"], c["domain.extra_depth"]) == (0.0, 15.2)
    assert c["geometry.z1"] - (g["z0"] - c["domain.extra_depth"]) == pytest.approx(20.0)
    # shallower than the thesis's 4.8 m: the base rises (the reflection study's model 1)
    shallow = Case.from_dict({"site.soil_depth": 3.0})
    assert (shallow["geometry.z0"], shallow["domain.extra_depth"]) == (1.8, 0.0)
    # the thesis's own values reproduce the thesis
    same = Case.from_dict({"site.building_distance": 9.9, "site.building_width": 7.2,
                           "site.soil_depth": 4.8, "site.building_length": 7.2})
    assert {k: v for k, v in same.data.items() if k != "site"} == \
        {k: v for k, v in Case.defaults().data.items() if k != "site"}
    centred = Case.from_dict({"site.track_length": 21.6})["geometry"]
    assert (centred["x2"], centred["x3"]) == (10.2, 17.4)


@pytest.mark.parametrize("changes, key, fragment", [
    ({"site.building_distance": 12.0, "geometry.ys2": -9.0}, "geometry.ys2",
     "geometry.ys2 = -9.0: site.building_distance = 12 m sets it to -12: give one of them"),
    ({"site.track_length": 30.0, "track.rail_length": 21.6}, "track.rail_length",
     "site.track_length = 30 m sets it to 30"),
    ({"site.soil_depth": 10.0, "domain.extra_depth": 1.0}, "domain.extra_depth",
     "site.soil_depth = 10 m sets it to 5.2"),
    ({"site.track_length": 30.1}, "site.track_length",
     "whole number of sleeper bays (track.sleeper_spacing = 0.6 m), e.g. 30 or 30.6 m"),
    ({"site.track_length": 7.2}, "site.track_length", "must lie beside the flexible track"),
    ({"site.building_distance": 3.0}, "site.building_distance",
     "must be > 4.25 m, the embankment toe"),
    ({"site.soil_depth": 2.0}, "site.soil_depth",
     "must be > 2.4 m, the depth of the building's base below the ground"),
    ({"track.rail_length": 30.0, "geometry.x4": 24.6}, "track.rail_length",
     "give one of track.rail_length and geometry.x4, the other follows"),
    ({"track.n_sleepers": 30}, "track.n_sleepers", "(it is derived: leave it out)"),
])
def test_a_site_refusal_is_one_line_naming_both(changes, key, fragment):
    problems = _problems(changes)
    assert len(problems) == 1, problems
    k, value, allowed = problems[0]
    assert k == key and fragment in f"{k} = {value!r}: {allowed}"


def test_probe_lines_expand_to_named_free_field_points():
    case = Case.defaults().replace({"probes.line": LINES})
    points = line_probes(case)
    assert list(points) == ["ff_5m", "ff_20m", "opp_6m"]
    assert points["ff_5m"].point == (13.8, -5.0, 4.8)          # mid-track, building side
    assert points["ff_20m"].point == (13.8, -20.0, 4.8)        # beyond the building
    assert points["opp_6m"].point == (10.0, 6.0, 4.8)
    assert case["probes.line"][0]["side"] == "building"
    # the modal path: reconstruct adds them as user probes of role free_field
    from railvib_hpc.reconstruct.stage import reconstruct_options

    opts = reconstruct_options(case, ROOT / "no_such_folder")
    assert np.allclose(opts["user_probes"]["opp_6m"], (10.0, 6.0, 4.8))
    assert opts["user_probe_roles"] == {n: "free_field" for n in points}
    # the transient path: after the mesh and user probes
    from types import SimpleNamespace

    from railvib_hpc.transient.stage import probe_points

    names, coords = probe_points(SimpleNamespace(probes={"slab1": (1.0, 2.0, 3.0)}),
                                 case.replace({"output.probes": [1.0, -6.0, 4.8]}))
    assert names == ["slab1", "user_1", "ff_5m", "ff_20m", "opp_6m"]
    assert coords[-1].tolist() == [10.0, 6.0, 4.8]


@pytest.mark.parametrize("line, key, fragment", [
    ({"name": "ff", "distances": [5.0, 12.0]}, "probes.line[1].distances",
     "= 12.0: outside the soil's ground on the building side at x = 13.8 m: allowed 4.25 to "
     "9.9 m or 17.1 to 29.1 m from the centreline of track 1"),
    ({"name": "ff", "distances": [40.0]}, "probes.line[1].distances", "17.1 to 29.1 m"),
    ({"name": "ff", "distances": [2.0]}, "probes.line[1].distances", "allowed 4.25 to"),
    ({"name": "ff", "distances": [9.0], "side": "away"}, "probes.line[1].distances",
     "allowed 4.25 to 8.25 m"),
    ({"name": "ff", "distances": [5.0], "x": 50.0}, "probes.line[1].x",
     "must lie along the soil, 3 to 24.6 m"),
    ({"distances": [5.0]}, "probes.line[1].name", "missing"),
    ({"name": "ff", "distances": [-1.0]}, "probes.line[1].distances", "numbers > 0"),
    ({"name": "ff", "distances": [5.0], "side": "left"}, "probes.line[1].side",
     "'building', 'away'"),
    ({"name": "ff", "distances": [5.0], "step": 1.0}, "probes.line[1].step", "unknown key"),
])
def test_a_bad_probe_line_is_one_line_naming_key_value_and_range(line, key, fragment):
    problems = _problems({"probes.line": [line]})
    assert len(problems) == 1, problems
    k, value, allowed = problems[0]
    assert k == key and fragment in f"{k} = {value!r}: {allowed}"


def test_probe_line_ranges_follow_the_building_and_an_open_trench():
    """Beside the building (x before X2) the whole width is ground; an open trench is a
    hole in it; two lines may not share a name."""
    Case.defaults().replace({"probes.line": [{"name": "a", "distances": [12.0], "x": 8.0}]})
    trench = {"trench.type": "open", "trench.width": 0.6, "trench.depth": 3.0,
              "trench.distance": 6.0}
    (k, value, allowed), = _problems({**trench, "probes.line": [
        {"name": "a", "distances": [6.3]}]})
    assert value == 6.3 and "allowed 4.25 to 6 m or 6.6 to 9.9 m or 17.1 to 29.1 m" in allowed
    (k, value, allowed), = _problems({"probes.line": [{"name": "a", "distances": [5.0]},
                                                       {"name": "a", "distances": [6.0]}]})
    assert k == "probes.line[2].name"


def test_cli_refuses_a_probe_line_outside_the_soil_with_exit_code_2(tmp_path, capsys):
    """One line on stderr, exit code 2, no output folder (nothing half-written)."""
    bad = tmp_path / "site.toml"
    bad.write_text('[site]\ntrack_length = 30.0\nbuilding_distance = 12.0\n\n'
                   '[[probes.line]]\nname = "ff"\ndistances = [5.0, 45.0]\n')
    out = tmp_path / "out"
    assert run(["run", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "probes.line[1].distances = 45.0: outside the soil's ground on the building side " \
           "at x = 18 m: allowed 4.25 to 12 m or 19.2 to 31.2 m" in err
    assert not out.exists()
    bad.write_text(bad.read_text().replace("45.0", "25.0"))
    assert run(["check", str(bad)]) == 0


def test_the_reflection_study_changes_the_depth_a_site_gave():
    """A variant's own depth replaces site.soil_depth (its base, given now, plus the
    change), instead of being refused as a key the site key sets."""
    from railvib_hpc.config import parse_override
    from railvib_hpc.studies.reflection import domain_overrides

    case = Case.from_dict({"site.soil_depth": 3.0})
    for change, depth in (((2.0, 0.0, 0.0), 5.0), ((-0.5, 0.0, 0.0), 2.5)):
        overrides = dict(parse_override(o) for o in domain_overrides(case, change))
        variant = case.replace(overrides)
        base = variant["geometry.z0"] - variant["domain.extra_depth"]
        assert variant["geometry.z1"] - base == pytest.approx(depth)


def test_rayleigh_speed_is_the_root_of_rayleighs_equation():
    """Against Achenbach's table (c_R / c_S = 0.8740 at nu = 0, 0.9194 at 0.25, 0.9554 at
    0.5)."""
    from railvib_hpc.site import rayleigh_speed

    for nu, ratio in ((0.0, 0.8740), (0.25, 0.9194), (0.4999, 0.9553)):
        assert rayleigh_speed(1.0, nu) == pytest.approx(ratio, abs=2e-4)


def test_a_train_at_the_rayleigh_speed_is_refused_unless_accepted(tmp_path, capsys):
    from railvib_hpc.cli import run
    from railvib_hpc.config import load_case
    from railvib_hpc.transient.stage import speed_warning

    base = Path(__file__).resolve().parents[1] / "jobs" / "thesis_baseline.toml"
    assert run(["check", str(base), "--set", "vehicle.speed=200"]) == 2
    err = capsys.readouterr().err
    assert "vehicle.speed = 200.0: is at or above the ground's Rayleigh speed c_R = 193.3 m/s" \
        in err and "set vehicle.supercritical = true" in err and "Traceback" not in err
    assert run(["check", str(base), "--set", "vehicle.speed=200",
                "--set", "vehicle.supercritical=true"]) == 0
    case = load_case(base, ["vehicle.speed=200", "vehicle.supercritical=true"])
    assert "above the ground's Rayleigh speed" in speed_warning(case, 200.0)
    assert "near the ground's Rayleigh speed" in speed_warning(case, 150.0)
    assert speed_warning(case, 30.0) == ""
