"""Exceptions shared by all stages.

User errors (bad case files, bad overrides, missing files) derive from
:class:`UserError`; the CLI prints them without a traceback and exits with
code 2. Everything else is a bug or an environment failure and keeps its
traceback.
"""

from __future__ import annotations


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
        header = "invalid case file"
        if len(lines) > 1:
            header += f" ({len(lines)} problems)"
        super().__init__(header + ":\n  " + "\n  ".join(lines))

    def __reduce__(self):  # picklable, so it can be broadcast to every MPI rank
        return (type(self), (self.problems,))


class MeshError(UserError):
    """A mesh that cannot be used (inverted elements, missing physical groups, ...)."""
