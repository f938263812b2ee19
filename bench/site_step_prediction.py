"""Predict a site's explicit step, steps and cost on the IMEX engine from its mesh alone.

For a meshed case (``railvib mesh CASE --out DIR`` first): every soil hexahedron's own
allowed step (``transient.imex.element_allowed_steps``: its largest frequency alone with
the lumped mass, its Rayleigh damping at the second-order damping velocity, 0.9 of the
critical step), the element-wise partition of ``transient.implicit_elements = "auto"``, and
the smallest step left among the explicit elements. By Irons' element eigenvalue theorem
that is a lower bound of the explicit part's limit (the engine's own Krylov-Schur limit is
at least as large). With a measured cost per step and DOF (``--ns``, e.g. from a run's
timing table) and memory per DOF (``--bytes``), it prints the passage's steps, wall time
and memory: what a site run will take before it is started.

Usage::

    railvib mesh jobs/real_site.toml --out /tmp/site80 --set mesh.wavelength_hz=80 ...
    python bench/site_step_prediction.py jobs/real_site.toml /tmp/site80 \\
        --set mesh.wavelength_hz=80 ... [--ns 175] [--bytes 2600]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from railvib_hpc.config import load_case
from railvib_hpc.mesh.mesh_io import read_mesh_h5
from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID

#: Part name of each part id.
PART_NAME = {v: k for k, v in PART_ID.items()}


def main() -> None:
    """Print the predicted step, its limiting elements and the run's cost."""
    from mpi4py import MPI

    from railvib_hpc.mesh.stage import present_parts
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.transient.explicit import STEP_SAFETY
    from railvib_hpc.transient.imex import (
        AUTO_IMPLICIT_SHARE,
        element_allowed_steps,
        implicit_part_names,
    )
    from railvib_hpc.transient.scheme import steps_for_band
    from railvib_hpc.transient.stage import _passage

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("mesh_dir", type=Path)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--ns", type=float, default=0.0,
                    help="measured cost per step and DOF [ns] (all ranks' wall time)")
    ap.add_argument("--bytes", type=float, default=0.0,
                    help="measured peak memory per DOF [bytes] (all ranks)")
    args = ap.parse_args()
    case = load_case(args.case, args.overrides)
    problem = Problem.from_case(case)
    mesh, _ = read_mesh_h5(args.mesh_dir / "mesh.h5")
    dofmap = build_dofmap(mesh, 1, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    n_dofs = dofmap.n_dofs
    _, _, run = _passage(case, mesh, dofmap)
    t_end = float(run["t_end"])

    parts = implicit_part_names(list(case["transient.implicit_parts"]), present_parts(mesh))
    explicit = ~np.isin(mesh.hex_part, [PART_ID[p] for p in parts])
    steps = element_allowed_steps(mesh, problem, STEP_SAFETY)
    tr = case["transient"]
    target = tr["dt"] if tr["dt"] > 0 else steps_for_band(tr["f_max"], tr["steps_per_period"])
    n_auto = 0
    if tr["implicit_elements"] == "auto":
        cut = min(target, float(np.quantile(steps[explicit], AUTO_IMPLICIT_SHARE)))
        auto = explicit & (steps < cut)
        n_auto = int(auto.sum())
        explicit &= ~auto
    dt = min(target, float(steps[explicit].min()))
    worst = np.flatnonzero(explicit)[np.argsort(steps[explicit])[:200]]
    edges = np.ptp(mesh.points[mesh.hexes[worst]], axis=1)
    n_steps = math.ceil(t_end / dt)
    print(f"{args.case}: {len(mesh.points):,} nodes, {len(mesh.hexes):,} hexahedra, "
          f"{n_dofs:,} DOFs")
    print(f"implicit parts: {', '.join(parts) or 'none'}; auto: {n_auto:,} elements "
          f"({AUTO_IMPLICIT_SHARE:.0%} cap); explicit: {int(explicit.sum()):,} hexahedra")
    print(f"target step {target:.4g} s; smallest explicit element step {dt:.4g} s "
          "(0.9 x critical, element-wise bound)")
    names, counts = np.unique([PART_NAME[p] for p in mesh.hex_part[worst]], return_counts=True)
    print("the 200 smallest: " + ", ".join(f"{n} {c}" for n, c in zip(names, counts))
          + f"; edges x {np.median(edges[:, 0]):.3g}, y {np.median(edges[:, 1]):.3g}, "
          f"z {np.median(edges[:, 2]):.3g} m (median)")
    q = np.quantile(steps[explicit], [0.001, 0.01, 0.1, 0.5])
    print("explicit element steps, quantiles 0.1 / 1 / 10 / 50 %: "
          + " / ".join(f"{v:.3g}" for v in q) + " s")
    print(f"passage t_end {t_end:.4g} s: {n_steps:,} steps")
    if args.ns > 0:
        wall = n_steps * args.ns * 1e-9 * n_dofs
        print(f"at {args.ns:g} ns per step and DOF: {wall / 3600:.2f} h of stepping")
    if args.bytes > 0:
        print(f"at {args.bytes:g} bytes per DOF: {args.bytes * n_dofs / 1e9:.1f} GB")
    if MPI.COMM_WORLD.size > 1:
        print("(run on one rank: the prediction is serial)")


if __name__ == "__main__":
    main()
