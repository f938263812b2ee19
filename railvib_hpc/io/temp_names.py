"""Temporary names: the name of a file while it is written, and the removal of stale ones.

Every file is written under :func:`temp_path`
(``.<name>.part-<host>-<pid>_t<thread>_<random>``, unique per writer, threads included)
and renamed when complete (:mod:`railvib_hpc.io.atomic`); a result written over several
runs lives under :func:`resume_path` (``.<name>.resume``) until it is complete.
:func:`final_name` maps a temporary name back to its file. Taking a folder's lock
(:mod:`railvib_hpc.io.locks`) removes the temporary files of dead processes
(:func:`remove_stale_temps`).
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import threading
import uuid
from pathlib import Path

from .files import RECORD_DIR


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9.-]", "_", socket.gethostname()) or "host"


def temp_path(path: str | os.PathLike, suffix: bool = False) -> Path:
    """The temporary name of ``path`` while it is written:
    ``.<name>.part-<host>-<pid>_t<thread>_<random>`` (with ``suffix``, the file's extension
    again at the end, for writers such as gmsh that choose the format by it).

    Unique per writer: two threads of one process (two :class:`~railvib_hpc.api.Pipeline`
    objects), or two writes of one thread, never share a temporary name. The pid stays in
    the name for :func:`remove_stale_temps`.
    """
    path = Path(path)
    token = f"{os.getpid()}_t{threading.get_native_id()}_{uuid.uuid4().hex[:12]}"
    return path.with_name(f".{path.name}.part-{_host()}-{token}"
                          + (path.suffix if suffix else ""))


def final_name(name: str) -> str:
    """The final file name of a temporary name of :func:`temp_path` (others unchanged)."""
    m = _TEMP_RE.match(name)
    if not m:
        if name.startswith(".") and name.endswith(_RESUME_SUFFIX):
            return name[1:-len(_RESUME_SUFFIX)]
        return name
    return name[1:name.rindex(".part-" if ".part-" in name else ".copy-")]


_RESUME_SUFFIX = ".resume"


def resume_path(path: str | os.PathLike) -> Path:
    """The temporary name of a result that is written over several runs: ``.<name>.resume``
    (a resumable run's partial file, e.g. the fields of an interrupted ``railvib
    transient``).

    Unlike :func:`temp_path` it names no process, and :func:`remove_stale_temps` leaves it:
    a later run continues it when the provenance it carries matches its checkpoint, and
    deletes it otherwise. Complete it with :func:`~railvib_hpc.io.atomic.start_h5` ...
    :func:`~railvib_hpc.io.atomic.commit_h5`.
    """
    path = Path(path)
    return path.with_name(f".{path.name}{_RESUME_SUFFIX}")


#: A temporary name of :func:`temp_path`: ``.<name>.part-<host>-<pid>[_t<tid>_<hex>][.ext]``
#: (the older ``.<name>.part-<host>-<pid>`` and ``.<name>.part-<pid>`` included).
_TEMP_RE = re.compile(r"^\..+\.(?:part|copy)-(?:(?P<host>.+)-)?(?P<pid>\d+)"
                      r"(?:_t\d+_[0-9a-f]+)?(?:\.[A-Za-z0-9]+)?$")
_OLD_GMSH_TEMP = re.compile(r"^.+\.part\.msh$")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(folder: Path) -> tuple[int, int]:
    """Delete temporary files of dead processes in ``folder`` and its direct subfolders.

    Call only while holding the folder's lock: a temporary file of another host, or of a
    process of this host that no longer runs, then belongs to an interrupted run.

    Returns
    -------
    tuple
        Number of files and bytes removed.
    """
    count, nbytes = 0, 0
    host = _host()
    dirs = [folder] + [d for d in folder.iterdir() if d.is_dir() and not d.is_symlink()
                       and d.name != RECORD_DIR]
    for d in dirs:
        for p in d.iterdir():
            m = _TEMP_RE.match(p.name)
            stale = False
            if m:
                same_host = m["host"] is None or m["host"] == host
                stale = not same_host or not _pid_alive(int(m["pid"]))
            elif _OLD_GMSH_TEMP.match(p.name):
                stale = True
            if stale and p.is_file():
                with contextlib.suppress(OSError):
                    size = p.stat().st_size
                    p.unlink()
                    count += 1
                    nbytes += size
    return count, nbytes
