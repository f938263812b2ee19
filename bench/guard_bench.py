"""Cost of the divergence guard's check (:mod:`railvib_hpc.transient.guard`) per DOF,
against a step of each engine, on the soil box of ``bench/explicit_bench.py``.

For each engine: the box (absorbing faces, Rayleigh damping 3 %, a 20 Hz point load), a
few warm-up steps, then the best of ``--repeat`` timings of one
:meth:`~railvib_hpc.transient.guard.DivergenceGuard.check` and of one step. The check is the
kinetic energy (``m v`` on the lumped diagonal; the direct engine's consistent mass: one
product with M), its ``bincount`` by region, one ``Allreduce`` and one broadcast. Prints ns
per DOF per check, ns per DOF per step, and the check's share of the steps at the interval
the guard takes (the output stride widened to at most 1 % of the steps,
:data:`~railvib_hpc.transient.guard.GUARD_COST_SHARE`, at most 64 steps).

Usage::

    python bench/guard_bench.py --dofs 1e5
    mpirun -n 2 python bench/guard_bench.py --dofs 1e5
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _best(fn, repeat: int, comm) -> float:
    """The smallest wall time of ``fn()`` over ``repeat`` calls (collective)."""
    best = math.inf
    for _ in range(repeat):
        comm.Barrier()
        t0 = time.perf_counter()
        fn()
        comm.Barrier()
        best = min(best, time.perf_counter() - t0)
    return best


def one(n_dofs: float, engine: str, repeat: int) -> dict:
    """One engine on the box (collective)."""
    from explicit_bench import box
    from mpi4py import MPI

    from railvib_hpc.config import load_case
    from railvib_hpc.model.boundary import constraint_rules, dashpot_diagonal, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_damping
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.problem import Problem

    init_petsc([])
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        lumped_diagonal,
        stability_limit,
    )
    from railvib_hpc.transient.guard import (
        GUARD_COST_SHARE,
        MAX_CHECK_INTERVAL,
        DivergenceGuard,
        dof_regions,
        node_regions,
    )
    from railvib_hpc.transient.integrate import DirectSolver, State
    from railvib_hpc.transient.petsc import TransientSystem
    from railvib_hpc.transient.scheme import GeneralizedAlpha

    comm = MPI.COMM_WORLD
    lumped = engine == "explicit"
    case = load_case(None, [*(f"boundary.{f}=absorbing" for f in
                              ("x_min", "x_max", "y_min", "y_max", "base")),
                            f"modal.lumped_mass={'true' if lumped else 'false'}",
                            "damping.model=rayleigh", "modal.damping_ratio=0.03"])
    mesh, top = box(n_dofs)
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm, mass="diagonal" if lumped else True)
    if lumped:
        dashpots = dashpot_diagonal(mesh, problem, dofmap, comm.rank)
        C, _ = assemble_damping(mesh, problem, dofmap, comm, K, M, dashpots=False)
        dt = stability_limit(K, lumped_diagonal(M, comm), C, comm).dt_allowed
        system = ExplicitSystem(K, M, C, dt, comm, dashpots=dashpots)
    else:
        C, _ = assemble_damping(mesh, problem, dofmap, comm, K, M)
        dt = 1.0 / (20 * 80.0)
        system = TransientSystem(K, M, C, GeneralizedAlpha.from_radius(dt, 1.0), comm)
    dof = int(dofmap.index[top, 2])

    def load(n: int):
        return np.array([dof]), np.array([-1e4 * np.sin(2 * np.pi * 20.0 * n * dt)])

    solver = ExplicitSolver(system, load) if lumped else DirectSolver(system, load)
    st = State(0, *(np.zeros(system.n_local) for _ in range(3)))
    solver.start(st)
    region, names = node_regions(mesh, [])
    rows = dof_regions(region, dofmap.index, system.r0, system.r1)
    guard = DivergenceGuard(system, solver, rows, names, mesh.points, dofmap.index, dt, engine,
                            None, 1)
    guard.start(st)
    for _ in range(20):
        solver.step(st)
    t_check = _best(lambda: guard.check(st), repeat, comm)
    t_step = _best(lambda: solver.step(st), repeat, comm)
    n = dofmap.n_dofs
    interval = max(1, min(MAX_CHECK_INTERVAL, math.ceil(t_check / (GUARD_COST_SHARE
                                                                     * t_step))))
    solver.destroy()
    system.destroy()
    for A in (K, M, C):
        if A is not None:
            A.destroy()
    return {"engine": engine, "dofs": n, "ranks": comm.size,
            "check_ns_per_dof": 1e9 * t_check / n, "step_ns_per_dof": 1e9 * t_step / n,
            "interval": interval, "share": t_check / (interval * t_step)}


def main() -> None:
    from mpi4py import MPI

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dofs", type=float, default=1e5)
    p.add_argument("--repeat", type=int, default=20)
    args = p.parse_args()
    comm = MPI.COMM_WORLD
    rows = [one(args.dofs, engine, args.repeat) for engine in ("explicit", "direct")]
    if comm.rank == 0:
        print(f"{'engine':9s} {'DOFs':>9s} {'ranks':>5s} {'check ns/DOF':>12s} "
              f"{'step ns/DOF':>11s} {'interval':>8s} {'share':>7s}")
        for r in rows:
            print(f"{r['engine']:9s} {r['dofs']:9d} {r['ranks']:5d} "
                  f"{r['check_ns_per_dof']:12.3g} {r['step_ns_per_dof']:11.4g} "
                  f"{r['interval']:8d} {100 * r['share']:6.2f}%")


if __name__ == "__main__":
    main()
