"""Defect 4 of issue 16: a full disk gives one clear line on every rank, never a hang, a
segfault, a truncated file under its final name or an orphaned temporary file.

Measured before: a 40 MB tmpfs as --out holding mesh/modes/mbs hung ``mpirun -n 2``; on
one rank a traceback and a PETSc SEGV; at 10 MB libhdf5 segfaulted writing the modes; at
2 MB a truncated mesh.msh was renamed to its final name.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from faults import BASELINE, COARSE, can_mount, cli, copy_results, serial_only
from mpi4py import MPI

B = str(BASELINE)
MESH = ("mesh.h5", "mesh.msh", "mesh.xdmf", "mesh_report.json")


def _leftovers(out: Path) -> list[str]:
    return [p.name for p in out.iterdir() if ".part" in p.name]


@serial_only
@pytest.mark.parametrize("ranks", [2, 1])
def test_full_disk_at_the_fields(ranks, prepared, tmpfs, tally):
    """The issue's case: 40 MB holding a finished mesh, modes and mbs; the fields need 82 MB."""
    out = copy_results(prepared, tmpfs(40), (*MESH, "modes.h5", "modes.xdmf", "mbs.h5"))
    res = tally.result(f"full disk at fields.h5, {ranks} rank(s)",
                       cli(["run", B, "--out", out, *COARSE], ranks=ranks, timeout=300))
    assert res.outcome == "clear error", (res.code, res.err[-2000:])
    assert "not enough free space" in res.error_lines[0] and "fields.h5" in res.error_lines[0]
    assert not (out / "fields.h5").exists() and not _leftovers(out)


@serial_only
@pytest.mark.parametrize("ranks", [2, 1])
def test_full_disk_at_the_modes(ranks, prepared, tmpfs, tally):
    """10 MB: the mesh fits, the modes (7.7 MB + margin) do not; refused before the
    eigensolve, not by a segfault in libhdf5 after it."""
    out = copy_results(prepared, tmpfs(10), MESH)
    res = tally.result(f"full disk at modes.h5, {ranks} rank(s)",
                       cli(["modal", B, "--out", out, *COARSE], ranks=ranks, timeout=300))
    assert res.outcome == "clear error", (res.code, res.err[-2000:])
    assert "modes.h5" in res.error_lines[0] and "free" in res.error_lines[0]
    assert "[eigensolve]" not in res.out
    assert not (out / "modes.h5").exists() and not _leftovers(out)


@serial_only
def test_full_disk_at_the_mesh(tmpfs, tally):
    """2 MB: gmsh's .msh (3.6 MB) cannot be written; no truncated mesh.msh appears."""
    out = tmpfs(2)
    res = tally.result("full disk at mesh.msh", cli(["mesh", B, "--out", out, *COARSE],
                                                    timeout=300))
    assert res.outcome == "clear error", (res.code, res.err[-2000:])
    assert "mesh.msh" in res.error_lines[0]
    assert not (out / "mesh.msh").exists() and not (out / "mesh.h5").exists()
    assert not _leftovers(out)


def test_reservation_fails_cleanly_on_a_full_disk(tmpfs):
    from railvib_hpc.errors import OutputError
    from railvib_hpc.io.atomic import reserve

    out = tmpfs(1)
    f = out / "x"
    f.write_bytes(b"")
    with pytest.raises(OutputError, match="cannot reserve"):
        reserve(f, 4 * 2**20)


@pytest.mark.mpi
def test_write_failure_on_a_full_disk_is_collective(shared_tmp):
    """The data outgrow a (wrong) size prediction on a full tmpfs: every rank raises the
    same clear error (no hang), and no file or temporary file is left."""
    from railvib_hpc.errors import OutputError
    from railvib_hpc.io.atomic import write_h5
    from railvib_hpc.io.parallel_h5 import write_slab

    comm = MPI.COMM_WORLD
    ok = comm.bcast(can_mount() if comm.rank == 0 else None, root=0)
    if not ok:
        pytest.skip("cannot mount a tmpfs here")
    mnt = None
    if comm.rank == 0:
        import subprocess

        mnt = tempfile.mkdtemp(prefix="railvib-tmpfs-")
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16384k", "tmpfs", mnt], check=True)
    mnt = Path(comm.bcast(mnt, root=0))
    n = 1_000_000                         # 24 MB of data on a 16 MB disk, predicted 1 kB

    def fill(f, parallel):
        d = f.create_dataset("x", (n, 3), "f8")
        lo, hi = comm.rank * n // comm.size, (comm.rank + 1) * n // comm.size
        write_slab(d, (lo, 0), (hi - lo, 3), np.ones((hi - lo, 3)), parallel)

    try:
        with pytest.raises(OutputError) as info:
            write_h5(mnt / "x.h5", comm, fill, size_hint=1000)
        messages = comm.allgather(str(info.value))
        assert len(set(messages)) == 1 and "No space left on device" in messages[0]
        comm.Barrier()
        assert sorted(os.listdir(mnt)) == []
    finally:
        comm.Barrier()
        if comm.rank == 0:
            import subprocess

            subprocess.run(["umount", "-l", str(mnt)], capture_output=True)
            os.rmdir(mnt)


def test_truncated_msh_is_never_renamed(tmpfs):
    """Without the free-space check (no predicted size), gmsh.write fills the disk without
    an error; reading the file back finds the truncation before the rename."""
    from railvib_hpc.config import load_case
    from railvib_hpc.errors import OutputError
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.mesh.layout import build_layout

    out = tmpfs(2)
    layout = build_layout(load_case(BASELINE, ["mesh.refinement=0.5"]))
    with pytest.raises(OutputError, match=r"mesh\.msh failed: gmsh cannot read it back"):
        generate(layout, out / "mesh.msh")
    assert sorted(os.listdir(out)) == []
