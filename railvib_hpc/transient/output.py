"""Outputs of the full-order solution: probes, rail histories, ``fields.h5``, checkpoints.

The files have the layout of the ``reconstruct`` stage, so ``assess`` and the studies read
them unchanged:

* ``fields.h5`` (:class:`FieldWriter`): ``/time``, ``/steps``, ``/fields/displacement``,
  ``velocity``, ``acceleration`` (ns, n, 3) of every node at the output steps, ``/mesh``,
  and ``/stress`` at ``output.stress_times``; ``fields.xdmf``, ``stress.xdmf``. Written
  collectively while the run goes on (each rank its contiguous node range), under a
  hidden name that a resumed run continues, renamed when complete;
* probe histories (:class:`PointSampler`): the nodal solution interpolated with the
  trilinear shape functions of the containing hexahedron at every step;
* rail histories (:class:`RailSampler`): ``uz``, ``ry`` of every flexible-rail node at every
  step (rail bending moments, rail displacement under the wheels).

Checkpoints (:func:`write_checkpoint`, :func:`read_checkpoint`) hold the state vectors by
global DOF number (so a run may resume on another number of ranks) and rank 0's
histories.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..mesh.model import Mesh
from ..mesh.search import hex_shape_values, locate
from ..modal.dofmap import DofMap

#: Bumped when the content of the transient outputs changes (part of the reuse digest).
FORMAT_VERSION = 1


# --------------------------------------------------------------------------- sampling
class PointSampler:
    """Values of the nodal solution at points, as this rank's partial sums.

    Parameters
    ----------
    mesh, dofmap, rank
        Model and this rank's DOF range.
    coords
        (p, 3) points inside the hexahedra.
    names
        Point names (error messages).

    Raises
    ------
    railvib_hpc.reconstruct.probes.ProbeError
        A point outside every hexahedron.
    """

    def __init__(self, mesh: Mesh, dofmap: DofMap, rank: int, coords: np.ndarray,
                 names: list[str]):
        from ..reconstruct.probes import ProbeError

        coords = np.asarray(coords, dtype=float).reshape(-1, 3)
        self.n = len(coords)
        if self.n == 0:
            self.weights = np.zeros((0, 8))
            self.rows = np.zeros((0, 8, 3), np.int64)
            self.elem, self.xi = np.zeros(0, np.int64), np.zeros((0, 3))
            return
        elem, xi = locate(coords, mesh)
        bad = np.flatnonzero(elem < 0)
        if bad.size:
            where = ", ".join(f"'{names[i]}' at {tuple(float(v) for v in coords[i])}"
                              for i in bad)
            raise ProbeError(f"probe point(s) outside the hexahedral mesh: {where}")
        xi = np.clip(xi, -1.0, 1.0)
        self.elem, self.xi = elem, xi
        self.weights = hex_shape_values(xi)                        # (p, 8)
        r0, r1 = dofmap.owned_dofs(rank)
        idx = dofmap.index[mesh.hexes[elem]][:, :, :3]             # (p, 8, 3)
        self.rows = np.where((idx >= r0) & (idx < r1), idx - r0, -1)

    def sample(self, *fields: np.ndarray) -> np.ndarray:
        """(len(fields), p, 3) partial interpolated values from local DOF arrays."""
        out = np.zeros((len(fields), self.n, 3))
        ok = self.rows >= 0
        for k, f in enumerate(fields):
            vals = np.where(ok, f[np.where(ok, self.rows, 0)], 0.0)   # (p, 8, 3)
            out[k] = np.einsum("pa,pai->pi", self.weights, vals)
        return out


class RailSampler:
    """``uz`` and ``ry`` of every flexible-rail node (this rank's partial values)."""

    def __init__(self, rails, dofmap: DofMap, rank: int):
        r0, r1 = dofmap.owned_dofs(rank)
        idx = rails.dofs[:, :, :2]                                 # (2, k, [uz, ry])
        self.rows = np.where((idx >= r0) & (idx < r1), idx - r0, -1)
        self.shape = idx.shape

    def sample(self, u: np.ndarray) -> np.ndarray:
        ok = self.rows >= 0
        return np.where(ok, u[np.where(ok, self.rows, 0)], 0.0)


def node_values(u: np.ndarray, dofmap: DofMap, rank: int) -> np.ndarray:
    """(owned nodes, 3) translations of this rank's nodes from its DOF array."""
    nodes = dofmap.owned_nodes(rank)
    r0, _ = dofmap.owned_dofs(rank)
    idx = dofmap.index[nodes, :3]
    ok = idx >= 0
    out = np.zeros(idx.shape)
    out[ok] = u[idx[ok] - r0]
    return out


# --------------------------------------------------------------------------- fields
class FieldWriter:
    """``fields.h5`` written during the run (collective; layout of the reconstruct stage).

    Parameters
    ----------
    path
        The hidden file written while running (renamed by :meth:`finish`).
    comm
        MPI communicator.
    mesh, dofmap
        Model; each rank writes its node range ``dofmap.owned_nodes(rank)``.
    times, steps
        (ns,) times and step numbers of the output steps.
    float32
        Store single precision.
    attrs
        Root attributes (``inputs_sha256`` among them).
    resume
        Continue an existing file with the same ``inputs_sha256`` instead of creating it.
    block
        Output steps buffered before a collective write.
    """

    def __init__(self, path: Path, comm, mesh: Mesh, dofmap: DofMap, times: np.ndarray,
                 steps: np.ndarray, float32: bool, attrs: dict, resume: bool = False,
                 block: int = 16):
        from ..io.parallel_h5 import h5py_parallel_ok
        from ..reconstruct.fields import open_h5

        self.path, self.comm, self.dofmap = Path(path), comm, dofmap
        self.times, self.steps = np.asarray(times, float), np.asarray(steps, np.int64)
        self.ns, self.n = len(self.times), mesh.n_nodes
        self.ne = len(mesh.hexes)
        self.float32 = bool(float32)
        self.dtype = np.float32 if float32 else np.float64
        self.parallel = h5py_parallel_ok(comm)
        self.nodes = dofmap.owned_nodes(comm.rank)
        nl = self.nodes.stop - self.nodes.start
        self.block = max(1, int(block))
        self.buf = np.zeros((3, self.block, nl, 3), dtype=self.dtype)
        self.pending: list[int] = []
        self.hex_dtype, self.part_dtype = mesh.hexes.dtype.str, mesh.hex_part.dtype.str
        writes = self.parallel or comm.rank == 0
        self.file = None
        error = None
        if writes:
            try:
                if resume:
                    self.file = open_h5(self.path, "r+", comm, self.parallel)
                else:
                    self.file = open_h5(self.path, "w", comm, self.parallel)
                    self._create(mesh, attrs)
            except Exception as exc:     # raised on every rank below
                error = exc
        from ..reconstruct.fields import check_collective

        check_collective(comm, error, f"opening {self.path}")

    def _create(self, mesh: Mesh, attrs: dict) -> None:
        f = self.file
        f.attrs["complete"] = 0
        f.create_dataset("time", (self.ns,), "f8")
        f.create_dataset("steps", (self.ns,), "i8")
        g = f.create_group("fields")
        for name in ("displacement", "velocity", "acceleration"):
            g.create_dataset(name, (self.ns, self.n, 3), self.dtype)
        gm = f.create_group("mesh")
        gm.create_dataset("points", (self.n, 3), "f8")
        gm.create_dataset("hexes", mesh.hexes.shape, mesh.hexes.dtype)
        gm.create_dataset("hex_part", mesh.hex_part.shape, mesh.hex_part.dtype)
        f.attrs.update({"n_modes": 0, "n_extra": 0, "float32": int(self.float32),
                        "block_steps": self.block, "solver": "transient",
                        "modes_file": "", **attrs})
        if self.comm.rank == 0:
            f["time"][...] = self.times
            f["steps"][...] = self.steps
            gm["points"][...] = mesh.points
            gm["hexes"][...] = mesh.hexes
            gm["hex_part"][...] = mesh.hex_part

    def put(self, k: int, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """Buffer output step ``k`` (index into ``times``) from local DOF arrays."""
        slot = len(self.pending)
        for i, x in enumerate((u, v, a)):
            self.buf[i, slot] = node_values(x, self.dofmap, self.comm.rank)
        self.pending.append(int(k))
        if len(self.pending) == self.block:
            self.flush()

    def flush(self) -> None:
        """Write the buffered steps (collective; consecutive indices)."""
        from ..reconstruct.fields import check_collective, write_slab

        if not self.pending:
            # every rank must still agree that nothing is pending
            return
        k0, b = self.pending[0], len(self.pending)
        nl = self.nodes.stop - self.nodes.start
        names = ("displacement", "velocity", "acceleration")
        error = None
        try:
            if self.parallel:
                for i, name in enumerate(names):
                    write_slab(self.file[f"fields/{name}"], (k0, self.nodes.start, 0),
                               (b, nl, 3), self.buf[i, :b] if nl else None, True)
            else:
                parts = self.comm.gather((self.nodes.start, self.buf[:, :b].copy()), root=0)
                if self.comm.rank == 0:
                    for start, data in parts:
                        for i, name in enumerate(names):
                            if data.shape[2]:
                                self.file[f"fields/{name}"][k0:k0 + b, start:start
                                                            + data.shape[2]] = data[i]
        except Exception as exc:     # raised on every rank
            error = exc
        check_collective(self.comm, error, f"writing {self.path}")
        self.pending = []

    def close(self) -> None:
        self.flush()
        if self.file is not None:
            self.file.close()
            self.file = None

    def finish(self, final: Path, stress) -> None:
        """Close, add the stresses (``stress(tmp_path)``, collective), mark complete, rename,
        write ``fields.xdmf`` (rank 0)."""
        from ..io.stage_files import write_text
        from ..parallel import on_root
        from ..reconstruct.fields import fields_xdmf

        self.close()
        self.comm.Barrier()
        if stress is not None:
            stress(self.path)

        def rename() -> None:
            import h5py

            with h5py.File(self.path, "a") as f:
                f.attrs["complete"] = 1
            os.replace(self.path, final)
            write_text(final.with_suffix(".xdmf"),
                              fields_xdmf(final.name, self.n, self.ne, self.times, self.float32,
                                          self.hex_dtype, self.part_dtype))

        on_root(rename, self.comm)


def partial_fields_ok(path: Path, key: str) -> bool:
    """True when a hidden fields file of an interrupted run with digest ``key`` exists."""
    import h5py

    if not path.exists():
        return False
    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("inputs_sha256") == key and "fields/displacement" in f
    except OSError:
        return False


# --------------------------------------------------------------------------- checkpoints
def write_checkpoint(path: Path, comm, key: str, step: int, fields_written: int,
                     state, dofmap: DofMap, history: dict | None) -> None:
    """Store the state after ``step`` (collective, atomic; the previous one is replaced).

    ``history`` (rank 0: name -> array) holds the recorded histories.
    """
    from ..io.parallel_h5 import h5py_parallel_ok, write_collective

    parallel = h5py_parallel_ok(comm)
    r0, r1 = dofmap.owned_dofs(comm.rank)
    n = dofmap.n_dofs
    vecs = {"u": state.u, "v": state.v, "a": state.a}
    if not parallel and comm.size > 1:
        gathered = {k: comm.gather(v, root=0) for k, v in vecs.items()}
        if comm.rank == 0:
            vecs = {k: np.concatenate(v) for k, v in gathered.items()}
            r0, r1 = 0, n
    small = {"y": state.y, "y_dot": state.y_dot, "y_ddot": state.y_ddot,
             "penetration": state.penetration, "force": state.force}
    hist_meta = comm.bcast({k: (v.shape, v.dtype.str) for k, v in (history or {}).items()}
                           if comm.rank == 0 else None, root=0)

    def fill(f, par: bool) -> None:
        f.attrs["inputs_sha256"] = key
        f.attrs["step"] = int(step)
        f.attrs["fields_written"] = int(fields_written)
        f.attrs["format"] = FORMAT_VERSION
        g = f.create_group("state")
        for name, v in vecs.items():
            d = g.create_dataset(name, (n,), "f8")
            if r1 > r0:
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

    write_collective(path, comm, fill)


def read_checkpoint(path: Path, key: str, dofmap: DofMap, rank: int) -> dict | None:
    """This rank's part of a complete checkpoint with digest ``key`` (None if there is none).

    Every rank reads its own rows (plain h5py, read only).
    """
    import h5py

    if not path.exists():
        return None
    try:
        with h5py.File(path, "r") as f:
            if int(f.attrs.get("complete", 0)) != 1 or f.attrs.get("inputs_sha256") != key:
                return None
            r0, r1 = dofmap.owned_dofs(rank)
            out = {"step": int(f.attrs["step"]), "fields_written": int(f.attrs["fields_written"])}
            for name in ("u", "v", "a"):
                out[name] = f[f"state/{name}"][r0:r1]
            for name in f["small"]:
                out[name] = f[f"small/{name}"][()]
            out["history"] = ({name: f[f"history/{name}"][()] for name in f["history"]}
                              if rank == 0 else None)
            return out
    except (OSError, KeyError):
        return None


def json_attr(value) -> str:
    """JSON for an HDF5 attribute (numpy scalars as floats)."""
    return json.dumps(value, default=float)
