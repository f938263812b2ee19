"""The stage-file layer on its own: digests, records, verdicts, writes, locks."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.config import load_case
from railvib_hpc.errors import OutputError, OutputLockedError
from railvib_hpc.io import atomic, digests, locks, products, provenance, temp_names

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
comm = MPI.COMM_WORLD


def test_digest_is_canonical():
    assert digests.digest({"a": 1, "b": [1.5, "x"]}) == digests.digest({"b": [1.5, "x"], "a": 1})
    assert digests.digest({"a": 1}) != digests.digest({"a": 1.5})


@pytest.mark.mpi
def test_content_digest_does_not_depend_on_the_rank_count(shared_tmp, monkeypatch):
    """Block i on rank i mod size, combined in order: 1 rank and N ranks agree, and the
    digest changes with any byte."""
    monkeypatch.setattr(digests, "BLOCK_BYTES", 1000)
    path = shared_tmp / "blob"
    if comm.rank == 0:
        path.write_bytes(np.random.default_rng(3).bytes(10_500))
    comm.Barrier()
    many = digests.hash_file(path, comm)
    one = digests.hash_file(path)
    assert many == one and comm.allgather(many) == [many] * comm.size
    comm.Barrier()
    if comm.rank == 0:
        data = bytearray(path.read_bytes())
        data[7777] ^= 1
        path.write_bytes(bytes(data))
    comm.Barrier()
    assert digests.hash_file(path, comm) != many


def test_records_trust_size_and_mtime_and_detect_changes(tmp_path):
    p = tmp_path / "f.h5"
    p.write_bytes(b"abc" * 1000)
    assert digests.file_digest(p).status == "unrecorded"
    sha = digests.record_file(p)
    assert digests.file_digest(p) == digests.FileDigest(sha, "recorded")
    # a copy that keeps the mtime is trusted; one that does not is hashed and refreshed
    q = tmp_path / "copy"
    q.mkdir()
    shutil.copy2(p, q / "f.h5")
    (q / ".railvib").mkdir()
    shutil.copy2(digests.record_path(p), digests.record_path(q / "f.h5"))
    os.utime(q / "f.h5", ns=(time.time_ns(), time.time_ns() + 10**9))
    assert digests.file_digest(q / "f.h5") == digests.FileDigest(sha, "recorded")
    assert json.loads(digests.record_path(q / "f.h5").read_text())["mtime_ns"] == \
        (q / "f.h5").stat().st_mtime_ns
    # one byte changed after the record: "changed"
    with open(p, "r+b") as f:
        f.seek(10)
        f.write(b"X")
    assert digests.file_digest(p).status == "changed"


def test_temporary_names_round_trip_and_dead_ones_are_removed(tmp_path):
    t = temp_names.temp_path(tmp_path / "fields.h5")
    assert t.name.startswith(".fields.h5.part-") and f"-{os.getpid()}_t" in t.name
    assert t != temp_names.temp_path(tmp_path / "fields.h5")      # unique per writer (issue 26)
    assert temp_names.final_name(t.name) == "fields.h5"
    assert temp_names.final_name(temp_names.temp_path(tmp_path / "mesh.msh", suffix=True).name) \
        == "mesh.msh"
    dead = tmp_path / ".x.h5.part-somehost-1"
    dead.write_bytes(b"1234")
    mine = tmp_path / t.name
    mine.write_bytes(b"1")
    sub = tmp_path / "probes"
    sub.mkdir()
    (sub / f".a.csv.part-{temp_names._host()}-999999999").write_bytes(b"12")
    assert temp_names.remove_stale_temps(tmp_path) == (2, 6)
    assert mine.exists() and not dead.exists()


def test_case_differences_name_the_keys():
    old = load_case(BASELINE)
    new = load_case(BASELINE, ["materials.subgrade.E=4e8", "vehicle.speed=20",
                               "mbs.dt=1e-5", "mbs.store_every=2", "vehicle.preload=1.0"])
    assert provenance.case_differences("modes.h5", old.to_toml(), new) == \
        "materials.subgrade.E = 2e8, the case says 4e8"
    text = provenance.case_differences("mbs.h5", old.to_toml(), new)
    assert text.startswith("materials.subgrade.E = 2e8, the case says 4e8; mbs.dt = 0, the "
                           "case says 1e-5; mbs.store_every = 1, the case says 2")
    assert text.endswith("(+2 more)")
    # the soils' E, nu, rho are mesh inputs (mesh.elements_per_wavelength reads their
    # shear-wave speeds); the vehicle and the MBS are not
    assert provenance.case_differences("mesh.h5", old.to_toml(), new) == \
        "materials.subgrade.E = 2e8, the case says 4e8"
    concrete = load_case(BASELINE, ["materials.concrete.E=4e10", "vehicle.speed=20"])
    assert provenance.case_differences("mesh.h5", old.to_toml(), concrete) == ""
    with pytest.raises(ValueError):
        provenance.case_differences("mesh.h5", "", new)


def _fill(f, parallel):
    f.create_dataset("x", data=np.arange(10.0))


def test_examine_gives_each_kind_of_verdict(tmp_path):
    case = load_case(BASELINE)
    p = tmp_path / "mesh.h5"
    assert provenance.examine(p, case=case).kind == "missing"
    atomic.write_h5(p, None, _fill, size_hint=80, attrs=provenance.provenance("mesh.h5", case, {}))
    (tmp_path / "mesh.xdmf").write_text("x")
    (tmp_path / "mesh_report.json").write_text("{}")
    assert provenance.examine(p, case=case).ok
    other = load_case(BASELINE, ["mesh.refinement=2"])
    v = provenance.examine(p, case=other)
    assert (v.kind, v.reason) == ("inputs", "it was computed with mesh.refinement = 1, the "
                                            "case says 2")
    (tmp_path / "mesh.xdmf").unlink()
    assert provenance.examine(p, case=case).reason == "it lacks mesh.xdmf, written with it"
    assert provenance.examine(p, case=case, companions=False).ok
    # upstream digests: recorded vs expected, and vs the file in the folder
    q = tmp_path / "modes.h5"
    atomic.write_h5(q, None, _fill, size_hint=80,
                    attrs=provenance.provenance("modes.h5", case, {"mesh.h5": "0" * 64}))
    v = provenance.examine(q, case=case, companions=False)
    assert (v.kind, v.reason) == ("upstream", "it was computed from another mesh.h5 (mesh.h5 "
                                              "was written again since)")
    with h5py.File(q, "r+") as f:
        f.attrs["format_version"] = 1
    assert provenance.examine(q, case=case).kind == "format"
    with h5py.File(q, "r+") as f:
        f.attrs["complete"] = 0
    assert provenance.examine(q, case=case).kind == "incomplete"
    q.write_bytes(b"not hdf5")
    assert provenance.examine(q, case=case).kind == "corrupt"


def test_failed_writes_leave_nothing(tmp_path):
    def broken(f, parallel):
        raise OSError(28, "No space left on device")

    with pytest.raises(OutputError, match=f"writing {tmp_path / 'a.h5'}: No space left"):
        atomic.write_h5(tmp_path / "a.h5", None, broken, size_hint=10)
    with pytest.raises(OutputError, match="failed: it is bad"):
        atomic.write_h5(tmp_path / "b.h5", None, _fill, size_hint=10,
                        check=lambda tmp: ["it is bad"])
    with pytest.raises(OutputError, match="missing or empty"), \
            atomic.atomic_file(tmp_path / "c.msh") as tmp:
        tmp.write_bytes(b"")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_not_enough_space_is_said_before_writing(tmp_path):
    with pytest.raises(OutputError, match=r"not enough free space .* to write big\.h5"):
        atomic.ensure_space(tmp_path, 10**18, "big.h5")


def test_a_second_process_is_refused_with_the_holder(tmp_path):
    out = tmp_path / "o"
    with locks.output_lock(out, None, "railvib run x.toml"):
        code = ("from pathlib import Path; from railvib_hpc.io import locks\n"
                f"locks.acquire_lock(Path({str(out)!r}), 'second')")
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert p.returncode != 0
        assert "OutputLockedError" in p.stderr
        assert f"is in use by pid {os.getpid()}" in p.stderr and "railvib run x.toml" in p.stderr
    with locks.output_lock(out, None, "again"):        # released: free again
        pass
    with pytest.raises(OutputLockedError):
        holder = subprocess.Popen([sys.executable, "-c", (
            "import time; from pathlib import Path; from railvib_hpc.io import locks\n"
            f"locks.acquire_lock(Path({str(out)!r}), 'holder'); print('held', flush=True)"
            "\ntime.sleep(30)")], stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout.readline().strip() == "held"
            locks.acquire_lock(out, "me")
        finally:
            holder.kill()
            holder.wait()


def test_transient_rows_select_what_the_full_order_solution_depends_on():
    """Every key of K, M, C, loads and time step changes the transient files' hashes; the
    modal solver, the MBS, the stress times and the checkpoint interval do not."""
    base = load_case(BASELINE)

    def changed(name: str, *sets: str) -> bool:
        return products.inputs_hash(base, name) != \
            products.inputs_hash(load_case(BASELINE, list(sets)), name)

    for key in ("vehicle.speed=20", "damping.f2=50", "boundary.base=absorbing",
                "transient.rho_inf=0.8", "modal.damping_ratio=0.05", "output.dt=0.002",
                "irregularity.type=fra", "materials.subgrade.E=4e8"):
        assert changed("transient.h5", key), key
    for key in ("mbs.dt=1e-5", "modal.n_modes=50", "modal.tol=1e-9",
                "transient.checkpoint_interval=5", "output.stress_times=[0.3]",
                "output.probes=[1.0,2.0,3.0]", "output.window=[0.1,0.5]"):
        assert not changed("transient.h5", key), key
    assert changed("transient:fields.h5", "output.window=[0.1,0.5]")
    assert not changed("transient:fields.h5", "output.probes=[1.0,2.0,3.0]")
    assert changed("transient:probes.h5", "output.probes=[1.0,2.0,3.0]")
    assert changed("transient_checkpoint.h5", "output.probes=[1.0,2.0,3.0]")
    assert changed("transient_checkpoint.h5", "output.float32=true")
    assert not changed("transient_checkpoint.h5", "output.stress_times=[0.3]")
    assert not changed("modes.h5", "damping.f2=50")        # nothing else changed
    assert products.spec("transient:fields.h5").filename == "fields.h5"
    assert products.spec("fields.h5").filename == "fields.h5"


def test_fields_of_one_stage_are_foreign_to_the_other(tmp_path):
    case = load_case(BASELINE)
    path = tmp_path / "fields.h5"
    atomic.write_h5(path, None, lambda f, par: f.create_dataset("x", data=np.ones(3)),
                    size_hint=100, attrs=provenance.provenance("transient:fields.h5", case, {}))
    v = provenance.examine(path, "fields.h5", case, companions=False)
    assert (v.ok, v.kind) == (False, "foreign")
    assert v.reason == "it was written by 'railvib transient', not by 'railvib reconstruct'"
    assert provenance.examine(path, "transient:fields.h5", case, companions=False).ok
    err = provenance.refuse(path, v, "transient:fields.h5")
    assert str(err).endswith(": run 'railvib transient'")
    missing = provenance.refuse(tmp_path / "transient.h5", provenance.Verdict(False, "", "missing"))
    assert str(missing) == f"{tmp_path / 'transient.h5'} not found: run 'railvib transient' first"


def test_resume_path_survives_the_clean_up_of_dead_runs(tmp_path):
    part = temp_names.resume_path(tmp_path / "fields.h5")
    assert part.name == ".fields.h5.resume" and temp_names.final_name(part.name) == "fields.h5"
    part.write_bytes(b"partial")
    assert temp_names.remove_stale_temps(tmp_path) == (0, 0)
    assert part.exists()
