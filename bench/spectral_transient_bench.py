"""The spectral soil as ``railvib transient`` runs it: bytes held per DOF and ns per DOF and
step of the whole explicit step (kernel, damping, dashpots, springs, interface sum, load,
probes, guard, fields), next to the kernel's share, on a bare-soil box.

Usage::

    python bench/spectral_transient_bench.py                       # order 4, 2 m, 1 rank
    python bench/spectral_transient_bench.py --orders 2 4 6 --size 3
    mpirun -n 2 python bench/spectral_transient_bench.py --orders 4

The box is the moving-load box of ``tests/transient/moving_load_steady.py`` (60 m along x,
+-35 m, 20 m deep, absorbing faces with springs, the thesis subgrade at nu = 1/4, the load
at 0.6 c_R switched on over 0.01 s: no static start) at ``--size`` m hexahedra of order
N, for ``--duration`` s of simulated time at 0.9 of the stable step. Printed per order:
free DOFs, the step, ns per DOF and step of the loop and of its kernel calls (summed
over the ranks: core-ns), and the bytes held per DOF: this rank's operator, state, mass, damping,
springs and holds (``B/DOF held``), and the whole GLL node set every rank builds
(``B/DOF node set``; summed over the ranks).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "transient"), str(ROOT)]


def run(order: int, size: float, duration: float, comm) -> dict:
    """One ``railvib transient`` of the box; returns its statistics."""
    from moving_load_steady import BASELINE, box_overrides

    from railvib_hpc.config import load_case
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    extra = (f"mesh.order={order}", f"mesh.size_far={size}", f"mesh.size_deep={size}",
             "mesh.min_elements_per_wavelength=1.5", "load.start=ramp",
             "load.ramp_time=0.01", "load.x_end=18.5", f"load.t_after={duration}",
             "output.dt=0.01")
    case = load_case(BASELINE, box_overrides(0.6, extra=extra))
    folder = tempfile.mkdtemp(prefix="spectral-bench-") if comm.rank == 0 else None
    folder = Path(comm.bcast(folder, root=0))
    t0 = time.perf_counter()
    stats = run_transient_stage(case, folder, comm, Reporter(comm.rank))
    stats["wall"] = time.perf_counter() - t0
    return stats


def main(argv=None) -> None:
    from mpi4py import MPI

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--orders", type=int, nargs="+", default=[4])
    ap.add_argument("--size", type=float, default=2.0, help="hexahedron edge [m]")
    ap.add_argument("--duration", type=float, default=0.05,
                    help="simulated time after the load's 0.5 m [s]")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    rows = [(n, run(n, args.size, args.duration, comm)) for n in args.orders]
    if comm.rank:
        return
    print("\n| order | edge [m] | free DOFs | ranks | steps | dt [s] | ns/DOF/step (loop) | "
          "of which acceleration (kernel, damping, springs, interface sum) | B/DOF held | "
          "B/DOF node set | wall [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n, s in rows:
        print(f"| {n} | {args.size:g} | {s['n_dofs']:,} | {s['ranks']} | {s['n_steps']} | "
              f"{s['dt']:.3e} | {s['ns_per_dof_step']:.1f} | "
              f"{s['kernel_ns_per_dof_step']:.1f} | {s['bytes_per_dof']:.1f} | "
              f"{s['node_set_bytes_per_dof']:.1f} | {s['wall']:.1f} |")


if __name__ == "__main__":
    main()
