"""fields.h5 = Phi q exactly, on 1 and N ranks; XDMF; float32; budget; atomic writes."""

from __future__ import annotations

import io

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from reconstruct_cases import (
    histories,
    read_modes,
    relative_error,
    superpose,
    write_static_basis,
)

from railvib_hpc.io.xdmf import read_xdmf, views_path
from railvib_hpc.log import Reporter
from railvib_hpc.reconstruct import (
    block_steps_for_budget,
    node_range,
    reconstruct_fields,
)
from railvib_hpc.reconstruct import fields as fields_mod

comm = MPI.COMM_WORLD
M = 6                                   # modes used (of the 8 in the file)


def _reference(modes, t, q, qd, qdd, steps, extra=()):
    phi, mesh = read_modes(modes, M)
    out = {}
    for name, h, gi in (("displacement", q, 2), ("velocity", qd, 3), ("acceleration", qdd, 4)):
        ref = superpose(phi, h[steps])
        for e in extra:
            with h5py.File(e[0], "r") as f:
                ref += superpose(f[e[1]][()], e[gi][steps])
        out[name] = ref
    return out, mesh


def check_xdmf(xdmf_path, h5_path):
    """Read the XDMF file as a reader does: every grid shows the mesh of ``h5_path`` and
    every attribute of step k is row k of its dataset there (through the views)."""
    grids = read_xdmf(xdmf_path)
    assert views_path(xdmf_path).is_file()
    with h5py.File(h5_path, "r") as f:
        for k, g in enumerate(grids):
            assert g["topology"] == "Hexahedron" and g["n_cells"] == f["mesh/hexes"].shape[0]
            assert np.array_equal(g["points"], f["mesh/points"][()])
            assert np.array_equal(g["cells"], f["mesh/hexes"][()])
            for name, (center, data) in g["attributes"].items():
                if name == "part_id":
                    assert center == "Cell" and np.array_equal(data, f["mesh/hex_part"][()])
                    continue
                group = "fields" if f"fields/{name}" in f else "stress"
                assert center == ("Node" if group == "fields" else "Cell")
                assert data.dtype == f[group][name].dtype
                assert np.array_equal(data, f[group][name][k]), (name, k)
    return grids, [g["time"] for g in grids]


@pytest.mark.mpi
@pytest.mark.parametrize("parallel_io", [True, False])
def test_fields_equal_modal_superposition(coarse_modes, shared_tmp, monkeypatch, parallel_io):
    if not parallel_io:      # rank 0 gathers and writes: the path without parallel HDF5
        monkeypatch.setattr(fields_mod, "h5py_parallel_ok", lambda c: False)
    t, q, qd, qdd = histories(41, M)
    with h5py.File(coarse_modes, "r") as f:
        n = f["mesh/points"].shape[0]
    basis = shared_tmp / "static.h5"
    rng = np.random.default_rng(5)
    g = [rng.standard_normal((len(t), 2)) for _ in range(3)]
    if comm.rank == 0:
        write_static_basis(basis, n, 2)
    comm.Barrier()
    extra = [(basis, "basis", *g)]
    steps = np.arange(1, 41, 3)
    out = shared_tmp / "res" / "fields.h5"
    stats = reconstruct_fields(coarse_modes, out, comm, t, q, qd, qdd, steps=steps,
                               block_steps=4, extra=extra)
    comm.Barrier()
    ref, mesh = _reference(coarse_modes, t, q, qd, qdd, steps, extra)
    with h5py.File(out, "r") as f:
        assert int(f.attrs["complete"]) == 1
        assert int(f.attrs["n_modes"]) == M and int(f.attrs["n_extra"]) == 2
        for name, r in ref.items():
            ds = f["fields/" + name]
            assert ds.shape == (len(steps), n, 3) and ds.chunks is None   # contiguous
            assert relative_error(ds[()], r) < 1e-12
        assert np.array_equal(f["time"][()], t[steps])
        assert np.array_equal(f["steps"][()], steps)
        for key, value in mesh.items():
            assert np.array_equal(f["mesh/" + key][()], value)
    assert stats["n_steps"] == len(steps) and stats["n_basis"] == M + 2
    assert stats["bytes_written"] == 3 * len(steps) * n * 3 * 8
    assert stats["ranks"] == comm.size and stats["block_steps"] == 4
    assert stats["gemm_gflops"] > 0 and stats["write_gb_per_s"] > 0
    grids, times = check_xdmf(out.with_suffix(".xdmf"), out)
    assert len(grids) == len(steps) and np.allclose(times, t[steps], rtol=0, atol=1e-15)
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".fields")]


@pytest.mark.mpi
def test_failure_on_one_rank_raises_everywhere_and_leaves_no_file(coarse_modes, shared_tmp,
                                                                   monkeypatch):
    calls = {"n": 0}
    real = fields_mod._gemm

    def failing(a, b, out):
        calls["n"] += 1
        if calls["n"] == 4 and comm.rank == comm.size - 1:
            raise MemoryError("simulated failure")
        real(a, b, out)

    monkeypatch.setattr(fields_mod, "_gemm", failing)
    t, q, qd, qdd = histories(10, M)
    out = shared_tmp / "fields.h5"
    with pytest.raises((MemoryError, RuntimeError), match="simulated failure"):
        reconstruct_fields(coarse_modes, out, comm, t, q, qd, qdd, block_steps=3)
    comm.Barrier()
    assert not out.exists() and not out.with_suffix(".xdmf").exists()
    assert list(shared_tmp.iterdir()) == []          # no temporary file either


def test_float32_halves_the_dataset_size(coarse_modes, tmp_path):
    t, q, qd, qdd = histories(12, M)
    sizes = {}
    for f32 in (False, True):
        out = tmp_path / f"f{int(f32)}" / "fields.h5"
        stats = reconstruct_fields(coarse_modes, out, MPI.COMM_SELF, t, q, qd, qdd,
                                   float32=f32)
        with h5py.File(out, "r") as f:
            ds = f["fields/velocity"]
            sizes[f32] = ds.id.get_storage_size()
            assert ds.dtype == (np.float32 if f32 else np.float64)
            data = ds[()]
        sizes[f32, "stats"] = stats["bytes_written"]
        if f32:
            ref, _ = _reference(coarse_modes, t, q, qd, qdd, np.arange(12))
            assert relative_error(data.astype(float), ref["velocity"]) < 1e-6
            _, _ = check_xdmf(out.with_suffix(".xdmf"), out)
    assert sizes[True] * 2 == sizes[False]
    assert sizes[True, "stats"] * 2 == sizes[False, "stats"]


def test_progress_is_reported_with_eta(coarse_modes, tmp_path):
    stream = io.StringIO()
    t, q, qd, qdd = histories(20, M)
    reconstruct_fields(coarse_modes, tmp_path / "fields.h5", MPI.COMM_SELF, t, q, qd, qdd,
                       block_steps=5, rep=Reporter(0, stream))
    text = stream.getvalue()
    assert "fields: 20/20 steps" in text and "100.0 %" in text and "ETA" in text


def test_serial_failure_leaves_no_file_and_keeps_the_old_one(coarse_modes, tmp_path,
                                                             monkeypatch):
    t, q, qd, qdd = histories(8, M)
    out = tmp_path / "fields.h5"
    reconstruct_fields(coarse_modes, out, MPI.COMM_SELF, t, q, qd, qdd)
    before = out.read_bytes()

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(fields_mod, "write_slab", broken)
    with pytest.raises(OSError, match="disk full"):
        reconstruct_fields(coarse_modes, out, MPI.COMM_SELF, t, 2 * q, qd, qdd)
    assert out.read_bytes() == before                 # the previous result is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == [".railvib", "fields.h5", "fields.xdmf",
                                                          "fields_views.h5"]


def test_invalid_histories_are_rejected(coarse_modes, tmp_path):
    t, q, qd, qdd = histories(5, 9)
    with pytest.raises(ValueError, match="holds only 8 modes"):
        reconstruct_fields(coarse_modes, tmp_path / "f.h5", MPI.COMM_SELF, t, q, qd, qdd)
    t, q, qd, qdd = histories(5, 3)
    with pytest.raises(ValueError, match=r"\(nt, m\)"):
        reconstruct_fields(coarse_modes, tmp_path / "f.h5", MPI.COMM_SELF, t, q, qd[:4], qdd)
    with pytest.raises(ValueError, match="steps"):
        reconstruct_fields(coarse_modes, tmp_path / "f.h5", MPI.COMM_SELF, t, q, qd, qdd,
                           steps=[7])
    assert not (tmp_path / "f.h5").exists()


def test_node_split_and_memory_budget():
    for n, size in ((10, 3), (2, 4), (1_000_000, 2)):
        parts = [node_range(n, size, r) for r in range(size)]
        assert parts[0].start == 0 and parts[-1].stop == n
        assert all(a.stop == b.start for a, b in zip(parts, parts[1:]))
        assert max(p.stop - p.start for p in parts) - min(p.stop - p.start for p in parts) <= 1
    # one million nodes on 2 ranks: 1.5 M values per step and rank
    nb = block_steps_for_budget(3 * 500_000, float32=False)
    assert nb == 44 and nb * 3 * 500_000 * 8 <= fields_mod.OUTPUT_BUDGET_BYTES
    nb32 = block_steps_for_budget(3 * 500_000, float32=True)
    assert nb32 * 3 * 500_000 * 12 <= fields_mod.OUTPUT_BUDGET_BYTES
    assert block_steps_for_budget(10**9, float32=False) == 1


KILLED_RUN = """
import sys, time
import numpy as np
from mpi4py import MPI
from railvib_hpc.reconstruct import fields
real = fields._gemm
def slow(a, b, out):
    time.sleep(0.05)
    real(a, b, out)
fields._gemm = slow
t = np.arange(400) * 1e-3
q = np.ones((400, 4))
fields.reconstruct_fields(sys.argv[1], sys.argv[2], MPI.COMM_SELF, t, q, q, q, block_steps=1)
"""


def test_killed_run_leaves_no_fields_file(coarse_modes, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "fields.h5"
    proc = subprocess.Popen([sys.executable, "-c", KILLED_RUN, str(coarse_modes), str(out)])
    try:
        deadline = time.monotonic() + 60
        while not list(tmp_path.glob(".fields.h5.part-*")) and time.monotonic() < deadline:
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.05)
        time.sleep(0.3)                                  # some blocks written
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert list(tmp_path.glob(".fields.h5.part-*"))       # it was writing ...
    assert not out.exists() and not out.with_suffix(".xdmf").exists()   # ... but no result
