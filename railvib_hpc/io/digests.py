"""Content digests: a file's SHA-256 (the same for any number of ranks) and its record.

A file's content digest (:func:`hash_file`) is a SHA-256 over fixed 64 MiB blocks: the
digest of block ``i`` is computed on rank ``i mod size`` and the block digests are
combined in order, so the result does not depend on the number of ranks. It is computed
after the file is closed and renamed and kept in a small record
``<out>/.railvib/<file>.json`` (size, mtime_ns, digest). Later, a file whose size and
modification time match its record is trusted without reading it (:func:`file_digest`);
any other file is hashed again: the same digest refreshes the record, another one means
the file changed after it was written (corrupt). A file without record (deleted
``.railvib``) is hashed and fully data-checked.

API
---
:func:`digest` (JSON objects), :func:`hash_file` (collective), :func:`file_digest`
(trusting a matching record) -> :class:`FileDigest`, :func:`record_file` (hash and
record), :func:`record_path`, :func:`read_record`, :func:`write_record`, :func:`forget`
(a result and its record), :func:`utc_now` (the time stamp of records and provenance).
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .files import RECORD_DIR
from .temp_names import temp_path

#: Block size of the content digest (each block hashed on its own rank).
BLOCK_BYTES = 64 * 2**20
_DIGEST_TAG = b"railvib-sha256-blocks/1\0"


def digest(obj: Any) -> str:
    """SHA-256 of a JSON-serialisable object (canonical: sorted keys, ``str`` for others).

    Examples
    --------
    >>> digest({"b": 1, "a": [1.0, "x"]}) == digest({"a": [1.0, "x"], "b": 1})
    True
    """
    text = json.dumps(obj, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _hash_blocks(path: Path, blocks: Iterable[int]) -> dict[int, bytes]:
    out = {}
    with open(path, "rb") as f:
        for i in blocks:
            f.seek(i * BLOCK_BYTES)
            h = hashlib.sha256()
            left = BLOCK_BYTES
            while left:
                chunk = f.read(min(left, 8 * 2**20))
                if not chunk:
                    break
                h.update(chunk)
                left -= len(chunk)
            out[i] = h.digest()
    return out


def hash_file(path: str | os.PathLike, comm=None) -> str:
    """Content digest of a file: SHA-256 over its 64 MiB blocks (collective with ``comm``).

    Block ``i`` is hashed on rank ``i mod size``; the block digests are combined in
    order with the file size, so the digest is the same for any number of ranks.
    """
    from ..parallel import check_collective

    path = Path(path)
    size = comm.size if comm is not None else 1
    rank = comm.rank if comm is not None else 0
    nbytes, error = 0, None
    try:
        nbytes = os.stat(path).st_size
    except OSError as exc:
        error = exc
    if comm is not None:
        check_collective(comm, error, f"reading {path}")
        nbytes = comm.bcast(nbytes, root=0)
    elif error is not None:
        raise error
    n_blocks = max(1, math.ceil(nbytes / BLOCK_BYTES))
    parts: dict[int, bytes] = {}
    try:
        parts = _hash_blocks(path, range(rank, n_blocks, size))
    except OSError as exc:
        error = exc
    if comm is not None and size > 1:
        check_collective(comm, error, f"reading {path}")
        for p in comm.allgather(parts):
            parts.update(p)
    elif error is not None:
        raise error
    h = hashlib.sha256(_DIGEST_TAG + nbytes.to_bytes(8, "little"))
    for i in range(n_blocks):
        h.update(parts[i])
    return h.hexdigest()


def record_path(path: Path) -> Path:
    """The record of ``path``: ``<folder>/.railvib/<name>.json``."""
    return path.parent / RECORD_DIR / f"{path.name}.json"


def read_record(path: Path) -> dict | None:
    """The record of ``path`` (None when missing or unreadable)."""
    try:
        rec = json.loads(record_path(path).read_text())
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) else None


def write_record(path: Path, sha: str) -> None:
    """Record the size, modification time and content digest of ``path`` (rank 0)."""
    st = os.stat(path)
    rec = {"file": path.name, "size": st.st_size, "mtime_ns": st.st_mtime_ns, "sha256": sha,
           "block_bytes": BLOCK_BYTES, "recorded": utc_now()}
    rp = record_path(path)
    rp.parent.mkdir(exist_ok=True)
    _write_bytes_atomic(rp, json.dumps(rec, indent=1).encode())


def forget(path: Path) -> None:
    """Delete a result file and its record (before it is recomputed; rank 0)."""
    for p in (path, record_path(path)):
        if p.is_symlink() or p.exists():
            p.unlink()


@dataclass(frozen=True)
class FileDigest:
    """Content digest of a file and how it was obtained.

    ``status``: ``recorded`` (the record matches, or the file was hashed and equals it),
    ``unrecorded`` (no record: hashed now) or ``changed`` (hashed now, differs from the
    record written with the file: it was modified afterwards).
    """

    sha256: str
    status: str


def file_digest(path: str | os.PathLike, comm=None) -> FileDigest:
    """Digest of ``path`` (symlinks resolved), trusting a record whose size and mtime match.

    Collective when ``comm`` is given (only hashing needs every rank); serial otherwise.
    """
    real = Path(os.path.realpath(path))
    rank0 = comm is None or comm.rank == 0
    rec = read_record(real) if rank0 else None
    trusted = None
    if rank0:
        st = os.stat(real)
        if (rec is not None and rec.get("size") == st.st_size
                and rec.get("mtime_ns") == st.st_mtime_ns
                and rec.get("block_bytes") == BLOCK_BYTES and rec.get("sha256")):
            trusted = str(rec["sha256"])
    if comm is not None and comm.size > 1:
        trusted = comm.bcast(trusted, root=0)
    if trusted is not None:
        return FileDigest(trusted, "recorded")
    sha = hash_file(real, comm)
    if not rank0:
        return FileDigest(sha, "unrecorded")
    if rec is None:
        return FileDigest(sha, "unrecorded")
    if rec.get("sha256") == sha:
        with contextlib.suppress(OSError):           # e.g. copied: refresh size/mtime
            write_record(real, sha)
        return FileDigest(sha, "recorded")
    return FileDigest(sha, "changed")


def record_file(path: Path, comm=None) -> str:
    """Hash ``path`` (collective with ``comm``) and write its record (rank 0); returns it."""
    sha = hash_file(path, comm)
    if comm is None or comm.rank == 0:
        write_record(path, sha)
    return sha


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    tmp = temp_path(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def utc_now() -> str:
    """The current UTC time, ``2024-05-01T12:00:00.000000Z`` (records, provenance, locks)."""
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
