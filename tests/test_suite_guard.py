"""The suite's own hang guard (issue 26): pytest-timeout ends a hung test, per test, instead
of a wall-clock limit on the whole pass (``pyproject.toml``: ``timeout``, thread method)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
import tomllib
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial test")


def test_every_test_has_a_time_limit(pytestconfig):
    ini = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert pytestconfig.pluginmanager.hasplugin("timeout"), "pytest-timeout is not installed"
    assert ini["timeout_method"] == "thread"        # also ends a rank stuck in MPI
    assert float(pytestconfig.getini("timeout")) == float(ini["timeout"]) >= 300


def test_a_hung_test_is_ended_by_its_own_limit(tmp_path):
    hung = tmp_path / "test_hung.py"
    hung.write_text("import time\n\ndef test_hangs():\n    time.sleep(120)\n")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--timeout=2", "--rootdir", str(tmp_path), str(hung)],
                          capture_output=True, text=True, timeout=100, cwd=tmp_path)
    seconds = time.perf_counter() - t0
    assert proc.returncode != 0
    assert "Timeout" in proc.stdout + proc.stderr
    assert seconds < 60, seconds                     # ended by the 2 s limit, not the sleep


def test_the_fault_tally_survives_the_worker_processes():
    """``make test`` runs the one-rank pass in pytest-xdist workers, which print no summary:
    the fault-injection suite's tally reaches the controller's summary all the same."""
    target = "tests/reliability/test_user_errors.py::test_empty_case_file_is_refused"
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-n", "1", target], capture_output=True, text=True, timeout=600,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "fault-injection suite: 1 tries, 1 clear errors" in proc.stdout, proc.stdout[-2000:]
