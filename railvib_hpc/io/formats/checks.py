"""What the data checks and readers of the file formats share: finite values, bounds,
reading HDF5 (an input opened with one clear error, text attributes).

Each format module of :mod:`railvib_hpc.io.formats` has its ``check_<file>(path, full,
context)``, which returns a list of problems (empty: sound). ``full`` is False when the
file's content digest matches the record written right after its write-time checks: then
only the cheap checks run (attributes, shapes, small datasets); otherwise the big datasets
are streamed too. The same array checks run on the data in memory before a file is
written. :data:`railvib_hpc.io.stage_checks.CHECKS` names the check of each stage file.

Plausibility bound shared by ``mbs.h5`` and ``transient.h5``: contact forces
``|F| <= CONTACT_FORCE_FACTOR`` x the largest static wheel load
(:data:`CONTACT_FORCE_FACTOR` = 50; wheel-flat impacts reach 3-5 x static).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: Contact force vs the largest static wheel load.
CONTACT_FORCE_FACTOR = 50.0


def nonfinite(name: str, a: np.ndarray) -> list[str]:
    """``["<name> has k non-finite values"]`` or ``[]``."""
    bad = int(a.size - np.count_nonzero(np.isfinite(a)))
    return [f"{name} has {bad} non-finite value{'s' if bad > 1 else ''}"] if bad else []


def exceeds(name: str, a: np.ndarray, bound: np.ndarray | float, what: str) -> list[str]:
    """``["<name> reaches X, above the bound Y (what)"]`` when ``|a| > bound`` somewhere."""
    excess = np.abs(a) - bound
    if a.size == 0 or not np.any(excess > 0):
        return []
    k = np.unravel_index(int(np.argmax(excess)), a.shape)
    b = bound if np.isscalar(bound) else np.broadcast_to(bound, a.shape)[k]
    return [f"{name} reaches {float(np.abs(a[k])):.3g}, above the bound {float(b):.3g} ({what})"]


def h5_read(path: Path):
    """``path`` opened read-only with h5py (a context manager)."""
    import h5py

    return h5py.File(path, "r")


def text_attr(f, key: str, default=None):
    """The attribute ``key`` of an HDF5 object, bytes decoded (``default`` without it)."""
    v = f.attrs.get(key, default)
    return v.decode() if isinstance(v, bytes) else v


def open_input(path: Path, what: str, error: type[Exception]):
    """``path`` opened for reading, or ``error`` with one line naming ``what`` and the path
    (missing, or not a readable HDF5 file)."""
    import h5py

    if not path.is_file():
        raise error(f"{what} {path} not found")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise error(f"{what} {path} is not a readable HDF5 file ({exc})") from None


def absent(f, names) -> list[str]:
    """``["dataset '<name>' is missing", ...]`` for the ``names`` not in the HDF5 file ``f``."""
    return [f"dataset '{n}' is missing" for n in names if n not in f]


def static_wheel_load(f, context: dict) -> float:
    """The static wheel load [N]: from the caller's context, else from the file's ``stats``
    attribute (0 when neither has it)."""
    load = context.get("static_wheel_load")
    if load is not None:
        return load
    try:
        return max(json.loads(f.attrs.get("stats", "{}")).get("static_wheel_load") or [0.0])
    except (ValueError, TypeError):
        return 0.0
