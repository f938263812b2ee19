"""Small bare-soil boxes on spectral elements for the tests of ``railvib transient`` with
``mesh.order > 1`` (docs/spectral.md).

The box: 24 m along x (3-27 m), 8 m on either side of the path, 8 m deep, 2 m hexahedra of
the thesis subgrade with nu = 1/4, promoted to order :data:`ORDER` (352 elements, 11,050
GLL nodes at order 3), the explicit engine, one point load of ``[load]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from railvib_hpc.config import load_case

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The order of the small boxes.
ORDER = 3
#: The box (the baseline lists every key: the geometry keys, not [site]'s).
SMALL_BOX = ["track.count=0", "building.present=false", "load.force=1e5", "load.y=0",
             "materials.subgrade.nu=0.25", "damping.model=none", "mesh.layout=refined",
             "mesh.size_far=2", "mesh.size_deep=2", "modal.lumped_mass=true",
             "transient.engine=explicit", "transient.f_max=40",
             "transient.checkpoint_interval=0", "output.stress_times=[]",
             "output.dt=0.005", "track.rail_length=24", "geometry.x4=27",
             "domain.extra_depth=3.2", "geometry.ys0=8", "geometry.ys4=-8",
             "probes.line=[{name = 'r', x = 14.0, distances = [2.0, 5.0]}]"]
#: Absorbing faces with springs, the load standing at x = 10 m and moving to 16 m.
ABSORBING = [*(f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max",
                                                   "base")),
             "boundary.virtual_thickness=16", "load.start=static", "load.ramp_time=0.05",
             "load.half_width=2", "load.speed=114.7", "load.x_start=10", "load.x_end=16"]


def small_case(*overrides: str, order: int = ORDER):
    """The small box of order ``order`` with ``overrides``."""
    return load_case(BASELINE, [*SMALL_BOX, f"mesh.order={order}", *overrides])


def probes(folder: Path) -> dict[str, dict[str, np.ndarray]]:
    """``probes.h5`` of a run: name -> displacement, velocity (nt + 1, 3)."""
    from railvib_hpc.io.formats.probes import read_probes

    return {k: {q: h[q] for q in ("t", "displacement", "velocity", "acceleration")}
            for k, h in read_probes(folder / "probes.h5").items()}
