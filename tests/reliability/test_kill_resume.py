"""Kill-and-resume: a run killed anywhere (SIGKILL, no clean-up) leaves nothing that looks
current; the next run takes over the folder (the lock died with the process), removes the
dead run's temporary files and gives the same numbers as an uninterrupted run; on two
ranks the surviving rank never hangs.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from faults import BASELINE, COARSE, ENV, cli, copy_results, serial_only

B = str(BASELINE)
MESH = ("mesh.h5", "mesh.msh", "mesh.xdmf", "mesh_report.json")


def _kill_at(args: list[str], marker: str, ranks: int = 1, delay: float = 0.0,
             timeout: float = 300) -> tuple[float, str]:
    """Start ``railvib ARGS``, SIGKILL it (one rank's process when ``ranks`` > 1) once its
    output shows ``marker`` (+ ``delay``); returns the seconds until every process ended."""
    cmd = [sys.executable, "-m", "railvib_hpc", *map(str, args)]
    if ranks > 1:
        cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), *cmd]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         env=ENV, start_new_session=True)
    seen, t0 = [], time.time()
    for line in p.stdout:
        seen.append(line)
        if marker in line:
            break
        assert time.time() - t0 < timeout, "".join(seen)
    else:
        raise AssertionError(f"never saw {marker!r}: {''.join(seen)[-2000:]}")
    time.sleep(delay)
    victim = p.pid if ranks == 1 else _a_rank(p.pid)
    os.kill(victim, signal.SIGKILL)
    t_kill = time.time()
    try:
        p.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate()
        return float("inf"), "".join(seen)
    return time.time() - t_kill, "".join(seen)


def _a_rank(mpirun_pid: int) -> int:
    """The pid of one python rank started by mpirun."""
    out = subprocess.run(["pgrep", "-f", "-P", str(mpirun_pid), "railvib_hpc"],
                         capture_output=True, text=True).stdout.split()
    assert out, "no rank process found"
    return int(out[0])


def _same(a: Path, b: Path, name: str, dataset: str, rtol: float = 0.0) -> bool:
    with h5py.File(a / name, "r") as f, h5py.File(b / name, "r") as g:
        x, y = f[dataset][()], g[dataset][()]
    return x.shape == y.shape and (np.array_equal(x, y) if rtol == 0 else
                                   np.allclose(x, y, rtol=rtol, atol=rtol * np.abs(y).max()))


@pytest.mark.slow
@serial_only
def test_killed_eigensolve_resumes_with_identical_modes(prepared, tmp_path, tally):
    out = copy_results(prepared, tmp_path / "o", MESH)
    seconds, _ = _kill_at(["modal", B, "--out", out, *COARSE], "[eigensolve]", delay=1.0)
    assert seconds < 30
    assert not (out / "modes.h5").exists()
    res = cli(["modal", B, "--out", out, *COARSE], timeout=600)
    ok = res.code == 0 and _same(out, prepared, "modes.h5", "modes/translation")
    tally.add("kill during the eigensolve, then modal", "correct" if ok else res.outcome)
    assert ok, res.err
    assert not [p for p in out.iterdir() if ".part" in p.name]


@pytest.mark.slow
@serial_only
@pytest.mark.parametrize("ranks", [1, 2])
def test_killed_reconstruction_resumes(ranks, prepared, tmp_path, tally):
    """Killed while fields.h5 is written (its temporary file exists): the rerun removes it
    and writes the same fields; on 2 ranks the other rank ends at once."""
    out = copy_results(prepared, tmp_path / "o", (*MESH, "modes.h5", "modes.xdmf", "mbs.h5"))
    seconds, _ = _kill_at(["reconstruct", B, "--out", out, *COARSE], "[reconstruct fields]",
                          ranks=ranks, delay=0.3)
    tally.add(f"kill during the fields, {ranks} rank(s)", "hang" if seconds > 30 else
              "correct", f"all processes ended {seconds:.1f} s after the kill")
    assert seconds < 30
    assert not (out / "fields.h5").exists() or _same(out, prepared, "fields.h5",
                                                     "fields/acceleration", 1e-12)
    res = cli(["reconstruct", B, "--out", out, *COARSE], ranks=ranks, timeout=600)
    ok = res.code == 0 and _same(out, prepared, "fields.h5", "fields/acceleration", 1e-12) \
        and _same(out, prepared, "probes.h5", "probes/slab1/acceleration", 1e-12)
    tally.add(f"resume after a kill in the fields, {ranks} rank(s)",
              "correct" if ok else res.outcome, res.err[-300:])
    assert ok, res.err
    assert not [p for p in out.iterdir() if ".part" in p.name]


@serial_only
def test_killed_run_at_the_mbs_then_assess_refuses(prepared, tmp_path, tally):
    """A run at another speed killed after the mbs: assess at that speed must not label
    the old fields with it (the issue: +38 % wrong at 20 m/s)."""
    out = copy_results(prepared, tmp_path / "o")
    seconds, _ = _kill_at(["run", B, "--out", out, *COARSE, "--set", "vehicle.speed=20"],
                          "[reconstruct fields]")
    assert seconds < 30
    res = tally.result("assess after a run killed at the fields",
                       cli(["assess", B, "--out", out, *COARSE, "--set", "vehicle.speed=20"],
                           timeout=300))
    assert res.outcome == "clear error", res.err
    assert "vehicle.speed = 30, the case says 20" in res.error_lines[0] \
        or "not found" in res.error_lines[0]
