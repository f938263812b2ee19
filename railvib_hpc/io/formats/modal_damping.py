"""``modal_damping.h5``: its layout, writer, reader and check (``modal.damping = 'full'``).

Layout (HDF5, rank 0; the parts of the damping matrix projected on the modes, and on the
static fields with the static correction: :mod:`railvib_hpc.modal.projection`)::

    /dashpots (m, m)                       Phi^T C_dashpots Phi of the absorbing faces
    /pads (m, m)                           Phi^T C_pads Phi of the rail pads' dashpots
    /mass/<group>, /stiffness/<group>      Phi^T M_g Phi, Phi^T K_g Phi of every material
                                           group (per-material Rayleigh)
    attrs: the provenance (upstream mesh.h5 and modes.h5)

Writer :func:`write_damping_parts`, reader :func:`read_damping_parts`, check
:func:`check_modal_damping`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .checks import absent, h5_read, nonfinite


def check_modal_damping(path: Path, full: bool = True,
                        context: Mapping[str, Any] | None = None) -> list[str]:
    """``modal_damping.h5``: the dashpot and pad parts, every part square, symmetric and
    finite, all of one size."""
    with h5_read(path) as f:
        missing = absent(f, ("dashpots", "pads"))
        if missing:
            return missing
        parts: dict = {}
        f.visititems(lambda name, obj: parts.__setitem__(name, obj)
                     if hasattr(obj, "shape") else None)
        size = f["dashpots"].shape
        out: list[str] = []
        for name, d in parts.items():
            if d.ndim != 2 or d.shape[0] != d.shape[1] or d.shape != size:
                out.append(f"{name} has shape {d.shape}, the dashpots {size}")
                break
            if full:
                a = d[()]
                out += nonfinite(name, a)
                if not out and not np.allclose(a, a.T, rtol=1e-8,
                                               atol=1e-12 * float(np.abs(a).max() or 1)):
                    out.append(f"{name} is not symmetric")
                if out:
                    break
    return out


def write_damping_parts(path: Path, parts: dict[str, np.ndarray], attrs: dict) -> str:
    """Write ``modal_damping.h5`` (rank 0; checked, atomic, recorded); returns its digest.

    ``attrs``: its provenance (:func:`railvib_hpc.io.provenance.provenance`, upstream
    ``mesh.h5`` and ``modes.h5``).
    """
    from ..atomic import write_h5

    def fill(f, parallel: bool) -> None:
        for name, value in parts.items():
            f.create_dataset(name, data=value)

    size = sum(int(v.nbytes) for v in parts.values())
    return write_h5(path, None, fill, size_hint=size, attrs=attrs,
                    check=lambda tmp: check_modal_damping(tmp, True))


def read_damping_parts(path: Path) -> dict[str, np.ndarray]:
    """Every projected part of a ``modal_damping.h5`` (verified by the caller)."""
    import h5py

    out: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()])
                     if hasattr(obj, "shape") else None)
    return out
