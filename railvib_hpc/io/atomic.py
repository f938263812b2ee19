"""Atomic writes: every file written under a temporary name, checked, synced and renamed.

Every file is written under its :func:`~railvib_hpc.io.temp_names.temp_path`, checked (it
exists, is not empty, re-reads; HDF5 files are created, reserved with ``fallocate`` for
their predicted size and only then filled, so a full disk fails before any data is
written), flushed to disk (``fsync``), renamed and then recorded
(:func:`~railvib_hpc.io.digests.record_file`). Free space is checked against the
predicted size first. A stage deletes a stale result before recomputing it, so an
interrupted run never leaves a stale file that looks current.

API
---
:func:`write_h5` (collective HDF5), :func:`start_h5` + :func:`commit_h5` (the same steps
around a file filled over a long computation, e.g. under its
:func:`~railvib_hpc.io.temp_names.resume_path`), :func:`write_json`, :func:`write_text`,
:func:`atomic_file`, :func:`copy_file`, :func:`ensure_space`, :func:`reserve`,
:func:`free_bytes`, :func:`needed_bytes`, :func:`size_text`.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import os
import shutil
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import OutputError, UserError, exception_text, os_error_text
from .digests import hash_file, record_file, write_record
from .temp_names import temp_path

#: Free-space margin on top of a file's predicted size: HDF5 metadata, attributes
#: (the case TOML), companions; relative part and absolute part.
SPACE_MARGIN = (0.05, 8 * 2**20)


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):           # not every file system allows it
        _fsync_path(folder)


def free_bytes(folder: Path) -> int:
    """Bytes available to this user in ``folder``'s file system."""
    st = os.statvfs(folder)
    return st.f_bavail * st.f_frsize


def needed_bytes(size_hint: int) -> int:
    """Predicted size plus the :data:`SPACE_MARGIN`."""
    return int(size_hint * (1.0 + SPACE_MARGIN[0])) + SPACE_MARGIN[1]


def ensure_space(folder: str | os.PathLike, size_hint: int, what: str) -> None:
    """Raise :class:`OutputError` when ``folder`` lacks room for ``size_hint`` bytes (+ margin).

    HDF5 can crash or hang on a full disk, so every big file is checked before it is
    created.
    """
    folder = Path(folder)
    need = needed_bytes(size_hint)
    free = free_bytes(folder)
    if free < need:
        raise OutputError(f"not enough free space in {folder} to write {what}: it needs "
                          f"{size_text(need)} (predicted {size_text(size_hint)} + margin), "
                          f"{size_text(free)} are free; free some space or use another --out")


def size_text(n: float) -> str:
    """A byte count in words: ``512 B``, ``1.5 MB`` (decimal units)."""
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return f"{n:.1f} TB"


_FALLOC_FL_KEEP_SIZE = 1


def reserve(path: Path, nbytes: int) -> bool:
    """Reserve ``nbytes`` of disk for ``path`` without changing its size (Linux ``fallocate``
    with ``FALLOC_FL_KEEP_SIZE``), so later writes cannot fail for lack of space.

    Returns
    -------
    bool
        True when reserved, False when the file system does not support it.

    Raises
    ------
    OutputError
        When there is not enough space.
    """
    if nbytes <= 0 or not hasattr(os, "posix_fallocate"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fallocate = libc.fallocate
    except (OSError, AttributeError):
        return False
    fallocate.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
    fd = os.open(path, os.O_RDWR)
    try:
        if fallocate(fd, _FALLOC_FL_KEEP_SIZE, 0, int(nbytes)) != 0:
            err = ctypes.get_errno()
            if err in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                raise OutputError(f"cannot reserve {size_text(nbytes)} for {path.name} in "
                                  f"{path.parent}: {os.strerror(err)}; free some space or use "
                                  "another --out")
            return False                       # EOPNOTSUPP, EINVAL, ...: not supported
    finally:
        os.close(fd)
    return True


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, *, size_hint: int = 0,
                check: Callable[[Path], Sequence[str]] | None = None, record: bool = False,
                suffix: bool = False) -> Iterator[Path]:
    """Yield a temporary path for ``path``; on success check, fsync, rename (and record).

    Serial (one process). The temporary file is removed whatever happens; any
    ``OSError`` becomes :class:`OutputError` naming ``path``.

    Parameters
    ----------
    size_hint
        Predicted size: free space is checked before the block runs.
    check
        ``check(tmp) -> problems`` re-reads the written file (e.g. a truncated ``.msh``
        that ``gmsh.write`` did not report); any problem fails the write.
    record
        Record the content digest (stage files).
    suffix
        Keep the extension at the end of the temporary name (see :func:`temp_path`).
    """
    path = Path(path)
    tmp = temp_path(path, suffix)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if size_hint:
            ensure_space(path.parent, size_hint, path.name)
        yield tmp
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise OutputError(f"writing {path} failed: the written file is missing or empty "
                              "(disk full?)")
        _reread(check, tmp, path)
        _fsync_path(tmp)
        os.replace(tmp, path)
        _fsync_dir(path.parent)
        if record:
            write_record(path, hash_file(path))
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"writing {path}: {os_error_text(exc)}") from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_text(path: str | os.PathLike, text: str, record: bool = False) -> None:
    """Write a text file atomically (temporary name, fsync, rename)."""
    data = text.encode()
    with atomic_file(path, size_hint=len(data)) as tmp:
        tmp.write_bytes(data)
    if record:
        write_record(Path(path), hash_file(path))


def write_json(path: str | os.PathLike, doc: Mapping[str, Any], prov: Mapping[str, Any]
               | None = None) -> str:
    """Write a JSON stage file atomically with its provenance and ``complete = true`` last;
    record it. Returns its content digest."""
    body = dict(doc)
    if prov is not None:
        body["provenance"] = dict(prov)
    body["complete"] = True
    write_text(path, json.dumps(body, indent=1, default=_json_default))
    return record_file(Path(path))


def _json_default(x: Any) -> Any:
    try:
        import numpy as np

        if isinstance(x, np.generic):
            return x.item()
        if isinstance(x, np.ndarray):
            return x.tolist()
    except ImportError:  # pragma: no cover
        pass
    return float(x)


def _reread(check: Callable[[Path], Sequence[str]] | None, tmp: Path, path: Path) -> None:
    """Run a re-read check on a just-written temporary file; raise when it fails."""
    if check is None:
        return
    try:
        problems = list(check(tmp))
    except (OSError, ValueError, KeyError, IndexError, TypeError) as exc:
        problems = [f"it cannot be read back ({exception_text(exc)})"]
    if problems:
        raise OutputError(f"writing {path} failed: {problems[0]} (disk full or a bad file "
                          "system?)")


def _sync_h5(comm, error: BaseException | None, what: str, folder: Path) -> None:
    """Raise ``error`` of any rank on every rank (an ``OSError`` as :class:`OutputError`)."""
    from ..parallel import check_collective

    if isinstance(error, OSError) and not error.errno and not isinstance(error, UserError):
        with contextlib.suppress(OSError):        # MPI-IO reports no errno: name the cause
            if free_bytes(folder) < SPACE_MARGIN[1]:
                error = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    if comm is not None:
        check_collective(comm, error, what)
    elif error is not None:
        if isinstance(error, OSError) and not isinstance(error, UserError):
            raise OutputError(f"{what}: {os_error_text(error)}") from None
        raise error


def _sync_or_remove(comm, error: BaseException | None, what: str, folder: Path,
                    tmp: Path) -> None:
    """:func:`_sync_h5`, removing the temporary file ``tmp`` when any rank failed."""
    try:
        _sync_h5(comm, error, what, folder)
    except BaseException:
        _remove(comm, tmp)
        raise


def _remove(comm, tmp: Path) -> None:
    if comm is None or comm.rank == 0:
        with contextlib.suppress(OSError):
            tmp.unlink()


def start_h5(tmp: str | os.PathLike, comm, *, size_hint: int, what: str) -> None:
    """Create the temporary HDF5 file ``tmp`` of a stage file (collective over ``comm``).

    Rank 0 checks the free space for ``size_hint`` bytes (plus margin), creates the file
    with ``complete = 0`` and reserves the space, so that the data writes that follow
    cannot hit a full disk. The caller then opens it (``r+``, every rank with ``mpio`` or
    rank 0) and fills it; :func:`commit_h5` completes it. An error on any rank raises on
    every rank and removes the file. ``what`` names the final file in the messages.
    """
    import h5py

    tmp = Path(tmp)
    error = None
    if comm is None or comm.rank == 0:
        try:
            tmp.parent.mkdir(parents=True, exist_ok=True)
            ensure_space(tmp.parent, size_hint, what)
            with h5py.File(tmp, "w") as f:
                f.attrs["complete"] = 0
            reserve(tmp, needed_bytes(size_hint))
        except BaseException as exc:
            error = exc
    _sync_or_remove(comm, error, f"writing {tmp.parent / what}", tmp.parent, tmp)


def commit_h5(tmp: str | os.PathLike, path: str | os.PathLike, comm, *,
              check: Callable[[Path], Sequence[str]] | None = None,
              record: bool = True) -> str:
    """Complete a filled temporary HDF5 file and make it ``path`` (collective over ``comm``).

    Rank 0 sets ``complete = 1``, runs ``check(tmp)`` (re-read), fsyncs and renames; the
    content digest is computed on every rank and recorded. Call it after every rank closed
    the file. An error on any rank raises on every rank, and the temporary file is
    removed.

    Returns
    -------
    str
        The content digest of ``path`` ("" with ``record=False``).
    """
    import h5py

    tmp, path = Path(tmp), Path(path)
    error = None
    if comm is None or comm.rank == 0:
        try:
            with h5py.File(tmp, "r+") as f:
                f.attrs["complete"] = 1
            _reread(check, tmp, path)
            _fsync_path(tmp)
            os.replace(tmp, path)
            _fsync_dir(path.parent)
        except BaseException as exc:
            error = exc
    _sync_or_remove(comm, error, f"writing {path}", path.parent, tmp)
    if not record:
        return ""
    return record_file(path, comm)


def write_h5(path: str | os.PathLike, comm, fill: Callable[[Any, bool], None], *,
             size_hint: int, attrs: Mapping[str, Any] | None = None,
             parallel: bool | None = None,
             before_complete: Callable[[Path], None] | None = None,
             check: Callable[[Path], Sequence[str]] | None = None, record: bool = True,
             fill_everywhere: bool = False) -> str:
    """Write an HDF5 stage file atomically; collective over ``comm`` (None: serial).

    Steps: free space checked (rank 0); the file is created under its temporary name
    and ``size_hint`` bytes reserved (so data writes cannot hit a full disk; :func:`start_h5`);
    it is opened on every rank with the ``mpio`` driver (``parallel``) or on rank 0, the
    provenance ``attrs`` and ``complete = 0`` are written and ``fill(file, parallel)``
    writes the data; ``before_complete(tmp)`` may add more (collective); rank 0 sets
    ``complete = 1``, runs ``check(tmp)`` (re-read), fsyncs and renames; the content
    digest is computed on every rank and recorded (:func:`commit_h5`). An error on any
    rank raises on every rank (``OSError`` as :class:`OutputError`), and no file is left
    behind.

    ``fill_everywhere``: call ``fill(None, False)`` on the ranks that do not open the
    file (without parallel HDF5 they send their data to rank 0 inside ``fill``).

    Returns
    -------
    str
        The content digest of the new file.
    """
    import h5py

    from .parallel_h5 import h5py_parallel_ok

    path = Path(path)
    rank = comm.rank if comm is not None else 0
    if parallel is None:
        parallel = comm is not None and h5py_parallel_ok(comm)
    tmp = temp_path(path)
    if comm is not None and comm.size > 1:
        tmp = Path(comm.bcast(str(tmp) if rank == 0 else None, root=0))
    if comm is not None and comm.size > 1:
        attrs = comm.bcast(dict(attrs or {}) if rank == 0 else None, root=0)
    start_h5(tmp, comm, size_hint=size_hint, what=path.name)
    try:
        error = None
        try:
            if parallel or rank == 0:
                kw = {"driver": "mpio", "comm": comm} if parallel else {}
                with h5py.File(tmp, "r+", **kw) as f:
                    for k, v in (attrs or {}).items():
                        f.attrs[k] = v
                    f.attrs["complete"] = 0
                    fill(f, bool(parallel))
            elif fill_everywhere:
                fill(None, False)
        except BaseException as exc:
            error = exc
        _sync_h5(comm, error, f"writing {path}", path.parent)
        if before_complete is not None:
            before_complete(tmp)
    except BaseException:
        _remove(comm, tmp)
        raise
    return commit_h5(tmp, path, comm, check=check, record=record)


def copy_file(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` atomically (temporary name, rename)."""
    with atomic_file(dst) as tmp:
        shutil.copyfile(src, tmp)
