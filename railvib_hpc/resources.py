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


#: kB per GB: ``/proc/self/status`` and ``getrusage`` (Linux) report memory in kB.
KB_PER_GB = 1e6

#: The process's peak resident memory [kB] from before the last
#: :func:`reset_peak_memory` (the kernel's high-water mark only covers the time since).
_peak_before_reset_kb = 0.0


def _status_kb(*keys: str) -> dict[str, float]:
    """Fields of ``/proc/self/status`` in kB (Linux; empty where absent)."""
    out: dict[str, float] = {}
    try:
        with open("/proc/self/status") as f:
            for line in f:
                name, _, value = line.partition(":")
                if name in keys:
                    out[name] = float(value.split()[0])
    except (OSError, ValueError, IndexError):
        return {}
    return out


def current_memory_gb() -> float:
    """This process's resident memory now (``VmRSS``) [GB]; NaN where unknown (not Linux)."""
    kb = _status_kb("VmRSS").get("VmRSS")
    return float("nan") if kb is None else kb / KB_PER_GB


def peak_memory_gb(since_reset: bool = False) -> float:
    """This process's peak resident memory [GB].

    ``since_reset``: only since the last :func:`reset_peak_memory` (the kernel's
    ``VmHWM``); otherwise over the process's life (also across resets), as
    ``getrusage``'s ``ru_maxrss`` is without resets.
    """
    import resource

    hwm = _status_kb("VmHWM").get("VmHWM")
    if hwm is None:                        # no /proc: getrusage (no resets were possible)
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KB_PER_GB
    return (hwm if since_reset else max(hwm, _peak_before_reset_kb)) / KB_PER_GB


def reset_peak_memory() -> bool:
    """Restart the kernel's peak-memory count (``VmHWM``) at the current resident memory,
    so that :func:`peak_memory_gb` ``(since_reset=True)`` measures one phase (Linux >= 4.0:
    ``/proc/self/clear_refs`` = 5). The life-time peak is kept. Returns whether it worked."""
    global _peak_before_reset_kb
    hwm = _status_kb("VmHWM").get("VmHWM")
    if hwm is None:
        return False
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    _peak_before_reset_kb = max(_peak_before_reset_kb, hwm)
    return True


def release_memory() -> None:
    """Return freed heap memory to the operating system (glibc ``malloc_trim``).

    Blocks of n x 32 doubles (tens of MB) fall below glibc's dynamic mmap threshold and
    fragment the heap; measured, the peak of a band-sliced solve grew by ~1 GB per band at
    thesis size without this. A no-op where glibc is absent."""
    import contextlib
    import ctypes
    import ctypes.util

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim(0)
