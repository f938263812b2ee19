"""The absorbing faces' springs against the half-space's static stiffness (issue 28, item 7).

Below the Rayleigh speed a moving load's field is nearly quasi-static, so a truncated box
must give the static compliance of the half-space it stands for: the springs of
``boundary.virtual_thickness = t`` (``(lambda + 2 G) / t`` normal and ``G / t`` tangential
per unit area, :mod:`railvib_hpc.model.boundary`) carry the soil beyond the faces. This
bench measures which ``t`` does that, independently of the dynamic test that chose
``t = 36 m`` (``tests/transient/test_moving_load_halfspace.py``): the same box (half of the
half-space, ``y >= 0`` on a roller, 1 m cubes 96 x 36 x 30, thesis subgrade with
``nu = 1/4``), the same spread load (``+-3 m``), standing still at the dynamic test's
receiver section ``x = 72 m``; the static surface settlement at ``d`` beside the load
against Boussinesq's ``w = P (1 - nu) / (2 pi G r)`` summed over the spreading. One
static solve per ``t`` (the explicit engines' static start: a MUMPS factor where it fits,
else CG with smoothed-aggregation multigrid and the rigid-body modes), and one with the
four faces and the base fixed.

Usage::

    python bench/spring_static_study.py [--thickness 6 12 24 36 48 72] [--h 1.0]
        [--size 96 36 30] [--x-load 72] [--receivers 2 4 8 12] [--half-width 3]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "transient"), str(ROOT / "tests" / "fem"), str(ROOT)]

#: Full load [N] (half of it on the half model), as the dynamic test's.
FORCE = 1e5
#: The faces of the box that carry springs (``y_min`` is the symmetry plane's roller).
FACES = ("x_min", "x_max", "y_max", "base")


def boussinesq(d: float, offsets: np.ndarray, share: np.ndarray, mu: float, nu: float) -> float:
    """Surface settlement ``d`` beside a load ``FORCE`` spread along x (``offsets``, ``share``)
    on a half-space (Boussinesq 1885: ``P (1 - nu) / (2 pi G r)`` per point load)."""
    r = np.hypot(offsets, d)
    return float(FORCE * (1 - nu) / (2 * math.pi * mu) * (share / r).sum())


def settlements(comm, mesh, faces: str, thickness: float, nu: float, path, receivers: list[int]
                ) -> tuple[np.ndarray, str]:
    """Static downward settlement at the ``receivers`` nodes with the faces ``faces``
    ('absorbing' with springs of ``thickness``, or 'fixed'), and how it was solved (the
    explicit engines' static start: :meth:`ExplicitSystem.solve_matrix`)."""
    from wave_cases import soil_case

    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap, rigid_body_modes
    from railvib_hpc.model.petsc import assemble
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.explicit import ExplicitSystem
    from railvib_hpc.transient.integrate import gather_values
    from railvib_hpc.transient.surface_load import MovingSurfaceLoad

    case = soil_case(f"materials.subgrade.nu={nu}", "damping.model=none",
                     "modal.lumped_mass=true", "boundary.y_min=roller",
                     *[f"boundary.{f}={faces}" for f in FACES],
                     f"boundary.virtual_thickness={thickness if faces == 'absorbing' else 0}")
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm, mass="diagonal")
    system = ExplicitSystem(K, M, None, 0.0, comm)
    system.near_null = lambda: rigid_body_modes(mesh.points, dofmap, comm.rank)
    f = np.zeros((system.n_local, 1))
    dofs, values = MovingSurfaceLoad(mesh, dofmap.index, path, 1.0, 0)(0)
    own = (dofs >= system.r0) & (dofs < system.r1)
    np.add.at(f[:, 0], dofs[own] - system.r0, values[own])
    u = system.solve_matrix(K, f)[:, 0]
    w = -gather_values(comm, u, system.r0, dofmap.index[receivers, 2])
    how = system.static_method
    system.destroy()
    for A in (K, M):
        A.destroy()
    return w, how


def main() -> None:
    """Print the settlement error of each spring thickness at each receiver."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--thickness", type=float, nargs="+", default=[6, 12, 24, 36, 48, 72])
    ap.add_argument("--h", type=float, default=1.0)
    ap.add_argument("--size", type=float, nargs=3, default=[96.0, 36.0, 30.0])
    ap.add_argument("--x-load", type=float, default=72.0)
    ap.add_argument("--receivers", type=float, nargs="+", default=[2.0, 4.0, 8.0, 12.0])
    ap.add_argument("--half-width", type=float, default=3.0)
    ap.add_argument("--nu", type=float, default=0.25)
    args = ap.parse_args()

    from mpi4py import MPI
    from wave_cases import box_mesh, soil_case

    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.surface_load import SPREAD_SPACING, SurfaceLoadPath, spreading

    init_petsc([])
    comm = MPI.COMM_WORLD
    h = args.h
    n = tuple(int(round(s / h)) for s in args.size)
    mesh = box_mesh(n, tuple(args.size), origin=(0.0, 0.0, -args.size[2]))
    top = np.isclose(mesh.points[:, 2], 0.0)
    rec = [int(np.flatnonzero(top & np.isclose(mesh.points[:, 0], args.x_load)
                              & np.isclose(mesh.points[:, 1], d))[0]) for d in args.receivers]
    path = SurfaceLoadPath(forces=np.array([0.5 * FORCE]), offsets=np.zeros(1),
                           x_start=args.x_load, y=0.0, speed=0.0, ramp_time=0.0,
                           half_width=args.half_width)
    mat = soil_case()["materials.subgrade"]
    mu = mat["E"] / (2 * (1 + args.nu))
    offsets, share = spreading(args.half_width, SPREAD_SPACING * h)
    ref = np.array([boussinesq(d, offsets, share, mu, args.nu) for d in args.receivers])
    dist = {"x_min": args.x_load, "x_max": args.size[0] - args.x_load,
            "y_max": args.size[1], "base": args.size[2]}
    if comm.rank == 0:
        print(f"box {args.size[0]:g} x {args.size[1]:g} x {args.size[2]:g} m of {h:g} m cubes "
              f"({len(mesh.points) * 3:,} DOFs), nu = {args.nu:g}, G = {mu:.4g} Pa; load "
              f"spread +-{args.half_width:g} m at x = {args.x_load:g} m; the faces' distances "
              "from it: " + ", ".join(f"{k} {v:g} m" for k, v in dist.items()))
        print("Boussinesq settlement [m]: " + ", ".join(
            f"{d:g} m {w:.4e}" for d, w in zip(args.receivers, ref)))
        head = " | ".join(f"{d:g} m" for d in args.receivers)
        print(f"| faces | {head} | solved by |")
        print("|---|" + "---|" * (len(args.receivers) + 1))
    rows = [("fixed", 0.0)] + [("absorbing", t) for t in args.thickness]
    for faces, t in rows:
        w, how = settlements(comm, mesh, faces, t, args.nu, path, rec)
        if comm.rank == 0:
            err = " | ".join(f"{100 * (a / b - 1):+.1f} %" for a, b in zip(w, ref))
            name = "fixed" if faces == "fixed" else f"springs t = {t:g} m"
            print(f"| {name} | {err} | {how} |", flush=True)


if __name__ == "__main__":
    main()
