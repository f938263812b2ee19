"""Parallel behaviour: every rank gets the same case or the same error; none hangs.

Tests marked ``mpi`` run in the second pass of ``make test`` under
``mpirun -n 2``; they also pass on one rank.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.errors import CaseError
from railvib_hpc.parallel import RootFailure, on_root

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
comm = MPI.COMM_WORLD


def _all_equal(value) -> bool:
    values = comm.allgather(value)
    return all(v == values[0] for v in values)


@pytest.mark.mpi
def test_case_is_loaded_on_root_and_identical_everywhere():
    case = on_root(lambda: load_case(BASELINE, ["mesh.refinement=2"]))
    assert case["mesh.refinement"] == 2.0
    assert _all_equal(case.digest())


@pytest.mark.mpi
def test_case_error_raised_on_every_rank(shared_tmp):
    bad = shared_tmp / "bad.toml"
    if comm.rank == 0:
        bad.write_text("[materials.subgrade]\nnu = 0.7\n")
    comm.Barrier()
    with pytest.raises(CaseError) as info:
        on_root(lambda: load_case(bad))
    assert info.value.problems[0][0] == "materials.subgrade.nu"
    assert _all_equal(str(info.value))


@pytest.mark.mpi
def test_non_user_failure_on_root_reaches_all_ranks():
    def boom():
        raise ValueError("disk full")

    expected = ValueError if comm.rank == 0 else RootFailure
    with pytest.raises(expected, match="disk full"):
        on_root(boom)


@pytest.mark.mpi
def test_cli_exit_codes_agree_on_all_ranks(shared_tmp):
    bad = shared_tmp / "bad.toml"
    if comm.rank == 0:
        bad.write_text("[track]\nsleeper_spacing = 0.7\n")
    comm.Barrier()
    code = run(["check", str(bad)])
    assert code == 2 and _all_equal(code)
    code = run(["mbs", str(BASELINE), "--out", str(shared_tmp / "empty")])   # no modes.h5
    assert code == 2 and _all_equal(code)


@pytest.mark.mpi
def test_mesh_command_in_parallel_equals_serial(shared_tmp):
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.mesh.layout import build_layout
    from railvib_hpc.mesh.mesh_io import read_mesh_h5

    out = shared_tmp / "res"
    code = run(["mesh", str(BASELINE), "--set", "mesh.refinement=0.5", "--out", str(out)])
    assert code == 0 and _all_equal(code)
    comm.Barrier()
    mesh, _ = read_mesh_h5(out / "mesh.h5")
    serial, _ = generate(build_layout(load_case(BASELINE, ["mesh.refinement=0.5"])))
    assert np.array_equal(mesh.points, serial.points)
    assert np.array_equal(mesh.hexes, serial.hexes)


def _mpirun() -> list[str] | None:
    exe = shutil.which("mpirun")
    if exe is None:
        return None
    return [exe, "--oversubscribe", "-n", "2"]


@pytest.mark.skipif(comm.size > 1, reason="spawns its own mpirun; run in the serial pass")
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_mpirun_user_error_exits_2_on_all_ranks_without_hanging(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[geometry]\nxbbb = 1.0\n")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    proc = subprocess.run(_mpirun() + [sys.executable, "-m", "railvib_hpc", "mesh", str(bad),
                                       "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("did you mean 'geometry.xbb'") == 1  # printed by rank 0 only
    assert "Traceback" not in proc.stderr
