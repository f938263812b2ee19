"""``static.h5``: its layout and check (the modal stage's static fields of the static correction).

Layout (HDF5, with ``mbs.static_correction = true``; written collectively): for a unit
load on each of the k rail DOFs (``w`` and ``ry`` of every flexible-rail node of both
rails, column ``(rail * nodes + node) * 2 + component``)::

    /static/rail_flexibility (k, k)  K^-1 on the rail DOFs (zero rows and columns where
                                     constrained)
    /static/translation (k, n, 3)    the static displacement of every node
    /static/residual_mass (k, k)     X'^T M X' of those fields with the modes of modes.h5
                                     taken out (the residual modes' mass)
    /static/load_dofs (k, 3)         rail index, node id, component (0 w, 1 ry)
    attrs: the provenance (its upstream_sha256 names the modes.h5 it belongs to)

Writer: :func:`railvib_hpc.modal.static.write_static` (it takes the mesh and the DOF map
of the modal stage). Check: :func:`check_static`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .checks import absent, h5_read, nonfinite


def check_static(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``static.h5``: finite, symmetric rail flexibility with a non-negative diagonal, and
    the static fields' mass matrix."""
    with h5_read(path) as f:
        missing = absent(f, ("static/rail_flexibility", "static/translation",
                            "static/load_dofs", "static/residual_mass"))
        if missing:
            return missing
        x = f["static/rail_flexibility"][()]
        out = nonfinite("static/rail_flexibility", x)
        if not out and (x.ndim != 2 or x.shape[0] != x.shape[1] or np.any(np.diag(x) < 0)
                        or not np.allclose(x, x.T, rtol=1e-8,
                                           atol=1e-12 * float(np.abs(x).max() or 1))):
            out.append("static/rail_flexibility is not a symmetric flexibility matrix")
        mass = f["static/residual_mass"][()]
        if not out:
            out += nonfinite("static/residual_mass", mass)
        if not out and (mass.shape != x.shape or np.any(np.diag(mass) < 0)):
            out.append("static/residual_mass is not a mass matrix of the rail DOFs' static "
                       "fields")
        if full and not out:
            t = f["static/translation"]
            for k in range(0, t.shape[0], 64):
                out += nonfinite("static/translation", t[k:k + 64])
                if out:
                    break
    return out
