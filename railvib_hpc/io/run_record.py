"""``run.json``: what each stage call in an output folder cost, and with which software.

Every stage call made through the runner (:class:`~railvib_hpc.io.stage_protocol.StageRunner`:
every ``railvib`` stage command, ``railvib run``, the Python API's
:class:`~railvib_hpc.api.Pipeline` and the studies' variants) appends one entry to
``<out>/run.json`` and replaces the stage's entry in its ``stages`` table. The file is
rewritten atomically through the stage-file layer
(:func:`~railvib_hpc.io.atomic.atomic_file`: temporary name, fsync, rename) by rank 0
while the output folder's lock is held, so concurrent commands cannot interleave.

Layout (``format_version`` 1)::

    railvib_file    "run.json"
    format_version  1
    folder          the output folder (absolute)
    created         UTC time of the first entry
    updated         UTC time of the last entry
    stages          {stage: its latest entry}           (the table bench/ scripts read)
    calls           [entry, ...]                        (every call, oldest first; the
                                                        last MAX_CALLS are kept)

One entry::

    stage           mesh | modal | mbs | reconstruct | assess | ...
    status          "ok" or "failed"
    error           the one-line error (failed calls only)
    started, finished    UTC times
    wall_s          wall time of the call [s] (rank 0)
    substages       [[name, seconds], ...]: the Reporter's timed parts of the call
    reused          what the stage reused (its output's ``reused``: bool, per file, or
                    null for a stage that gives no reuse verdict, ``assess``)
    ranks, hosts    the MPI ranks and the distinct host names
    peak_rss_gb_per_rank, peak_rss_gb_total, peak_rss_gb_max
                    peak resident memory of every rank's process during the call
                    [GB = 1e9 B] (what the process already held counts too: Python, the
                    libraries, arrays an earlier stage of the same process kept)
    memory_measure  how it was measured (see below)
    command         the command line, or the API call
    case_name, case_file, case_sha256
                    the case (``case_sha256``: :meth:`Case.digest` of every section)
    versions        railvib, python, numpy, scipy, petsc, slepc, petsc4py, slepc4py,
                    mpi (library), mpi4py, h5py, hdf5, gmsh, host OS

Peak memory: at the start of a call every rank resets its process's high-water mark
(Linux: ``5`` written to ``/proc/self/clear_refs``) and reads ``VmHWM`` from
``/proc/self/status`` at its end, so each call reports its own peak even when several
stages run in one process; where that is not possible the process's lifetime peak
(``ru_maxrss``) is reported and ``memory_measure`` says so. A call that failed records
rank 0's memory only (the other ranks may not be able to take part in a collective).

Writing ``run.json`` never fails a stage: when it cannot be written (a full disk, a
read-only folder) rank 0 prints one warning line and the stage's own result stands.
"""

from __future__ import annotations

import contextlib
import datetime
import functools
import json
import os
import platform
import resource
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import __version__
from ..constants import BYTES_PER_GB
from ..errors import UserError
from .files import RUN_FILE

if TYPE_CHECKING:
    from mpi4py import MPI

#: Format of :data:`~railvib_hpc.io.files.RUN_FILE` (bumped when its layout changes).
RUN_FORMAT = 1
#: Entries kept in ``calls`` (oldest dropped first): a folder reused for years stays small.
MAX_CALLS = 500
#: Bytes per kB in ``/proc/self/status`` and ``ru_maxrss`` (Linux reports KiB).
_BYTES_PER_KB = 1024


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


# ----------------------------------------------------------------------------- memory
def reset_peak_memory() -> bool:
    """Reset this process's resident-memory high-water mark (Linux); True when done."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return True


def peak_memory_gb() -> tuple[float, str]:
    """This process's peak resident memory [GB] and how it was read.

    ``VmHWM`` of ``/proc/self/status`` (since the last :func:`reset_peak_memory`), else
    ``ru_maxrss`` (the process's lifetime peak).
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * _BYTES_PER_KB / BYTES_PER_GB, "VmHWM"
    except (OSError, ValueError, IndexError):
        pass
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb * _BYTES_PER_KB / BYTES_PER_GB, "ru_maxrss"


# ----------------------------------------------------------------------------- versions
def _dist_version(name: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


@functools.lru_cache(maxsize=1)
def _static_versions() -> dict[str, str | None]:
    """The versions that cannot change within a process (imports nothing heavy but
    numpy, scipy, h5py and mpi4py, which every stage loads anyway)."""
    import numpy
    import scipy

    out: dict[str, str | None] = {
        "railvib": __version__, "python": platform.python_version(),
        "numpy": numpy.__version__, "scipy": scipy.__version__,
        "petsc4py": _dist_version("petsc4py"), "slepc4py": _dist_version("slepc4py"),
        "gmsh": _dist_version("gmsh"),
        "os": f"{platform.system()} {platform.release()} {platform.machine()}",
    }
    try:
        import h5py

        out["h5py"] = h5py.__version__
        out["hdf5"] = h5py.version.hdf5_version
        out["h5py_mpi"] = "yes" if h5py.get_config().mpi else "no"
    except ImportError:
        out["h5py"] = out["hdf5"] = None
    try:
        import mpi4py
        from mpi4py import MPI

        out["mpi4py"] = mpi4py.__version__
        out["mpi"] = (MPI.Get_library_version().replace("\0", "").strip().splitlines()
                      or [""])[0].strip(", ")
        out["mpi_standard"] = "{}.{}".format(*MPI.Get_version())
    except ImportError:
        out["mpi4py"] = out["mpi"] = None
    return out


def versions() -> dict[str, str | None]:
    """The versions of everything a result depends on.

    PETSc's and SLEPc's library versions are read from the loaded libraries; a call that
    did not need PETSc (e.g. ``mbs``) leaves PETSc unloaded and reports the installed
    petsc4py/slepc4py (whose version is PETSc's) instead.

    Examples
    --------
    >>> v = versions()
    >>> sorted(k for k in ("railvib", "python", "petsc", "mpi", "h5py", "gmsh") if k in v)
    ['gmsh', 'h5py', 'mpi', 'petsc', 'python', 'railvib']
    """
    out = dict(_static_versions())
    petsc = sys.modules.get("petsc4py.PETSc")
    slepc = sys.modules.get("slepc4py.SLEPc")
    out["petsc"] = ("{}.{}.{}".format(*petsc.Sys.getVersion()) if petsc is not None
                    else f"{out['petsc4py']} (petsc4py; PETSc not loaded)")
    out["slepc"] = ("{}.{}.{}".format(*slepc.Sys.getVersion()) if slepc is not None
                    else f"{out['slepc4py']} (slepc4py; SLEPc not loaded)")
    return out


# ----------------------------------------------------------------------------- the file
def read_run_record(out_dir: str | os.PathLike) -> dict | None:
    """``<out_dir>/run.json`` (None when missing, unreadable or of another format).

    Examples
    --------
    >>> import tempfile
    >>> read_run_record(tempfile.mkdtemp()) is None
    True
    """
    try:
        doc = json.loads((Path(out_dir) / RUN_FILE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("railvib_file") != RUN_FILE \
            or doc.get("format_version") != RUN_FORMAT:
        return None
    return doc


def append_entry(out_dir: str | os.PathLike, entry: dict[str, Any]) -> Path:
    """Append ``entry`` to ``<out_dir>/run.json`` and make it its stage's latest (rank 0).

    A missing, unreadable or foreign ``run.json`` is started afresh. Written atomically.

    Raises
    ------
    OutputError
        When the file cannot be written.
    """
    from .atomic import atomic_file

    out_dir = Path(out_dir)
    path = out_dir / RUN_FILE
    doc = read_run_record(out_dir) or {
        "railvib_file": RUN_FILE, "format_version": RUN_FORMAT,
        "folder": str(out_dir.resolve()), "created": entry["started"], "stages": {},
        "calls": []}
    doc["updated"] = entry["finished"]
    doc["stages"][entry["stage"]] = entry
    doc["calls"] = [*doc.get("calls", []), entry][-MAX_CALLS:]
    data = json.dumps(doc, indent=1, default=_plain).encode()
    with atomic_file(path) as tmp:
        tmp.write_bytes(data)
    return path


def _plain(x: Any) -> Any:
    if hasattr(x, "tolist"):
        return x.tolist()
    if hasattr(x, "item"):
        return x.item()
    return str(x)


# ----------------------------------------------------------------------------- recording
class StageCall:
    """What :func:`record_stage` yields: give it the stage's result with :meth:`done`."""

    def __init__(self) -> None:
        self.reused: Any = None

    def done(self, result: Any) -> None:
        """The stage returned ``result``: its typed output
        (:class:`~railvib_hpc.io.stage_protocol.StageOutput`, duck-typed), whose
        ``reused`` goes into the entry, or a plain summary dict (its ``reused``)."""
        if isinstance(result, dict):
            self.reused = result.get("reused")
        else:
            self.reused = getattr(result, "reused", None)


@contextlib.contextmanager
def record_stage(out_dir: str | os.PathLike, comm: MPI.Comm | None, stage: str, case,
                 rep, command: str) -> Iterator[StageCall]:
    """Time a stage call and record it in ``<out_dir>/run.json`` (collective on success).

    Call it inside the output folder's lock. ``rep`` is the
    :class:`~railvib_hpc.log.Reporter` of the call (its timings during the block become
    the entry's ``substages``); ``case`` gives the name, file and digest.

    The exception of a failed block is re-raised unchanged after rank 0 recorded it.
    """
    rank = comm.rank if comm is not None else 0
    size = comm.size if comm is not None else 1
    reset = reset_peak_memory()
    started, t0 = _now(), time.perf_counter()
    n_timed = len(rep.timings) if rep is not None else 0
    call = StageCall()
    identity = _case_identity(case)

    def entry(status: str, peaks: list[float], measure: str, hosts: list[str]) -> dict:
        return {"stage": stage, "status": status, "started": started, "finished": _now(),
                "wall_s": time.perf_counter() - t0,
                "substages": [[n, t] for n, t in (rep.timings[n_timed:] if rep else [])],
                "reused": call.reused, "ranks": size, "hosts": sorted(set(hosts)),
                "peak_rss_gb_per_rank": peaks, "peak_rss_gb_total": float(sum(peaks)),
                "peak_rss_gb_max": float(max(peaks)) if peaks else None,
                "memory_measure": measure, "command": command, **identity,
                "versions": versions()}

    def write(doc: dict) -> None:
        try:
            append_entry(out_dir, doc)
        except (UserError, OSError) as exc:
            if rep is not None:
                rep.info(f"warning: could not update {Path(out_dir) / RUN_FILE}: "
                         f"{(str(exc).splitlines() or [''])[0]}")

    measure_of = {"VmHWM": "VmHWM since the call started" if reset else
                  "VmHWM (process lifetime: the reset was refused)",
                  "ru_maxrss": "ru_maxrss (process lifetime peak)"}
    try:
        yield call
    except BaseException as exc:
        if rank == 0:
            with contextlib.suppress(Exception):
                peak, how = peak_memory_gb()
                doc = entry("failed", [peak], measure_of[how] + "; rank 0 only",
                            [socket.gethostname()])
                doc["error"] = (str(exc).splitlines() or [type(exc).__name__])[0]
                write(doc)
        raise
    peak, how = peak_memory_gb()
    mine = (peak, how, socket.gethostname())
    gathered = comm.gather(mine, root=0) if comm is not None and size > 1 else [mine]
    if rank == 0:
        measures = {measure_of[g[1]] for g in gathered}
        write(entry("ok", [g[0] for g in gathered], "; ".join(sorted(measures)),
                    [g[2] for g in gathered]))


def _case_identity(case) -> dict[str, Any]:
    if case is None:
        return {"case_name": None, "case_file": None, "case_sha256": None}
    try:
        sha = case.digest()
    except (OSError, UserError):           # e.g. a mesh.file that vanished: not our error
        sha = None
    return {"case_name": case["case.name"],
            "case_file": str(case.path) if case.path is not None else None,
            "case_sha256": sha}
