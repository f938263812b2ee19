"""Defect 2 of issue 16: single-stage commands must never use stale or foreign upstream files.

Each single-stage command whose input was computed for other case values, or from
other upstream files, refuses with one line naming the file, the changed key and the
command to run; ``run`` recomputes what is stale and says why.
"""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest
from faults import BASELINE, COARSE, cli, copy_results, serial_only

from railvib_hpc.cli import run

B = str(BASELINE)


def _run(capsys, *args) -> tuple[int, str, str]:
    code = run([*map(str, args)])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _one_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _record(tally, fault, code, err, expect_code=2):
    outcome = ("clear error" if code == 2 and len(err.strip().splitlines()) == 1
               and "Traceback" not in err else "silent wrong" if code == 0 else "unclear")
    tally.add(fault, outcome, err.strip())
    assert code == expect_code, err


def test_mbs_refuses_modes_of_another_case(work, capsys, tally):
    """The issue's first repro: mbs with E = 4e8 used the E = 2e8 modes."""
    stamp = (work / "mbs.h5").stat().st_mtime_ns
    code, _, err = _run(capsys, "mbs", B, "--out", work, *COARSE, "--set",
                        "materials.subgrade.E=4e8", "--set", "vehicle.speed=20")
    _record(tally, "stale upstream: mbs after E changed", code, err)
    line = _one_error(err)
    assert "modes.h5 was computed with materials.subgrade.E = 2e8, the case says 4e8" in line
    assert "run 'railvib modal' (or 'railvib run')" in line
    assert (work / "mbs.h5").stat().st_mtime_ns == stamp


def test_reconstruct_refuses_mbs_of_another_speed(work, capsys, tally):
    code, _, err = _run(capsys, "reconstruct", B, "--out", work, *COARSE, "--set",
                        "vehicle.speed=40")
    _record(tally, "stale upstream: reconstruct after speed changed", code, err)
    line = _one_error(err)
    assert "mbs.h5 was computed with vehicle.speed = 30, the case says 40" in line
    assert "run 'railvib mbs'" in line


def test_assess_names_the_most_upstream_stale_file(work, capsys, tally):
    """The issue's report.md said 50 m/s and c_P = 775 m/s over the 30 m/s numbers."""
    before = (work / "assessment.json").read_bytes()
    code, _, err = _run(capsys, "assess", B, "--out", work, *COARSE, "--set",
                        "vehicle.speed=50", "--set", "materials.subgrade.E=1e9")
    _record(tally, "stale upstream: assess after speed and E changed", code, err)
    line = _one_error(err)
    assert "modes.h5 was computed with materials.subgrade.E = 2e8, the case says 1e9" in line
    assert (work / "assessment.json").read_bytes() == before


def test_assess_refuses_fields_of_other_output_settings(work, capsys, tally):
    code, _, err = _run(capsys, "assess", B, "--out", work, *COARSE, "--set",
                        "output.dt=0.002")
    _record(tally, "stale upstream: assess after output.dt changed", code, err)
    assert "fields.h5 was computed with output.dt = 0.01, the case says 0.002" in _one_error(err)


def test_assess_after_a_new_mbs_refuses_the_old_fields(work, capsys, tally):
    """The issue's interrupted run: mbs recomputed at 20 m/s, reconstruct never ran; assess
    at 20 m/s must not label the 30 m/s fields with the new case."""
    assert _run(capsys, "mbs", B, "--out", work, *COARSE, "--set", "vehicle.speed=20")[0] == 0
    code, _, err = _run(capsys, "assess", B, "--out", work, *COARSE, "--set",
                        "vehicle.speed=20")
    _record(tally, "stale upstream: assess after an interrupted run", code, err)
    line = _one_error(err)
    assert "fields.h5 was computed with vehicle.speed = 30, the case says 20" in line
    assert "run 'railvib reconstruct'" in line


def test_same_case_but_recomputed_upstream_is_detected(work, capsys, tally):
    """mbs.h5 written again (same case, new file): the fields computed from the old one
    are refused by assess although every case key matches."""
    (work / "mbs.h5").unlink()
    assert _run(capsys, "mbs", B, "--out", work, *COARSE)[0] == 0
    code, _, err = _run(capsys, "assess", B, "--out", work, *COARSE)
    _record(tally, "stale upstream: same case, recomputed mbs.h5", code, err)
    assert "fields.h5 was computed from another mbs.h5" in _one_error(err)


def test_foreign_modes_file_is_refused(work, prepared, tmp_path, capsys, tally):
    """A modes.h5 copied from another model (refinement 0.5 into a refinement-0.75 case)."""
    other = tmp_path / "other"
    copy_results(prepared, other, ("modes.h5",))
    code, _, err = _run(capsys, "mbs", B, "--out", other, *COARSE, "--set",
                        "mesh.refinement=0.75")
    _record(tally, "foreign upstream: modes.h5 of another mesh", code, err)
    assert "mesh.refinement = 0.5, the case says 0.75" in _one_error(err)


def test_missing_upstream_is_named(tmp_path, capsys, tally):
    for cmd, name in (("mbs", "modes.h5"), ("reconstruct", "modes.h5"), ("assess", "modes.h5")):
        code, _, err = _run(capsys, cmd, B, "--out", tmp_path / cmd, *COARSE)
        _record(tally, f"missing upstream: {cmd}", code, err)
        assert f"{name} not found: run 'railvib modal' first" in _one_error(err)


@pytest.mark.slow
def test_run_recomputes_what_is_stale_and_says_why(work, prepared, capsys, tally):
    """run with a new speed: mesh and modes reused, mbs/fields/probes recomputed, each
    with its reason; the report carries the new speed's numbers."""
    code, out, err = _run(capsys, "run", B, "--out", work, *COARSE, "--set",
                          "vehicle.speed=20")
    assert code == 0, err
    assert "reusing" in out and f"reusing {work / 'modes.h5'}" in out
    assert (f"recomputing {work / 'mbs.h5'}: it was computed with vehicle.speed = 30, the "
            "case says 20") in out
    assert f"recomputing {work / 'fields.h5'}: it was computed with vehicle.speed" in out
    with h5py.File(work / "mbs.h5", "r") as f:
        x, t = f["wheels/x"][:, 0], f["time"][()]
    np.testing.assert_allclose(np.diff(x) / np.diff(t), 20.0, rtol=1e-12)
    new = json.loads((work / "assessment.json").read_text())
    old = json.loads((prepared / "assessment.json").read_text())
    key = "slab1_vertical_acceleration"
    ok = new["thesis_comparison"][key]["railvib"] != old["thesis_comparison"][key]["railvib"]
    tally.add("stale outputs: run with a new speed", "recomputed" if ok else "silent wrong")
    assert ok
    assert "vehicle" in new["provenance"]["case_toml"] and "speed = 20.0" in \
        new["provenance"]["case_toml"]


@pytest.mark.slow
@serial_only
def test_issue_repro_sequence_on_two_ranks(prepared, tmp_path, tally):
    """The issue's four commands (run, mbs, reconstruct, assess) under mpirun -n 2."""
    out = copy_results(prepared, tmp_path / "o")
    shutil.rmtree(out / "probes", ignore_errors=True)
    for args, needle in (
            (["mbs", "--set", "materials.subgrade.E=4e8", "--set", "vehicle.speed=20"],
             "modes.h5 was computed with materials.subgrade.E = 2e8, the case says 4e8"),
            (["reconstruct", "--set", "vehicle.speed=40"],
             "mbs.h5 was computed with vehicle.speed = 30, the case says 40"),
            (["assess", "--set", "vehicle.speed=50", "--set", "materials.subgrade.E=1e9"],
             "materials.subgrade.E = 2e8, the case says 1e9")):
        res = tally.result(f"stale upstream, 2 ranks: {args[0]}",
                           cli([args[0], B, "--out", out, *COARSE, *args[1:]], ranks=2,
                               timeout=240))
        assert res.outcome == "clear error", res.err
        assert needle in res.error_lines[0]
