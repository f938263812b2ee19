"""``probes.h5``: its layout and check (the probe histories of ``reconstruct`` and ``transient``).

Layout (HDF5)::

    /names, /coords
    /probes/<name>/{time,displacement,velocity,acceleration}
    /rail/{time,x,y,nodes,bending_moment}

``probes/<name>.csv`` with ``t,ux,uy,uz,vx,...,az``. Writer and reader:
:func:`railvib_hpc.reconstruct.probes.write_probes_h5` and
:func:`~railvib_hpc.reconstruct.probes.read_probes`. Check: :func:`check_probes`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .checks import absent, h5_read, nonfinite


def check_probes(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``probes.h5`` (small: always completely): every history finite."""
    with h5_read(path) as f:
        missing = absent(f, ("names", "coords", "probes"))
        if missing:
            return missing
        out = []
        for name, g in f["probes"].items():
            for key in ("time", "displacement", "velocity", "acceleration"):
                if key not in g:
                    out.append(f"probes/{name}/{key} is missing")
                else:
                    out += nonfinite(f"probes/{name}/{key}", g[key][()])
        if "rail" in f:
            for key, ds in f["rail"].items():
                out += nonfinite(f"rail/{key}", ds[()])
        return out
