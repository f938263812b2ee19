"""The static start against the steady state of a point load moving over a half-space, at
several speeds: the sweep behind the table of ``tests/transient/test_moving_load_steady.py``.

The test tier runs one speed (0.6 c_R, the side-by-side case against STEM); this script
runs the box of :mod:`moving_load_steady` (``tests/transient/``) at each speed asked and
prints, per speed and distance, the errors in u_z and v_z against
:mod:`railvib_hpc.fem.halfspace` with the harness's derived tolerance beside them, the DOFs,
the steps and the wall time per speed.

Usage::

    python bench/moving_load_steady.py                    # 0.3, 0.6 and 0.8 c_R
    python bench/moving_load_steady.py --ratios 0.3 0.8 --out /tmp/box
    python bench/moving_load_steady.py --ratios 0.6 --spectral   # order 4, 2 m: ~7 min

``--spectral`` runs the box on the spectral soil (:data:`SPECTRAL`: order 4 on 2 m
hexahedra, 1,979,439 DOFs; docs/spectral.md has the measured table: at 0.6 c_R u_z 17.5 /
29.5 / 52.4 % and v_z 67 / 139 / 204 % at 5 / 10 / 20 m, within 1-3 points of the trilinear
soil's: the box and the start, not the element, limit it). It was a slow test; at 420 s
wall it was a fifth of the slow tier's time for a regression guard, so it lives here.

Measured (2026-12, the shared 2-core machine, one rank): 272,853 DOFs; 78-96 s per speed
alone, of which about half is the static start's MUMPS factor; the errors are those
listed in the test module's notes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "transient"))
sys.path.insert(0, str(ROOT / "tests"))

#: The spectral soil's overrides of the harness's box: 2 m hexahedra of order 4 (0.5 m
#: between GLL nodes on average), the comparison's band the grid's at 1.5 elements (6 GLL
#: points) per S wavelength.
SPECTRAL = ("mesh.order=4", "mesh.size_far=2", "mesh.size_deep=2",
            "mesh.min_elements_per_wavelength=1.5")


def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print the table; 0 when every speed ran."""
    from moving_load_steady import box_overrides, compare, format_rows, run_box, soil
    from mpi4py import MPI

    parser = argparse.ArgumentParser(
        description="the moving point load's static start against the steady state, per speed")
    parser.add_argument("--ratios", type=float, nargs="+", default=[0.3, 0.6, 0.8],
                        help="load speeds over the Rayleigh speed")
    parser.add_argument("--spectral", action="store_true",
                        help="the spectral soil (order 4 on 2 m hexahedra) instead of "
                             "the trilinear one")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for the runs (default: a temporary one)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        base = args.out or Path(scratch)
        for ratio in args.ratios:
            t0 = time.perf_counter()
            extra = SPECTRAL if args.spectral else ()
            run = run_box(base / f"box_{ratio:g}", box_overrides(ratio, extra=extra),
                          MPI.COMM_SELF)
            rows = compare(run)
            print(f"\nc = {ratio:g} c_R: {run.stats['n_dofs']:,} DOFs, "
                  f"{run.stats['n_steps']} steps of {run.stats['dt']:.3g} s, "
                  f"{time.perf_counter() - t0:.0f} s wall")
            print(format_rows(rows, soil(run.case)["c_r"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
