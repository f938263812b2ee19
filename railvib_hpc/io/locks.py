"""Locks: one command at a time per output folder, re-entrant within the thread holding it.

One lock per output folder (:func:`output_lock`): ``fcntl.flock`` on
``<out>/.railvib/lock``, held by rank 0 for the whole command and re-entrant within the
thread that took it; the holder writes its pid, host and command into the file. A second
command into the same folder -- another process, or another thread of this process (a
second :class:`~railvib_hpc.api.Pipeline` on the same folder) -- refuses at once naming
the holder, or waits with ``wait=True`` (``--wait``). Taking the lock removes the
temporary files of dead processes (:func:`~railvib_hpc.io.temp_names.remove_stale_temps`).
(``flock`` works across the nodes of a cluster on NFSv4 and Lustre; on file systems
without distributed locks, concurrent jobs must use different ``--out`` folders.)

API
---
:func:`output_lock` (collective context manager), :func:`acquire_lock`,
:func:`release_lock`, :func:`holds_lock`.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..errors import OutputError, OutputLockedError, os_error_text
from .atomic import size_text
from .digests import utc_now
from .files import LOCK_FILE, RECORD_DIR
from .out_folder import refuse_foreign_folder
from .temp_names import remove_stale_temps

#: (fd None while the owning thread is still taking the file lock; holder: who, in
#: words). Guarded by :data:`_HELD_COND`.
_HELD: dict[str, list] = {}
#: Guards :data:`_HELD`; threads waiting for a folder held by another thread wait on it.
_HELD_COND = threading.Condition()


def _holder_text(lock: Path) -> str:
    try:
        info = json.loads(lock.read_text() or "{}")
    except (OSError, ValueError):
        info = {}
    if not info:
        return "another railvib process"
    return (f"pid {info.get('pid')} on {info.get('host')} ('{info.get('command')}', since "
            f"{info.get('started')})")


def _locked_error(out_dir: Path, holder: str) -> OutputLockedError:
    return OutputLockedError(f"the output folder {out_dir} is in use by {holder}; wait for "
                             "it to finish, use another --out, or add --wait")


def _claim(key: str, out_dir: Path, command: str, wait: bool,
           notify: Callable[[str], None] | None) -> bool:
    """Claim ``key`` for this thread in :data:`_HELD`: True when this thread already holds
    it (one level more), False when it is newly claimed (the file lock is still to take).
    Another thread of this process holding it refuses like another process, or waits."""
    me = threading.get_ident()
    with _HELD_COND:
        held = _HELD.get(key)
        if held is not None and held[2] == me:
            held[1] += 1
            return True
        if held is not None:
            holder = held[3]
            if not wait:
                raise _locked_error(out_dir, holder)
            if notify is not None:
                notify(f"waiting for the output folder {out_dir}, in use by {holder}")
            _HELD_COND.wait_for(lambda: key not in _HELD)
        _HELD[key] = [None, 1, me, f"thread {threading.get_native_id()} of this process "
                      f"(pid {os.getpid()}, '{command}', since {utc_now()})"]
        return False


def _unclaim(key: str) -> None:
    with _HELD_COND:
        _HELD.pop(key, None)
        _HELD_COND.notify_all()


def acquire_lock(out_dir: Path, command: str, wait: bool = False,
                 notify: Callable[[str], None] | None = None) -> tuple[int, int]:
    """Take the lock of ``out_dir`` for this thread (re-entrant within it); rank 0 only.

    Another process, or another thread of this process, holding it refuses (or, with
    ``wait``, waits). Creates the folder. Returns the number and bytes of stale temporary
    files removed.

    Raises
    ------
    OutputLockedError
        When another process or thread holds it and ``wait`` is False.
    OutputError
        When the folder cannot be created or used.
    OutputFolderError
        When railvib must not write there: its own source tree, or a folder of someone
        else's files of railvib's names (:mod:`.out_folder`).
    """
    refuse_foreign_folder(out_dir)            # its own source tree, someone else's files
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        key = os.path.realpath(out_dir)
    except OSError as exc:
        raise _folder_error(out_dir, exc) from None
    lock = out_dir / RECORD_DIR / LOCK_FILE
    if _claim(key, out_dir, command, wait, notify):
        return 0, 0
    try:
        try:
            (out_dir / RECORD_DIR).mkdir(exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise _folder_error(out_dir, exc) from None
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _holder_text(lock)
                if not wait:
                    raise _locked_error(out_dir, holder) from None
                if notify is not None:
                    notify(f"waiting for the output folder {out_dir}, in use by {holder}")
                fcntl.flock(fd, fcntl.LOCK_EX)
            info = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
                    "thread": threading.get_native_id(), "started": utc_now()}
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(info).encode(), 0)
        except BaseException:
            os.close(fd)
            raise
    except BaseException:
        _unclaim(key)
        raise
    with _HELD_COND:
        _HELD[key][0] = fd
    try:
        return remove_stale_temps(out_dir)
    except OSError:
        return 0, 0


def _folder_error(out_dir: Path, exc: OSError) -> OutputError:
    reason = os.strerror(exc.errno) if exc.errno else os_error_text(exc)
    where = f" ({exc.filename})" if exc.filename and str(exc.filename) != str(out_dir) \
        else ""
    return OutputError(f"cannot use the output folder {out_dir}: {reason}{where}")


def release_lock(out_dir: Path) -> None:
    """Release one level of this thread's lock of ``out_dir`` (rank 0); a lock that another
    thread holds is left alone."""
    key = os.path.realpath(out_dir)
    with _HELD_COND:
        held = _HELD.get(key)
        if held is None or held[2] != threading.get_ident() or held[0] is None:
            return
        held[1] -= 1
        if held[1] > 0:
            return
        fd = held[0]
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        del _HELD[key]
        _HELD_COND.notify_all()


def holds_lock(out_dir: Path) -> bool:
    """True when this thread holds the lock of ``out_dir``."""
    held = _HELD.get(os.path.realpath(out_dir))
    return held is not None and held[2] == threading.get_ident() and held[0] is not None


@contextlib.contextmanager
def output_lock(out_dir: str | os.PathLike, comm, command: str, wait: bool = False,
                rep=None) -> Iterator[None]:
    """Hold the lock of ``out_dir`` for the block (collective; rank 0 holds it).

    Re-entrant within a thread: stages called by a command that holds the lock do not lock
    again. Another thread of this process is kept out like another process. Prints how
    many temporary files of interrupted runs were removed.
    """
    from ..parallel import on_root

    out_dir = Path(out_dir)
    notify = rep.info if rep is not None else None
    if wait and comm is not None and comm.size > 1:
        count, nbytes = _root_while_others_sleep(
            lambda: acquire_lock(out_dir, command, wait, notify), comm)
    else:
        count, nbytes = on_root(lambda: acquire_lock(out_dir, command, wait, notify), comm)
    if count and rep is not None:
        rep.info(f"removed {count} temporary file(s) ({size_text(nbytes)}) left in {out_dir} by "
                 "interrupted runs")
    try:
        yield
    finally:
        if comm is None or comm.rank == 0:
            release_lock(out_dir)


def _root_while_others_sleep(fn: Callable[[], Any], comm) -> Any:
    """Like :func:`~railvib_hpc.parallel.on_root` for a call that may block for long (waiting
    for a lock): the other ranks poll a non-blocking receive and sleep, instead of spinning
    in a broadcast."""
    import time

    from ..parallel import root_outcome, settle

    tag = 7316
    original = None
    if comm.rank == 0:
        outcome, original = root_outcome(fn)
        for r in range(1, comm.size):
            comm.send(outcome, dest=r, tag=tag)
    else:
        req = comm.irecv(source=0, tag=tag)
        while True:
            done, outcome = req.test()
            if done:
                break
            time.sleep(0.2)
    return settle(outcome, original)
