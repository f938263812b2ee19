"""Memory and size pre-checks: refuse a run before it allocates what the machine lacks."""

from __future__ import annotations

import os

from .errors import ResourceError

#: Share of the available memory a single allocation plan may use.
MEMORY_SHARE = 0.8


def available_memory_bytes() -> float:
    """MemAvailable of this node (Linux ``/proc/meminfo``; else physical memory; inf if unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return float("inf")


def gb(nbytes: float) -> str:
    """``12.3 GB``."""
    return f"{nbytes / 1e9:.3g} GB"


def check_memory(nbytes: float, what: str, advice: str) -> None:
    """Raise :class:`ResourceError` when ``nbytes`` exceed :data:`MEMORY_SHARE` of the
    available memory.

    Parameters
    ----------
    nbytes
        Predicted memory of the plan [bytes].
    what
        What needs it, e.g. ``"the multibody histories (9.2e8 steps)"``.
    advice
        What the user can change, e.g. ``"use a larger mbs.dt"``.
    """
    avail = available_memory_bytes()
    if nbytes > MEMORY_SHARE * avail:
        raise ResourceError(f"{what} would need {gb(nbytes)} of memory, {gb(avail)} are "
                            f"available: {advice}")
