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

Writer: :func:`write_static_h5` (the arrays; :func:`railvib_hpc.modal.static.write_static`
forms them from the modal stage's mesh and DOF map). Reader: :func:`read_rail_statics`
(``K^-1`` on the rail DOFs and the residual mass, for the passage). Check:
:func:`check_static`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..atomic import write_h5
from .checks import absent, h5_read, nonfinite

if TYPE_CHECKING:
    from mpi4py import MPI


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


def write_static_h5(path: Path, comm: MPI.Comm, n_nodes: int, flex: np.ndarray,
                    mass: np.ndarray, table: np.ndarray, translation: np.ndarray, nodes: slice,
                    attrs: dict, parallel: bool) -> str:
    """Write ``static.h5`` (collective; checked, atomic, recorded); returns its digest.

    ``flex``, ``mass`` (k, k) and ``table`` (k, 3): rank 0's; ``translation`` (k, nodes, 3):
    this rank's slice ``nodes`` of the n_nodes nodes (all of them on rank 0, none elsewhere,
    when not ``parallel``); ``attrs``: its provenance.
    """
    n_r = table.shape[0]

    def fill(f, par: bool) -> None:
        g = f.create_group("static")
        d_f = g.create_dataset("rail_flexibility", (n_r, n_r), "f8")
        d_m = g.create_dataset("residual_mass", (n_r, n_r), "f8")
        d_t = g.create_dataset("translation", (n_r, n_nodes, 3), "f8")
        d_l = g.create_dataset("load_dofs", table.shape, "i8")
        if comm.rank == 0:
            d_f[...] = flex
            d_m[...] = mass
            d_l[...] = table
        if nodes.stop > nodes.start:
            d_t[:, nodes, :] = translation

    size = 8 * (n_r * n_nodes * 3 + 2 * n_r * n_r + table.size)
    return write_h5(path, comm, fill, size_hint=size, attrs=attrs, parallel=parallel,
                    check=lambda tmp: check_static(tmp, False))


def read_rail_statics(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``/static/rail_flexibility`` and ``/static/residual_mass`` of ``static.h5``."""
    import h5py

    with h5py.File(path, "r") as f:
        return f["static/rail_flexibility"][()], f["static/residual_mass"][()]
