"""Memory per DOF and time per step per DOF of the explicit engine (issue 28's table).

Usage (under the shared lock; one configuration per process, so peak memory is its own)::

    flock /tmp/railvib-heavy.lock python bench/explicit_bench.py --dofs 0.5e6 1e6 2e6 4e6
    flock /tmp/railvib-heavy.lock python bench/explicit_bench.py --dofs 1e6 --ranks 2
    flock /tmp/railvib-heavy.lock python bench/explicit_bench.py --engine imex --dofs 1e6

``--engine imex``: the same box with a 2 m wide concrete strip (part ``slab``, one element
deep, along x through the load: a stand-in for a track) integrated implicitly
(:mod:`railvib_hpc.transient.imex`): its factor, the explicit part's limit, the step.

Each line: a box of soil (the thesis subgrade, c_S 212 m/s, in 1 m hexahedra, 2:2:1,
sized to the asked DOF count; all five truncation faces absorbing; Rayleigh damping 3 %)
with a vertical point load on the surface, through the real path: distributed assembly
(K, lumped M, C with the dashpots), the stability limit
(:func:`railvib_hpc.transient.explicit.stability_limit`), then ``--steps`` steps of
:class:`~railvib_hpc.transient.explicit.ExplicitSolver` at 0.9 of the critical step.

Printed: DOFs, ranks, assembly and stability-limit times, the step, time per step, time per
step per DOF, the stored matrix entries (K, the diagonal M and the dashpots; Rayleigh's
``alpha M + beta K`` is applied, not stored) and their bytes, peak resident memory
summed over the ranks (``VmHWM``) and per DOF, and the achieved memory traffic of the
products (12 bytes per stored entry of K and C, plus 8 per DOF for the vectors each
product reads and writes) against a STREAM-like triad measured on the same cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from railvib_hpc.problem import Problem

ROOT = Path(__file__).resolve().parents[1]


def triad_gbs(n: int = 20_000_000, repeat: int = 5) -> float:
    """Memory bandwidth of one core by ``a = b + s c`` (GB/s, best of ``repeat``)."""
    b, c = np.ones(n), np.ones(n)
    a = np.empty(n)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        np.multiply(c, 1.5, out=a)
        np.add(a, b, out=a)
        best = min(best, time.perf_counter() - t0)
    return 4 * 8 * n / best / 1e9          # (two passes: read c, write a; read a, b, write a)


def box(n_dofs: float, strip: bool = False):
    """A soil box of about ``n_dofs`` free DOFs: 2:2:1 aspect, 1 m hexahedra scaled."""
    from railvib_hpc.mesh.model import Mesh
    from railvib_hpc.schema import PART_ID

    nodes = n_dofs / 3.0
    nz = max(2, int(round((nodes / 4.0) ** (1.0 / 3.0))))
    nx = ny = 2 * nz
    h = 1.0
    xs, ys, zs = (np.arange(k + 1) * h for k in (nx, ny, nz))
    X, Y, Z = np.meshgrid(xs, ys, -zs[::-1], indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    idx = np.arange(pts.shape[0]).reshape(nx + 1, ny + 1, nz + 1)
    c = idx[:-1, :-1, :-1].ravel()
    sx, sy = (ny + 1) * (nz + 1), nz + 1
    hexes = np.stack([c, c + sx, c + sx + sy, c + sy,
                      c + 1, c + sx + 1, c + sx + sy + 1, c + sy + 1], axis=1)
    part = np.full(len(hexes), PART_ID["subgrade"])
    if strip:       # the top layer of a 2-element-wide strip along x through the centre
        centre = pts[hexes].mean(axis=1)
        on = ((np.abs(centre[:, 1] - 0.5 * ny * h) < h) & (centre[:, 2] > -h)
              & (centre[:, 0] > h) & (centre[:, 0] < (nx - 1) * h))   # (soil at the faces)
        part[on] = PART_ID["slab"]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    sets = {"bottom": np.flatnonzero(np.isclose(pts[:, 2], lo[2])),
            "x_faces": np.flatnonzero(np.isclose(pts[:, 0], lo[0]) | np.isclose(pts[:, 0], hi[0])),
            "y_faces": np.flatnonzero(np.isclose(pts[:, 1], lo[1]) | np.isclose(pts[:, 1], hi[1]))}
    mesh = Mesh(points=pts, hexes=hexes.astype(np.int64), hex_part=part.astype(np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets=sets)
    top = int(idx[nx // 2, ny // 2, nz])
    return mesh, top


def time_per_step(solver, n_local: int, comm, steps: int) -> float:
    """Seconds per step of ``solver`` from rest, after one warm-up step (collective)."""
    from railvib_hpc.transient.integrate import State

    st = State(0, *(np.zeros(n_local) for _ in range(3)))
    solver.step(st)                                      # (warm-up)
    comm.Barrier()
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step(st)
    comm.Barrier()
    return (time.perf_counter() - t0) / steps


def one(n_dofs: float, steps: int, engine: str = "explicit") -> dict:
    """One configuration in this process (collective)."""
    from mpi4py import MPI

    from railvib_hpc.config import load_case
    from railvib_hpc.io.run_record import peak_memory_gb
    from railvib_hpc.model.boundary import constraint_rules, dashpot_diagonal, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import (
        assemble,
        assemble_damping,
        assemble_partition,
        destroy_damping,
        rayleigh_operator,
        rayleigh_parts,
    )
    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    from railvib_hpc.transient.explicit import (
        STEP_SAFETY,
        ExplicitSolver,
        ExplicitSystem,
        lumped_diagonal,
        stability_limit,
    )
    from railvib_hpc.transient.imex import DAMPING_STABILITY_FACTOR, ImexSystem
    from railvib_hpc.transient.integrate import DirectSolver

    comm = MPI.COMM_WORLD
    case = load_case(None, [*(f"boundary.{f}=absorbing" for f in
                              ("x_min", "x_max", "y_min", "y_max", "base")),
                            "modal.lumped_mass=true", "damping.model=rayleigh",
                            "modal.damping_ratio=0.03"])
    t0 = time.perf_counter()
    imex = engine == "imex"
    mesh, top = box(n_dofs, strip=imex)
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm, mass="diagonal")
    # as the stage does: Rayleigh damping applied around K; the dashpots stored alone
    # (IMEX: implicit in its partition) or, explicit, a diagonal taken at the full step
    dashpots = None if imex else dashpot_diagonal(mesh, problem, dofmap, comm.rank)
    C, _ = rayleigh_operator(mesh, problem, dofmap, comm, K, lumped_diagonal(M, comm),
                             dashpots=dashpots is None)
    if C is None:
        C, _ = assemble_damping(mesh, problem, dofmap, comm, K, M, dashpots=dashpots is None)
    partition = assemble_partition(mesh, problem, dofmap, comm, ("slab",)) if imex else None
    t_assembly = time.perf_counter() - t0
    t0 = time.perf_counter()
    lim = stability_limit(K, lumped_diagonal(M, comm), C, comm, minus=partition,
                          damping_factor=DAMPING_STABILITY_FACTOR if imex else 1.0)
    dt = lim.dt_allowed
    t_limit = time.perf_counter() - t0
    t0 = time.perf_counter()
    system = (ImexSystem(K, M, C, *partition, dt, comm) if imex
              else ExplicitSystem(K, M, C, dt, comm, dashpots=dashpots))
    t_factor = time.perf_counter() - t0
    dof = int(dofmap.index[top, 2])

    def load(n: int):
        return np.array([dof]), np.array([-1e4 * np.sin(2 * np.pi * 20.0 * n * system.dt)])

    solver = DirectSolver(system, load) if imex else ExplicitSolver(system, load)
    t_steps = time_per_step(solver, system.n_local, comm, steps)
    ray = rayleigh_parts(C)
    stored = [K, M, *([C] if ray is None else [ray.C_b])]
    nnz = sum(A.getInfo()["nz_used"] for A in stored)              # (summed over the ranks)
    implicit_rows = system.implicit_rows if imex else 0
    factor_gb = system.factor_memory_gb
    peak, _ = peak_memory_gb()
    peak = comm.allreduce(peak)
    n = dofmap.n_dofs
    traffic = (12.0 * nnz + 2 * 2 * 8.0 * n + 10 * 8.0 * n) / t_steps / 1e9
    solver.destroy()
    system.destroy()
    for A in (K, M):
        A.destroy()
    destroy_damping(C)
    return {"dofs": n, "ranks": comm.size, "assembly_s": t_assembly, "limit_s": t_limit,
            "factor_s": t_factor, "implicit_rows": implicit_rows, "factor_gb": factor_gb,
            "limit_iterations": lim.iterations, "dt": dt,
            "dt_mode": STEP_SAFETY * lim.dt_mode, "step_s": t_steps,
            "step_ns_per_dof": 1e9 * t_steps / n, "nnz": int(nnz),
            "matrix_gb": 12.0 * nnz / 1e9, "peak_gb": peak, "bytes_per_dof": peak * 1e9 / n,
            "traffic_gbs": traffic}


def run_one(script: str, ranks: int, argv: list[str]) -> tuple[dict | None, str]:
    """``script argv`` under ``mpirun -n ranks`` in its own processes (so its peak memory is
    its own): the dict its rank 0 printed after ``RESULT``, or None and the error's tail."""
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), sys.executable, script, *argv]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode or not line:
        return None, proc.stderr.strip()[-300:]
    return json.loads(line[0][7:]), ""


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dofs", type=float, nargs="+", default=[0.5e6, 1e6, 2e6, 4e6])
    p.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--engine", choices=("explicit", "imex"), default="explicit")
    p.add_argument("--json", help="append each result as a JSON line to this file (input of "
                   "bench/transient_scaling_model.py --measured)")
    p.add_argument("--one", type=float, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.one:
        out = one(args.one, args.steps, args.engine)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps(out))
        return
    bw = triad_gbs()
    print(f"# engine {args.engine}; one-core triad bandwidth {bw:.1f} GB/s; "
          f"{os.cpu_count()} cores")
    print("| DOFs | ranks | assembly [s] | limit [s] (its.) | factor [s] (implicit rows, GB) | "
          "dt [s] (largest mode's own) | step [s] | step / DOF [ns] | K + C entries | "
          "matrices [GB] | peak [GB] | "
          "peak / DOF [B] | traffic [GB/s] | of ranks x triad |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in args.dofs:
        for ranks in args.ranks:
            r, error = run_one(__file__, ranks, ["--one", str(n), "--steps", str(args.steps),
                                                 "--engine", args.engine])
            if r is None:
                print(f"| {n:.3g} | {ranks} | failed: {error} |")
                continue
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps({**r, "engine": args.engine,
                                        "triad_fraction": r["traffic_gbs"] / bw}) + "\n")
            print(f"| {r['dofs']:,} | {ranks} | {r['assembly_s']:.1f} | {r['limit_s']:.1f} "
                  f"({r['limit_iterations']}) | {r['factor_s']:.1f} ({r['implicit_rows']:,}, "
                  f"{r['factor_gb']:.2f}) | {r['dt']:.3e} ({r['dt_mode']:.3e}) | "
                  f"{r['step_s']:.4f} | "
                  f"{r['step_ns_per_dof']:.1f} | {r['nnz']:,} | {r['matrix_gb']:.2f} | "
                  f"{r['peak_gb']:.2f} | {r['bytes_per_dof']:.0f} | {r['traffic_gbs']:.1f} | "
                  f"{r['traffic_gbs'] / (ranks * bw):.0%} |", flush=True)


if __name__ == "__main__":
    main()
