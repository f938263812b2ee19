"""Matrix-free stiffness product (one element matrix per class, batched GEMM) against the
assembled matrix (SciPy CSR, PETSc MatMult): time, memory and rates (issue 28, item 1).

Usage (one rank; under the shared lock so the timings are the machine's own)::

    flock /tmp/railvib-heavy.lock python bench/matrix_free_bench.py --dofs 0.5e6 1e6 2e6

Each line: a structured box of hexahedra (2:2:1, 1 m x 1 m x 0.5 m elements, two soil
materials: 2 element classes, as a site's structured blocks), all nodes free. Times are the
best of ``--repeat`` products after one warm-up (the Numba kernel compiles in the warm-up).
Printed per operator: setup [s], memory the operator holds [B per DOF], time per product
[ms] and per DOF [ns], achieved memory traffic (CSR: 12 B per entry + 16 B per DOF; matrix
free: the gather's 8 B per element DOF + 4 B of its index, the scatter's 8 + 4, the vectors'
16 B per DOF) against the one-core triad, and flop rate (CSR: 2 per entry; matrix free:
2 x 24 x 24 per element).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from explicit_bench import triad_gbs


def structured_box(n_dofs: float):
    """Points and hexahedra of a box with about ``n_dofs`` DOFs, and E per element."""
    n = max(2, int(round((n_dofs / 3 / 2) ** (1 / 3))))
    nx, ny, nz = 2 * n, n, n
    axes = (np.arange(nx + 1, dtype=float), np.arange(ny + 1, dtype=float),
            0.5 * np.arange(nz + 1, dtype=float))
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    nid = np.arange(len(points)).reshape(nx + 1, ny + 1, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz),
                                              indexing="ij"))
    conn = np.stack([nid[i, j, k], nid[i + 1, j, k], nid[i + 1, j + 1, k], nid[i, j + 1, k],
                     nid[i, j, k + 1], nid[i + 1, j, k + 1], nid[i + 1, j + 1, k + 1],
                     nid[i, j + 1, k + 1]], axis=1)
    E = np.where(k < nz // 2, 1.2e8, 3.0e8)                   # two layers
    return points, conn, E


def best_time(fn, repeat: int) -> float:
    fn()                                                      # warm-up (and compilation)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def one(n_target: float, repeat: int, bw: float) -> list[str]:
    from railvib_hpc.fem.assemble_serial import assemble_matrix, element_dofs
    from railvib_hpc.fem.hex8 import hex8_stiffness
    from railvib_hpc.fem.matrix_free import MatrixFreeStiffness, compiled_kernel

    points, conn, E = structured_box(n_target)
    n, nel = 3 * len(points), len(conn)
    u = np.random.default_rng(0).standard_normal(n)
    rows = []

    t0 = time.perf_counter()
    K = assemble_matrix(element_dofs(conn, 3), hex8_stiffness(points[conn], E, 0.3), n)
    t_csr = time.perf_counter() - t0
    K.indices = K.indices.astype(np.int32)
    nnz = K.nnz
    csr_bytes = 12.0 * nnz + 16.0 * n
    ref = K @ u

    def row(name, setup, held, t, traffic, flops, err):
        rows.append(f"| {n:,} | {name} | {setup:.1f} | {held / n:.0f} | {1e3 * t:.2f} | "
                    f"{1e9 * t / n:.1f} | {traffic / t / 1e9:.1f} ({traffic / t / 1e9 / bw:.0%}) "
                    f"| {flops / t / 1e9:.2f} | {err:.1e} |")

    row("SciPy CSR", t_csr, K.data.nbytes + K.indices.nbytes + K.indptr.nbytes,
        best_time(lambda: K @ u, repeat), csr_bytes, 2.0 * nnz, 0.0)
    try:
        from petsc4py import PETSc

        A = PETSc.Mat().createAIJ(size=K.shape, csr=(K.indptr.astype(PETSc.IntType),
                                                      K.indices.astype(PETSc.IntType), K.data),
                                  comm=PETSc.COMM_SELF)
        x, y = A.createVecs()
        x.getArray()[:] = u
        A.mult(x, y)
        err = np.abs(y.getArray() - ref).max() / np.abs(ref).max()
        row("PETSc MatMult (SeqAIJ)", t_csr, 12.0 * nnz + 4.0 * n,
            best_time(lambda: A.mult(x, y), repeat), csr_bytes, 2.0 * nnz, err)
        A.destroy()
        x.destroy()
        y.destroy()
    except ImportError:
        rows.append(f"| {n:,} | PETSc MatMult | petsc4py not importable |")
    K = None                                                  # (free it)

    t0 = time.perf_counter()
    op = MatrixFreeStiffness(points, conn, E, 0.3)
    t_mf = time.perf_counter() - t0
    mf_bytes = 24.0 * nel * (8 + 4) * 2 + 16.0 * n
    mf_flops = 2.0 * 24 * 24 * nel
    err = np.abs(op.apply(u) - ref).max() / np.abs(ref).max()
    row(f"matrix-free NumPy ({op.n_classes} classes)", t_mf, op.nbytes,
        best_time(lambda: op.apply(u), repeat), mf_bytes, mf_flops, err)
    if compiled_kernel() is not None:
        err = np.abs(op.apply_compiled(u) - ref).max() / np.abs(ref).max()
        row("matrix-free Numba", t_mf, op.nbytes, best_time(lambda: op.apply_compiled(u), repeat),
            mf_bytes, mf_flops, err)
    else:
        rows.append(f"| {n:,} | matrix-free Numba | numba not installed (optional) |")
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dofs", type=float, nargs="+", default=[0.5e6, 1e6, 2e6])
    p.add_argument("--repeat", type=int, default=10)
    args = p.parse_args()
    bw = triad_gbs()
    print(f"# one-core triad bandwidth {bw:.1f} GB/s; one rank")
    print("| DOFs | operator | setup [s] | held [B/DOF] | product [ms] | per DOF [ns] | "
          "traffic [GB/s] (of triad) | GFlop/s | error vs CSR |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in args.dofs:
        for line in one(n, args.repeat, bw):
            print(line, flush=True)


if __name__ == "__main__":
    main()
