"""Outputs of the full-order solution: probes, rail histories, ``fields.h5``.

The files have the layout of the ``reconstruct`` stage, so ``assess`` and the studies read
them unchanged:

* ``fields.h5`` (:class:`FieldWriter`): ``/time``, ``/steps``, ``/fields/displacement``,
  ``velocity``, ``acceleration`` (ns, n, 3) of every node at the output steps, ``/mesh``,
  and ``/stress`` at ``output.stress_times``; ``fields.xdmf``, ``stress.xdmf`` (with their
  per-step views). Written collectively while the run goes on (each rank its contiguous
  node range) under :func:`~railvib_hpc.io.temp_names.resume_path` (created with its
  space reserved by :func:`~railvib_hpc.io.atomic.start_h5`), which a resumed run
  continues, and completed, checked, renamed and recorded by
  :func:`~railvib_hpc.io.atomic.commit_h5`;
* probe histories (:class:`PointSampler`): the nodal solution interpolated with the
  trilinear shape functions of the containing hexahedron at every step;
* rail histories (:class:`RailSampler`): ``uz``, ``ry`` of every flexible-rail node at every
  step (rail bending moments, rail displacement under the wheels).

The checkpoints (``transient_checkpoint.h5``) and ``transient.h5`` have their layout,
writer and reader in :mod:`railvib_hpc.io.formats.transient`; whether a checkpoint may be
resumed is decided by the stage (:mod:`.stage`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..mesh.model import Mesh
from ..mesh.search import hex_shape_values, locate
from ..model.dofmap import DofMap


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
        The final file; the data go to its :func:`~railvib_hpc.io.temp_names.resume_path`
        until :meth:`finish`.
    comm
        MPI communicator.
    mesh, dofmap
        Model; each rank writes its node range ``dofmap.owned_nodes(rank)``.
    times, steps
        (ns,) times and step numbers of the output steps.
    float32
        Store single precision.
    attrs
        Root attributes (the provenance, the run id).
    resume
        Continue the existing partial file (the stage checked that it belongs to the
        checkpoint) instead of creating it.
    block
        Output steps buffered before a collective write.
    extra_bytes
        Space reserved for what is added before completion (the stresses).
    """

    def __init__(self, path: Path, comm, mesh: Mesh, dofmap: DofMap, times: np.ndarray,
                 steps: np.ndarray, float32: bool, attrs: dict, resume: bool = False,
                 block: int = 16, extra_bytes: int = 0):
        from ..io.atomic import start_h5
        from ..io.parallel_h5 import h5py_parallel_ok, open_h5
        from ..io.temp_names import resume_path
        from ..parallel import check_collective

        self.final = Path(path)
        self.path = resume_path(self.final)
        self.comm, self.dofmap = comm, dofmap
        self.times, self.steps = np.asarray(times, float), np.asarray(steps, np.int64)
        self.ns, self.n = len(self.times), mesh.n_nodes
        self.float32 = bool(float32)
        self.dtype = np.float32 if float32 else np.float64
        self.parallel = h5py_parallel_ok(comm)
        self.nodes = dofmap.owned_nodes(comm.rank)
        nl = self.nodes.stop - self.nodes.start
        self.block = max(1, int(block))
        self.buf = np.zeros((3, self.block, nl, 3), dtype=self.dtype)
        self.pending: list[int] = []
        if not resume:
            size = (3 * self.ns * self.n * 3 * np.dtype(self.dtype).itemsize
                    + 8 * (3 * self.n + 9 * len(mesh.hexes)) + 16 * self.ns + int(extra_bytes))
            start_h5(self.path, comm, size_hint=size, what=self.final.name)
        writes = self.parallel or comm.rank == 0
        self.file = None
        error = None
        if writes:
            try:
                self.file = open_h5(self.path, "r+", comm, self.parallel)
                if not resume:
                    self._create(mesh, attrs)
            except Exception as exc:     # raised on every rank below
                error = exc
        check_collective(comm, error, f"writing {self.final}")

    def _create(self, mesh: Mesh, attrs: dict) -> None:
        import h5py

        from ..io.formats.fields import create_fields, fill_fields_mesh, set_fields_attrs

        f = self.file
        # storage allocated now (no fill written): after the first :meth:`sync` the file's
        # metadata on disk does not change any more, so a killed run leaves a readable file
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
        dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)
        dsets = create_fields(f, self.ns, self.n, mesh.hexes.shape, mesh.hexes.dtype,
                              mesh.hex_part.dtype, self.dtype, dcpl=dcpl)
        f.attrs.update(attrs)
        set_fields_attrs(f, n_modes=0, n_extra=0, float32=self.float32,
                         block_steps=self.block, solver="transient", modes_file="",
                         complete=0)
        if self.comm.rank == 0:
            fill_fields_mesh(dsets, self.times, self.steps, mesh.points, mesh.hexes,
                             mesh.hex_part)

    def put(self, k: int, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """Buffer output step ``k`` (index into ``times``) from local DOF arrays."""
        slot = len(self.pending)
        for i, x in enumerate((u, v, a)):
            self.buf[i, slot] = node_values(x, self.dofmap, self.comm.rank)
        self.pending.append(int(k))
        if len(self.pending) == self.block:
            self.flush()

    def flush(self) -> None:
        """Write the buffered steps (collective; consecutive indices). Non-finite values
        (a diverged integration) stop the run on every rank: nothing is written."""
        from ..io.formats.checks import nonfinite
        from ..io.parallel_h5 import write_slab
        from ..parallel import check_collective

        if not self.pending:
            return                       # the same on every rank: they buffer the same steps
        k0, b = self.pending[0], len(self.pending)
        nl = self.nodes.stop - self.nodes.start
        names = ("displacement", "velocity", "acceleration")
        error = None
        try:
            for i, name in enumerate(names):
                bad = nonfinite(f"the {name} field", self.buf[i, :b])
                if bad:
                    from ..errors import DataError

                    raise DataError(f"{bad[0]} at t = {self.times[k0]:.6g} .. "
                                    f"{self.times[k0 + b - 1]:.6g} s: the time integration "
                                    f"diverged; {self.final} was not written (check "
                                    "transient.dt and the vehicle and contact settings)")
        except Exception as exc:         # raised on every rank
            error = exc
        check_collective(self.comm, error, f"writing {self.final}")
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
        check_collective(self.comm, error, f"writing {self.final}")
        self.pending = []

    def sync(self) -> None:
        """Write what is buffered and make the partial file on disk complete up to here
        (collective: ``H5Fflush`` of the data and metadata, then ``fsync``), so that a
        checkpoint written next can trust it even if the process is killed."""
        import os

        from ..parallel import check_collective

        self.flush()
        error = None
        try:
            if self.file is not None:
                self.file.flush()
            if self.comm.rank == 0:
                fd = os.open(self.path, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
        except Exception as exc:         # raised on every rank
            error = exc
        check_collective(self.comm, error, f"writing {self.final}")

    def close(self) -> None:
        """Write what is buffered and close the partial file (collective)."""
        try:
            self.flush()
        finally:
            if self.file is not None:
                self.file.close()
                self.file = None

    def finish(self, stress) -> str:
        """Close, add the stresses (``stress(partial_path)``, collective), complete, check,
        rename and record ``fields.h5``; write ``fields.xdmf`` (rank 0). Returns the content
        digest."""
        from ..io.atomic import commit_h5
        from ..io.formats.fields import check_fields, write_fields_xdmf
        from ..parallel import on_root

        self.close()
        self.comm.Barrier()
        if stress is not None:
            stress(self.path)
        sha = commit_h5(self.path, self.final, self.comm,
                        check=lambda tmp: check_fields(tmp, False))
        on_root(lambda: write_fields_xdmf(self.final), self.comm)
        return sha
