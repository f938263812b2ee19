"""Benchmark (not collected by pytest): field reconstruction throughput vs a plain write.

Reconstructs displacement, velocity and acceleration of every node of the
thesis model from random modal histories (300 modes), then, in the same run and
to the same folder, writes the same number of bytes with one plain sequential
``numpy.ndarray.tofile`` from rank 0. Both are timed until ``fsync`` returns.
Target: reconstruction wall time within 2x of the plain write. Prints GB/s and the GEMM rate.

Run: ``mpirun -n 2 .venv/bin/python bench/reconstruct_bench.py [modes.h5] [n_steps]``
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from railvib_hpc.reconstruct.fields import reconstruct_fields

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    """Time both writes and print the comparison."""
    comm = MPI.COMM_WORLD
    modes = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "results/thesis_baseline/modes.h5"
    nt = int(sys.argv[2]) if len(sys.argv) > 2 else 400
    import h5py

    with h5py.File(modes, "r") as f:
        m = f["modes/eigenvalue"].shape[0]
    rng = np.random.default_rng(0)
    q = rng.standard_normal((nt, m)) * 1e-6
    t = np.arange(nt) * 1e-3
    folder = comm.bcast(tempfile.mkdtemp(prefix="railvib-bench-", dir=ROOT / "results")
                        if comm.rank == 0 else None)
    out = Path(folder) / "fields.h5"
    comm.Barrier()
    t0 = time.perf_counter()
    st = reconstruct_fields(modes, out, comm, t, q, q, q)
    if comm.rank == 0:                     # to disk, like the plain write below
        with open(out, "rb+") as fh:
            os.fsync(fh.fileno())
    comm.Barrier()
    wall = time.perf_counter() - t0
    nbytes = st["bytes_written"]
    if comm.rank == 0:
        raw = Path(folder) / "plain.bin"
        buf = np.ones(nbytes // 8)
        t1 = time.perf_counter()
        with open(raw, "wb") as fh:
            buf.tofile(fh)
            fh.flush()
            os.fsync(fh.fileno())
        plain = time.perf_counter() - t1
        print(f"{st['n_nodes']} nodes x {nt} steps x {m} modes on {comm.size} rank(s), "
              f"{nbytes / 1e9:.2f} GB (3 fields, float64)")
        print(f"reconstruction (incl. fsync): wall {wall:.2f} s "
              f"({nbytes / wall / 1e9:.2f} GB/s), GEMM "
              f"{st['seconds_gemm']:.2f} s ({st['gemm_gflops']:.1f} GFlop/s), HDF5 writes "
              f"{st['seconds_write']:.2f} s ({st['write_gb_per_s']:.2f} GB/s)")
        print(f"plain sequential write of the same bytes (tofile + fsync): {plain:.2f} s "
              f"({nbytes / plain / 1e9:.2f} GB/s)")
        print(f"ratio reconstruction / plain write: {wall / plain:.2f} (target <= 2)")
        import shutil

        shutil.rmtree(folder, ignore_errors=True)
    comm.Barrier()


if __name__ == "__main__":
    main()
