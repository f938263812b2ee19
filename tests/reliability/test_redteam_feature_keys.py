"""The red team's finding that keys of a feature that is off were accepted and ignored
(silently wrong: ``vehicle.n_cars`` with the wheelset, ``transient.rho_inf`` with the explicit
engine...): one rule, declared next to each key (:attr:`railvib_hpc.schema.Param.applies`),
and a test that every declared key obeys it. Each repro is one tally entry (``railvib check``,
no mesh)."""

from __future__ import annotations

import pytest
from faults import BASELINE

from railvib_hpc.cli import run
from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.schema import iter_params
from railvib_hpc.studies.common import variant_case
from railvib_hpc.validation import ALL_KEYS, feature_key_problems

B = str(BASELINE)


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


# --------------------------------------------------- keys of a feature that is off: one rule
@pytest.mark.parametrize("sets, needle", [
    (["vehicle.n_cars=3"], "vehicle.n_cars = 3: applies to vehicle.type = 'vehicle' only; "
                           "here vehicle.type = 'wheelset': leave it at its default 1"),
    (["vehicle.force=5e4"], "vehicle.force = 50000.0: applies to vehicle.type = "
                            "'moving_force' only; here vehicle.type = 'wheelset'"),
    (["track.count=2", "geometry.ys0=12.25", "train2.n_cars=3"],
     "train2.n_cars = 3: applies to vehicle.type = 'vehicle' only"),
    (["transient.implicit_elements=auto"], "transient.implicit_elements = 'auto': applies "
                                           "to transient.engine = 'imex' only; here "
                                           "transient.engine = 'direct'"),
    (["transient.engine=explicit", "modal.lumped_mass=true", "transient.rho_inf=0.5"],
     "transient.rho_inf = 0.5: applies to transient.engine = 'direct' only; here "
     "transient.engine = 'explicit'"),
    # more of the pattern
    (["vehicle.type=moving_force", "irregularity.type=fra"],
     "irregularity.type = 'fra': applies to wheels on the rails (vehicle.type != "
     "'moving_force') only"),
    (["boundary.pml_power=3"], "boundary.pml_power = 3.0: applies to a perfectly matched "
                               "layer (boundary.x_min, x_max, y_min, y_max or base = 'pml'"),
    (["boundary.virtual_thickness=10"], "applies to an absorbing face"),
    (["usp.shear_ratio=0.5"], "usp.shear_ratio = 0.5: applies to usp.modulus > 0 only"),
    (["building.storeys=1", "building.z_slab2_base=6"], "applies to building.storeys >= 2"),
    (["modal.band_modes=100"], "applies to the band-sliced eigensolve (modal.f_max > 0)"),
    (["mbs.static_correction=false", "output.static_correction_rates=true"],
     "applies to mbs.static_correction = True only"),
    (["assessment.standards=[iso2631]", "assessment.fta_events=infrequent"],
     "assessment.fta_events = 'infrequent': applies to assessment.standards with 'fta'"),
    (["train2.t_start=2"], "train2.t_start = 2.0: applies to a second track (track.count = "
                           "2) only; here track.count = 1"),
    (["mesh.size_far=1.2"], "mesh.size_far = 1.2: applies to mesh.layout = 'refined' only"),
    (["track.count=0", "load.force=1e5", "pads.kz=1e8"],
     "pads.kz = 100000000.0: applies to a case with a track (track.count > 0) only"),
])
def test_a_key_of_a_feature_that_is_off_is_refused(sets, needle, tally, capsys):
    """Each exited 0 and the key did nothing."""
    code, line = _cli(tally, f"off feature: {' '.join(sets)}", "check", sets, capsys)
    assert code == 2 and needle in line, line


def _other_value(key: str, param):
    """A valid value of ``key`` that differs from its default (None: none found)."""
    d = param.default
    if param.choices and param.kind == "str":
        return next(c for c in param.choices if c != d)
    if param.kind == "bool":
        return not d
    if param.kind == "int":
        return d + 1
    if param.kind == "float":
        return {"fraction": 0.5 if d != 0.5 else 0.25, "unit": 0.5 if d != 0.5 else 0.25,
                "poisson": 0.3 if d != 0.3 else 0.35}.get(param.check, 2 * d + 1.0)
    if param.kind == "floats":
        return [1.0] if not d else [2 * x + 1 for x in d]
    if param.kind == "strs":
        return ["slab1"] if not d else d[:1]
    if param.kind == "str":
        return "x"
    if param.kind == "vehicle":
        return {"car_mass": 4.0e4}
    return None


#: A case in which each declared key's feature is off (the defaults, or these changes).
_OFF_CASES = [{}, {"track.count": 0, "load.force": 1e5},
              {"vehicle.type": "moving_force"}, {"vehicle.type": "vehicle"},
              {"building.slab_bases": [4.2, 8.0]}, {"building.present": False},
              {"transient.engine": "imex", "modal.lumped_mass": True},
              {"assessment.standards": ["iso2631"]}, {"modal.method": "krylovschur"}]


@pytest.mark.parametrize("key", [k for k, p in iter_params() if p.applies is not None])
def test_every_declared_key_obeys_the_rule(key):
    """Set to another value in a case where its feature is off, every key that declares
    its feature is refused by the one rule (not by a list of special cases)."""
    param = ALL_KEYS[key]
    value = _other_value(key, param)
    assert value is not None, key
    base = next((c for c in (Case.defaults().replace(x) if x else Case.defaults()
                             for x in _OFF_CASES) if not param.applies.holds(c)), None)
    if base is None:
        pytest.skip(f"{key}'s feature is on in every case of the test")
    problems = _refused({key: value}, base)
    mine = [p for p in problems if p[0].startswith(key) and "applies to" in p[2]]
    assert mine, (key, value, problems)


def test_keys_listed_at_their_defaults_are_accepted():
    """The rule judges values, not spellings: the baseline lists every key at its default
    (the train's with track.count = 0 too), and a preset's values are its defaults."""
    base = Case.from_file(B, ["track.count=0", "load.force=1e5"])
    assert feature_key_problems(base) == []
    # the preset's value where the file gives none; the schema's where the file lists it
    table1 = Case.from_dict({"case.preset": "table1", "track.count": 0, "load.force": 1e5})
    assert table1["materials.ballast.rho"] == 1300.0 and feature_key_problems(table1) == []
    listed = Case.from_file(B, ["case.preset=table1", "track.count=0", "load.force=1e5"])
    assert listed["materials.ballast.rho"] == 1800.0 and feature_key_problems(listed) == []
    assert Case.from_file(B, ["vehicle.n_cars=1"])["vehicle.n_cars"] == 1


def test_a_study_variant_that_switches_a_feature_off_resets_its_keys():
    """The reflection study's 'thesis' boundaries in place of the case's layer: the
    layer's keys no longer apply and are reset in the variant, not refused."""
    case = Case.from_file(B, ["boundary.y_min=pml", "boundary.layer_thickness=4",
                              "boundary.pml_power=3", "domain.extra_width=4"])
    rollers = ["boundary.x_min=roller", "boundary.x_max=roller", "boundary.y_min=roller",
               "boundary.y_max=roller", "boundary.base=fixed"]
    variant = variant_case(case, rollers)
    assert variant["boundary.pml_power"] == 2.0 and variant["boundary.layer_thickness"] == 0
    assert variant_case(case, [])["boundary.pml_power"] == 3.0


