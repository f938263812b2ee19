"""``probes.h5`` and ``probes/<name>.csv``: layout, writers, reader and check (the probe
histories of ``reconstruct`` and ``transient``; rank 0, serial).

``probes.h5`` (:func:`write_probes_h5`, read by :func:`read_probes`)::

    /names (p,) S64, /coords (p, 3)          probe names and coordinates [m]
    /probes/<name>/time (nt,)                [s]
    /probes/<name>/displacement (nt, 3)      [m]      ux uy uz
    /probes/<name>/velocity (nt, 3)          [m/s]
    /probes/<name>/acceleration (nt, 3)      [m/s^2]
        attrs: coords, element (containing hex), xi (reference coordinates), role
        (railvib_hpc.schema.PROBE_ROLES)
    /<group>/<dataset>                       optional extra groups (e.g. /rail)
    attrs: complete = 1, plus the caller's attrs

``probes/<name>.csv`` (:func:`write_probes_csv`): one file per probe, a header line
``t,ux,uy,uz,vx,vy,vz,ax,ay,az`` (SI units: s, m, m/s, m/s^2) and one row per step.

Check: :func:`check_probes` (on write and on reuse).
"""

from __future__ import annotations

import io
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import UserError
from ..atomic import write_h5, write_text
from .checks import absent, h5_read, nonfinite

#: The header line of ``probes/<name>.csv``.
CSV_HEADER = "t,ux,uy,uz,vx,vy,vz,ax,ay,az"


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


def _file_name(name: str) -> str:
    """A safe file / group name for a probe."""
    return re.sub(r"[^A-Za-z0-9_.+-]", "_", name) or "probe"


def write_probes_csv(directory: str | os.PathLike, histories: Mapping[str, Mapping]
                     ) -> list[Path]:
    """One CSV per probe (header ``t,ux,uy,uz,vx,vy,vz,ax,ay,az``), each written atomically.

    Returns
    -------
    list of Path
        The files written.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, h in histories.items():
        table = np.column_stack([h["t"], h["displacement"], h["velocity"], h["acceleration"]])
        buf = io.StringIO()
        np.savetxt(buf, table, delimiter=",", fmt="%.17g", header=CSV_HEADER, comments="")
        path = directory / f"{_file_name(name)}.csv"
        write_text(path, buf.getvalue())
        paths.append(path)
    return paths


def write_probes_h5(path: str | os.PathLike, histories: Mapping[str, Mapping],
                    attrs: Mapping[str, object] | None = None,
                    groups: Mapping[str, Mapping[str, np.ndarray]] | None = None) -> str:
    """Write ``probes.h5`` atomically, checked and recorded (serial, rank 0); layout in the
    module docstring. Returns its content digest.

    Parameters
    ----------
    path
        Output file.
    histories
        From :func:`~railvib_hpc.reconstruct.probes.probe_histories`.
    attrs
        Root attributes (e.g. an input digest).
    groups
        Extra groups of datasets, e.g. ``{"rail": {"bending_moment": ..., "x": ...}}``.
    """
    names = list(histories)

    def fill(f, parallel: bool) -> None:
        f.create_dataset("names", data=np.array(names, dtype="S64"))
        f.create_dataset("coords", data=np.array([histories[k]["coords"] for k in names],
                                                 dtype=float).reshape(-1, 3))
        g = f.create_group("probes")
        for name in names:
            h = histories[name]
            p = g.create_group(_file_name(name))
            p.attrs["name"] = name
            p.attrs["coords"] = np.asarray(h["coords"], dtype=float)
            for key in ("element", "xi"):
                if key in h:
                    p.attrs[key] = h[key]
            if h.get("role"):
                p.attrs["role"] = h["role"]
            p.create_dataset("time", data=h["t"])
            for key in ("displacement", "velocity", "acceleration"):
                p.create_dataset(key, data=h[key])
        for gname, data in (groups or {}).items():
            grp = f.create_group(gname)
            for key, value in data.items():
                grp.create_dataset(key, data=value)

    size = sum(np.asarray(h[k]).nbytes for h in histories.values()
               for k in ("t", "displacement", "velocity", "acceleration"))
    size += sum(np.asarray(v).nbytes for d in (groups or {}).values() for v in d.values())
    return write_h5(path, None, fill, size_hint=int(size), attrs=attrs, check=check_probes)


class ProbesFileError(UserError):
    """A ``probes.h5`` that is missing, incomplete or written by an older version."""


def read_probes(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """Probe histories from ``probes.h5`` (layout above)."""
    import h5py

    if not path.exists():
        raise ProbesFileError(f"{path} not found: run 'railvib reconstruct' first")
    out = {}
    with h5py.File(path, "r") as f:
        if int(f.attrs.get("complete", 1)) != 1:
            raise ProbesFileError(f"{path} is incomplete: rerun 'railvib reconstruct'")
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["names"][()]]
        coords = f["coords"][()]
        for name, xyz in zip(names, coords):
            g = f[f"probes/{name}"]
            role = g.attrs.get("role")
            if role is None:
                raise ProbesFileError(f"{path}: probe '{name}' has no role (file written by "
                                       "an older version): rerun 'railvib run' (modal and "
                                       "reconstruct recompute their files)")
            out[name] = {"t": g["time"][()], "displacement": g["displacement"][()],
                         "velocity": g["velocity"][()], "acceleration": g["acceleration"][()],
                         "coords": np.asarray(xyz, dtype=float),
                         "role": role.decode() if isinstance(role, bytes) else str(role)}
    return out
