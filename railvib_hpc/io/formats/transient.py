"""``transient.h5`` and ``transient_checkpoint.h5`` (``railvib transient``): layouts,
writers, readers, checks.

Layout of ``transient.h5`` (HDF5, rank 0)::

    /time (nt+1,)
    /wheels/{x,contact_force,penetration,rail_displacement,wheel_height,rail_index}
    /vehicle/{y,y_dot,y_ddot}          (attrs: dof_names (JSON), type)
    /rail/{x,uz,ry}                    at every step
    attrs: the provenance, solver, stats (JSON: time step, timings, memory, contact forces)

Layout of ``transient_checkpoint.h5``: ``/state/{u,v,a}`` (the state vectors by global DOF
number: the numbering does not depend on the number of ranks, so a run may resume on
another number of ranks), ``/small/*`` (the vehicle's state, the contact) and
``/history/*`` (rank 0's histories so far, at least ``step + 1`` rows); attrs ``step``,
``fields_written``, ``run_id`` and the provenance (:class:`CheckpointHeader`).

Writers: :func:`write_transient_h5` (of plain arrays; the transient stage,
:mod:`railvib_hpc.transient.stage`, forms them from its recorder) and
:func:`write_checkpoint` (collective, of this rank's rows of the state vectors). Readers:
:class:`TransientFile` (every reader of ``transient.h5``: the run statistics, the contact
forces of the assessment), :func:`read_checkpoint` (this rank's rows) and
:class:`CheckpointHeader` (whether a checkpoint may be resumed is decided by the stage).
Checks: :func:`check_transient`, :func:`check_checkpoint`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import write_h5
from .checks import CONTACT_FORCE_FACTOR, absent, exceeds, h5_read, nonfinite, static_wheel_load

#: The per-step histories of ``transient.h5`` besides the rail's (the keys of the writer's
#: ``histories``), of the wheels and of the vehicle.
WHEEL_HISTORIES = ("contact_force", "penetration", "rail_displacement", "wheel_height")
VEHICLE_HISTORIES = ("y", "y_dot", "y_ddot")


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
        header = CheckpointHeader.of_attrs(f.attrs)
        step, written = header.step, header.fields_written
        if step < 0 or written < 0:
            out.append(f"its step {step} or fields_written {written} is negative or missing")
        n = f["state/u"].shape
        for name in ("state/u", "state/v", "state/a"):
            if f[name].shape != n:
                out.append(f"{name} has shape {f[name].shape}, expected {n}")
            else:
                out += nonfinite(name, f[name][()])
        engine = f["engine"].items() if "engine" in f else ()
        for name, ds in (*f["small"].items(), *f["history"].items(), *engine):
            out += nonfinite(name, ds[()])
        for name, ds in f["history"].items():
            if ds.ndim == 0 or ds.shape[0] <= step:
                out.append(f"history/{name} has {ds.shape[0] if ds.ndim else 0} rows, the "
                           f"checkpoint is at step {step}")
        return out


# --------------------------------------------------------------------------- transient.h5
def transient_stats(attrs: Mapping[str, Any]) -> dict:
    """The run statistics of ``transient.h5``'s attributes (its ``stats``; ``{}`` without)."""
    v = attrs.get("stats", "{}")
    return json.loads(v.decode() if isinstance(v, bytes) else str(v))


def transient_nbytes(time: np.ndarray, wheel_x: np.ndarray, histories: Mapping[str, np.ndarray],
                     rail: np.ndarray) -> int:
    """Predicted size of ``transient.h5`` (its arrays)."""
    return int(sum(v.nbytes for v in histories.values()) + rail.nbytes + time.nbytes
               + wheel_x.nbytes)


def fill_transient(f, *, time: np.ndarray, wheel_x: np.ndarray, rail_index: np.ndarray,
                   histories: Mapping[str, np.ndarray], dof_names: Sequence[str],
                   vehicle_type: str, rail_x: np.ndarray, rail: np.ndarray) -> None:
    """Fill an open ``transient.h5`` (layout in the module notes).

    Parameters
    ----------
    f
        The open file.
    time, wheel_x, rail_index
        (nt+1,) times, (nt+1, n_wheels) wheel positions, (n_wheels,) the rail of each wheel.
    histories
        (nt+1, ...) arrays of :data:`WHEEL_HISTORIES` and :data:`VEHICLE_HISTORIES`.
    dof_names, vehicle_type
        The vehicle's DOF names (empty without a vehicle) and ``vehicle.type``.
    rail_x, rail
        (n_rails, k) rail node positions and (nt+1, n_rails, k, 2) their ``uz``, ``ry``.
    """
    f["time"] = time
    w = f.create_group("wheels")
    w["x"] = wheel_x
    for name in WHEEL_HISTORIES:
        w[name] = histories[name]
    w["rail_index"] = rail_index
    v = f.create_group("vehicle")
    for name in VEHICLE_HISTORIES:
        v[name] = histories[name]
    v.attrs["dof_names"] = json.dumps(list(dof_names))
    v.attrs["type"] = vehicle_type
    r = f.create_group("rail")
    r["x"] = rail_x
    r["uz"] = rail[..., 0]
    r["ry"] = rail[..., 1]


def write_transient_h5(path: Path, *, stats: Mapping[str, Any], provenance: Mapping[str, Any],
                       check: Callable[[Path], Sequence[str]] | None = None, **fields) -> str:
    """Write ``transient.h5`` (serial, rank 0; checked, atomic, recorded); returns its digest.

    ``stats``: the run statistics (stored as JSON, non-JSON numbers as floats);
    ``provenance``: its provenance attributes; ``fields``: those of :func:`fill_transient`.
    """
    def fill(f, parallel: bool) -> None:
        fill_transient(f, **fields)

    attrs = {**provenance, "stats": json.dumps(dict(stats), default=float),
             "solver": "transient"}
    size = transient_nbytes(fields["time"], fields["wheel_x"], fields["histories"],
                            fields["rail"])
    return write_h5(path, None, fill, size_hint=size, attrs=attrs, check=check)


class TransientFile:
    """Reader of ``transient.h5`` (plain h5py, read only)."""

    def __init__(self, path: Path):
        self.path = Path(path)

    def _h5(self):
        import h5py

        return h5py.File(self.path, "r")

    def contact(self) -> tuple[np.ndarray, np.ndarray]:
        """``wheels/x`` and ``wheels/contact_force`` (nt+1, n_wheels)."""
        with self._h5() as f:
            return f["wheels/x"][()], f["wheels/contact_force"][()]

    def stats(self) -> dict:
        """The run statistics (:func:`transient_stats`)."""
        with self._h5() as f:
            return transient_stats(f.attrs)

    def summary(self) -> tuple[dict, str]:
        """The run statistics and ``inputs_sha256`` (``'?'`` when absent) for the report."""
        with self._h5() as f:
            return transient_stats(f.attrs), f.attrs.get("inputs_sha256", "?")


# ----------------------------------------------------------------- transient_checkpoint.h5
@dataclass(frozen=True)
class CheckpointHeader:
    """The attributes of ``transient_checkpoint.h5`` that say where it stands: its run id
    (``''`` without), the step of its state and the output steps of ``fields.h5`` written
    (-1 when missing)."""

    run_id: str
    step: int
    fields_written: int

    @classmethod
    def of_attrs(cls, attrs: Mapping[str, Any]) -> CheckpointHeader:
        """The header of the checkpoint's attributes (or of its provenance verdict's)."""
        return cls(str(attrs.get("run_id", "")), int(attrs.get("step", -1)),
                   int(attrs.get("fields_written", -1)))


def write_checkpoint(path: Path, comm, attrs: dict | None, step: int, fields_written: int,
                     vectors: Mapping[str, np.ndarray], rows: tuple[int, int], n_dofs: int,
                     small: Mapping[str, Any], history: Mapping[str, np.ndarray] | None,
                     engine: Mapping[str, tuple[str, np.ndarray]] | None = None) -> None:
    """Store the state after ``step`` (collective, atomic, recorded; the previous checkpoint
    is replaced by the rename).

    Parameters
    ----------
    path, comm
        The file and the run's communicator.
    attrs
        Rank 0: its provenance and run id (None on the others).
    step, fields_written
        The step of the state and the output steps of ``fields.h5`` on disk.
    vectors, rows, n_dofs
        ``u``, ``v``, ``a``: this rank's rows ``rows = (r0, r1)`` of the state vectors of
        ``n_dofs`` global DOFs.
    small
        The vehicle's state and the contact (rank 0's values are stored).
    history
        Rank 0: the recorded histories (name: array); None on the others.
    engine
        Rank 0: the engine's own state gathered over the ranks, ``name: (kind, array)``
        (``/engine/<name>`` with the attribute ``kind``: ``rows``, a vector over the
        global DOFs; ``elements``, one row per element of the ``ids`` entry); None on the
        others or without.
    """
    from ..parallel_h5 import h5py_parallel_ok

    parallel = h5py_parallel_ok(comm)
    r0, r1 = rows
    n = n_dofs
    vecs = dict(vectors)
    if not parallel and comm.size > 1:
        gathered = {k: comm.gather(v, root=0) for k, v in vecs.items()}
        if comm.rank == 0:
            vecs = {k: np.concatenate(v) for k, v in gathered.items()}
            r0, r1 = 0, n
    hist_meta = comm.bcast({k: (v.shape, v.dtype.str) for k, v in (history or {}).items()}
                           if comm.rank == 0 else None, root=0)
    engine_meta = comm.bcast({k: (kind, v.shape, v.dtype.str) for k, (kind, v)
                              in (engine or {}).items()} if comm.rank == 0 else None, root=0)
    size = 3 * 8 * n + sum(8 * np.size(v) for v in small.values()) + sum(
        int(np.prod(shape)) * np.dtype(dt).itemsize for shape, dt in hist_meta.values()) + sum(
        int(np.prod(shape)) * np.dtype(dt).itemsize for _, shape, dt in engine_meta.values())

    def fill(f, par: bool) -> None:
        f.attrs["step"] = int(step)
        f.attrs["fields_written"] = int(fields_written)
        g = f.create_group("state")
        for name, v in vecs.items():
            d = g.create_dataset(name, (n,), "f8")
            if par:
                from ..parallel_h5 import write_slab

                write_slab(d, (r0,), (r1 - r0,), v if r1 > r0 else None, True)
            elif r1 > r0:
                d[r0:r1] = v
        s = f.create_group("small")
        for name, v in small.items():
            d = s.create_dataset(name, np.shape(v), "f8")
            if comm.rank == 0 and np.size(v):
                d[...] = v
        h = f.create_group("history")
        for name, (shape, dtype) in hist_meta.items():
            d = h.create_dataset(name, shape, dtype)
            if comm.rank == 0:
                d[...] = history[name]
        if engine_meta:
            e = f.create_group("engine")
            for name, (kind, shape, dtype) in engine_meta.items():
                d = e.create_dataset(name, shape, dtype)
                d.attrs["kind"] = kind
                if comm.rank == 0 and np.size(engine[name][1]):
                    d[...] = engine[name][1]

    write_h5(path, comm, fill, size_hint=int(size), attrs=attrs, parallel=parallel,
             check=lambda tmp: check_checkpoint(tmp))


def read_checkpoint(path: Path, rows: tuple[int, int], rank: int,
                    elements: np.ndarray | None = None) -> dict:
    """This rank's part of a checkpoint the stage found current and sound (every rank reads
    its own rows ``rows = (r0, r1)`` of the state vectors, plain h5py, read only): ``step``,
    ``fields_written``, ``u``, ``v``, ``a``, the ``/small`` values by name, ``history``
    (rank 0: name: array; None on the others) and ``engine``: the engine's state, this
    rank's rows of its ``rows`` entries and the rows of ``elements`` (this rank's global
    element numbers, increasing) of its ``elements`` entries (``{}`` without).

    Raises
    ------
    KeyError
        An element of ``elements`` is not in the checkpoint's ``ids``.
    """
    with h5_read(path) as f:
        engine = _read_engine_state(f, rows, elements) if "engine" in f else {}
        r0, r1 = rows
        header = CheckpointHeader.of_attrs(f.attrs)
        out = {"step": header.step, "fields_written": header.fields_written}
        for name in ("u", "v", "a"):
            out[name] = f[f"state/{name}"][r0:r1]
        for name in f["small"]:
            out[name] = f[f"small/{name}"][()]
        out["history"] = ({name: f[f"history/{name}"][()] for name in f["history"]}
                          if rank == 0 else None)
        out["engine"] = engine
        return out


def _read_engine_state(f, rows: tuple[int, int], elements: np.ndarray | None) -> dict:
    """``/engine`` of an open checkpoint: this rank's part (:func:`read_checkpoint`)."""
    group = f["engine"]
    kinds = {name: str(ds.attrs.get("kind", "")) for name, ds in group.items()}
    ids = [group[name][()] for name, kind in kinds.items() if kind == "ids"]
    at = None
    if ids and elements is not None:
        stored = np.asarray(ids[0], dtype=np.int64)
        at = np.searchsorted(stored, elements)
        if np.any(at >= stored.size) or np.any(stored[np.minimum(at, stored.size - 1)]
                                                 != elements):
            raise KeyError("the checkpoint's engine state lacks elements of this rank")
    out = {}
    r0, r1 = rows
    for name, kind in kinds.items():
        ds = group[name]
        if kind == "rows":
            out[name] = ds[r0:r1]
        elif kind == "elements":
            out[name] = (ds[()][at] if at is not None and ds.shape[0] else
                         np.zeros((0, *ds.shape[1:])))
        else:
            out[name] = ds[()]
    return out
