"""Issue 26, items 3, 6, 11 and 17: the API's results, two pipelines in one process, and
what a study reports (its modal band, unfinished variants, ``--merge`` with nothing
finished, ``solver = direct``).

Each repro is recorded in the fault suite's tally (``clear error``, ``correct``, or
``silent wrong`` / ``data loss`` when the defect is back).
"""

from __future__ import annotations

import json
import pickle
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from faults import BASELINE, COARSE, serial_only

import railvib_hpc as rv
from railvib_hpc.api import AssessResult, ProbePeak, ReconstructResult
from railvib_hpc.cli import run
from railvib_hpc.errors import OutputLockedError, UserError
from railvib_hpc.io import locks, temp_names

ROOT = Path(__file__).resolve().parents[2]
MITIGATION = ROOT / "jobs" / "mitigation_study.toml"
#: The tiny model of tests/studies/studies_tiny.py (as typed values).
TINY = {"mesh.refinement": 0.25, "modal.n_modes": 8, "modal.block_size": 8}


def _coarse_case(**extra) -> rv.Case:
    values = {COARSE[i + 1].split("=")[0]: float(COARSE[i + 1].split("=")[1])
              for i in range(0, len(COARSE), 2)}
    values["modal.n_modes"] = int(values["modal.n_modes"])
    return rv.Case.from_file(BASELINE).replace({**values, **extra})


# ----------------------------------------------------------------------------- item 6
def _common(stage: str, out: Path) -> dict:
    return {"stage": stage, "out_dir": out, "reused": False, "seconds": 1.0,
            "timings": {"x": 1.0}, "summary": {"verdict": {"slab1": True}, "list": [1, 2],
                                               "nested": {"a": [{"b": 1}]}},
            "unused_petsc_options": ()}


def test_results_are_deeply_frozen(tmp_path, tally):
    """``r.assess.verdict["slab1"] = False`` flipped ``r.passed``, and
    ``r.reconstruct.probes["slab1"] = None`` was accepted: now both raise, every mapping
    and list of a result is read-only, and the results still pickle (MPI) and compare."""
    verdict = {"slab1": True, "slab2": None}
    assess = AssessResult(**_common("assess", tmp_path), assessment_json=tmp_path / "a.json",
                          report_html=None, report_md=None, report_json=None,
                          verdict=verdict, max_utilisation={"slab1": 0.5, "slab2": None})
    peak = ProbePeak(name="slab1", role="floor", coords=[1.0, 2.0, 3.0], acc_vertical=1.0,
                     acc_total=2.0, t_acc_total=0.1, vel_total=0.0, disp_total=0.0,
                     t_onset=None)
    recon = ReconstructResult(**_common("reconstruct", tmp_path), fields_h5=tmp_path / "f",
                              fields_xdmf=None, stress_xdmf=None, probes_h5=tmp_path / "p",
                              probes={"slab1": peak})
    verdict["slab1"] = False                    # the caller's dict is copied
    assert assess.passed is True
    refused = []
    for what, change in [
            ("verdict[...] = False", lambda: assess.verdict.__setitem__("slab1", False)),
            ("verdict.update", lambda: assess.verdict.update(slab1=False)),
            ("max_utilisation.pop", lambda: assess.max_utilisation.pop("slab1")),
            ("probes[...] = None", lambda: recon.probes.__setitem__("slab1", None)),
            ("probes.clear", lambda: recon.probes.clear()),
            ("summary nested", lambda: assess.summary["nested"]["a"][0].__setitem__("b", 2)),
            ("timings[...] =", lambda: assess.timings.__setitem__("y", 2.0))]:
        try:
            change()
        except TypeError:
            refused.append(what)
    ok = len(refused) == 7 and assess.passed is True and recon.probes["slab1"] is peak
    tally.add("API result: r.assess.verdict['slab1'] = False, r.reconstruct.probes['slab1'] "
              "= None", "clear error" if ok else "silent wrong", ", ".join(refused))
    assert ok, refused
    assert isinstance(assess.summary["list"], tuple) and peak.coords == (1.0, 2.0, 3.0)
    with pytest.raises(AttributeError):
        assess.verdict = {}                     # the dataclass itself is frozen
    # still a dict to read: equality, JSON, pickling (comm.allgather) keep the freeze
    assert assess.verdict == {"slab1": True, "slab2": None}
    assert json.loads(json.dumps(assess.summary))["nested"] == {"a": [{"b": 1}]}
    again = pickle.loads(pickle.dumps(recon))
    assert again == recon and isinstance(again.probes, rv.api.FrozenDict)
    with pytest.raises(TypeError):
        again.probes["slab1"] = None
    mutable = dict(assess.verdict)              # an explicit copy may be changed
    mutable["slab1"] = False
    assert assess.passed is True


def test_result_arrays_are_read_only_copies(tmp_path):
    from railvib_hpc.api import MBSResult

    force = np.array([1.0, 2.0])
    r = MBSResult(**_common("mbs", tmp_path), mbs_h5=tmp_path / "m", plots=[], n_modes=1,
                  dt=1.0, n_steps=1, t_end=1.0, static_wheel_load=force,
                  mean_contact_force=force, peak_contact_force=force,
                  min_contact_force=force, max_rail_deflection=0.0, loss_of_contact_steps=0)
    force[0] = 9.0                                # the caller's array is not shared
    assert r.peak_contact_force[0] == 1.0 and r.plots == ()
    with pytest.raises(ValueError, match="read-only"):
        r.peak_contact_force[0] = 5.0
    assert not pickle.loads(pickle.dumps(r)).peak_contact_force.flags.writeable


def test_study_result_settings_are_frozen_and_can_be_given_back():
    from railvib_hpc.studies.settings import study_settings

    frozen = rv.api._freeze(study_settings("speed", values={"speeds": [20.0, 40.0]}))
    with pytest.raises(TypeError):
        frozen["speeds"] = ()
    assert frozen["speeds"] == (20.0, 40.0)
    # a StudyResult's settings given back to run_study are accepted as they are
    assert study_settings("speed", values=frozen)["speeds"] == [20.0, 40.0]


# ----------------------------------------------------------------------------- item 11
def test_lock_keeps_other_threads_out_and_temp_names_are_unique(tmp_path, tally):
    """The lock was re-entrant for the whole process: a second thread (a second
    Pipeline) walked in. Now another thread is refused like another process, or waits."""
    out = tmp_path / "out"
    held, release, log = threading.Event(), threading.Event(), []

    def holder():
        locks.acquire_lock(out, "holder")
        locks.acquire_lock(out, "holder again")            # re-entrant in its own thread
        locks.release_lock(out)
        log.append(("held", locks.holds_lock(out)))
        held.set()
        release.wait(30)
        log.append(("released", time.monotonic()))
        locks.release_lock(out)

    t = threading.Thread(target=holder)
    t.start()
    assert held.wait(30)
    try:
        assert not locks.holds_lock(out)                    # not this thread's
        with pytest.raises(OutputLockedError, match=r"in use by thread \d+ of this process"):
            locks.acquire_lock(out, "second")
        locks.release_lock(out)                             # not ours: nothing happens
        assert t.is_alive() and log == [("held", True)]
        names = []

        def temp():
            names.append(temp_names.temp_path(out / "mbs.h5"))

        others = [threading.Thread(target=temp) for _ in range(4)]
        for o in others:
            o.start()
        for o in others:
            o.join()
        assert len(set(names)) == 4                      # one name per writer
        assert all(temp_names.final_name(n.name) == "mbs.h5" for n in names)
        threading.Timer(0.3, release.set).start()
        locks.acquire_lock(out, "waiting", wait=True)        # waits for the holder
        got = time.monotonic()
        assert locks.holds_lock(out)
    finally:
        release.set()
        t.join(30)
    locks.release_lock(out)
    assert not locks.holds_lock(out)
    ok = log[-1][0] == "released" and got >= log[-1][1]
    tally.add("lock of one folder from two threads", "clear error" if ok else "data loss")
    assert ok


def test_temporary_files_of_live_threads_are_kept(tmp_path):
    """The new temporary names still carry the pid: a live process's files are kept, a
    dead one's removed (``remove_stale_temps``)."""
    mine = temp_names.temp_path(tmp_path / "mesh.msh", suffix=True)
    mine.write_bytes(b"1")
    dead = tmp_path / f".modes.h5.part-{temp_names._host()}-999999999_t12_abcdef"
    dead.write_bytes(b"12")
    assert temp_names.remove_stale_temps(tmp_path) == (1, 2)
    assert mine.exists() and not dead.exists()


def _two_threads(work: Path, case: rv.Case, call: str, wait: bool) -> list:
    start = threading.Barrier(2)
    outcomes: list = [None, None]

    def go(i: int) -> None:
        pipe = rv.Pipeline(case, work, quiet=True, wait=wait)
        start.wait(30)
        try:
            outcomes[i] = ("ok", getattr(pipe, call)().reused)
        except UserError as exc:
            outcomes[i] = (type(exc).__name__, str(exc))
        except Exception as exc:
            outcomes[i] = ("traceback", repr(exc))

    threads = [threading.Thread(target=go, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    return outcomes


def _mbs_intact(path: Path) -> bool:
    try:
        with h5py.File(path, "r") as f:
            return int(f.attrs.get("complete", 0)) == 1 and "wheels" in f
    except OSError:
        return False


@serial_only
def test_two_pipelines_in_threads_never_lose_mbs(work, tally):
    """The issue: two Pipeline(...).mbs() on one folder in two threads both failed and
    mbs.h5 was gone. Now one runs, the other is refused at once (or, with wait=True, runs
    after it and reuses its file); mbs.h5 is complete and current afterwards."""
    case = _coarse_case(**{"vehicle.speed": 25.0})           # the mbs stage must recompute
    outcomes = _two_threads(work, case, "mbs", wait=False)
    kinds = sorted(o[0] for o in outcomes)
    intact = _mbs_intact(work / "mbs.h5")
    after = rv.Pipeline(case, work, quiet=True).mbs()
    ok = (kinds == ["OutputLockedError", "ok"] or kinds == ["ok", "ok"]) and intact \
        and after.reused is True
    tally.add("two Pipeline.mbs() threads on one folder", "clear error" if ok else
              "data loss", "; ".join(f"{k}: {v}"[:140] for k, v in outcomes))
    assert ok, outcomes
    refused = [v for k, v in outcomes if k == "OutputLockedError"]
    assert all("another thread" in v or "of this process" in v for v in refused)
    assert not [p for p in work.iterdir() if ".part-" in p.name]
    # with wait=True both succeed: one computes, the other waits and reuses it
    case2 = _coarse_case(**{"vehicle.speed": 35.0})
    outcomes = _two_threads(work, case2, "mbs", wait=True)
    ok = sorted(outcomes) == [("ok", False), ("ok", True)] and _mbs_intact(work / "mbs.h5")
    tally.add("two Pipeline.mbs() threads on one folder, wait=True",
              "correct" if ok else "data loss", str(outcomes)[:200])
    assert ok, outcomes


# ----------------------------------------------------------------------------- item 17
def _study(capsys, *args: str) -> tuple[int, str, str]:
    code = run(["study", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_merge_with_nothing_finished_is_an_error(tmp_path, capsys, tally):
    """``study ... --merge`` with 0 finished variants exited 0."""
    code, _out, err = _study(capsys, "speed", str(BASELINE), "--out", str(tmp_path),
                            "--set", "mesh.refinement=0.25", "--study-set",
                            "speeds=[20,40,60]", "--merge")
    lines = [ln for ln in err.splitlines() if ln.startswith("railvib study: error:")]
    ok = code == 2 and len(lines) == 1 and "Traceback" not in err
    tally.add("study speed --merge with 0 finished", "clear error" if ok else
              "silent wrong", lines[0] if lines else err[-200:])
    assert ok, (code, err)
    assert "none of the 3 variants has finished (3 pending)" in lines[0]
    assert not (tmp_path / "speed" / "report.md").exists()
    with pytest.raises(UserError, match="none of the 3 variants has finished"):
        rv.run_study("speed", BASELINE, tmp_path, settings={"speeds": [20.0, 40.0, 60.0]},
                     merge_only=True, quiet=True)


def test_speed_verdict_never_claims_every_unfinished_speed():
    from railvib_hpc.studies import speed

    q = {"slab1 a_z": 1.0, "slab1 |a|": 1.0, "peak contact force": 8e3}
    data = [{"variant": "v20", "speed": 20.0, "quantities": q, "dynamic_factor": 1.0,
             "max_utilisation": 0.1, "governing_probe": "slab1", "passed": True}]
    acc = ["slab1 a_z", "slab1 |a|"]
    part = speed._verdict(data, acc, planned=3)
    assert "every speed" not in part["text"] and part["ok"] is None
    assert "every finished speed (1 of 3) passes every standard" in part["text"]
    full = speed._verdict(data, acc, planned=1)
    assert "every speed passes every standard" in full["text"] and full["ok"] is True


@serial_only
@pytest.mark.slow
def test_merge_of_one_of_three_speeds_says_two_are_missing(tmp_path, capsys, tally):
    """With 1 of 3 finished, the verdict said "every speed passes every standard"."""
    args = ["speed", str(BASELINE), "--out", str(tmp_path), "--set", "mesh.refinement=0.25",
            "--set", "modal.n_modes=8", "--set", "modal.block_size=8", "--study-set",
            "speeds=[20,40,60]"]
    assert _study(capsys, *args, "--variant", "v20")[0] == 0
    code, out, _err = _study(capsys, *args, "--merge")
    verdict = next(ln for ln in out.splitlines() if ln.startswith("VERDICT:"))
    ok = code == 0 and "every speed" not in verdict and \
        "INCOMPLETE: 2 of 3 variants not finished (v40 pending, v60 pending)" in verdict
    tally.add("study speed --merge with 1 of 3 finished", "correct" if ok else
              "silent wrong", verdict[:200])
    assert ok, verdict
    report = json.loads((tmp_path / "speed" / "report.json").read_text())
    assert report["verdict"]["missing"] == ["v40", "v60"]
    assert report["verdict"]["complete"] is False and report["verdict"]["ok"] is None
    # item 3 on the way: 8 modes end near 15 Hz, far below 80 Hz -- said, and warned
    cov = report["analysis"]["band_coverage"]
    assert cov["variants"][0]["f_max_hz"] < 20 and cov["warning"]
    assert "[WARNING: the solution of 1 of 1 finished variants does not cover the " \
        "assessment band 1–80 Hz" in verdict
    assert "## Frequency band of each variant" in (tmp_path / "speed" / "report.md").read_text()


# ----------------------------------------------------------------------------- item 3
def _result(f_max: float, scale: float = 1.0, direct: bool = False) -> dict:
    from railvib_hpc.studies.common import _third_octave_nominals

    bands = _third_octave_nominals(1.0, 80.0)
    spec = {"bands_hz": bands, "acc_rms": {c: [scale * (k + 1.0) for k in range(len(bands))]
                                           for c in ("x", "y", "z", "total")}}
    return {"model": {"solver": "direct" if direct else None, "modes_used": None if direct
                      else 20, "frequencies_hz": [None] if direct else [10.2, 11.0],
                      "f_max_hz": f_max},
            "spectra": {"slab1": spec}}


def test_spectra_are_cut_to_the_band_the_solution_resolves():
    from railvib_hpc.studies.common import StudyPlan, Variant, band_coverage, resolved_spectra

    r = _result(18.1)
    cut = resolved_spectra(r)
    assert cut["spectra"]["slab1"]["bands_hz"][-1] == 16.0
    assert len(cut["spectra"]["slab1"]["acc_rms"]["total"]) == \
        len(cut["spectra"]["slab1"]["bands_hz"])
    assert cut["unresolved_bands_hz"]["slab1"][0] == 20.0
    assert r["spectra"]["slab1"]["bands_hz"][-1] == 80.0         # the result is not changed
    plan = StudyPlan("mitigation", (Variant("baseline", ()), Variant("m", ()),
                                    Variant("d", ())))
    cov = band_coverage(plan, {"baseline": r, "m": _result(18.1), "d": _result(80.0, direct=True)})
    assert [p["top_band_hz"] for p in cov["variants"]] == [16.0, 16.0, 80.0]
    assert cov["variants"][0]["f1_hz"] == 10.2 and cov["variants"][2]["f1_hz"] is None
    assert cov["warning"].startswith("the solution of 2 of 3 finished variants does not "
                                     "cover the assessment band 1–80 Hz (baseline: 20 modes, "
                                     "10.2–18.1 Hz")
    assert band_coverage(plan, {"d": _result(80.0, direct=True)})["warning"] is None


def test_mitigation_reports_no_band_above_the_modes(tmp_path, monkeypatch):
    """The issue: 20 modes span 10–18 Hz, yet insertion losses were reported per band up to
    80 Hz. The merged report now holds only the bands both variants resolve, lists each
    variant's band and warns."""
    from railvib_hpc.studies import runner
    from railvib_hpc.studies.common import StudyPlan, Variant

    plan = StudyPlan("mitigation", (
        Variant("baseline", (), {"measure": "baseline", "reference": None}),
        Variant("shallow", ("trench.type=open",), {"measure": "shallow",
                                                   "reference": "baseline"})))
    res = {"baseline": _result(18.1), "shallow": _result(18.1, scale=0.5)}
    for r in res.values():
        r.update(probes={"slab1": {"acc_vertical": 1.0, "acc_total": 1.0}},
                 mbs={"peak_contact_force": 1.0}, timings={"total": 1.0},
                 assessment={"slab1": {"passed": True, "max_utilisation": 0.5}})
    entries = [{"name": n, "parameter": {}, "status": "finished", "folder": "."} for n in res]
    monkeypatch.setattr(runner, "status", lambda *a: (entries, res))
    settings = {"probes": ["slab1"], "measures": [], "same_mesh": False}
    case = rv.Case.defaults()
    merged = runner.merge("mitigation", plan, case, tmp_path, settings, _quiet())
    band_table = next(t for t in merged["tables"] if t["title"].startswith("Insertion loss "
                                                                            "per one-third"))
    heads = [float(h.split()[0]) for h in band_table["head"][1:]]
    assert heads and max(heads) == 16.0
    row = merged["rows"][0]
    assert max(float(f) for f in row["il_band_db"]["slab1"]) == 16.0
    assert "[WARNING: the solution of 2 of 2 finished variants does not cover" in \
        merged["verdict"]["text"]
    table = next(t for t in merged["tables"] if t["title"] == "Frequency band of each variant")
    assert table["rows"][0][3:] == ["10.2", "18.1", "16"]
    md = (tmp_path / "report.md").read_text()
    assert "80 Hz" not in band_table["head"] and "| 20 Hz" not in md


def _quiet():
    from railvib_hpc.log import Reporter

    class _Null:
        def write(self, s):
            return len(s)

        def flush(self):
            pass

    return Reporter(0, _Null())


def test_studies_accept_solver_direct(tmp_path, monkeypatch, tally):
    """The mitigation study (and convergence, speed) accept ``solver = direct`` as the
    reflection study does: every variant then runs ``railvib transient``'s stage."""
    from railvib_hpc.studies.runner import make_plan
    from railvib_hpc.studies.settings import StudySettingsError, study_settings

    case = rv.Case.from_file(MITIGATION).replace(TINY)
    for kind in ("mitigation", "convergence", "speed", "reflection"):
        assert study_settings(kind, ["solver=direct"])["solver"] == "direct"
    with pytest.raises(StudySettingsError, match="solver"):
        study_settings("mitigation", ["solver=fast"])
    sp = make_plan("speed", case, study_settings("speed", ["solver=direct", "speeds=[20]"]))
    assert sp.shared_overrides is None and not any(v.shared for v in sp.variants)
    called = []

    def fake_transient(ctx, *args, **kwargs):           # the stage's context: its folder
        called.append(ctx.out_dir.name)
        raise UserError("full-order solve not run in this test")

    import railvib_hpc.transient.stage as ts

    monkeypatch.setattr(ts, "_transient", fake_transient)
    res = rv.run_study("mitigation", case, tmp_path, quiet=True, variants=["baseline"],
                       settings={"measures": ["soft: pads.kz=1.2e8"], "solver": "direct"})
    ok = called == ["baseline"] and res.failed == ("baseline",)
    tally.add("study mitigation --study-set solver=direct", "correct" if ok else
              "silent wrong", str(res.failed))
    assert ok
