"""``fields.h5``: its layout and check (the fields of ``reconstruct`` and of ``transient``).

Layout (HDF5)::

    /time (ns,), /steps (ns,)             (step numbers in mbs.h5)
    /fields/{displacement,velocity,acceleration} (ns, n, 3)   float64 or float32
    /mesh/{points,hexes,hex_part}
    /stress/{von_mises,strain_eq} (n_sel, n_hex), /stress/time   (optional)
    attrs: the provenance, n_modes, n_extra (static-correction columns), stress_complete

``fields.xdmf`` / ``stress.xdmf``: temporal collections of per-step views
(``fields_views.h5``, ``stress_views.h5``; :mod:`railvib_hpc.io.xdmf`). The full-order
solution's ``fields.h5`` (``n_modes = 0``, ``solver = transient``) has this layout too.
Writers: :func:`railvib_hpc.reconstruct.fields.reconstruct_fields` and
:class:`railvib_hpc.transient.output.FieldWriter` (they stream the fields of the
distributed solution). Check: :func:`check_fields` (shapes and times; with ``full``
every field value is finite).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .checks import absent, h5_read, nonfinite

#: Steps per block when streaming ``fields.h5``.
_STEPS_PER_BLOCK = 16


def check_fields(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``fields.h5``: shapes and times; with ``full`` every field value is finite."""
    names = ("fields/displacement", "fields/velocity", "fields/acceleration")
    with h5_read(path) as f:
        missing = absent(f, ("time", "steps", *names, "mesh/points", "mesh/hexes"))
        if missing:
            return missing
        t = f["time"][()]
        out = nonfinite("time", t)
        if not out and np.any(np.diff(t) <= 0):
            out.append("time is not strictly increasing")
        n = f["mesh/points"].shape[0]
        for name in names:
            if f[name].shape != (len(t), n, 3):
                out.append(f"{name} has shape {f[name].shape}, expected ({len(t)}, {n}, 3)")
        if "stress" in f and int(f.attrs.get("stress_complete", 0)) == 1:
            for name in ("stress/von_mises", "stress/strain_eq"):
                if name in f:
                    out += nonfinite(name, f[name][()])
        if out or not full:
            return out
        for name in names:
            ds = f[name]
            for s0 in range(0, ds.shape[0], _STEPS_PER_BLOCK):
                out += nonfinite(name, ds[s0:s0 + _STEPS_PER_BLOCK])
                if out:
                    return out
    return out
