"""Parallel reconstruction of nodal fields from modal histories: ``fields.h5`` + ``fields.xdmf``.

The nodal displacement, velocity and acceleration of the whole model follow from the
modal histories by superposition (thesis chapter 5)::

    U(t) = Phi q(t),   V(t) = Phi q_dot(t),   A(t) = Phi q_ddot(t)

with ``Phi`` the (3 n, m) mass-normalised translational mode shapes of ``modes.h5``.
Additional bases (a static correction, ``extra``) are appended to ``Phi`` as extra
columns and their coordinates ``g(t)`` to ``q(t)``: they are treated exactly like extra
modes.

Parallel layout
---------------
Every rank owns a contiguous range of nodes (even split, :func:`node_range`). It reads
its slice of the first ``m`` mode shapes once (``driver="mpio"``, collective, when
h5py is MPI-enabled and there is more than one rank; otherwise with the plain driver)
and keeps it as a C-contiguous (m, 3 n_local) matrix. The selected steps are streamed
in blocks of ``nb`` steps: for each field one BLAS GEMM
``q_block (nb, m) @ Phi_local (m, 3 n_local)`` fills a C-contiguous output buffer
(nb, 3 n_local), which is exactly the hyperslab ``[s0:s0+nb, n0:n1, :]`` of the
(ns, n, 3) dataset, written collectively. One buffer is reused for the three fields.

Memory per rank: ``Phi_local`` (8 (m + k) 3 n_local bytes, the input, e.g. 3.6 GB for
300 modes and 500 000 nodes per rank) plus the output buffer, whose step count ``nb``
is chosen so that it stays below :data:`OUTPUT_BUDGET_BYTES` (512 MB; 12 bytes per value
with ``float32=True``: a float64 GEMM result plus its float32 copy). One million nodes
and 1000 steps (72 GB of float64 output in total) therefore need about 7.2 GB of mode
shapes (300 modes) plus 2 x 0.5 GB of buffers on 2 ranks: feasible in 24 GB. Without an
MPI-enabled h5py and several ranks, rank 0 receives every block and writes it (its
receive buffer is bounded by the same budget).

``fields.h5`` layout::

    /time                       (ns,)        times of the stored steps [s]
    /steps                      (ns,)        indices of the stored steps in the histories
    /fields/displacement        (ns, n, 3)   [m]      contiguous, float64 (float32 option)
    /fields/velocity            (ns, n, 3)   [m/s]
    /fields/acceleration        (ns, n, 3)   [m/s^2]
    /mesh/points (n, 3), /mesh/hexes (ne, 8) (VTK order), /mesh/hex_part (ne,)
    attrs: complete, n_modes, n_extra, float32, block_steps, modes_file, railvib_version
           (+ the caller's attrs: the provenance of the reconstruct stage)

The file is written by :func:`railvib_hpc.io.atomic.write_h5`: under a hidden
temporary name with its space reserved, ``complete`` set and renamed by rank 0 only
after every rank finished (a failed or killed run never leaves a ``fields.h5``), then
recorded. Every block is checked for non-finite values before it is written.
``fields.xdmf`` (rank 0, after the rename) is a temporal collection with one grid per
stored step, with the hexahedra and their part ids; its node attributes are per-step
views of the three datasets in the sidecar ``fields_views.h5`` (HDF5 virtual datasets,
no data copied; see :mod:`railvib_hpc.io.xdmf`): both of ParaView's XDMF readers open it
directly.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .. import __version__
from ..io.atomic import write_h5
from ..io.formats.checks import nonfinite
from ..io.formats.fields import (  # FIELD_NAMES, write_fields_xdmf re-exported
    FIELD_NAMES,
    check_fields,
    create_fields,
    fill_fields_mesh,
    set_fields_attrs,
    write_fields_xdmf,
)
from ..io.parallel_h5 import h5py_parallel_ok, open_h5, read_slab, write_slab
from ..log import Reporter
from ..parallel import check_collective, on_root

if TYPE_CHECKING:
    from mpi4py import MPI

#: Upper bound for the per-rank output buffers of one block of steps (bytes).
OUTPUT_BUDGET_BYTES = 512 * 2**20

#: An extra basis: (h5 file, dataset of shape (k, n, 3), g (nt, k), g_dot, g_ddot).
ExtraBasis = tuple[str | os.PathLike, str, np.ndarray, np.ndarray, np.ndarray]


def node_range(n: int, size: int, rank: int) -> slice:
    """Contiguous, even split of ``n`` items over ``size`` ranks (first ranks get one more).

    Parameters
    ----------
    n
        Number of items (nodes, hexahedra).
    size, rank
        Communicator size and this rank.

    Returns
    -------
    slice
        ``slice(start, stop)`` of the items owned by ``rank``.
    """
    base, rest = divmod(n, size)
    start = rank * base + min(rank, rest)
    return slice(start, start + base + (1 if rank < rest else 0))


def block_steps_for_budget(n_local_values: int, float32: bool,
                           budget: int = OUTPUT_BUDGET_BYTES) -> int:
    """Number of steps per block so that the output buffers stay below ``budget`` bytes.

    Parameters
    ----------
    n_local_values
        Values per step on this rank (3 x owned nodes).
    float32
        Output stored as float32 (an extra float32 copy of the buffer).
    budget
        Memory budget in bytes.

    Returns
    -------
    int
        At least 1.
    """
    per_step = max(n_local_values, 1) * (12 if float32 else 8)
    return max(1, budget // per_step)


# --------------------------------------------------------------------------- main routine
def _read_basis(comm: MPI.Comm, parallel: bool, modes_path: Path, m: int,
                extra: Sequence[ExtraBasis], nodes: slice, n: int) -> np.ndarray:
    """This rank's rows of all bases as one C-contiguous (m + sum k, n_local, 3) array."""
    ks = [np.asarray(e[2]).shape[1] for e in extra]
    nl = nodes.stop - nodes.start
    phi = np.empty((m + sum(ks), nl, 3))
    sources = [(modes_path, "modes/translation", m)] + [(Path(e[0]), e[1], k)
                                                         for e, k in zip(extra, ks)]
    row = 0
    for path, name, rows in sources:
        with open_h5(path, "r", comm, parallel) as f:
            if name not in f:
                raise KeyError(f"{path}: no dataset '{name}'")
            ds = f[name]
            if ds.ndim != 3 or ds.shape[1:] != (n, 3) or ds.shape[0] < rows:
                raise ValueError(f"{path}:{name} has shape {ds.shape}, expected "
                                 f"(>= {rows}, {n}, 3)")
            read_slab(ds, (0, nodes.start, 0), (rows, nl, 3),
                      phi[row:row + rows] if nl and rows else None, parallel)
        row += rows
    return phi


def reconstruct_fields(modes_path: str | os.PathLike, out_path: str | os.PathLike, comm: MPI.Comm,
                       t: np.ndarray, q: np.ndarray, q_dot: np.ndarray, q_ddot: np.ndarray, *,
                       steps: Sequence[int] | np.ndarray | None = None, float32: bool = False,
                       block_steps: int | None = None, extra: Sequence[ExtraBasis] | None = None,
                       rep: Reporter | None = None, attrs: dict | None = None,
                       step_numbers: Sequence[int] | np.ndarray | None = None,
                       before_complete: Callable[[Path], object] | None = None,
                       record: bool = True, extra_bytes: int = 0) -> dict:
    """Write ``fields.h5`` and ``fields.xdmf`` from modal histories (collective).

    Parameters
    ----------
    modes_path
        A complete ``modes.h5``; its first ``m = q.shape[1]`` modes are used.
    out_path
        The ``fields.h5`` to write (``fields.xdmf`` goes next to it).
    comm
        MPI communicator; every rank calls with the same arguments.
    t
        (nt,) times [s].
    q, q_dot, q_ddot
        (nt, m) modal displacements, velocities and accelerations.
    steps
        Indices of the steps to store (all by default), in the order they are stored.
    float32
        Store the fields in single precision (computed in double precision, rounded once).
    block_steps
        Steps per block (default: from :data:`OUTPUT_BUDGET_BYTES`).
    extra
        Additional bases ``(h5 file, dataset, g, g_dot, g_ddot)``: dataset shape (k, n, 3),
        ``g`` arrays (nt, k). Added like ``k`` extra modes (static correction).
    rep
        Progress reporter (rank 0 prints percent and ETA).
    attrs
        Extra root attributes of ``fields.h5`` (e.g. an input digest for reuse).
    step_numbers
        Values written to ``/steps`` (default: ``steps``), e.g. indices in a longer
        history of which ``t``, ``q``, ... are an excerpt.
    before_complete
        Collective callback ``fn(temporary_path)`` run on every rank after the fields are
        written and before the file is marked complete and renamed (e.g. to add
        ``/stress``): if it raises, no ``fields.h5`` is produced.
    record
        Record the content digest of the new file (see :mod:`railvib_hpc.io.digests`).
    extra_bytes
        What ``before_complete`` adds (reserved with the fields).

    Returns
    -------
    dict
        ``n_nodes``, ``n_steps``, ``n_basis``, ``block_steps``, ``bytes_written``,
        ``seconds_read`` / ``seconds_gemm`` / ``seconds_write`` (maximum over ranks),
        ``seconds_total``, ``gemm_gflops`` (all ranks together, over the GEMM time),
        ``write_gb_per_s`` (bytes written over the write time), ``ranks``, ``parallel_io``.

    Raises
    ------
    ValueError
        Inconsistent history shapes or mode counts (on every rank).
    OSError, RuntimeError
        When reading or writing fails on some rank (on every rank); no ``fields.h5`` is
        left behind.
    """
    t_start = time.perf_counter()
    modes_path, out_path = Path(modes_path), Path(out_path)
    extra = list(extra or [])
    t = np.asarray(t, dtype=float)
    steps, hist, m = _coefficient_histories(len(t), q, q_dot, q_ddot, steps, extra)
    ns = len(steps)
    parallel = h5py_parallel_ok(comm)

    # ---- read this rank's slice of the mode shapes (and the extra bases)
    t0 = time.perf_counter()
    basis = _read_mode_shapes(comm, parallel, modes_path, m, extra)
    n, nodes, phi2, n_basis = basis.n, basis.nodes, basis.phi2, basis.phi2.shape[0]
    nl = nodes.stop - nodes.start
    t_read = time.perf_counter() - t0

    # ---- blocks of steps
    nb = int(block_steps) if block_steps else block_steps_for_budget(3 * nl, float32)
    nb = comm.allreduce(nb, op=_mpi_min()) if comm.size > 1 else nb
    nb = max(1, min(nb, ns))
    dtype = np.float32 if float32 else np.float64
    buf = np.empty((nb, 3 * nl))
    buf32 = np.empty((nb, 3 * nl), dtype=np.float32) if float32 else None
    gather = comm.size > 1 and not parallel

    stats = {"t_gemm": 0.0, "t_write": 0.0}

    def fill(f, par: bool) -> None:
        error = None
        dsets: dict = {}
        try:
            if f is not None:
                dsets = create_fields(f, ns, n, basis.hexes_shape, basis.hexes_dtype,
                                      basis.part_dtype, dtype)
                set_fields_attrs(f, n_modes=m, n_extra=n_basis - m, float32=float32,
                                 block_steps=nb, modes_file=modes_path.name,
                                 railvib_version=__version__)
            if comm.rank == 0:
                _copy_mesh(modes_path, dsets, t[steps],
                           steps if step_numbers is None else np.asarray(step_numbers))
        except Exception as exc:   # re-raised on every rank
            error = exc
        check_collective(comm, error, f"writing {out_path}")
        _stream(comm, dsets, hist, phi2, buf, buf32, nb, ns, nodes, parallel, gather,
                stats, rep, out_path)

    nbytes = 3 * ns * n * 3 * np.dtype(dtype).itemsize
    mesh_bytes = 8 * (3 * n + basis.hexes_shape[0] * 9) + 16 * ns
    write_h5(out_path, comm, fill, size_hint=nbytes + mesh_bytes + int(extra_bytes), attrs=attrs,
             parallel=parallel, before_complete=before_complete, fill_everywhere=True,
             check=lambda tmp: check_fields(tmp, False), record=record)

    def xdmf():
        write_fields_xdmf(out_path)

    on_root(xdmf, comm)
    t_gemm = _max_over_ranks(comm, stats["t_gemm"])
    t_write = _max_over_ranks(comm, stats["t_write"])
    t_read = _max_over_ranks(comm, t_read)
    t_total = _max_over_ranks(comm, time.perf_counter() - t_start)
    flops = 2.0 * sum(h.shape[1] for h in hist) * 3 * n * ns
    return {"n_nodes": n, "n_steps": ns, "n_basis": n_basis, "n_modes": m,
            "n_extra": n_basis - m, "block_steps": nb, "bytes_written": nbytes,
            "seconds_read": t_read, "seconds_gemm": t_gemm, "seconds_write": t_write,
            "seconds_total": t_total,
            "gemm_gflops": flops / t_gemm / 1e9 if t_gemm > 0 else float("nan"),
            "write_gb_per_s": nbytes / t_write / 1e9 if t_write > 0 else float("nan"),
            "ranks": comm.size, "parallel_io": parallel, "float32": bool(float32)}


def _coefficient_histories(nt: int, q: np.ndarray, q_dot: np.ndarray, q_ddot: np.ndarray,
                           steps: Sequence[int] | np.ndarray | None,
                           extra: list[ExtraBasis]
                           ) -> tuple[np.ndarray, list[np.ndarray], int]:
    """Check the histories; return the stored steps, the coefficient histories of all bases
    at them (displacement, velocity, acceleration: each (ns, M), C-contiguous, trailing
    all-zero columns dropped) and the number of modes ``m``."""
    q, q_dot, q_ddot = (np.asarray(a, dtype=float) for a in (q, q_dot, q_ddot))
    if q.ndim != 2 or q.shape[0] != nt or q_dot.shape != q.shape or q_ddot.shape != q.shape:
        raise ValueError(f"modal histories must be (nt, m) = ({nt}, m), got q {q.shape}, "
                         f"q_dot {q_dot.shape}, q_ddot {q_ddot.shape}")
    for e in extra:
        g = [np.asarray(a) for a in e[2:5]]
        if g[0].ndim != 2 or g[0].shape[0] != nt or any(a.shape != g[0].shape for a in g):
            raise ValueError(f"extra basis {e[0]}:{e[1]}: g, g_dot, g_ddot must be (nt, k) "
                             f"with nt = {nt}, got {[a.shape for a in g]}")
    steps = np.arange(nt) if steps is None else np.asarray(steps, dtype=np.int64)
    if steps.ndim != 1 or len(steps) == 0 or steps.min() < 0 or steps.max() >= nt:
        raise ValueError(f"steps must be a non-empty list of indices in [0, {nt})")
    # coefficient histories of all bases, restricted to the stored steps (small: ns x M)
    hist = [np.ascontiguousarray(np.hstack([a[steps]] + [np.asarray(e[2 + i], float)[steps]
                                                         for e in extra]))
            for i, a in enumerate((q, q_dot, q_ddot))]
    # a field whose trailing coefficients are all zero (e.g. a static correction applied to
    # the displacements only) multiplies only its leading basis rows
    hist = [np.ascontiguousarray(h[:, :_leading_columns(h)]) for h in hist]
    return steps, hist, q.shape[1]


class _RankBasis(NamedTuple):
    """This rank's share of the bases, and the mesh of ``modes.h5`` the fields file copies.

    Attributes
    ----------
    n
        Nodes of the mesh.
    nodes
        The nodes this rank owns (:func:`node_range`).
    phi2
        Their rows of all bases, C-contiguous (m + sum k, 3 n_local).
    hexes_shape, hexes_dtype, part_dtype
        Shape and dtype of ``mesh/hexes``, dtype of ``mesh/hex_part``.
    """

    n: int
    nodes: slice
    phi2: np.ndarray
    hexes_shape: tuple[int, ...]
    hexes_dtype: str
    part_dtype: str


def _read_mode_shapes(comm: MPI.Comm, parallel: bool, modes_path: Path, m: int,
                      extra: list[ExtraBasis]) -> _RankBasis:
    """Check ``modes.h5`` (complete, at least ``m`` modes) and read this rank's rows of its
    first ``m`` mode shapes and of the extra bases (collective; an error on any rank is
    raised on every rank)."""

    def shapes():
        import h5py

        with h5py.File(modes_path, "r") as f:
            d = f["modes/translation"]
            return (int(f.attrs.get("complete", 0)), d.shape, f["mesh/hexes"].shape,
                    f["mesh/hexes"].dtype.str, f["mesh/hex_part"].dtype.str)

    complete, tshape, hshape, hdtype, pdtype = on_root(shapes, comm)
    if complete != 1:                       # the same decision on every rank
        raise ValueError(f"{modes_path} is not a complete modes file")
    n = tshape[1]
    if m > tshape[0]:
        raise ValueError(f"q has {m} modal coordinates but {modes_path} holds only "
                         f"{tshape[0]} modes")
    nodes = node_range(n, comm.size, comm.rank)
    nl = nodes.stop - nodes.start
    error = None
    phi = None
    try:
        phi = _read_basis(comm, parallel, modes_path, m, extra, nodes, n)
    except Exception as exc:       # re-raised on every rank below
        error = exc
    check_collective(comm, error, f"reading the mode shapes of {modes_path}")
    return _RankBasis(n, nodes, phi.reshape(phi.shape[0], 3 * nl), hshape, hdtype, pdtype)


def _max_over_ranks(comm: MPI.Comm, value: float) -> float:
    """The largest ``value`` of all ranks (collective)."""
    return comm.allreduce(value, op=_mpi_max()) if comm.size > 1 else value


def _mpi_min():
    from mpi4py import MPI

    return MPI.MIN


def _mpi_max():
    from mpi4py import MPI

    return MPI.MAX


def _copy_mesh(modes_path: Path, dsets: dict, times: np.ndarray, steps: np.ndarray) -> None:
    """Rank 0: copy the mesh arrays from ``modes.h5`` and write the times."""
    import h5py

    with h5py.File(modes_path, "r") as src:
        mesh = [src["mesh/" + key][()] if dsets[key].size else None
                for key in ("points", "hexes", "hex_part")]
    fill_fields_mesh(dsets, times, steps, *mesh)


def _stream(comm: MPI.Comm, dsets: dict, hist: list[np.ndarray], phi2: np.ndarray, buf: np.ndarray,
            buf32: np.ndarray | None, nb: int, ns: int, nodes: slice, parallel: bool,
            gather: bool, stats: dict, rep: Reporter | None, out_path: Path) -> None:
    """GEMM + collective write of every block of steps and every field.

    Errors are checked on all ranks after every GEMM and every write, so that a failure
    on one rank makes every rank raise instead of waiting in the next collective call.
    Every computed block is checked for non-finite values before it is written (the
    data check of ``fields.h5`` on write).
    """
    nl = nodes.stop - nodes.start
    t_first = time.perf_counter()
    last = -1e9
    ranges = comm.allgather((nodes.start, nodes.stop)) if gather else None
    for s0 in range(0, ns, nb):
        s1 = min(ns, s0 + nb)
        b = s1 - s0
        for name, h in zip(FIELD_NAMES, hist):
            error = None
            t0 = time.perf_counter()
            out = buf[:b]
            try:
                _gemm(h[s0:s1], phi2[:h.shape[1]], out)
                bad = nonfinite(f"the {name} field", out)
                if bad:
                    from ..errors import DataError

                    raise DataError(f"{bad[0]} (steps {s0}..{s1 - 1}); {out_path} was not "
                                    "written: its inputs hold non-finite values")
                if buf32 is not None:
                    np.copyto(buf32[:b], out, casting="same_kind")
                    out = buf32[:b]
            except Exception as exc:   # checked collectively
                error = exc
            stats["t_gemm"] += time.perf_counter() - t0
            check_collective(comm, error, f"computing the {name} field of {out_path}")
            t0 = time.perf_counter()
            try:
                block = out.reshape(b, nl, 3)
                if gather:
                    _gather_write(comm, dsets.get(name), block, s0, b, ranges)
                else:
                    write_slab(dsets[name], (s0, nodes.start, 0), (b, nl, 3), block, parallel)
            except Exception as exc:   # checked collectively
                error = exc
            stats["t_write"] += time.perf_counter() - t0
            check_collective(comm, error, f"writing {out_path}")
        now = time.perf_counter()
        if rep is not None and (now - last > 2.0 or s1 == ns):
            last = now
            rep.progress(f"fields: {s1}/{ns} steps", s1, ns, t_first)


def _leading_columns(h: np.ndarray) -> int:
    """Number of leading columns of ``h`` up to its last column with a nonzero entry."""
    nonzero = np.flatnonzero(np.any(h != 0.0, axis=0))
    return int(nonzero[-1]) + 1 if nonzero.size else 1


def _gemm(q_block: np.ndarray, phi2: np.ndarray, out: np.ndarray) -> None:
    """``out = q_block @ phi2`` (BLAS GEMM on C-contiguous arrays, no temporary)."""
    np.matmul(q_block, phi2, out=out)


def _gather_write(comm: MPI.Comm, ds, block: np.ndarray, s0: int, b: int, ranges) -> None:
    """Without parallel HDF5: rank 0 receives every rank's block and writes it.

    Rank 0 keeps receiving after a failed write (the error is raised afterwards), so the
    other ranks never wait forever in ``Send``.
    """
    if comm.rank != 0:
        comm.Send(np.ascontiguousarray(block), dest=0, tag=77)
        return
    error = None
    for r in range(comm.size):
        a, z = ranges[r]
        if r == 0:
            data = block
        else:
            data = np.empty((b, z - a, 3), dtype=block.dtype)
            comm.Recv(data, source=r, tag=77)
        if z > a and error is None:
            try:
                ds[s0:s0 + b, a:z, :] = data
            except Exception as exc:   # raised once everything is received
                error = exc
    if error is not None:
        raise error
