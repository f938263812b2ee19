"""Defect 3 of issue 16: two commands into one output folder, and leftovers of dead runs.

The second command refuses at once naming the holder (or waits with ``--wait``); each
report carries its own case's numbers. Temporary files of dead processes are removed
when the folder's lock is taken.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from faults import BASELINE, COARSE, ENV, cli, serial_only

from railvib_hpc.cli import run

B = str(BASELINE)


def _start(args: list[str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "railvib_hpc", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def _wait_for_holder(out: Path, proc: subprocess.Popen, timeout: float = 60) -> dict:
    lock = out / ".railvib" / "lock"
    t0 = time.time()
    while time.time() - t0 < timeout:
        try:
            info = json.loads(lock.read_text() or "{}")
        except (OSError, ValueError):
            info = {}
        if info.get("pid") == proc.pid:
            return info
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("the first command never took the lock")


def _slab1(out: Path) -> float:
    doc = json.loads((out / "assessment.json").read_text())
    return doc["thesis_comparison"]["slab1_vertical_acceleration"]["railvib"]


@pytest.mark.slow
@serial_only
def test_second_run_refuses_then_waits_and_each_report_is_its_own(work, prepared, tally):
    """The issue: run (30 m/s) and, 0.5 s later, run at 20 m/s into the same --out: the 20
    m/s report showed the 30 m/s slab value. Now the second refuses at once, naming the
    holder; with --wait it runs after the first and reports its own numbers."""
    first = _start(["run", B, "--out", work, *COARSE, "--set", "vehicle.speed=20"])
    try:
        holder = _wait_for_holder(work, first)
        assert holder["command"].startswith("railvib run")
        second = cli(["run", B, "--out", work, *COARSE], timeout=120)
        tally.result("concurrent run into one --out", second)
        assert second.outcome == "clear error", second.err
        line = second.error_lines[0]
        assert f"is in use by pid {first.pid}" in line and "--wait" in line
        assert second.seconds < 60
        waiting = _start(["run", B, "--out", work, *COARSE, "--wait"])
        _, err = first.communicate(timeout=600)
        assert first.returncode == 0, err
        slab_20 = _slab1(work)
        out2, err2 = waiting.communicate(timeout=600)
        assert waiting.returncode == 0, err2
        assert "waiting for the output folder" in out2
    finally:
        for p in (first,):
            if p.poll() is None:
                p.kill()
    slab_30 = _slab1(work)
    ok = slab_30 == _slab1(prepared) and slab_20 != slab_30
    tally.add("concurrent run with --wait", "correct" if ok else "silent wrong",
              f"slab1 {slab_20:.6g} at 20 m/s, {slab_30:.6g} at 30 m/s")
    assert ok


def test_lock_is_reentrant_and_released(tmp_path):
    """A command holds its folder's lock through every stage (the stages lock again, the
    same process) and releases it at the end."""
    import fcntl

    from railvib_hpc.io.locks import acquire_lock, holds_lock, release_lock

    out = tmp_path / "o"
    acquire_lock(out, "outer")
    acquire_lock(out, "inner")
    release_lock(out)
    assert holds_lock(out)
    fd = os.open(out / ".railvib" / "lock", os.O_RDWR)
    try:
        with pytest.raises(BlockingIOError):
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        release_lock(out)
        assert not holds_lock(out)
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)


def test_temporary_files_of_dead_runs_are_removed(work, capsys, tally):
    """The issue: .part files were never cleaned (142 MB on the coarse model) and one
    blocked the next run."""
    from railvib_hpc.io.temp_names import temp_path

    dead = 2**22 + 12345                      # above the default pid_max: never alive
    while True:
        try:
            os.kill(dead, 0)
            dead += 1
        except ProcessLookupError:
            break
    names = [temp_path(work / "fields.h5").name.rsplit("-", 1)[0] + f"-{dead}",
             f".modes.h5.part-{dead}",                          # the old format
             ".mesh.msh.part-otherhost-1.msh",                  # another host
             "mesh.msh.part.msh"]                               # the old gmsh name
    for n in names:
        (work / n).write_bytes(b"x" * 4096)
    alive = work / (temp_path(work / "mbs.h5").name)            # this process: kept
    alive.write_bytes(b"y")
    code = run(["mbs", B, "--out", str(work), *COARSE])
    out = capsys.readouterr().out
    left = [n for n in names if (work / n).exists()]
    tally.add("stale temporary files", "cleaned" if not left and code == 0 else "unclear",
              out.splitlines()[0] if out else "")
    assert code == 0 and not left
    assert "removed 4 temporary file(s)" in out
    assert alive.exists()
