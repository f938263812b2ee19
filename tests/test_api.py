"""The Python API: immutable cases and their variants, the pipeline object and its typed
results (the same on every rank), PETSc options only while a stage runs, run.json, studies
as result objects."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

import railvib_hpc as rv
from railvib_hpc.config import load_case

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: A tiny model (the modal solve takes ~2 s on one core).
TINY = {"mesh.refinement": 0.25, "modal.n_modes": 8, "modal.block_size": 8,
        "output.dt": 0.01}
comm = MPI.COMM_WORLD


# ----------------------------------------------------------------------------- Case
def test_flat_api_is_importable_and_light():
    import subprocess
    import sys

    code = ("import sys, railvib_hpc as rv; heavy = [m for m in ('numpy', 'h5py', "
            "'petsc4py', 'gmsh', 'mpi4py') if m in sys.modules]; print(heavy); "
            "assert all(hasattr(rv, n) for n in rv.__all__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_result_fields_are_declared_once_in_a_light_module():
    """Each API result inherits its fields from the stage's output type
    (railvib_hpc/io/stage_outputs.py); that module loads neither numpy nor a stage module,
    and the API loads no stage module."""
    import subprocess
    import sys

    from railvib_hpc.io import stage_outputs as so

    pairs = {rv.MeshResult: so.MeshOutput, rv.ModalResult: so.ModesOutput,
             rv.MBSResult: so.PassageOutput, rv.ReconstructResult: so.FieldsOutput,
             rv.AssessResult: so.AssessmentOutput}
    common = [f.name for f in dataclasses.fields(rv.StageResult)]
    for result, output in pairs.items():
        assert issubclass(result, output) and issubclass(result, rv.StageResult)
        own = [f.name for f in dataclasses.fields(output)]
        assert [f.name for f in dataclasses.fields(result)] == \
            common + [n for n in own if n not in common]
        assert not set(vars(result).get("__annotations__", {})) & set(own), result
    stages = [f"railvib_hpc.{s}.stage" for s in ("mesh", "modal", "mbs", "reconstruct",
                                                 "assess")]
    code = ("import sys, railvib_hpc.io.stage_outputs; a = 'numpy' in sys.modules; "
            f"import railvib_hpc.api; print(a, [m for m in {stages!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "False []"


def test_case_replace_is_typed_validated_and_leaves_the_original():
    case = rv.Case.from_file(BASELINE)
    soft = case.replace({"materials.subgrade.E": 1.5e8, "vehicle.speed": 20,
                         "output.probe_roles": []})
    assert soft["materials.subgrade.E"] == 1.5e8 and isinstance(soft["vehicle.speed"], float)
    assert case["materials.subgrade.E"] == 2e8 and case["vehicle.speed"] == 30.0
    assert soft.path == case.path and soft != case
    with pytest.raises(dataclasses.FrozenInstanceError):
        case.path = None
    probes = case["output.probes"]
    probes.append(1.0)                                  # a copy: the case is unchanged
    assert case["output.probes"] != probes
    # equal to the same values given as --set strings
    assert soft == load_case(BASELINE, ["materials.subgrade.E=1.5e8", "vehicle.speed=20",
                                        "output.probe_roles=[]"])


def test_case_errors_are_the_command_lines():
    case = rv.Case.from_file(BASELINE)
    with pytest.raises(rv.CaseError) as api:
        case.replace({"materials.subgrade.E": -1.0, "vehicle.sped": 3})
    with pytest.raises(rv.CaseError) as cli:
        load_case(BASELINE, ["materials.subgrade.E=-1.0", "vehicle.sped=3"])
    assert str(api.value) == str(cli.value)
    assert "vehicle.sped = 3: unknown key; did you mean 'vehicle.speed'?" in str(api.value)
    with pytest.raises(rv.CaseError, match="expected a number"):
        case.replace({"vehicle.speed": "fast"})
    with pytest.raises(rv.CaseError, match="file not found"):
        rv.Case.from_file(ROOT / "no_such_case.toml")


def test_case_from_dict_nested_or_flat_and_presets_reapplied():
    a = rv.Case.from_dict({"vehicle": {"speed": 25.0}, "case.name": "x"})
    b = rv.Case.from_dict({"vehicle.speed": 25.0, "case": {"name": "x"}})
    assert a == b and a["vehicle.speed"] == 25.0 and a.path is None
    # changing the preset applies its values (unless the case gives them explicitly)
    table1 = rv.Case.defaults().replace({"case.preset": "table1"})
    assert table1 == rv.Case.from_dict({"case.preset": "table1"})
    assert table1["pads.kz"] != rv.Case.defaults()["pads.kz"]
    assert rv.Case.from_file(BASELINE, {"modal.n_modes": 20}) == \
        rv.Case.from_file(BASELINE, ["modal.n_modes=20"])


def test_pipeline_refuses_bad_options_and_copies_them(tmp_path):
    opts = ["-railvib_eig_st_ksp_type", "preonly"]
    p = rv.Pipeline(BASELINE, tmp_path, petsc_options=opts, quiet=True)
    assert p.petsc_options == tuple(opts) and opts == ["-railvib_eig_st_ksp_type", "preonly"]
    assert p.case == rv.Case.from_file(BASELINE)
    with pytest.raises(rv.UserError, match="'preonly' after '--'"):
        rv.Pipeline(BASELINE, tmp_path, petsc_options=["preonly"])
    with pytest.raises(ValueError, match="unknown stage 'nope'"):
        p.stage("nope")
    with pytest.raises(ValueError, match="unknown stage 'nope'"):
        p.run_stages(["mesh", "nope"])               # refused before anything runs
    assert not (tmp_path / "mesh.h5").exists()


# ----------------------------------------------------------------------------- Pipeline
@pytest.mark.slow
@pytest.mark.mpi
def test_pipeline_results_match_the_files_on_every_rank(shared_tmp):
    case = rv.Case.from_file(BASELINE).replace(TINY)
    opts = ["-railvib_eig_st_ksp_type", "preonly", "-railvib_no_such_option", "1"]
    given = list(opts)
    pipe = rv.Pipeline(case, shared_tmp / "run", petsc_options=opts, quiet=True)
    result = pipe.run()
    assert opts == given                                  # the caller's list is untouched
    assert result.unused_petsc_options == ("-railvib_no_such_option",)
    from petsc4py import PETSc

    assert not PETSc.Options().hasName("railvib_eig_st_ksp_type")   # removed after the run

    # the same result on every rank
    mine = (result.modal.frequencies_hz.tolist(), result.mbs.peak_contact_force.tolist(),
            result.reconstruct.probes, result.assess.verdict, result.assess.max_utilisation,
            result.mesh.n_nodes, result.modal.reused)
    assert all(other == mine for other in comm.allgather(mine))
    assert result.mesh.reused is False and result.modal.reused is False
    assert set(result.timings) == {"mesh", "modal", "mbs", "reconstruct", "assess"}
    assert "eigensolve" in result.modal.timings and result.modal.n_modes == 8
    assert not result.modal.frequencies_hz.flags.writeable
    if comm.rank == 0:
        out = shared_tmp / "run"
        with h5py.File(out / "modes.h5", "r") as f:
            np.testing.assert_array_equal(result.modal.frequencies_hz, f["modes/frequency_hz"])
        with h5py.File(out / "mbs.h5", "r") as f:
            np.testing.assert_array_equal(result.mbs.peak_contact_force,
                                          f["wheels/contact_force"][()].max(axis=0))
        with h5py.File(out / "probes.h5", "r") as f:
            a = f["probes/slab1/acceleration"][()]
        slab1 = result.reconstruct.probes["slab1"]
        assert slab1.role == "floor" and slab1.acc_vertical == np.abs(a[:, 2]).max()
        assert slab1.acc_total == np.linalg.norm(a, axis=1).max()
        summary = json.loads((out / "assessment.json").read_text())
        assert result.assess.verdict == summary["verdict"] and result.passed is True
        assert result.assess.report_html == out / "report.html"
        assert result.mesh.mesh_h5.exists() and result.reconstruct.fields_xdmf.exists()
        assert result.mbs.static_wheel_load[0] == pytest.approx(7690, rel=1e-3)
        record = rv.read_run_record(out)
        assert [c["stage"] for c in record["calls"]] == ["mesh", "modal", "mbs",
                                                         "reconstruct", "assess"]
        modal = record["stages"]["modal"]
        assert modal["ranks"] == comm.size and len(modal["peak_rss_gb_per_rank"]) == comm.size
        assert 0 < modal["peak_rss_gb_total"] < 20 and modal["status"] == "ok"
        assert modal["case_sha256"] == case.digest()
        assert modal["command"].endswith(".run()")
        assert {"railvib", "python", "petsc", "slepc", "mpi", "h5py", "gmsh"} <= \
            set(modal["versions"])
        assert modal["versions"]["petsc"].startswith("3.")
        assert [n for n, _ in modal["substages"]][:1] == ["mesh (load/build + broadcast)"]
    comm.Barrier()
    # a second call reuses and records it
    again = pipe.modal()
    assert again.reused is True and again.frequencies_hz.tolist() == \
        result.modal.frequencies_hz.tolist()
    assert again.peak_rss_gb_total is None
    assert pipe.reconstruct().reused == {"fields": True, "stress": True, "probes": True}
    again = pipe.run_stages(["mbs", "reconstruct"])
    assert list(again.results) == ["mbs", "reconstruct"] and again["mbs"].reused is True
    record = pipe.run_record()
    assert [c["stage"] for c in record["calls"]][-4:] == ["modal", "reconstruct", "mbs",
                                                          "reconstruct"]
    assert record["stages"]["modal"]["reused"] is True
    assert record["stages"]["modal"]["command"].endswith(".modal()")
    assert record["stages"]["mbs"]["command"].endswith(".run()")


@pytest.mark.mpi
def test_pipeline_errors_reach_every_rank_and_are_recorded(shared_tmp):
    case = rv.Case.from_file(BASELINE).replace(TINY)
    pipe = rv.Pipeline(case, shared_tmp / "empty", quiet=True)
    with pytest.raises(rv.StaleInputError, match=r"modes\.h5 not found: run 'railvib modal'"):
        pipe.mbs()
    if comm.rank == 0:
        failed = rv.read_run_record(shared_tmp / "empty")["stages"]["mbs"]
        assert failed["status"] == "failed" and "modes.h5 not found" in failed["error"]
    comm.Barrier()


# ----------------------------------------------------------------------------- studies
@pytest.mark.slow
@pytest.mark.mpi
def test_run_study_returns_a_result(shared_tmp):
    case = rv.Case.from_file(BASELINE).replace(TINY)
    opts = ["-railvib_eig_st_ksp_type", "preonly"]
    res = rv.run_study("speed", case, shared_tmp, settings={"speeds": [20.0, 60.0]},
                       petsc_options=opts, quiet=True)
    assert opts == ["-railvib_eig_st_ksp_type", "preonly"]
    assert res.ok and res.merged and res.computed == ("v20", "v60")
    assert [v.status for v in res.variants] == ["finished", "finished"]
    assert res.verdict_text.startswith("largest building acceleration at")
    assert [r["speed"] for r in res.rows] == [20.0, 60.0]
    assert res.tables and res.tables[0].head and res.report["json"].exists()
    assert res.settings["speeds"] == (20.0, 60.0)          # frozen: tuples, not lists
    if comm.rank == 0:                  # every stage call recorded: shared modes, each passage
        shared = rv.read_run_record(shared_tmp / "speed" / "model")
        assert shared["stages"]["modal"]["command"] == "railvib study speed: shared model"
        v20 = rv.read_run_record(res.variants[0].folder)
        assert v20["stages"]["mbs"]["command"] == "railvib study speed --variant v20"
        assert v20["stages"]["mbs"]["ranks"] == comm.size
    comm.Barrier()
    listed = rv.run_study("speed", case, shared_tmp, settings={"speeds": [20.0, 60.0]},
                          list_only=True, quiet=True)
    assert not listed.merged and listed.computed == () and \
        [v.status for v in listed.variants] == ["finished", "finished"]
    mine = (res.verdict, res.rows, res.variants, res.tables)
    assert all(_same(other, mine) for other in comm.allgather(mine))
    with pytest.raises(rv.UserError, match="unknown variant"):
        rv.run_study("speed", case, shared_tmp, settings={"speeds": [20.0, 60.0]},
                     variants=["v30"], quiet=True)


def _same(a, b) -> bool:
    """Equal, with NaN equal to NaN (the study rows hold NaN for undefined values)."""
    return json.dumps(a, default=repr, sort_keys=True) == json.dumps(b, default=repr,
                                                                      sort_keys=True)
