"""The direct path's cost on a real site, predicted from measured factors (issue 28).

Usage (under the shared lock; one size per process, so memory is its own)::

    flock /tmp/railvib-heavy.lock python bench/direct_cost_ratio.py \\
        [--dofs 0.05e6 0.1e6 0.2e6 0.4e6] [--ranks 1] [--site-dofs 8.4e6]

For every size, the soil box of ``bench/explicit_bench.py`` (the thesis subgrade in 1 m
hexahedra, 2:2:1, all five truncation faces absorbing, Rayleigh damping 3 %) is assembled
as ``railvib transient``'s direct engine does (consistent mass, C with the dashpots) and
``K_eff`` of Newmark's average acceleration is factored once with MUMPS Cholesky
(:class:`~railvib_hpc.transient.petsc.TransientSystem`): printed are the factor's entries
(MUMPS INFOG(29)), its memory (INFOG(22)), the factorisation time and the time of one step
(:class:`~railvib_hpc.transient.integrate.DirectSolver`: two triangular solves and the
products); then the explicit engine's step on the same box
(:func:`explicit_bench.one`: lumped mass, two sparse products).

Power laws ``y = a n^p`` are fitted to the measured sizes (``numpy.polyfit`` on the
logarithms) and extrapolated to the site (``--site-dofs``): the factor's memory and time,
the step of each path, and one passage (``--passage-s``) at each path's step: the direct
path's automatic step for the band (:func:`~railvib_hpc.transient.scheme.choose_time_step`
with the defaults: 20 steps per period of 80 Hz, 8 steps per 0.12 m rail element at
30 m/s), the explicit engine's at the rail's beam limit and the IMEX engine's at the soil's
(``--explicit-dt``, ``--imex-dt``: the issue's known numbers). The IMEX step is costed at
the explicit engine's step time (the implicit track and building factor is small:
docs/transient.md, IMEX cost table). These are predictions from small boxes of soil only:
the site's factor also holds the track and the building, and the fill of a nested
dissection of a box grows with its shortest side; the exponents printed say how well
the power laws fit.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

#: The issue's known steps at 80 Hz resolution: rail beam elements of 0.12 m need about
#: 2e-5 s explicitly; the soil allows 2-4e-4 s (the IMEX engine's explicit part).
EXPLICIT_DT = 2e-5
IMEX_DT = 2e-4
#: One car (18 m) passing 96.6 m of flexible track at 30 m/s, plus 0.3 s of ring-down:
#: the issue's site.
PASSAGE_S = (96.6 + 18.0) / 30.0 + 0.3


def one(n_dofs: float, steps: int) -> dict:
    """The direct path's factor and step on the box of ``n_dofs`` (collective)."""
    from explicit_bench import box, time_per_step
    from mpi4py import MPI

    from railvib_hpc.config import load_case
    from railvib_hpc.io.run_record import peak_memory_gb
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_damping, destroy_damping
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.problem import Problem

    init_petsc([])
    from railvib_hpc.transient.integrate import DirectSolver
    from railvib_hpc.transient.petsc import TransientSystem
    from railvib_hpc.transient.scheme import GeneralizedAlpha

    comm = MPI.COMM_WORLD
    case = load_case(None, [*(f"boundary.{f}=absorbing" for f in
                              ("x_min", "x_max", "y_min", "y_max", "base")),
                            "damping.model=rayleigh", "modal.damping_ratio=0.03"])
    mesh, top = box(n_dofs)
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    t0 = time.perf_counter()
    K, M, _ = assemble(mesh, problem, dofmap, comm)
    C, _ = assemble_damping(mesh, problem, dofmap, comm, K, M, dashpots=True)
    t_assembly = time.perf_counter() - t0
    system = TransientSystem(K, M, C, GeneralizedAlpha.newmark(5e-4), comm)
    entries = int(system.op.factor.getMumpsInfog(29))
    dof = int(dofmap.index[top, 2])

    def load(n: int):
        return np.array([dof]), np.array([-1e4 * np.sin(2 * np.pi * 20.0 * n * 5e-4)])

    solver = DirectSolver(system, load)
    t_step = time_per_step(solver, system.n_local, comm, steps)
    peak, _ = peak_memory_gb()
    out = {"dofs": dofmap.n_dofs, "ranks": comm.size, "assembly_s": t_assembly,
           "factor_s": system.time_factorization, "factor_entries": entries,
           "factor_gb": system.factor_memory_gb, "step_s": t_step,
           "peak_gb": comm.allreduce(peak)}
    solver.destroy()
    system.destroy()
    for A in (K, M):
        A.destroy()
    destroy_damping(C)
    return out


def _fit(n: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """``(p, a)`` of ``y = a n^p`` (least squares on the logarithms)."""
    p, log_a = np.polyfit(np.log(n), np.log(y), 1)
    return float(p), float(np.exp(log_a))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dofs", type=float, nargs="+", default=[0.05e6, 0.1e6, 0.2e6, 0.4e6])
    p.add_argument("--ranks", type=int, default=1)
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--site-dofs", type=float, default=8.4e6)
    p.add_argument("--passage-s", type=float, default=PASSAGE_S)
    p.add_argument("--explicit-dt", type=float, default=EXPLICIT_DT)
    p.add_argument("--imex-dt", type=float, default=IMEX_DT)
    p.add_argument("--one", type=float, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.one:
        from explicit_bench import one as explicit_one
        from mpi4py import MPI

        direct = one(args.one, args.steps)
        explicit = explicit_one(args.one, args.steps)
        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps({**direct, "explicit_step_s": explicit["step_s"]}))
        return
    print(f"# direct path vs explicit engine, soil boxes, {args.ranks} rank(s), "
          f"{os.cpu_count()} cores")
    print("| DOFs | factor entries | factor [GB] | factorisation [s] | direct step [s] | "
          "explicit step [s] | peak [GB] |")
    print("|---|---|---|---|---|---|---|")
    from explicit_bench import run_one

    rows = []
    for n in args.dofs:
        r, error = run_one(__file__, args.ranks, ["--one", str(n), "--steps", str(args.steps)])
        if r is None:
            print(f"| {n:.3g} | failed: {error} |")
            continue
        rows.append(r)
        print(f"| {r['dofs']:,} | {r['factor_entries']:,} | {r['factor_gb']:.2f} | "
              f"{r['factor_s']:.1f} | {r['step_s']:.4f} | {r['explicit_step_s']:.4f} | "
              f"{r['peak_gb']:.2f} |", flush=True)
    if len(rows) < 2:
        return
    predict(rows, args)


def predict(rows: list[dict], args) -> None:
    """The fits and the site's predicted costs (printed).

    The factor's entries and its time follow power laws in n (fitted; nested dissection of
    a 3-D grid: n^(4/3) and n^2). Its memory and the direct step (two triangular solves,
    bound by reading the factor) are proportional to the entries, and the explicit step to
    n: those use the measured ratios (their mean), which are robust where a fit of a few
    noisy times is not.
    """
    from railvib_hpc.transient.scheme import choose_time_step

    n = np.array([r["dofs"] for r in rows], dtype=float)
    entries = np.array([r["factor_entries"] for r in rows], dtype=float)
    p_e, a_e = _fit(n, entries)
    p_f, a_f = _fit(n, np.array([r["factor_s"] for r in rows], dtype=float))
    site = args.site_dofs
    e_site = a_e * site**p_e
    gb_per_entry = float(np.mean(np.array([r["factor_gb"] for r in rows]) / entries))
    s_per_entry = float(np.mean(np.array([r["step_s"] for r in rows]) / entries))
    s_per_dof = float(np.mean(np.array([r["explicit_step_s"] for r in rows]) / n))
    at = {"factor entries": (f"n^{p_e:.2f} (theory 4/3)", f"{e_site:.3g}"),
          "factor memory": (f"{gb_per_entry * 1e9:.1f} B per entry",
                            f"{gb_per_entry * e_site:.0f} GB"),
          "factorisation": (f"n^{p_f:.2f} (theory 2)", f"{a_f * site**p_f / 3600:.1f} h"),
          "direct step": (f"{s_per_entry * 1e9:.2f} ns per factor entry",
                          f"{s_per_entry * e_site:.1f} s"),
          "explicit step": (f"{s_per_dof * 1e9:.1f} ns per DOF", f"{s_per_dof * site:.2f} s")}
    print("\n| quantity | law (measured) | at the site |")
    print("|---|---|---|")
    for key, (law, value) in at.items():
        print(f"| {key} | {law} | {value} |")
    dt_direct = choose_time_step(80.0, 20, 1e-3, 0.12 / 30.0, 8)
    steps = {"direct": args.passage_s / dt_direct, "explicit": args.passage_s / args.explicit_dt,
             "imex": args.passage_s / args.imex_dt}
    factor_s = a_f * site**p_f
    cost = {"direct": factor_s + steps["direct"] * s_per_entry * e_site,
            "explicit": steps["explicit"] * s_per_dof * site,
            "imex": steps["imex"] * s_per_dof * site}
    print(f"\nsite: {site:,.0f} DOFs, a passage of {args.passage_s:.2f} s, {args.ranks} "
          "rank(s)")
    for name, dt in (("direct", dt_direct), ("explicit", args.explicit_dt),
                     ("imex", args.imex_dt)):
        print(f"  {name:8s} dt {dt:.3e} s, {steps[name]:9,.0f} steps, predicted "
              f"{cost[name] / 3600:8.1f} h")
    print(f"  ratio direct / imex {cost['direct'] / cost['imex']:.1f}, direct / explicit "
          f"{cost['direct'] / cost['explicit']:.2f}; the factor alone needs "
          f"{gb_per_entry * e_site / 16.0:.1f} x the 16 GB goal")


if __name__ == "__main__":
    main()
