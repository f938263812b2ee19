"""``transient.h5`` and ``transient_checkpoint.h5`` (``railvib transient``): layouts, checks.

Layout of ``transient.h5`` (HDF5)::

    /time (nt+1,)
    /wheels/{x,contact_force,penetration,rail_displacement,wheel_height,rail_index}
    /vehicle/{y,y_dot,y_ddot}
    /rail/{x,uz,ry}                    at every step
    attrs: the provenance, solver, stats (JSON: time step, timings, memory, contact forces)

Layout of ``transient_checkpoint.h5``: ``/state/{u,v,a}`` (the state vectors), ``/small/*``
and ``/history/*`` (the histories so far, at least ``step + 1`` rows); attrs ``step``,
``fields_written`` and the provenance. Writers: the transient stage
(:mod:`railvib_hpc.transient.stage`) and :func:`railvib_hpc.transient.output.write_checkpoint`
(reader :func:`~railvib_hpc.transient.output.read_checkpoint`), which take its DOF map.
Checks: :func:`check_transient`, :func:`check_checkpoint`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .checks import CONTACT_FORCE_FACTOR, absent, exceeds, h5_read, nonfinite, static_wheel_load


def check_transient(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                    ) -> list[str]:
    """``transient.h5`` (small: always completely): every history finite, consistent shapes,
    time strictly increasing, contact forces within :data:`CONTACT_FORCE_FACTOR` x the
    static wheel load (``context["static_wheel_load"]``, else the stored ``stats``)."""
    context = context or {}
    with h5_read(path) as f:
        missing = absent(f, ("time", "wheels/x", "wheels/contact_force", "wheels/penetration",
                            "wheels/rail_displacement", "vehicle/y", "rail/x", "rail/uz",
                            "rail/ry"))
        if missing:
            return missing
        t = f["time"][()]
        out = nonfinite("time", t)
        if not out and (t.ndim != 1 or t.size == 0 or np.any(np.diff(t) <= 0)):
            out.append("time must be non-empty and strictly increasing")
        for name in ("wheels/x", "wheels/contact_force", "wheels/penetration",
                     "wheels/rail_displacement", "wheels/wheel_height", "vehicle/y",
                     "vehicle/y_dot", "vehicle/y_ddot", "rail/uz", "rail/ry"):
            if name not in f:
                continue
            a = f[name][()]
            if a.shape[:1] != t.shape:
                out.append(f"{name} has shape {a.shape}, expected {t.size} rows (time)")
            out += nonfinite(name, a)
        if out:
            return out
        load = static_wheel_load(f, context)
        if load:
            out += exceeds("wheels/contact_force", f["wheels/contact_force"][()],
                           CONTACT_FORCE_FACTOR * float(load),
                           f"{CONTACT_FORCE_FACTOR:g} x the static wheel load {load:.4g} N")
    return out


def check_checkpoint(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                     ) -> list[str]:
    """``transient_checkpoint.h5``: the state vectors (one length, finite), the step and the
    recorded histories (finite, at least ``step + 1`` rows)."""
    with h5_read(path) as f:
        missing = absent(f, ("state/u", "state/v", "state/a", "small", "history"))
        if missing:
            return missing
        out = []
        step, written = int(f.attrs.get("step", -1)), int(f.attrs.get("fields_written", -1))
        if step < 0 or written < 0:
            out.append(f"its step {step} or fields_written {written} is negative or missing")
        n = f["state/u"].shape
        for name in ("state/u", "state/v", "state/a"):
            if f[name].shape != n:
                out.append(f"{name} has shape {f[name].shape}, expected {n}")
            else:
                out += nonfinite(name, f[name][()])
        for name, ds in (*f["small"].items(), *f["history"].items()):
            out += nonfinite(name, ds[()])
        for name, ds in f["history"].items():
            if ds.ndim == 0 or ds.shape[0] <= step:
                out.append(f"history/{name} has {ds.shape[0] if ds.ndim else 0} rows, the "
                           f"checkpoint is at step {step}")
        return out
