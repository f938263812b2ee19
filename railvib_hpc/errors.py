"""Exceptions shared by all stages.

User and environment errors (bad case files, bad overrides, missing, stale or
corrupt files, a full disk, a locked output folder) derive from
:class:`UserError`; the CLI prints them as one line without a traceback and
exits with code 2, on every MPI rank together. A time integration that grew without
bound (:class:`DivergenceError`, a :class:`UserError` too) exits with code 3: the input
was accepted, but the run is not a result. Everything else is a bug: the CLI prints one
"please report" line naming a log file with the traceback and exits with code 1.
"""

from __future__ import annotations

import os


class UserError(Exception):
    """An error caused by the user's input; printed without traceback, exit code 2."""

    exit_code = 2


class CaseError(UserError):
    """One or more invalid entries of a case file.

    Parameters
    ----------
    problems
        Each entry is ``(key, value, allowed)``: the dotted key, the offending
        value (or ``None`` when the key is missing) and a sentence saying what
        is allowed.
    """

    def __init__(self, problems: list[tuple[str, object, str]]):
        self.problems = list(problems)
        lines = [f"{key} = {value!r}: {allowed}" for key, value, allowed in self.problems]
        if len(lines) == 1:                       # one problem: one line
            super().__init__(f"invalid case file: {lines[0]}")
            return
        header = f"invalid case file ({len(lines)} problems)"
        super().__init__(header + ":\n  " + "\n  ".join(lines))

    def __reduce__(self):  # picklable, so it can be broadcast to every MPI rank
        return (type(self), (self.problems,))


class MeshError(UserError):
    """A mesh that cannot be used (inverted elements, missing physical groups, ...)."""


class OutputError(UserError, OSError):
    """An operating-system error on railvib's files: disk full, permission denied, read-only
    file system, a path below a file, a name too long. Raised on every rank together."""


class StaleInputError(UserError):
    """An input file of a stage is missing, incomplete, stale (computed for other case
    values or from other upstream files), foreign or corrupt."""


class OutputLockedError(UserError):
    """The output folder is in use by another railvib process."""


class ResourceError(UserError):
    """A run that would exceed the memory, disk or step-count limits (checked before the
    long arrays are allocated or the files written)."""


def os_error_text(exc: OSError, action: str = "") -> str:
    """One line for an operating-system error: ``action path: reason`` (no traceback text).

    h5py's messages carry a multi-line dump of the failing write; the errno's standard
    text is used instead when there is one.
    """
    if isinstance(exc, UserError):
        return str(exc)
    reason = os.strerror(exc.errno) if exc.errno else (str(exc).splitlines() or [""])[0]
    if not reason:
        reason = type(exc).__name__
    name = exc.filename
    head = " ".join(p for p in (action, str(name) if name else "") if p)
    return f"{head}: {reason}" if head else reason


def exception_text(exc: BaseException) -> str:
    """One line for any exception: :func:`os_error_text` for an ``OSError``, else
    ``<type>: <first line>`` (the type alone when it says nothing)."""
    if isinstance(exc, OSError):
        return os_error_text(exc)
    text = (str(exc).splitlines() or [""])[0]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class DivergenceError(UserError):
    """A time integration whose energy grew past what its loads can have put in (the
    divergence guard of :mod:`railvib_hpc.transient.guard`): stopped, nothing written as a
    result; exit code 3, apart from the input errors' 2."""

    exit_code = 3


class ContactNewtonError(DivergenceError):
    """The wheel-rail contact's Newton iteration did not converge within its iterations
    (a penetration that no Hertz force can balance: a step too large for the contact's
    stiffness, or a rail that has already grown without bound). Not a result; exit code 3.

    Parameters
    ----------
    iterations
        The Newton iterations taken.
    correction
        The last Newton correction of the penetration [m].
    tolerance
        The tolerance it had to reach [m].
    """

    def __init__(self, iterations: int, correction: float, tolerance: float):
        self.iterations, self.correction, self.tolerance = iterations, correction, tolerance
        super().__init__(f"the wheel-rail contact's Newton iteration did not converge in "
                         f"{iterations} iterations (last correction {correction:.3g} m, "
                         f"tolerance {tolerance:.3g} m)")

    def __reduce__(self):  # picklable, so it can be broadcast to every MPI rank
        return (type(self), (self.iterations, self.correction, self.tolerance))


class DataError(UserError):
    """Computed or stored data that fail their data checks (non-finite or implausible values)."""
