"""MUMPS block low-rank (BLR) and out-of-core factorisations of the thesis model, measured.

Usage (under the shared lock; one configuration per process, so memory is its own)::

    flock /tmp/railvib-heavy.lock mpirun -n 2 python bench/mumps_blr_bench.py \\
        [--refinement 1] [--shift-hz 0 40] [--blr 0 1e-10 1e-8 1e-6] [--ooc]

For every (shift, BLR tolerance) it factors ``K - sigma M`` with MUMPS Cholesky through the
same :class:`~railvib_hpc.model.factor.ShiftInvertFactor` as the eigensolver (options
prefix ``railvib_eig_st_``; BLR = ICNTL(35) = 2, CNTL(7) = tolerance), and prints the
analysis estimate (INFOG(17) in core, INFOG(27) out of core), the entries of the factor
(INFOG(29): after BLR compression), the factorisation time, the time of a block of 32
right-hand sides, the relative residual of those solves and of the eigen-residual one
purification step would see, and the process peak memory (sum over ranks).
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from railvib_hpc.problem import Problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--refinement", type=float, default=1.0)
    ap.add_argument("--shift-hz", type=float, nargs="*", default=[0.0])
    ap.add_argument("--blr", type=float, nargs="*", default=[0.0, 1e-10, 1e-8, 1e-6])
    ap.add_argument("--ooc", action="store_true", help="MUMPS out of core (ICNTL(22) = 1)")
    ap.add_argument("--relax", type=int, default=0,
                    help="MUMPS ICNTL(14), the working-space relaxation in percent (0: "
                         "PETSc's default); BLR stops with INFOG(1) = -20 at the default")
    args = ap.parse_args()

    from mpi4py import MPI

    from railvib_hpc.config import load_case
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.mesh.layout import build_layout
    from railvib_hpc.parallel import on_root
    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    from petsc4py import PETSc

    from railvib_hpc.modal.block_lanczos import start_block
    from railvib_hpc.modal.eigen import PREFIX
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.factor import ShiftInvertFactor
    from railvib_hpc.model.petsc import assemble

    comm = MPI.COMM_WORLD
    case = load_case(None, [f"mesh.refinement={args.refinement!r}"])
    mesh = on_root(lambda: generate(build_layout(case))[0], comm)
    dofmap = build_dofmap(mesh, comm.size)
    K, M, _ = assemble(mesh, Problem.from_case(case), dofmap, comm)
    r0, r1 = dofmap.owned_dofs(comm.rank)
    B = start_block(dofmap.n_dofs, r0, r1, 32)
    opts = PETSc.Options()
    names = {"icntl_35": f"{PREFIX}st_mat_mumps_icntl_35", "cntl_7": f"{PREFIX}st_mat_mumps_cntl_7",
             "icntl_22": f"{PREFIX}st_mat_mumps_icntl_22",
             "icntl_14": f"{PREFIX}st_mat_mumps_icntl_14"}
    if comm.rank == 0:
        print(f"# refinement {args.refinement}: {dofmap.n_dofs:,} DOFs, {comm.size} rank(s)"
              f"{', out of core' if args.ooc else ''}"
              f"{f', ICNTL(14) = {args.relax}' if args.relax else ''}")
        print("| shift [Hz] | BLR tol | estimate [GB] | factor entries (INFOG(29)) | "
              "factorisation [s] | 32 RHS [s] | solve rel. residual | peak [GB] |")
        print("|---|---|---|---|---|---|---|---|")
    for shift in args.shift_hz:
        for tol in args.blr:
            if tol > 0:
                opts.setValue(names["icntl_35"], 2)
                opts.setValue(names["cntl_7"], tol)
            if args.ooc:
                opts.setValue(names["icntl_22"], 1)
            if args.relax:
                opts.setValue(names["icntl_14"], args.relax)
            sigma = (2 * np.pi * shift) ** 2
            t0 = time.perf_counter()
            op = ShiftInvertFactor(K, M, sigma, comm, PREFIX,
                                   out_of_core="never" if not args.ooc else "always")
            t_fact = time.perf_counter() - t0
            F = op.factor
            entries = F.getMumpsInfog(29)
            t1 = time.perf_counter()
            Y = op.solve(B, chunk=32)
            t_solve = time.perf_counter() - t1
            R = B - (op.stiffness(Y) - sigma * op.mass(Y))
            rel = np.sqrt(comm.allreduce(float(np.sum(R**2)))) / \
                np.sqrt(comm.allreduce(float(np.sum(B**2))))
            op.destroy()
            for n in names.values():
                opts.delValue(n)
            peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)
            if comm.rank == 0:
                print(f"| {shift:g} | {tol:g} | {op.factor_memory_gb:.2f} | {entries:,} | "
                      f"{t_fact:.1f} | {t_solve:.2f} | {rel:.1e} | {peak:.2f} |", flush=True)


if __name__ == "__main__":
    main()
