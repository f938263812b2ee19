"""``railvib transient``: end to end, resume, reuse, ranks, bad input (issue 12, step 2)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE, TINY, run_transient_only, tiny_case

from railvib_hpc.cli import run
from railvib_hpc.log import Reporter
from railvib_hpc.petsc_env import init_petsc

comm = MPI.COMM_WORLD
SETS = [arg for s in TINY for arg in ("--set", s)]


def _run(case, out, c=None, **kw):
    init_petsc([])
    from railvib_hpc.transient.stage import run_transient_stage

    c = c or MPI.COMM_SELF
    return run_transient_stage(case, out, c, Reporter(c.rank), **kw)


def _histories(out):
    with h5py.File(out / "transient.h5", "r") as f:
        h = {k: f[f"wheels/{k}"][()] for k in ("contact_force", "penetration",
                                                  "rail_displacement")}
        h["y"] = f["vehicle/y"][()]
        h["uz"] = f["rail/uz"][()]
    with h5py.File(out / "probes.h5", "r") as f:
        for name in f["probes"]:
            h[name] = f[f"probes/{name}/acceleration"][()]
        h["moment"] = f["rail/bending_moment"][()]
    with h5py.File(out / "fields.h5", "r") as f:
        h["fields"] = f["fields/velocity"][()]
        h["stress"] = f["stress/von_mises"][()]
    return h


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny wheelset run, serial, uninterrupted."""
    out = tmp_path_factory.mktemp("ref")
    stats = _run(tiny_case(), out)
    return out, stats


def test_wheelset_run_writes_the_reconstruct_files(reference):
    out, stats = reference
    for name in ("fields.h5", "fields.xdmf", "stress.xdmf", "probes.h5", "transient.h5",
                 "probes/slab1.csv"):
        assert (out / name).exists(), name
    assert not (out / "transient_checkpoint.h5").exists()
    with h5py.File(out / "fields.h5", "r") as f:
        assert f.attrs["complete"] == 1
        d = f["fields/displacement"]
        assert d.shape[1:] == (f["mesh/points"].shape[0], 3)
        t = f["time"][()]
        assert np.allclose(np.diff(t), 0.002)
    # the wheel rests on the rigid rail first (static wheel load, rail at rest), then
    # pushes the flexible rail down
    h = _histories(out)
    f0 = h["contact_force"]
    assert f0[0] == pytest.approx([7691.0, 7691.0], rel=1e-3)
    assert np.all(f0 > 0.5 * 7691.0)
    assert h["rail_displacement"][0] == pytest.approx([0.0, 0.0], abs=1e-15)
    assert h["rail_displacement"][-1].max() < -1e-5
    assert stats["steps_run"] == stats["n_steps"]


def test_rerun_reuses_the_results(reference, tmp_path):
    out, _ = reference
    before = (out / "transient.h5").stat().st_mtime_ns
    again = _run(tiny_case(), out)
    assert again["reused"] is True
    assert (out / "transient.h5").stat().st_mtime_ns == before


def test_interrupted_run_resumes_to_the_same_answer(reference, tmp_path):
    from railvib_hpc.transient.stage import Interrupted

    out = tmp_path / "resume"
    with pytest.raises(Interrupted):
        _run(tiny_case(), out, checkpoint_steps=30, stop_after=60)
    assert (out / "transient_checkpoint.h5").exists()
    assert not (out / "transient.h5").exists() and not (out / "fields.h5").exists()
    stats = _run(tiny_case(), out)
    assert stats["steps_run"] < stats["n_steps"]
    ref = _histories(reference[0])
    new = _histories(out)
    for k in ref:
        # same state, same factor, same operations: the same numbers
        np.testing.assert_array_equal(new[k], ref[k], err_msg=k)


#: The serial run both 2-rank tests below compare with, computed once (tests/conftest.py:
#: ``serial_refs``, side by side with the other modules' references): seconds on one rank,
#: builder.
SERIAL_REFERENCES = {"transient_tiny": (9.0, lambda folder: _run(tiny_case(), folder))}


@pytest.mark.slow
@pytest.mark.mpi
def test_two_ranks_give_the_serial_answer(tmp_path_factory, serial_refs):
    """The tiny run on ``comm.size`` ranks equals the one alone on ``MPI.COMM_SELF``
    (``serial_refs``)."""
    init_petsc([])
    base = tmp_path_factory.mktemp("ranks") if comm.rank == 0 else None
    base = comm.bcast(str(base) if base else None, root=0)
    from pathlib import Path

    base = Path(base)
    _run(tiny_case(), base / "parallel", comm)
    if comm.rank == 0:
        a, b = _histories(serial_refs["transient_tiny"]), _histories(base / "parallel")
        for k in a:
            scale = np.abs(a[k]).max()
            # K and M agree to their kernels' round-off (test_boundary) and MUMPS orders
            # the factorization by rank: differences at the round-off of the solves
            assert np.abs(b[k] - a[k]).max() <= 1e-8 * scale, k


@pytest.mark.slow
@pytest.mark.mpi
def test_two_ranks_resume_an_interrupted_run_on_two_ranks_or_one(tmp_path_factory,
                                                                serial_refs):
    """The checkpoint is written collectively (mpio) by global DOF: a run interrupted on 2
    ranks resumes on 2 ranks, or on 1, to the uninterrupted answer (the serial run of
    ``serial_refs``; to the round-off of the 2-rank factorization)."""
    import shutil
    from pathlib import Path

    from railvib_hpc.transient.stage import Interrupted

    init_petsc([])
    base = tmp_path_factory.mktemp("resume2") if comm.rank == 0 else None
    base = Path(comm.bcast(str(base) if base else None, root=0))
    with pytest.raises(Interrupted):
        _run(tiny_case(), base / "parallel", comm, checkpoint_steps=30, stop_after=60)
    if comm.rank == 0:
        assert (base / "parallel" / "transient_checkpoint.h5").exists()
        assert (base / "parallel" / ".fields.h5.resume").exists()
        shutil.copytree(base / "parallel", base / "one", symlinks=True)
    comm.Barrier()
    stats = _run(tiny_case(), base / "parallel", comm)
    assert 0 < stats["steps_run"] < stats["n_steps"]
    if comm.rank == 0:
        one = _run(tiny_case(), base / "one")
        assert 0 < one["steps_run"] < one["n_steps"]
        ref = _histories(serial_refs["transient_tiny"])
        for folder in ("parallel", "one"):
            new = _histories(base / folder)
            for k in ref:
                scale = np.abs(ref[k]).max()
                assert np.abs(new[k] - ref[k]).max() <= 1e-8 * scale, (folder, k)
        assert not (base / "parallel" / "transient_checkpoint.h5").exists()
        assert not (base / "parallel" / ".fields.h5.resume").exists()
    comm.Barrier()


def test_moving_force_run(tmp_path):
    stats = _run(tiny_case("vehicle.type=moving_force"), tmp_path)
    with h5py.File(tmp_path / "transient.h5", "r") as f:
        force = f["wheels/contact_force"][()]
        assert np.all(force == force[0])
        assert json.loads(f.attrs["stats"])["n_steps"] == stats["n_steps"]


def test_coarse_time_step_is_warned_with_the_numbers(tmp_path, capsys):
    init_petsc([])
    from railvib_hpc.transient.stage import time_step

    dt = time_step(tiny_case("transient.dt=0.002", "transient.f_max=80"), 0.0,
                   Reporter(0))
    assert dt == 0.002
    out = capsys.readouterr().out
    assert "transient.dt = 0.002 s resolves transient.f_max = 80 Hz with 6.2 steps per " \
           "period (period error 7.9" in out
    assert "dt <= 0.000625 s" in out


def test_time_step_must_divide_the_output_step(capsys):
    assert run(["check", str(BASELINE), *SETS, "--set", "transient.dt=0.0015"]) == 2
    err = capsys.readouterr().err
    assert "transient.dt = 0.0015: must divide output.dt = 0.002 s" in err


@pytest.mark.slow
def test_cli_transient_runs_and_assesses(tmp_path, capsys):
    code = run(["transient", str(BASELINE), "--out", str(tmp_path),
                *SETS, "--set", "vehicle.type=moving_force"])
    assert code == 0
    text = capsys.readouterr().out
    assert "transient complete: 14 probes assessed" in text
    assert "assessed the results of the full-order time integration (railvib transient)" in text
    report = (tmp_path / "report.md").read_text()
    assert "solver               full-order time integration (railvib transient)" in report
    doc = json.loads((tmp_path / "assessment.json").read_text())
    assert doc["solver"] == "transient"
    assert set(json.loads(doc["provenance"]["upstream_sha256"])) == {
        "transient.h5", "fields.h5", "probes.h5"}
    # the XDMF of the fields has its per-step views (both ParaView XDMF readers)
    assert (tmp_path / "fields_views.h5").exists() and (tmp_path / "stress_views.h5").exists()
    # a rerun reuses everything and assesses again
    assert run(["transient", str(BASELINE), "--out", str(tmp_path),
                *SETS, "--set", "vehicle.type=moving_force"]) == 0
    assert "reusing the transient results" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.mpi
def test_two_trains_run_the_full_order_model(shared_tmp):
    """Two tracks, the second wheelset the other way: each wheel keeps its rail, train 2
    runs the mirror image of train 1's path, both stay in contact on the flexible rail."""
    out = shared_tmp / "transient_two_tracks"
    run_transient_only(out, [*SETS[1::2], "track.count=2", "geometry.ys0=14.0",
                             "output.stress_times=[]"])
    if comm.rank == 0:
        with h5py.File(out / "transient.h5", "r") as f:
            w = f["wheels"]
            rails, x, force = w["rail_index"][()], w["x"][()], w["contact_force"][()]
        assert rails.tolist() == [0, 1, 2, 3]
        assert x[:, 2] == pytest.approx(0.0 + 27.6 - x[:, 0], abs=1e-9)   # X0 + X4 + rigid
        static = force[0, 0]
        assert np.all(force > 0.5 * static)                             # no wheel lifts off
        assert np.ptp(force[:, 2]) > 1e-3 * static                      # train 2 feels the track
    comm.Barrier()
