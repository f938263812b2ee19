"""The perfectly matched layer's verification table and its cost (issue 29, item 2).

Usage (a few minutes; on 1 or N ranks; rank 0 prints markdown)::

    [mpirun -n 2] .venv/bin/python bench/pml_verification.py [--elements 5 8] [--skip-oblique]
        [--skip-cost] [--cost-inside 20 20 10] [--engine explicit|direct]

(a) Oblique incidence: plane-strain P and SV line sources, reflected energy over the
    incident at 0, 31, 45 and 60 degrees for layers of ``--elements`` elements, on the
    homogeneous and the two-layer site, and a fixed base for contrast (the models of
    tests/transient/test_pml_oblique.py).
(b) Cost: a 3-D soil box of 1 m hexahedra whose inside is ``--cost-inside`` with a
    5-element PML on its four sides and its base, against the same inside box with
    Lysmer-Kuhlemeyer dashpots on those faces: DOFs, layer elements, allowed step, time per
    step and time per step per DOF (on the ranks it runs on). ``--engine direct``: the
    direct engine instead (one Cholesky factor, the layer implicit), both boxes at
    :data:`DIRECT_STEP`.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "transient"), str(ROOT / "tests" / "fem"), str(ROOT)]

from mpi4py import MPI  # noqa: E402
from pml_cases import run_box  # noqa: E402
from test_pml_oblique import ANGLES, HOMOGENEOUS, LAYERED, reflection_energy  # noqa: E402
from wave_cases import box_mesh  # noqa: E402

COMM = MPI.COMM_WORLD
#: Faces that absorb in the cost comparison (the top is free).
ABSORBING = ("x_min", "x_max", "y_min", "y_max", "base")
#: Signal time stepped in the cost comparison [s] (about 60-100 steps of 1 m hexahedra).
COST_TIME = 0.15
#: The direct engine's step in the cost comparison [s] (83 steps per period of the 12 Hz
#: Ricker, as in tests/transient/test_pml_direct.py).
DIRECT_STEP = 1e-3


def section_oblique(elements: list[int]) -> list[str]:
    """The reflected-energy table."""
    head = " | ".join(f"{k} {a:.0f}°" for k in ("P", "SV") for a in ANGLES)
    out = ["## (a) Oblique incidence: reflected / incident energy", "",
           f"| site | layer | {head} |", "|---|---|" + "---|" * 2 * len(ANGLES)]
    rows = [(site, n) for site in (HOMOGENEOUS, LAYERED) for n in elements]
    rows.append((HOMOGENEOUS, 0))
    for site, n in rows:
        values = []
        for kind in ("P", "SV"):
            r = reflection_energy(kind, layer=n, site=site, comm_=COMM)
            values += [f"{x:.2e}" for x in r["R_E"]]
        name = "two-layer" if site.layered else "homogeneous"
        label = f"{n} elements" if n else "fixed base"
        out.append(f"| {name} | {label} | " + " | ".join(values) + " |")
    r = reflection_energy("P", site=HOMOGENEOUS, comm_=COMM)
    out += ["", f"Angles (nearest nodes): {', '.join(f'{a:.2f}' for a in r['angles'])} deg; "
            f"DOFs box / reference {r['dofs'][0]:,} / {r['dofs'][1]:,}; {r['steps']} steps "
            f"to {r['t_end']:.3f} s.", ""]
    return out


def _cost_run(inside, pml: bool, engine: str = "explicit") -> dict:
    layer = 5 if pml else 0
    n = (inside[0] + 2 * layer, inside[1] + 2 * layer, inside[2] + layer)
    mesh = box_mesh(n, tuple(float(k) for k in n), (-layer, -layer, -layer))
    centre = np.array([inside[0] / 2, inside[1] / 2, float(inside[2])])
    faces = {f: "pml" if pml else "absorbing" for f in ABSORBING}
    out = run_box(mesh, faces, float(layer), (centre, 2, 1e6), centre[None, :], COST_TIME,
                  12.0, COMM, direct=DIRECT_STEP if engine == "direct" else None)
    out["elements"] = int(np.prod(n))
    return out


def section_cost(inside, engine: str = "explicit") -> list[str]:
    """PML box vs dashpot box with the same inside."""
    step = "each run's allowed step" if engine == "explicit" else f"{DIRECT_STEP:g} s"
    out = [f"## (b) Cost: the same inside box with a PML or with dashpots ({engine} engine)",
           "", f"Inside {inside[0]} x {inside[1]} x {inside[2]} m of 1 m hexahedra, "
           f"{COMM.size} rank(s), {COST_TIME} s stepped at {step}.", "",
           "| faces | DOFs | layer elements | dt [s] | time/step [s] | time/step/DOF [s] |",
           "|---|---|---|---|---|---|"]
    runs = {}
    for pml in (False, True):
        r = _cost_run(inside, pml, engine)
        runs[pml] = r
        name = "PML, 5 elements" if pml else "dashpots"
        out.append(f"| {name} | {r['dofs']:,} | {r['pml_elements']:,} | {r['dt']:.3e} | "
                   f"{r['time_per_step']:.4f} | {r['time_per_step'] / r['dofs']:.2e} |")
    a, b = runs[False], runs[True]
    out += ["", f"PML / dashpots: DOFs x{b['dofs'] / a['dofs']:.2f}, time per step "
            f"x{b['time_per_step'] / a['time_per_step']:.2f}, steps per second of signal "
            f"x{a['dt'] / b['dt']:.2f}.", ""]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--elements", type=int, nargs="+", default=[5, 8])
    p.add_argument("--cost-inside", type=int, nargs=3, default=[20, 20, 10])
    p.add_argument("--skip-oblique", action="store_true")
    p.add_argument("--skip-cost", action="store_true")
    p.add_argument("--engine", choices=("explicit", "direct"), default="explicit")
    args = p.parse_args(argv)
    lines = ["# Perfectly matched layer: verification and cost", ""]
    if not args.skip_oblique:
        lines += section_oblique(args.elements)
    if not args.skip_cost:
        lines += section_cost(args.cost_inside, args.engine)
    if COMM.rank == 0:
        print("\n".join(lines), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
