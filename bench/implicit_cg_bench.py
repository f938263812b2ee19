"""The third candidate of issue 28, item 1: an implicit step solved by warm-started CG,
against the explicit engine on the same soil box.

The issue lists three O(N) candidates to measure against each other: explicit central
differences (``transient.engine = "explicit"``), the implicit-explicit split (``"imex"``)
and an implicit step solved iteratively, "CG with a multigrid or Chebyshev-Jacobi
preconditioner, warm-started". This bench measures the third on the box of
``bench/explicit_bench.py`` (the thesis subgrade in 1 m cubes, c_S 212 m/s, all five faces
absorbing, Rayleigh damping 3 %, a 20 Hz point load on the surface):

* the explicit engine at its allowed step ``dt_e`` (:func:`~railvib_hpc.transient.explicit.
  stability_limit`): seconds per step;
* Newmark's average acceleration (the direct engine's default scheme, unconditionally
  stable) on the same K, lumped M and C (Rayleigh and the dashpots assembled), each step
  ``(M + dt/2 C + dt^2/4 K) a_{n+1} = f_{n+1} - K u~ - C v~`` solved by PETSc CG to a
  relative residual ``--rtol``, the previous step's acceleration as the first guess, with
  GAMG (the six rigid-body motions as its near null space, as the static start uses) or
  Jacobi; at steps ``dt = m dt_e`` for ``m`` in ``--multiples``: CG iterations per step,
  seconds per step, the preconditioner's setup, peak memory.

What decides between them is the cost of a simulated second, ``(t_step / dt)``, at the
step that accuracy allows. In the soil the implicit step cannot be much longer than the
explicit one: a mesh of ``epw`` elements per S wavelength resolves ``f = c_S / (epw h)``,
and 20 steps per period of it (the trapezoidal rule's period error 0.8 %,
``transient.steps_per_period``) give ``dt_acc = epw h / (20 c_S)``, which the bench
prints in units of ``dt_e`` (scale-free: both grow with ``h``). The implementation is
checked against the direct engine (the same scheme, one MUMPS factor) at every step of
the first row with each preconditioner (``u_z`` at the load, to about ``--rtol``), and
the explicit history is printed beside it (the schemes differ by ``O(dt^2)``).

Usage::

    python bench/implicit_cg_bench.py --dofs 3e5
    mpirun -n 2 python bench/implicit_cg_bench.py --dofs 3e5 --multiples 1 4
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "bench"), str(ROOT)]

#: Steps per period of the resolved frequency the scheme needs (transient.steps_per_period).
STEPS_PER_PERIOD = 20
#: Elements per S wavelength at the resolved frequency (the mesh check's usual 6 and 9).
EPW = (6.0, 9.0)
#: Fewest steps of an implicit run.
MIN_STEPS = 5
#: The point load's frequency [Hz] and amplitude [N].
LOAD_HZ, LOAD_N = 20.0, 1e4


def _model(n_dofs: float):
    """The box, its K, lumped M, the explicit engine's C and dashpots, and the assembled C
    (Rayleigh and dashpots) of the implicit step (collective)."""
    from explicit_bench import box
    from mpi4py import MPI

    from railvib_hpc.config import load_case
    from railvib_hpc.model.boundary import constraint_rules, dashpot_diagonal, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap, rigid_body_modes
    from railvib_hpc.model.petsc import assemble, assemble_damping, rayleigh_operator
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.problem import Problem

    init_petsc([])
    from railvib_hpc.transient.explicit import lumped_diagonal

    comm = MPI.COMM_WORLD
    case = load_case(None, [*(f"boundary.{f}=absorbing" for f in
                              ("x_min", "x_max", "y_min", "y_max", "base")),
                            "modal.lumped_mass=true", "damping.model=rayleigh",
                            "modal.damping_ratio=0.03"])
    mesh, top = box(n_dofs)
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm, mass="diagonal")
    # the direct engine's system adds M to K's pattern: the same lumped mass stored there
    M_k = assemble(mesh, problem, dofmap, comm, mass=True)[1]
    dashpots = dashpot_diagonal(mesh, problem, dofmap, comm.rank)
    C_e, _ = rayleigh_operator(mesh, problem, dofmap, comm, K, lumped_diagonal(M, comm),
                               dashpots=False)
    C_i, _ = assemble_damping(mesh, problem, dofmap, comm, K, M, dashpots=True)
    c_s = math.sqrt(problem.materials["subgrade"].E
                    / (2 * (1 + problem.materials["subgrade"].nu))
                    / problem.materials["subgrade"].rho)
    return {"comm": comm, "K": K, "M": M, "M_k": M_k, "C_e": C_e, "C_i": C_i, "dashpots": dashpots,
            "dof": int(dofmap.index[top, 2]), "n": dofmap.n_dofs, "c_s": c_s,
            "near_null": rigid_body_modes(mesh.points, dofmap, comm.rank)}


def _load(dof: int, dt: float):
    def load(n: int):
        return np.array([dof]), np.array([-LOAD_N * math.sin(2 * math.pi * LOAD_HZ * n * dt)])
    return load


def explicit_step(m: dict) -> float:
    """The explicit engine's allowed step ``dt_e`` on the box (Krylov-Schur; collective)."""
    from railvib_hpc.transient.explicit import lumped_diagonal, stability_limit

    comm = m["comm"]
    return stability_limit(m["K"], lumped_diagonal(m["M"], comm), m["C_e"], comm).dt_allowed


def explicit_run(m: dict, dt: float, steps: int) -> dict:
    """The explicit engine at the step ``dt``: seconds per step, the load's history of
    ``u_z`` (collective)."""
    from railvib_hpc.transient.explicit import ExplicitSolver, ExplicitSystem
    from railvib_hpc.transient.integrate import State, gather_values

    comm = m["comm"]
    system = ExplicitSystem(m["K"], m["M"], m["C_e"], dt, comm, dashpots=m["dashpots"])
    solver = ExplicitSolver(system, _load(m["dof"], system.dt))
    st = State(0, *(np.zeros(system.n_local) for _ in range(3)))
    uz = [0.0]
    comm.Barrier()
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step(st)
        uz.append(float(gather_values(comm, st.u, system.r0, np.array([m["dof"]]))[0]))
    comm.Barrier()
    out = {"dt": system.dt, "step_s": (time.perf_counter() - t0) / steps, "uz": np.array(uz)}
    solver.destroy()
    system.destroy()
    return out


def direct_run(m: dict, dt: float, steps: int) -> np.ndarray:
    """The direct engine (one MUMPS factor) with the same scheme, matrices and load: the
    load's ``u_z``, the check of :func:`implicit_run` (collective)."""
    from railvib_hpc.transient.integrate import DirectSolver, State, gather_values
    from railvib_hpc.transient.petsc import TransientSystem
    from railvib_hpc.transient.scheme import GeneralizedAlpha

    comm = m["comm"]
    system = TransientSystem(m["K"], m["M_k"], m["C_i"], GeneralizedAlpha.newmark(dt), comm)
    solver = DirectSolver(system, _load(m["dof"], dt))
    st = State(0, *(np.zeros(system.n_local) for _ in range(3)))
    solver.start(st)
    uz = [0.0]
    for _ in range(steps):
        solver.step(st)
        uz.append(float(gather_values(comm, st.u, system.r0, np.array([m["dof"]]))[0]))
    solver.destroy()
    system.destroy()
    return np.array(uz)


def implicit_run(m: dict, dt: float, steps: int, pc: str, rtol: float) -> dict:
    """Newmark's average acceleration at ``dt``, each step by CG with ``pc`` from the
    previous acceleration: iterations and seconds per step, the setup, the load's ``u_z``
    (collective)."""
    from petsc4py import PETSc

    comm = m["comm"]
    K, M, C = m["K"], m["M"], m["C_i"]
    t0 = time.perf_counter()
    A = K.duplicate(copy=True)
    A.scale(0.25 * dt * dt)
    A.axpy(0.5 * dt, C, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
    A.axpy(1.0, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    A.setOption(PETSc.Mat.Option.SPD, True)
    ksp = PETSc.KSP().create(comm=A.getComm())
    ksp.setOperators(A)
    ksp.setType("cg")
    ksp.getPC().setType(pc)
    if pc == "gamg":
        vecs = []
        for j in range(m["near_null"].shape[1]):
            v = A.createVecRight()
            v.getArray()[:] = m["near_null"][:, j]
            vecs.append(v)
        null = PETSc.NullSpace().create(vectors=vecs, comm=A.getComm())
        A.setNearNullSpace(null)
    ksp.setTolerances(rtol=rtol, atol=0.0, max_it=10_000)
    ksp.setInitialGuessNonzero(True)
    ksp.setUp()
    setup = time.perf_counter() - t0
    u, v, a, rhs, tmp, w = (A.createVecRight() for _ in range(6))
    r0 = A.getOwnershipRange()[0]
    load = _load(m["dof"], dt)
    uz, iters = [0.0], []
    comm.Barrier()
    t0 = time.perf_counter()
    for n in range(1, steps + 1):
        # predictors u~ = u + dt v + dt^2/4 a, v~ = v + dt/2 a (in u, v)
        u.axpy(dt, v)
        u.axpy(0.25 * dt * dt, a)
        v.axpy(0.5 * dt, a)
        K.mult(u, rhs)
        C.mult(v, tmp)
        rhs.axpy(1.0, tmp)
        rhs.scale(-1.0)
        dofs, vals = load(n)
        mine = (dofs >= r0) & (dofs < r0 + rhs.getLocalSize())
        if mine.any():
            rhs.getArray()[dofs[mine] - r0] += vals[mine]
        a.copy(w)                                      # the first guess: a_n
        ksp.solve(rhs, w)
        iters.append(ksp.getIterationNumber())
        w.copy(a)
        u.axpy(0.25 * dt * dt, a)
        v.axpy(0.5 * dt, a)
        owner = (m["dof"] >= r0) and (m["dof"] < r0 + u.getLocalSize())
        uz.append(comm.allreduce(float(u.getArray()[m["dof"] - r0]) if owner else 0.0))
    comm.Barrier()
    step_s = (time.perf_counter() - t0) / steps
    for x in (u, v, a, rhs, tmp, w, A):
        x.destroy()
    ksp.destroy()
    return {"dt": dt, "setup_s": setup, "step_s": step_s, "iterations": float(np.mean(iters[1:])),
            "iterations_max": int(max(iters)), "uz": np.array(uz)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dofs", type=float, default=3e5, help="size of the box [DOFs]")
    ap.add_argument("--multiples", type=float, nargs="+", default=[1.0, 2.0, 4.0, 8.0],
                    help="implicit steps in units of the explicit allowed step")
    ap.add_argument("--pcs", nargs="+", default=["gamg", "jacobi"])
    ap.add_argument("--rtol", type=float, default=1e-8, help="CG's relative residual")
    ap.add_argument("--time", type=float, default=0.06,
                    help="simulated time of every run [s] (the comparison at m = 1)")
    args = ap.parse_args(argv)
    from railvib_hpc.io.run_record import peak_memory_gb, reset_peak_memory
    from railvib_hpc.resources import current_memory_gb

    m = _model(args.dofs)
    comm = m["comm"]
    say = print if comm.rank == 0 else (lambda *a, **k: None)
    dt_e = explicit_step(m)
    # the explicit history covers every implicit run (each at least MIN_STEPS steps)
    steps_e = int(math.ceil(max(args.time, MIN_STEPS * max(args.multiples) * dt_e) / dt_e))
    ex = explicit_run(m, dt_e, steps_e)
    say(f"box: {m['n']:,} DOFs on {comm.size} rank(s); explicit dt_e = {dt_e:.4e} s, "
        f"{ex['step_s'] * 1e3:.2f} ms per step ({1e9 * ex['step_s'] / m['n']:.0f} ns per "
        f"DOF), {steps_e} steps")
    for epw in EPW:
        dt_acc = epw * 1.0 / (STEPS_PER_PERIOD * m["c_s"])
        say(f"  accuracy: {epw:g} elements per S wavelength resolve {m['c_s'] / epw:.1f} Hz; "
            f"{STEPS_PER_PERIOD} steps per period: dt_acc = {dt_acc:.3e} s = "
            f"{dt_acc / dt_e:.2f} dt_e")
    say(f"{'pc':>7} {'m':>4} {'dt [s]':>10} {'setup [s]':>9} {'CG its':>7} {'max':>5} "
        f"{'t_step [ms]':>11} {'x explicit':>10} {'cost/sim s':>10} {'uz vs expl':>10} "
        f"{'vs direct':>9} {'+bytes/DOF':>10}")
    for pc in args.pcs:
        for i, mult in enumerate(args.multiples):
            dt = mult * dt_e
            steps = max(MIN_STEPS, int(round(args.time / dt)))
            base = current_memory_gb()
            reset_peak_memory()
            r = implicit_run(m, dt, steps, pc, args.rtol)
            added = comm.allreduce(peak_memory_gb()[0] - base) * 1e9 / m["n"]
            # u_z at the common times against the explicit history (linear interpolation)
            t_i = np.arange(steps + 1) * dt
            t_x = np.arange(steps_e + 1) * dt_e
            ref = np.interp(t_i, t_x, ex["uz"])
            diff = np.abs(r["uz"] - ref).max() / np.abs(ex["uz"]).max()
            cost = (r["step_s"] / dt) / (ex["step_s"] / dt_e)
            check = "" if i else \
                f"{np.abs(r['uz'] - direct_run(m, dt, steps)).max() / np.abs(r['uz']).max():9.1e}"
            say(f"{pc:>7} {mult:4g} {dt:10.3e} {r['setup_s']:9.2f} {r['iterations']:7.1f} "
                f"{r['iterations_max']:5d} {r['step_s'] * 1e3:11.2f} "
                f"{r['step_s'] / ex['step_s']:10.1f} {cost:10.2f} {diff:10.2e} {check:>9} "
                f"{added:10.0f}")
    say("cost/sim s: seconds per simulated second over the explicit engine's (below 1: the "
        "implicit step is cheaper); +bytes/DOF: the implicit run's peak resident memory above "
        "the model's (K, M, C and the explicit engine's), summed over the ranks")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
