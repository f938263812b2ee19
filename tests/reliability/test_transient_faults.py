"""Faults of the full-order solution (``railvib transient``) on the one stage-file layer.

A stale input recomputes all three products (``fields.h5``, ``probes.h5``,
``transient.h5``) and says why in one line; a foreign, corrupt or truncated product is
recomputed to the same numbers; ``assess`` refuses a corrupt transient input naming it and
``railvib transient``; a checkpoint that is stale, corrupt or whose partial fields belong
to another run is not resumed (the run starts at t = 0, saying why); a run killed during
the time integration resumes from its checkpoint to the uninterrupted numbers; a second
``railvib transient`` into a folder in use is refused at once.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from faults import BASELINE, ENV, cli, copy_results, serial_only
from mpi4py import MPI

from railvib_hpc.cli import run

B = str(BASELINE)
#: The tiny full-order case of tests/transient: coarse thesis model, a wheelset entering
#: the flexible rail at 10 ms, 100 steps of 0.5 ms, output every 2 ms, stresses at 40 ms.
TINY = ["mesh.refinement=0.25", "vehicle.x_start=2.7", "vehicle.x_end=4.2",
        "output.dt=0.002", "output.stress_times=[0.04]", "transient.checkpoint_interval=0",
        "transient.f_max=100"]
SETS = [arg for s in TINY for arg in ("--set", s)]
FILES = ("mesh.h5", "mesh.msh", "mesh.xdmf", "mesh_report.json", "fields.h5", "fields.xdmf",
         "fields_views.h5", "stress.xdmf", "stress_views.h5", "probes.h5", "transient.h5",
         "assessment.json")
CHECKPOINT = "transient_checkpoint.h5"


@pytest.fixture(scope="module")
def tprepared(tmp_path_factory) -> Path:
    """A finished ``railvib transient`` of the tiny case (computed once per module)."""
    comm = MPI.COMM_WORLD
    path = Path(comm.bcast(str(tmp_path_factory.mktemp("tprepared")) if comm.rank == 0
                           else None, root=0))
    assert run(["transient", B, *SETS, "--out", str(path)]) == 0
    return path


@pytest.fixture
def twork(tprepared, tmp_path) -> Path:
    """A private copy of the prepared transient results (records kept valid)."""
    return copy_results(tprepared, tmp_path / "out", FILES)


def _run(capsys, out: Path, *extra: str) -> tuple[int, str, str]:
    code = run(["transient", B, *SETS, "--out", str(out), *extra])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _stage(capsys, out: Path, *extra: str) -> tuple[int, str, str]:
    """The stage's entry point alone (no assessment: quicker), like ``_run``; 2 for a user
    error."""
    from railvib_hpc.config import load_case
    from railvib_hpc.errors import UserError
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    sets = [e for e in extra if e != "--set"]
    code = 0
    try:
        run_transient_stage(load_case(BASELINE, [*TINY, *sets]), out, MPI.COMM_WORLD,
                            Reporter(MPI.COMM_WORLD.rank))
    except UserError as exc:
        print(f"railvib transient: error: {exc}", file=sys.stderr)
        code = 2
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _numbers(out: Path) -> dict[str, np.ndarray]:
    """The histories that must not change when a result is recomputed or resumed."""
    h = {}
    with h5py.File(out / "transient.h5", "r") as f:
        h["contact_force"] = f["wheels/contact_force"][()]
        h["uz"] = f["rail/uz"][()]
    with h5py.File(out / "probes.h5", "r") as f:
        h["slab1"] = f["probes/slab1/acceleration"][()]
    with h5py.File(out / "fields.h5", "r") as f:
        h["fields"] = f["fields/velocity"][()]
        h["stress"] = f["stress/von_mises"][()]
    return h


def _same_numbers(a: Path, b: Path) -> bool:
    """Bit-identical histories (serial: the same operations in the same order)."""
    x, y = _numbers(a), _numbers(b)
    return all(np.array_equal(x[k], y[k]) for k in x)


def _line(out: str, start: str) -> str:
    hits = [ln for ln in out.splitlines() if ln.startswith(start)]
    assert hits, out[-3000:]
    return hits[0]


def _one_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --------------------------------------------------------------------------- stale inputs
@pytest.mark.slow
def test_stale_input_recomputes_all_three_with_the_reason(twork, capsys, tally):
    code, out, err = _run(capsys, twork, "--set", "vehicle.speed=20")
    line = _line(out, "recomputing the transient results")
    tally.add("stale input: transient after vehicle.speed changed",
              "recomputed" if code == 0 else "unclear", line)
    assert code == 0, err
    assert line == (f"recomputing the transient results in {twork}: transient.h5 was "
                    "computed with vehicle.speed = 30, the case says 20")
    for name in ("fields.h5", "probes.h5", "transient.h5"):
        with h5py.File(twork / name, "r") as f:
            assert "speed = 20" in f.attrs["case_toml"].replace("20.0", "20"), name
    doc = json.loads((twork / "assessment.json").read_text())
    assert doc["solver"] == "transient"
    assert "speed = 20" in doc["provenance"]["case_toml"].replace("20.0", "20")


def test_only_new_probes_recompute_the_solution_and_say_which_file(twork, capsys):
    with h5py.File(twork / "probes.h5", "r") as f:
        xyz = [float(v) for v in f["probes/ground_mid"].attrs["coords"]]
    code, out, err = _stage(capsys, twork, "--set", f"output.probes={xyz}")
    assert code == 0, err
    assert _line(out, "recomputing the transient results") == (
        f"recomputing the transient results in {twork}: probes.h5 was computed with "
        "output.probes = [], the case says [" + ", ".join(f"{v:g}" for v in xyz) + "]")
    with h5py.File(twork / "probes.h5", "r") as f:
        assert "user_1" in f["probes"]
        assert f["probes/user_1"].attrs["role"] == "ground"


def test_new_stress_times_recompute_only_the_stresses(twork, tprepared, capsys):
    before = (twork / "transient.h5").stat().st_mtime_ns
    code, out, err = _stage(capsys, twork, "--set", "output.stress_times=[0.03]")
    assert code == 0, err
    assert "reusing the transient results" in out and "[transient: stresses]" in out
    assert (twork / "transient.h5").stat().st_mtime_ns == before
    with h5py.File(twork / "fields.h5", "r") as f:
        assert f["stress/time"][()] == pytest.approx([0.03])
    # the record of the rewritten fields.h5 was renewed: a rerun reuses everything
    code, out, err = _stage(capsys, twork, "--set", "output.stress_times=[0.03]")
    assert code == 0, err
    assert "reusing /stress of" in out and "recomputing" not in out


def test_checkpoint_interval_is_not_an_input(twork, capsys):
    before = (twork / "transient.h5").stat().st_mtime_ns
    code, out, err = _stage(capsys, twork, "--set", "transient.checkpoint_interval=5")
    assert code == 0, err
    assert "reusing the transient results" in out
    assert (twork / "transient.h5").stat().st_mtime_ns == before


# --------------------------------------------------------------------------- corrupt files
def _record_path(path: Path) -> Path:
    return path.parent / ".railvib" / f"{path.name}.json"


def _set_attrs(path: Path, **attrs) -> None:
    with h5py.File(path, "r+") as f:
        for k, v in attrs.items():
            f.attrs[k] = v


def _nan(path: Path, dataset: str) -> None:
    with h5py.File(path, "r+") as f:
        d = f[dataset]
        d[tuple(s // 2 for s in d.shape)] = np.nan


#: fault -> (how to inject it, the reason printed)
FAULTS = {
    "foreign transient.h5": (
        lambda d: _set_attrs(d / "transient.h5", railvib_file="mbs.h5", stage="mbs"),
        "transient.h5 is not a railvib transient.h5 (it says mbs.h5)"),
    "fields.h5 of reconstruct": (
        lambda d: _set_attrs(d / "fields.h5", railvib_file="fields.h5", stage="reconstruct"),
        "fields.h5 was written by 'railvib reconstruct', not by 'railvib transient'"),
    "NaN in transient.h5": (
        lambda d: _nan(d / "transient.h5", "wheels/contact_force"),
        "transient.h5 is corrupt (its content changed after it was written)"),
    "NaN in transient.h5, no record": (
        lambda d: (_nan(d / "transient.h5", "wheels/contact_force"),
                   _record_path(d / "transient.h5").unlink()),
        "transient.h5 is corrupt (wheels/contact_force has 1 non-finite value)"),
    "truncated transient.h5": (
        lambda d: os.truncate(d / "transient.h5", (d / "transient.h5").stat().st_size // 2),
        "transient.h5 cannot be read"),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_foreign_or_corrupt_product_is_recomputed_to_the_same_numbers(fault, twork, tprepared,
                                                                      capsys, tally):
    inject, reason = FAULTS[fault]
    inject(twork)
    code, out, err = _stage(capsys, twork)
    line = _line(out, "recomputing the transient results")
    ok = code == 0 and _same_numbers(twork, tprepared)
    tally.add(f"transient: {fault}", "recomputed" if ok else "silent wrong", line)
    assert code == 0, err
    assert line.startswith(f"recomputing the transient results in {twork}: {reason}"), line
    assert ok


def test_assess_refuses_a_corrupt_transient_input(twork, capsys, tally):
    _nan(twork / "transient.h5", "wheels/contact_force")
    before = (twork / "assessment.json").read_bytes()
    code = run(["assess", B, *SETS, "--out", str(twork)])
    err = capsys.readouterr().err
    tally.add("corrupt transient.h5: assess", "clear error" if code == 2 else "silent wrong",
              err.strip())
    assert code == 2
    assert _one_error(err) == (
        f"railvib assess: error: {twork / 'transient.h5'} is corrupt (its content changed "
        "after it was written): run 'railvib transient'")
    assert (twork / "assessment.json").read_bytes() == before


def test_assess_refuses_transient_results_of_another_case(twork, capsys):
    code = run(["assess", B, *SETS, "--out", str(twork), "--set", "damping.f2=50"])
    err = capsys.readouterr().err
    assert code == 2
    assert _one_error(err) == (
        f"railvib assess: error: {twork / 'transient.h5'} was computed with damping.f2 = 40, "
        "the case says 50: run 'railvib transient'")


# --------------------------------------------------------------------------- checkpoints
@pytest.fixture
def interrupted(tmp_path) -> Path:
    """A folder with the checkpoint (step 60 of 100) and partial fields of a stopped run."""
    from railvib_hpc.config import load_case
    from railvib_hpc.log import Reporter
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.stage import Interrupted, run_transient_stage

    init_petsc([])
    out = tmp_path / "stopped"
    with pytest.raises(Interrupted):
        run_transient_stage(load_case(BASELINE, TINY), out, MPI.COMM_SELF, Reporter(0),
                            checkpoint_steps=30, stop_after=60)
    assert (out / CHECKPOINT).exists() and (out / ".fields.h5.resume").exists()
    return out


def _steps(out: Path) -> tuple[int, int]:
    with h5py.File(out / "transient.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    return stats["steps_run"], stats["n_steps"]


CHECKPOINT_FAULTS = {
    "stale": (None, ["--set", "damping.f2=50"],
              "it was computed with damping.f2 = 40, the case says 50"),
    "corrupt": (lambda d: _nan(d / CHECKPOINT, "state/u"), [],
                "it is corrupt (its content changed after it was written)"),
    "foreign partial fields": (
        lambda d: _set_attrs(d / ".fields.h5.resume", run_id="another-run"), [],
        "the partial fields file .fields.h5.resume belongs to another run"),
    "partial fields missing": (lambda d: (d / ".fields.h5.resume").unlink(), [],
                               "its partial fields file .fields.h5.resume is missing or "
                               "unreadable"),
}


@pytest.mark.parametrize("fault", list(CHECKPOINT_FAULTS))
def test_unusable_checkpoint_is_not_resumed(fault, interrupted, tprepared, capsys, tally):
    inject, extra, reason = CHECKPOINT_FAULTS[fault]
    if inject is not None:
        inject(interrupted)
    code, out, err = _stage(capsys, interrupted, *extra)
    assert code == 0, err
    line = _line(out, "not resuming from")
    steps_run, n_steps = _steps(interrupted)
    ok = steps_run == n_steps and "resuming from the checkpoint" not in out
    tally.add(f"transient checkpoint: {fault}", "recomputed" if ok else "silent wrong", line)
    assert line == (f"not resuming from {interrupted / CHECKPOINT}: {reason}; starting at "
                    "t = 0")
    assert ok
    assert not (interrupted / CHECKPOINT).exists()
    assert not (interrupted / ".fields.h5.resume").exists()
    if not extra:
        assert _same_numbers(interrupted, tprepared)


def test_current_checkpoint_is_resumed_to_the_same_numbers(interrupted, tprepared, capsys):
    code, out, err = _stage(capsys, interrupted)
    assert code == 0, err
    assert "resuming from the checkpoint at step 60 of 100" in out
    assert _steps(interrupted) == (40, 100)
    assert _same_numbers(interrupted, tprepared)


# --------------------------------------------------------------------------- processes
def _start(args: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "railvib_hpc", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=ENV, start_new_session=True)


@pytest.mark.slow
@serial_only
def test_second_concurrent_transient_is_refused(tmp_path, tally):
    out = tmp_path / "busy"
    first = _start(["transient", B, *SETS, "--out", out])
    try:
        lock = out / ".railvib" / "lock"
        t0 = time.time()
        while True:
            try:
                holder = json.loads(lock.read_text() or "{}")
            except (OSError, ValueError):
                holder = {}
            if holder.get("pid") == first.pid:
                break
            assert first.poll() is None, first.communicate()[0]
            assert time.time() - t0 < 120, "the first command never took the lock"
            time.sleep(0.05)
        assert holder["command"].startswith("railvib transient")
        second = cli(["transient", B, *SETS, "--out", out], timeout=120)
        tally.result("concurrent railvib transient into one --out", second)
        assert second.outcome == "clear error", second.err
        assert f"is in use by pid {first.pid}" in second.error_lines[0]
        assert "--wait" in second.error_lines[0] and second.seconds < 60
        text, _ = first.communicate(timeout=600)
        assert first.returncode == 0, text
    finally:
        if first.poll() is None:
            first.kill()


@pytest.mark.slow
@serial_only
def test_killed_run_resumes_from_its_checkpoint(tmp_path, tprepared, tally):
    """SIGKILL during the time integration (checkpoints every 0.2 s of wall clock: not an
    input, the results are the prepared ones); the next run resumes and gives the same
    numbers."""
    out = tmp_path / "killed"
    args = ["transient", B, *SETS, "--set", "transient.checkpoint_interval=0.2", "--out", out]
    p = _start(args)
    seen = []
    try:
        for line in p.stdout:
            seen.append(line)
            if "transient: step" in line:
                break
        else:
            raise AssertionError("".join(seen)[-3000:])
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert not (out / "transient.h5").exists()
    assert (out / CHECKPOINT).exists(), "".join(seen)[-3000:]
    res = cli(args, timeout=300)
    resumed = "resuming from the checkpoint at step" in res.out
    ok = res.code == 0 and resumed and _same_numbers(out, tprepared)
    tally.add("transient killed during the time integration",
              "resumed" if ok else "silent wrong" if res.code == 0 else res.outcome,
              _line(res.out, "resuming") if resumed else res.err[-300:])
    assert res.code == 0, res.err
    assert resumed, res.out[-3000:]
    assert ok
    assert not (out / CHECKPOINT).exists() and not (out / ".fields.h5.resume").exists()
