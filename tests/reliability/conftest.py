"""Fixtures of the fault-injection suite: a prepared coarse output folder, private copies,
small tmpfs mounts and the tally of outcomes.

Every fault the suite injects is recorded with its outcome (:class:`faults.Tally`); the
terminal summary prints the counts (tries, clear errors, recomputations, warnings,
tracebacks, hangs, silent wrong results) and ``RAILVIB_FAULT_TALLY=<file>`` writes them
as JSON.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest
from faults import (
    BASELINE,
    COARSE,
    TALLY,
    Tally,
    can_mount,
    copy_results,
    tally_line,
    write_tally,
)
from mpi4py import MPI


@pytest.fixture(scope="session")
def tally() -> Tally:
    return TALLY


def pytest_terminal_summary(terminalreporter):
    if not TALLY.entries or MPI.COMM_WORLD.rank != 0:
        return
    terminalreporter.write_line(tally_line(TALLY.entries))
    write_tally(TALLY.entries)


def pytest_sessionfinish(session):
    """Under pytest-xdist a worker prints no summary: it hands its entries to the
    controller (``workeroutput``), whose ``tests/conftest.py`` prints them all."""
    output = getattr(session.config, "workeroutput", None)
    if output is not None and TALLY.entries:
        output["fault_tally"] = list(TALLY.entries)


@pytest.fixture(scope="session")
def prepared(tmp_path_factory) -> Path:
    """A finished ``railvib run`` of the coarse model (computed once per session)."""
    from railvib_hpc.cli import run

    comm = MPI.COMM_WORLD
    path = Path(comm.bcast(str(tmp_path_factory.mktemp("prepared")) if comm.rank == 0
                           else None, root=0))
    assert run(["run", str(BASELINE), *COARSE, "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="session")
def prepared_static(prepared, tmp_path_factory) -> Path:
    """The prepared model with the static correction: ``static.h5`` and its ``mbs.h5``."""
    from railvib_hpc.cli import run

    path = tmp_path_factory.mktemp("prepared_static")
    copy_results(prepared, path, ("mesh.h5", "mesh.msh", "mesh.xdmf", "mesh_report.json",
                                  "modes.h5", "modes.xdmf"))
    sets = [*COARSE, "--set", "mbs.static_correction=true"]
    assert run(["modal", str(BASELINE), *sets, "--out", str(path)]) == 0
    assert run(["mbs", str(BASELINE), *sets, "--out", str(path)]) == 0
    return path


@pytest.fixture
def work(prepared, tmp_path) -> Path:
    """A private copy of the prepared results."""
    return copy_results(prepared, tmp_path / "out")


@pytest.fixture
def tmpfs():
    """``tmpfs(size_mb, ro=False) -> Path``: mount small tmpfs folders (unmounted after)."""
    if not can_mount():
        pytest.skip("cannot mount a tmpfs here (needs root and mount permission)")
    mounts = []

    def make(size_mb: float, ro: bool = False) -> Path:
        d = Path(tempfile.mkdtemp(prefix="railvib-tmpfs-"))
        opts = f"size={int(size_mb * 1024)}k" + (",ro" if ro else "")
        subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(d)], check=True)
        mounts.append(d)
        return d

    yield make
    for d in mounts:
        subprocess.run(["umount", "-l", str(d)], capture_output=True)
        shutil.rmtree(d, ignore_errors=True)
