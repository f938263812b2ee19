"""Session fixtures of the reconstruct tests (MPI-aware: every rank sees the same files)."""

from __future__ import annotations

import pytest
from mpi4py import MPI
from reconstruct_cases import BASELINE, COARSE, remove_dir, shared_dir


@pytest.fixture(scope="session")
def coarse_modes():
    """``modes.h5`` of the coarse thesis model (8 modes), computed once per session."""
    from railvib_hpc.cli import run

    folder = shared_dir()
    assert run(["modal", str(BASELINE), *COARSE, "--out", str(folder)]) == 0
    MPI.COMM_WORLD.Barrier()
    yield folder / "modes.h5"
    remove_dir(folder)

