"""Study settings, plans, variant selection, verdict logic and the CLI (no computation)."""

from __future__ import annotations

from pathlib import Path

import pytest

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.studies import STUDY_MODULES, StudySettingsError, study_settings
from railvib_hpc.studies.common import StudyError, variant_case
from railvib_hpc.studies.reflection import weyl_count
from railvib_hpc.studies.runner import make_plan, select
from railvib_hpc.studies.settings import SETTINGS, describe, parse_study_set

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
PROBES = ["footing", "basement_wall", "slab1", "slab2"]


@pytest.fixture(scope="module")
def case():
    return load_case(BASELINE)


def test_defaults_and_overrides():
    s = study_settings("convergence")
    assert s["levels"] == [0.5, 0.75, 1.0, 1.25] and s["tolerance"] == 5.0
    s = study_settings("convergence", ["levels=[1, 0.5, 0.75]", "tolerance=2"])
    assert s["levels"] == [0.5, 0.75, 1.0] and s["tolerance"] == 2.0
    assert study_settings("speed", ["probes=[slab1,slab2]"])["probes"] == ["slab1", "slab2"]
    assert study_settings("modes", values={"n_modes": [20, 10]})["n_modes"] == [10, 20]
    r = study_settings("reflection", ["domains=[[0,0,0],[1,2,3]]"])
    assert r["names"] == ["domain1", "domain2"]
    assert parse_study_set("speed", "speeds = [10, 20]") == ("speeds", [10, 20])
    for kind in SETTINGS:
        assert "| setting |" in describe(kind)


def test_every_problem_named_with_key_value_and_allowed():
    with pytest.raises(StudySettingsError) as exc:
        study_settings("convergence", ["levels=[0.5, 7]", "tolerence=3", "n_frequencies=x"])
    msg = str(exc.value)
    assert "3 problems" in msg
    assert "study.convergence.levels = [0.5, 7]: entry 7.0 must satisfy 0 < value <= 6" in msg
    assert "study.convergence.tolerence = 3: unknown setting" in msg
    assert "did you mean 'study.convergence.tolerance'" in msg
    assert "study.convergence.n_frequencies = 'x': expected an integer" in msg
    with pytest.raises(StudySettingsError, match="need at least 2 refinement levels"):
        study_settings("convergence", ["levels=[1.0]"])
    with pytest.raises(StudySettingsError, match="needs one name per entry of domains"):
        study_settings("reflection", ["domains=[[0,0,0],[1,1,1]]", "names=[a]"])
    with pytest.raises(StudySettingsError, match="entries must be distinct"):
        study_settings("speed", ["speeds=[10, 10]"])
    with pytest.raises(StudySettingsError, match="key=value"):
        study_settings("speed", ["speeds"])
    with pytest.raises(StudySettingsError, match=r"expected a list of \[a, b, c\] number"):
        study_settings("reflection", ["domains=[1, 2]"])


def test_plans(case):
    p = make_plan("convergence", case, study_settings("convergence"))
    assert [v.name for v in p.variants] == ["r0.5", "r0.75", "r1", "r1.25"]
    assert p.variants[0].overrides == ("mesh.refinement=0.5",) and p.shared_overrides is None
    m = make_plan("modes", case, study_settings("modes", ["n_modes=[10, 30]"]))
    assert [v.name for v in m.variants] == ["n10_modal", "n10_corrected", "n30_modal",
                                            "n30_corrected"]
    assert "modal.n_modes=30" in m.shared_overrides
    assert "mbs.static_correction=true" in m.shared_overrides
    assert all(v.shared for v in m.variants)
    vc = variant_case(case, m.variants[0].overrides)
    assert vc["mbs.n_modes"] == 10 and vc["modal.n_modes"] == 30
    assert not vc["mbs.static_correction"]
    r = make_plan("reflection", case, study_settings("reflection"))
    assert [v.name for v in r.variants] == ["model1", "model2", "model3", "larger"]
    big = variant_case(case, r.variants[-1].overrides)
    assert (big["domain.extra_depth"], big["domain.extra_length"],
            big["domain.extra_width"]) == (4.0, 4.0, 12.0)
    # the thesis's labels (section 6.7): Model 1 has a 3 m deep subgrade, Model 2 is the
    # APDL domain (4.8 m, the thesis's "5 m"), Model 3 adds length and 6 m of width
    m1, m2, m3 = (variant_case(case, v.overrides) for v in r.variants[:3])
    assert m1["geometry.z1"] - m1["geometry.z0"] == pytest.approx(3.0)
    assert m2.data == variant_case(case, ()).data
    assert (m3["domain.extra_length"], m3["domain.extra_width"]) == (2.0, 6.0)
    rb = make_plan("reflection", case, study_settings("reflection", ["band_hz=30"]))
    # every domain: its modes below the band by the band-sliced (inertia-checked) solve
    assert all(variant_case(case, v.overrides)["modal.f_max"] == 30.0 for v in rb.variants)
    assert rb.variants[0].band_hz == 30.0
    with pytest.raises(StudySettingsError, match="only the depth change may be negative"):
        study_settings("reflection", ["domains=[[0,0,0],[0,-1,0]]"])
    with pytest.raises(StudySettingsError, match=r"depth change must be > -2\.4 m"):
        make_plan("reflection", case, study_settings("reflection",
                                                     ["domains=[[-2.4,0,0],[0,0,0]]"]))
    sp = make_plan("speed", case, study_settings("speed"))
    assert sp.shared_overrides == () and [v.parameter["speed"] for v in sp.variants] == \
        [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
    with pytest.raises(StudySettingsError, match="unknown probes"):
        make_plan("speed", case, study_settings("speed", ["probes=[roof]"]))


def test_weyl_estimate_close_to_the_computed_mode_counts(case):
    # the thesis baseline has 118 modes below 30 Hz and its 300th mode at 42.655 Hz
    assert weyl_count(case, 30.0) == pytest.approx(118, rel=0.2)
    assert weyl_count(case, 42.655) == pytest.approx(300, rel=0.1)


def test_select_by_name_or_index(case):
    p = make_plan("speed", case, study_settings("speed"))
    assert [v.name for v in select(p, ["v20", "3", "v20,0"])] == ["v20", "v40", "v10"]
    with pytest.raises(StudyError, match="unknown variant"):
        select(p, ["v35"])
    with pytest.raises(StudyError, match="index out of range"):
        select(p, ["6"])


def _fake(parameter, *, dofs=1000, acc=1.0, force=8000.0, defl=1e-5, util=0.2, f1=9.0,
          spectra=None):
    probes = {p: {"acc_vertical": acc, "acc_total": 2 * acc} for p in PROBES}
    return {"parameter": parameter, "timings": {"total": 1.0}, "duration": 1.0,
            "model": {"n_dofs": dofs, "n_nodes": dofs // 3, "n_hexes": dofs // 4,
                      "frequencies_hz": [f1, f1 + 1, f1 + 2, f1 + 3, f1 + 4],
                      "f_max_hz": 40.0, "modes_used": 300},
            "mbs": {"peak_contact_force": force, "dynamic_factor": force / 7691.0,
                    "min_contact_force": 7000.0, "max_rail_deflection": defl,
                    "loss_of_contact_steps": 0},
            "probes": probes,
            "assessment": {p: {"passed": util <= 1, "max_utilisation": util} for p in PROBES},
            "spectra": spectra or {p: {"bands_hz": [10.0, 12.5], "acc_rms": {
                "total": [acc, acc]}} for p in PROBES}}


def test_convergence_verdict_from_an_analytic_sequence(case):
    s = study_settings("convergence", ["levels=[0.5, 0.75, 1.0]", "tolerance=5"])
    plan = make_plan("convergence", case, s)
    dofs = [8000, 27000, 64000]                       # h = 0.05, 0.0333, 0.025
    res = {}
    for v, n in zip(plan.variants, dofs):
        h = n ** (-1 / 3)
        res[v.name] = _fake(v.parameter, dofs=n, acc=1.0 + 8.0 * h**2, f1=9.0 + 40 * h**2,
                            force=8000.0 * (1 + h**2))
    a = STUDY_MODULES["convergence"].analyse(plan, res, s)
    rich = a["richardson"]
    assert rich["slab1 a_z"]["observed_order"] == pytest.approx(2.0, rel=1e-8)
    assert rich["slab1 a_z"]["extrapolated"] == pytest.approx(1.0, rel=1e-10)
    worst = max(e["error"] for e in rich.values())
    assert a["verdict"]["error"] == pytest.approx(worst)
    assert a["verdict"]["ok"] is (worst <= 0.05)
    assert (f"{100 * worst:.2f} %") in a["verdict"]["text"]
    s = study_settings("convergence", ["levels=[0.5, 0.75, 1.0]", "tolerance=50"])
    a = STUDY_MODULES["convergence"].analyse(plan, res, s)
    assert a["verdict"]["text"].startswith(f"converged within {100 * worst:.2f} %")


def test_modes_verdict(case):
    s = study_settings("modes", ["n_modes=[50, 100, 300]"])
    plan = make_plan("modes", case, s)
    res = {}
    for v in plan.variants:
        n, c = v.parameter["n_modes"], v.parameter["static_correction"]
        err = (0.5 if not c else 0.2) * 50 / n if n < 300 else (0.0 if c else 0.3)
        res[v.name] = _fake(v.parameter, acc=1.0 + err, defl=1e-5 * (1 + err))
    a = STUDY_MODULES["modes"].analyse(plan, res, s)
    assert a["reference"] == "n300_corrected"
    assert a["modes_needed"] == {"modal": None, "corrected": 300}
    res["n100_corrected"] = _fake({"n_modes": 100, "static_correction": True}, acc=1.01,
                                  defl=1.01e-5)
    a = STUDY_MODULES["modes"].analyse(plan, res, s)
    assert a["modes_needed"]["corrected"] == 100
    assert "with the static correction: 100 modes" in a["verdict"]["text"]
    # per quantity: the building accelerations are within 5 % from 100 modes on (50 % off
    # at 50) in both families; the rail deflection never is without the correction (30 %
    # off), with it from 50 modes on (2 % off)
    for v in plan.variants:
        n, c = v.parameter["n_modes"], v.parameter["static_correction"]
        acc = 1.0 + (0.5 if n == 50 else 0.01)
        defl = 1e-5 * (1.0 if c else 0.7) * (1.0 + (0.02 if n < 300 else 0.0))
        res[v.name] = _fake(v.parameter, acc=acc, defl=defl)
    a = STUDY_MODULES["modes"].analyse(plan, res, s)
    pq = a["modes_needed_per_quantity"]
    assert pq["modal"]["slab1 a_z"] == 100 and pq["modal"]["max rail deflection"] is None
    assert pq["corrected"]["slab1 a_z"] == 100 and pq["corrected"]["max rail deflection"] == 50
    assert pq["corrected"]["peak contact force"] == 50
    assert ("with the static correction: building accelerations 100, contact force 50, "
            "rail deflection 50") in a["verdict"]["text"]
    assert "modes only: building accelerations 100, contact force 50, rail deflection not "\
           "reached" in a["verdict"]["text"]


def test_reflection_and_speed_verdicts(case):
    s = study_settings("reflection", ["threshold=10"])
    plan = make_plan("reflection", case, s)
    accs = [1.3, 1.2, 1.02, 1.0]
    res = {v.name: _fake(v.parameter, acc=a) for v, a in zip(plan.variants, accs)}
    a = STUDY_MODULES["reflection"].analyse(plan, res, s)
    # the verdict is about the case's own domain: model2 (the thesis's Model 2)
    assert a["verdict"]["reflections_matter"] is True
    assert a["verdict"]["max_deviation"] == pytest.approx(0.2)
    assert "for the model2 domain" in a["verdict"]["text"]
    assert a["verdict"]["within_threshold_from"] == "model3"
    res["model2"] = _fake({}, acc=1.05)
    assert STUDY_MODULES["reflection"].analyse(plan, res, s)["verdict"]["ok"] is True
    sp = study_settings("speed", ["speeds=[10, 20, 30]"])
    splan = make_plan("speed", case, sp)
    res = {v.name: _fake(v.parameter, acc=a, util=u, force=f)
           for v, a, u, f in zip(splan.variants, (1.0, 3.0, 2.0), (0.2, 1.4, 0.9),
                                 (7800.0, 8100.0, 9000.0))}
    a = STUDY_MODULES["speed"].analyse(splan, res, sp)
    assert a["verdict"]["critical_speed"] == 20.0
    assert a["verdict"]["failing_speeds"] == [20.0] and a["verdict"]["ok"] is False
    assert a["verdict"]["max_contact_force_speed"] == 30.0


def test_cli_study_errors_and_list(capsys, tmp_path):
    assert run(["study", "convergence", str(BASELINE), "--study-set", "levels=[0.5, 9]",
                "--out", str(tmp_path)]) == 2
    assert ("study.convergence.levels = [0.5, 9]: entry 9.0 must satisfy 0 < value <= 6"
            in capsys.readouterr().err)
    assert run(["study", "speed", str(BASELINE), "--variant", "v33", "--list",
                "--out", str(tmp_path)]) == 2
    assert "unknown variant of the speed study" in capsys.readouterr().err
    assert run(["study", "modes", str(BASELINE), "--list", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "n300_corrected" in out and "pending" in out and "shared model" in out
    # the overrides all variants share once above the table, each row its own
    assert "every variant: modal.n_modes=300 modal.f_max=0.0" in out
    row = next(ln for ln in out.splitlines() if " n50_modal " in ln)
    assert "mbs.n_modes=50" in row and "modal.f_max" not in row


def test_thesis_study_plan_and_table(case):
    s = study_settings("thesis")
    assert s["band_hz"] == 57.87 and s["n_modes"] == 300
    assert s["drop_heights"] == [0.0, 1e-5, 1e-4]
    plan = make_plan("thesis", case, s)
    assert plan.shared_overrides == ("modal.f_max=57.87",)
    assert [v.name for v in plan.variants] == [
        "n300_drop0mm", "n300_drop0.01mm", "n300_drop0.1mm",
        "band_drop0mm", "band_drop0.01mm", "band_drop0.1mm"]
    v = variant_case(case, plan.variants[2].overrides)
    assert (v["mbs.n_modes"], v["vehicle.drop_height"], v["modal.f_max"]) == (300, 1e-4, 57.87)
    assert variant_case(case, plan.variants[3].overrides)["mbs.n_modes"] == 0
    res = {}
    for var, acc in zip(plan.variants, (0.008, 0.03, 0.07, 0.01, 0.04, 0.09)):
        r = _fake(var.parameter, acc=acc)
        r["probes"]["basement_wall_far"] = {"acc_vertical": acc, "acc_total": acc,
                                            "t_onset": 0.06}
        res[var.name] = r
    a = STUDY_MODULES["thesis"].analyse(plan, res, s)
    head, rows = a["tables"][0]["head"], a["tables"][0]["rows"]
    assert head[:2] == ["quantity", "thesis"]
    slab1 = next(r for r in rows if r[0] == "slab 1 a_z [m/s²]")
    assert slab1[1] == "0.06" and slab1[2] == "0.008"
    onset = next(r for r in rows if r[0].startswith("basement_wall_far onset"))
    assert onset[1] == "0.16" and onset[2] == "0.06"      # x_start = 0: the thesis's clock
    # 0.008..0.07 (count) and 0.01..0.09 (band) bracket 0.060, 0.045 and 0.041 (the fake
    # floor totals are twice the vertical: 0.016..0.14, 0.02..0.18 bracket 0.041 and 0.052)
    assert a["verdict"]["brackets_thesis"]["count"] == [
        "slab 1 a_z", "slab 2 a_z", "floor 1 |a|", "floor 2 |a|"]
    assert "brackets 4 of 4 thesis values" in a["verdict"]["text"]
    assert "not a fitted value" in a["verdict"]["text"]
    with pytest.raises(StudySettingsError, match="drop_heights"):
        study_settings("thesis", ["drop_heights=[-1e-5]"])


def test_study_tables_in_the_case_file_use_the_case_schema_engine(tmp_path):
    """[study.KIND] tables are case keys: load_case checks them; --study-set overrides them."""
    from railvib_hpc.errors import CaseError

    path = tmp_path / "case.toml"
    path.write_text('[study.speed]\nspeeds = [40, 20]\nprobes = ["slab1"]\n')
    case = load_case(path)
    s = study_settings("speed", case=case)
    assert s["speeds"] == [20.0, 40.0] and s["probes"] == ["slab1"]
    assert study_settings("speed", ["speeds=[5]"], case=case)["speeds"] == [5.0]
    path.write_text("[study.speed]\nspeeds = [40, -20]\n")
    with pytest.raises(CaseError, match=r"study\.speed\.speeds = \[40, -20\]: entry -20.0 "
                                        "must be > 0"):
        load_case(path)
    path.write_text('[study.reflection]\nnames = ["a"]\n')
    with pytest.raises(CaseError, match="needs one name per entry of domains"):
        load_case(path)
    with pytest.raises(StudySettingsError) as info:
        study_settings("speed", ["speeds=[x]"])
    assert isinstance(info.value, CaseError)
