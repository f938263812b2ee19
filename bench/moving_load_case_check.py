"""The free field of a case with a moving surface load against the half-space's steady state.

For the results of ``railvib transient`` of a case without a track (``track.count = 0``,
``[load]``; e.g. ``jobs/moving_load_halfspace.toml``): the vertical surface velocity of
every free-field probe-line point (``[[probes.line]]``, role ``free_field``) against the
steady state of the load moving over an elastic half-space of the top soil
(:func:`railvib_hpc.fem.halfspace.moving_load_velocity`, convolved with the load's
spreading, summed over the loads), as ``tests/transient/test_moving_load_halfspace.py``
does on its hand-built box: the largest downward velocity while the leading load
approaches the point (``0 < xi <= 2 d``, ``d`` its distance from the path), FE over the
reference, minus 1; then where in that window the FE maximum and the reference's maximum
lie (``xi FE``, ``xi peak``: the load's distance ahead of the point, m) and the FE velocity
at the reference's maximum over it, minus 1 (``at peak``). Where the two positions differ
by more than ``d / 2`` the FE maximum belongs to something else (the switch-on's Rayleigh
pulse, a reflection; flagged) and only ``at peak`` measures the field. The reference holds
for a homogeneous, undamped soil below the Rayleigh speed, after the switch-on's pulse has
passed and before reflections arrive.

Usage::

    python bench/moving_load_case_check.py CASE.toml RESULTS_DIR [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from railvib_hpc.config import load_case
from railvib_hpc.fem.halfspace import moving_load_velocity
from railvib_hpc.io.formats.probes import read_probes
from railvib_hpc.mesh.mesh_io import read_mesh_h5
from railvib_hpc.site import soil_layers
from railvib_hpc.transient.surface_load import SPREAD_SPACING, spreading

#: Approach window: the load between 2 d and 0 ahead of a point d from the path (the
#: window of tests/transient/test_moving_load_halfspace.py).
WINDOW_DISTANCES = 2.0


def main() -> None:
    """Print the approach-peak error of every free-field point."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("results", type=Path)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    args = ap.parse_args()
    case = load_case(args.case, args.overrides)
    ld = case["load"]
    top = soil_layers(case)[0] if soil_layers(case) else None
    if top is not None:
        nu, rho, c_s = top["nu"], top["rho"], top["c_s"]
    else:
        m = case["materials.subgrade"]
        nu, rho = m["nu"], m["rho"]
        c_s = math.sqrt(m["E"] / (2 * (1 + nu)) / rho)
    mu = rho * c_s**2
    hist = read_probes(args.results / "probes.h5")
    mesh, _ = read_mesh_h5(args.results / "mesh.h5")
    edges = np.diff(np.unique(np.round(mesh.points[:, 0], 9)))       # as MovingSurfaceLoad
    spacing = SPREAD_SPACING * (float(edges.min()) if edges.size else 1.0)
    offsets, share = spreading(ld["half_width"], spacing)
    print(f"load {ld['force']:g} N at {ld['speed']:g} m/s on y = {ld['y']:g} m; soil c_S "
          f"{c_s:.1f} m/s, nu {nu:g}")
    print(f"  {'probe':12s} {'d [m]':>6s} {'FE peak':>11s} {'steady':>11s} {'error':>8s} "
          f"{'xi FE':>8s} {'xi peak':>8s} {'at peak':>9s}")
    for name, h in hist.items():
        if h["role"] != "free_field":
            continue
        x, y = float(h["coords"][0]), float(h["coords"][1])
        d = abs(y - ld["y"])
        lead = ld["x_start"] + ld["speed"] * h["t"]
        xi = x - lead
        window = (xi > 0) & (xi <= WINDOW_DISTANCES * d)
        if not window.any() or d == 0:
            print(f"  {name:12s} {d:6.2f}   (the load does not approach it in the run)")
            continue
        exact = sum(ld["force"] * moving_load_velocity(
            (xi[window] - o)[:, None] - offsets[None, :], d, 1.0, mu, nu, c_s,
            ld["speed"]) @ share for o in ld["offsets"])
        fe = -h["velocity"][window, 2]
        err = fe.max() / exact.max() - 1.0
        i_fe, i_ref = int(np.argmax(fe)), int(np.argmax(exact))
        at_peak = fe[i_ref] / exact[i_ref] - 1.0
        xw = xi[window]
        # the FE maximum far from the steady state's: something else (the switch-on's
        # pulse, a reflection) set it, and the window's error says nothing of the field
        flag = "" if abs(xw[i_fe] - xw[i_ref]) <= 0.5 * d else "  <- FE max not at the peak"
        print(f"  {name:12s} {d:6.2f} {fe.max():11.4e} {exact.max():11.4e} {err:+8.2%} "
              f"{xw[i_fe]:8.2f} {xw[i_ref]:8.2f} {at_peak:+9.2%}{flag}")


if __name__ == "__main__":
    main()
