"""The progress callback of the eigensolver's long phases (:data:`Progress`), which the
block Lanczos iteration and the factorisation's blocked solves both report to."""

from __future__ import annotations

from collections.abc import Callable

#: Progress callback of the long phases: ``progress(phase, done, total)`` (units of work
#: done of ``total``; rank 0 prints it, throttled, with the phase's percent and ETA).
Progress = Callable[[str, int, int], None]
