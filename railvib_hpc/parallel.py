"""MPI helpers: root-only work with broadcast results and errors.

Every rank reaches every collective: work that can fail on rank 0 (reading
files, gmsh) runs inside :func:`on_root`, which broadcasts either the result
or the exception, so all ranks return or raise together.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from .errors import OutputError, UserError, os_error_text

if TYPE_CHECKING:
    from mpi4py import MPI

T = TypeVar("T")


def world() -> MPI.Comm:
    """The MPI communicator used by railvib (COMM_WORLD)."""
    from mpi4py import MPI

    return MPI.COMM_WORLD


class RootFailure(RuntimeError):
    """A non-user error raised on rank 0, re-raised on the other ranks."""


def on_root(fn: Callable[[], T], comm: MPI.Comm | None = None,
            broadcast_result: bool = True) -> T | None:
    """Run ``fn`` on rank 0 only and broadcast its outcome.

    Parameters
    ----------
    fn
        Zero-argument callable.
    comm
        Communicator (default COMM_WORLD).
    broadcast_result
        If False, other ranks receive ``None`` instead of the result (for large results).

    Raises
    ------
    UserError
        On every rank, when ``fn`` raised a user error on rank 0; an ``OSError`` (disk
        full, permissions, bad paths) arrives everywhere as
        :class:`~railvib_hpc.errors.OutputError`.
    RootFailure
        On ranks > 0 when ``fn`` raised any other exception (rank 0 re-raises the original).
    """
    comm = comm or world()
    outcome: tuple[bool, Any] = (True, None)
    original: BaseException | None = None
    if comm.rank == 0:
        outcome, original = root_outcome(fn)
    if comm.size > 1:
        ok, payload = outcome
        msg = comm.bcast((ok, payload if (not ok or broadcast_result) else None), root=0)
        if comm.rank != 0:
            outcome = msg
    return settle(outcome, original)


def root_outcome(fn: Callable[[], T]) -> tuple[tuple[bool, Any], BaseException | None]:
    """Call ``fn`` (on rank 0) and turn what happened into a message for the other ranks.

    Returns ``((ok, value_or_exception), original)``: a user error travels as itself, an
    ``OSError`` as :class:`~railvib_hpc.errors.OutputError`, anything else as
    :class:`RootFailure`, with the original exception kept for rank 0 to re-raise.
    """
    try:
        return (True, fn()), None
    except UserError as exc:
        return (False, exc), None
    except OSError as exc:
        return (False, OutputError(os_error_text(exc))), None
    except BaseException as exc:
        return (False, RootFailure(f"rank 0 failed: {type(exc).__name__}: {exc}")), exc


def settle(outcome: tuple[bool, Any], original: BaseException | None = None) -> Any:
    """The value of an outcome of :func:`root_outcome`, or raise its error (rank 0 raises the
    original exception)."""
    ok, payload = outcome
    if not ok:
        if original is not None:
            raise original
        raise payload
    return payload


def check_collective(comm, error: BaseException | None, what: str) -> None:
    """Raise on every rank when any rank had an error (call it before the next collective).

    Parameters
    ----------
    comm
        Communicator.
    error
        This rank's exception, or None.
    what
        What was being done, e.g. ``"writing /out/fields.h5"`` (prefix of the message).

    Raises
    ------
    UserError
        On every rank, the first (lowest rank) user error; an ``OSError`` arrives on every
        rank as :class:`~railvib_hpc.errors.OutputError` ``"<what>: <reason>"``.
    RuntimeError
        On the other ranks when a rank had any other (internal) error; that rank
        re-raises its own exception with its traceback.
    """
    def classify(exc: BaseException | None):
        if exc is None:
            return None
        if isinstance(exc, UserError):
            return ("user", exc)
        if isinstance(exc, OSError):
            return ("user", OutputError(f"{what}: {os_error_text(exc)}"))
        return ("internal", f"{type(exc).__name__}: {exc}")

    mine = classify(error)
    outcomes = [mine] if comm.size == 1 else comm.allgather(mine)
    bad = [(r, o) for r, o in enumerate(outcomes) if o is not None]
    if not bad:
        return
    users = [o[1] for _, o in bad if o[0] == "user"]
    if users:
        raise users[0]
    if error is not None:
        raise error
    rank, (_, text) = bad[0]
    raise RuntimeError(f"{what} failed on rank {rank}: {text}")
