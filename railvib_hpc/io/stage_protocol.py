"""The stage protocol: every stage declared once (:class:`Stage`), run by :class:`StageRunner`.

A stage module declares one :class:`Stage`, in one place: its name, its help line, its
products (:class:`~railvib_hpc.io.products.StageFile` rows: format version, the case keys
each depends on, the upstream files it is computed from, its companion files and its data
check; declaring the stage adds them to the one table,
:data:`~railvib_hpc.io.products.STAGE_FILES`, and their checks to
:data:`~railvib_hpc.io.stage_checks.CHECKS`), the upstream files it reads and
``compute(ctx)``. The case keys it depends on are its products' rows'
(:attr:`Stage.case_keys`). Adding a stage is its module and one line of the registry
(:data:`railvib_hpc.pipeline.STAGES`).

``compute`` gets a :class:`StageContext` (case, output folder, communicator, reporter,
PETSc options) and returns a frozen result (a :class:`StageOutput`). The context gives
it the one reuse helper (:meth:`StageContext.reuse`: examine, then ``reusing <file>
(why)`` or ``recomputing <file>: reason`` and forget), the check of the upstream files it
reads (:meth:`StageContext.require`) and the provenance of what it writes
(:meth:`StageContext.provenance`), so no stage module calls the reuse, provenance,
lock or run-record layer itself (``tests/test_stage_protocol.py`` checks it).

:class:`StageRunner` does everything else, for any sequence of stages into one output
folder: it takes the folder's lock once (:meth:`StageRunner.session`; nested sessions share
it), keeps the PETSc options in PETSc's database for that session only (and collects the
ones nothing used), starts PETSc for the stages that solve with it, records each call in
``run.json`` (:func:`~railvib_hpc.io.run_record.record_stage`) and times it. The registry
of the package's stages, the pipelines and the loop over them are
:mod:`railvib_hpc.pipeline`.

Example
-------
The ``modal`` stage's declaration (``tests/example_stage.py`` is a whole new stage):

>>> from railvib_hpc.pipeline import stage
>>> modal = stage("modal")
>>> modal.products, modal.reads, modal.petsc
(('modes.h5', 'static.h5', 'modal_damping.h5', 'bands/index.json'), ('mesh.h5',), True)
>>> [key for key, _ in modal.case_keys][:3]
['geometry', 'track', 'building']
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from .digests import forget
from .locks import output_lock
from .products import Selection, StageFile, declare, spec
from .provenance import Verdict, examine, provenance, require_inputs
from .stage_checks import CHECKS
from .stage_outputs import StageOutput

__all__ = ["NotReusable", "Reuse", "Stage", "StageContext", "StageOutput", "StageRun",
           "StageRunner", "declare_product"]


# ----------------------------------------------------------------------------- declaration
def declare_product(row: StageFile, check: Callable | None = None) -> str:
    """Add a new product's row (and data check, default the row's) to the one table;
    returns its name (:func:`~railvib_hpc.io.products.declare`).

    Raises
    ------
    ValueError
        For another row under a name the table already has.
    """
    if check is not None and row.check is None:
        row = replace(row, check=check)
    return declare(row)


@dataclass(frozen=True)
class Stage:
    """One stage, declared once in its module (``STAGE = Stage(...)``).

    Attributes
    ----------
    name
        The stage's name (``railvib <name>``, the ``stage`` of its products' rows).
    help
        The command line's help line.
    products
        The files it writes: their rows (:class:`~railvib_hpc.io.products.StageFile`,
        added to :data:`~railvib_hpc.io.products.STAGE_FILES` when the stage is
        declared); after the declaration, their table names.
    reads
        The table names of the upstream files it reads.
    compute
        ``compute(ctx) -> StageOutput``: the stage's work (collective over ``ctx.comm``).
    petsc
        True when it solves with PETSc (the runner starts PETSc with the options first).
    """

    name: str
    help: str
    compute: Callable[[StageContext], Any]
    products: tuple[str | StageFile, ...] = ()
    reads: tuple[str, ...] = ()
    petsc: bool = False

    def __post_init__(self) -> None:
        names = tuple(declare_product(p) if isinstance(p, StageFile) else p
                      for p in self.products)
        object.__setattr__(self, "products", names)
        for name in names:
            if spec(name).stage != self.name:
                raise ValueError(f"stage {self.name}: {name} is written by "
                                 f"'railvib {spec(name).stage}'")
        for name in self.reads:
            spec(name)                          # a known stage file

    @property
    def rows(self) -> tuple[StageFile, ...]:
        """The table rows of its products."""
        return tuple(spec(n) for n in self.products)

    @property
    def case_keys(self) -> Selection:
        """The case keys its products depend on (the union of their rows' inputs)."""
        keys: list = []
        for row in self.rows:
            keys += [k for k in row.inputs if k not in keys]
        return tuple(keys)


class NotReusable(Exception):
    """Raised by an ``accept`` callback of :meth:`StageContext.reuse`: the file passed
    :func:`~railvib_hpc.io.provenance.examine` but cannot be reused (the message says
    why, ``it ...``)."""


@dataclass(frozen=True)
class Reuse:
    """The outcome of :meth:`StageContext.reuse`.

    Attributes
    ----------
    ok
        True: the file is reused.
    verdict
        The verdict of :func:`~railvib_hpc.io.provenance.examine` (``sha256``, ``attrs``).
    value
        What the ``accept`` callback returned (None without one, or when not reused).
    """

    ok: bool
    verdict: Verdict
    value: Any = None

    @property
    def sha256(self) -> str:
        """The file's content digest (reused files)."""
        return self.verdict.sha256


def _file_reason(path: Path, reason: str) -> str:
    """``modes.h5 was computed with ...`` of a verdict's ``it was computed with ...``."""
    return f"{path.name} {reason[3:]}" if reason.startswith("it ") else f"{path.name}: {reason}"


@dataclass
class StageContext:
    """What a stage's ``compute`` works with, and its reuse and provenance helpers.

    Attributes
    ----------
    case
        The validated case (None for a library call on files outside a case).
    out_dir
        The output folder.
    comm
        MPI communicator (None: serial, this process only).
    rep
        The :class:`~railvib_hpc.log.Reporter` (rank 0 prints).
    petsc_options
        The PETSc options of the call.
    options
        Keyword options of the call (e.g. the transient stage's test hooks).
    """

    case: Any
    out_dir: Path
    comm: Any = None
    rep: Any = None
    petsc_options: tuple[str, ...] = ()
    options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from ..log import Reporter

        self.out_dir = Path(self.out_dir)
        if self.rep is None:
            self.rep = Reporter(0)

    def path(self, product: str) -> Path:
        """Where ``product`` (a table name) lies in the output folder."""
        return self.out_dir / spec(product).filename

    def reuse(self, product: str, *, path: Path | None = None, why: str | None = None,
              detail: Callable[[Any], str] | None = None,
              accept: Callable[[Verdict], Any] | None = None,
              stale: Callable[[Path, str], str] | None = None, discard: bool = True,
              **examine_options: Any) -> Reuse:
        """Reuse ``product`` when it is current and sound, else forget it, saying why (rank 0).

        Examines the file (:func:`~railvib_hpc.io.provenance.examine`, with the table's
        data check unless ``data_check`` is given), then runs ``accept(verdict)`` on a
        current file: its value is the reused content; raising :class:`NotReusable`
        rejects the file.

        Parameters
        ----------
        product
            Its table name.
        path
            The file (default: :meth:`path`).
        why
            Printed as ``reusing <path> (<why>)`` when reused (None: nothing printed).
        detail
            ``detail(value)``, appended as ``: <detail>`` to that line.
        accept
            See above.
        stale
            ``stale(path, reason)``: the line printed when an existing file is not reused
            (default ``recomputing <path>: <reason>``).
        discard
            Delete a file that is not reused, with its record (default).
        **examine_options
            Passed to :func:`~railvib_hpc.io.provenance.examine` (``context``,
            ``inputs_sha256``, ``upstream``, ...).
        """
        path = path or self.path(product)
        options = {"data_check": CHECKS.get(product), **examine_options}
        verdict = examine(path, product, self.case, **options)
        value = None
        if verdict.ok and accept is not None:
            try:
                value = accept(verdict)
            except NotReusable as exc:
                verdict.ok, verdict.reason = False, str(exc)
        if verdict.ok:
            if why is not None:
                self.rep.info(f"reusing {path} ({why})"
                              + (f": {detail(value)}" if detail is not None else ""))
            return Reuse(True, verdict, value)
        if verdict.kind != "missing":
            self.rep.info(stale(path, verdict.reason) if stale is not None
                          else f"recomputing {path}: {verdict.reason}")
        if discard:
            forget(path)
        return Reuse(False, verdict)

    def reuse_together(self, products: tuple[str, ...], what: str, *,
                       context: Mapping[str, Any] | None = None) -> dict[str, Verdict] | None:
        """Reuse products that come from one computation only together (rank 0).

        All current and sound: their verdicts. Otherwise ``recomputing the <what> in
        <out_dir>: <the first file's reason>`` (unless none of them exists), all of them
        are forgotten, and None is returned.
        """
        reason, present, verdicts = None, False, {}
        for name in products:
            path = self.path(name)
            v = examine(path, name, self.case, data_check=CHECKS.get(name), context=context)
            present = present or v.kind != "missing"
            if not v.ok and reason is None:
                reason = _file_reason(path, v.reason)
            verdicts[name] = v
        if reason is None:
            return verdicts
        if present:
            self.rep.info(f"recomputing the {what} in {self.out_dir}: {reason}")
        for name in products:
            forget(self.path(name))
        return None

    def require(self, products: Sequence[str], checks: Mapping[str, Callable] | None = None,
                *, context: Mapping[str, Any] | None = None) -> dict[str, str]:
        """Verify the upstream files a stage reads, upstream first (rank 0); their digests.

        Each file must be current for the case and sound
        (:func:`~railvib_hpc.io.provenance.require_inputs`).

        Parameters
        ----------
        products
            Their table names, in pipeline order (e.g. ``("modes.h5", "mbs.h5")``).
        checks
            ``{name: data check}`` (None: the table's checks,
            :data:`~railvib_hpc.io.stage_checks.CHECKS`).
        context
            Passed to the data checks.

        Returns
        -------
        dict
            ``{table name: content digest}``, in the order of ``products``.

        Raises
        ------
        StaleInputError
            For the first file that is missing, stale, foreign or corrupt: one line naming
            it, what differs and the command to run.
        """
        verdicts = require_inputs(self.out_dir, products, self.case,
                                  CHECKS if checks is None else checks, context=context)
        return {name: v.sha256 for name, v in verdicts.items()}

    def discard(self, path: Path) -> None:
        """Delete a result file and its record before it is written anew (rank 0)."""
        forget(path)

    def provenance(self, product: str, upstream: Mapping[str, str], extra: Any = None, *,
                   inputs_sha256: str | None = None) -> dict[str, Any]:
        """The provenance attributes of a new ``product`` computed for the case from
        ``upstream`` (``{file name: content digest}``; see
        :func:`~railvib_hpc.io.provenance.provenance`)."""
        return provenance(product, self.case, upstream, extra, inputs_sha256=inputs_sha256)


# ----------------------------------------------------------------------------- the runner
@dataclass(frozen=True)
class StageRun:
    """One stage call of :meth:`StageRunner.run` (the same on every rank: rank 0's).

    Attributes
    ----------
    stage
        The stage's name.
    result
        What its ``compute`` returned.
    seconds
        Wall time of the call [s].
    timings
        The reporter's timed parts of the call, ``{name: seconds}``.
    """

    stage: str
    result: Any
    seconds: float
    timings: dict[str, float]


class StageRunner:
    """Runs stages into one output folder: the lock, the PETSc options, run.json, timings.

    Parameters
    ----------
    out_dir
        The output folder.
    comm
        MPI communicator.
    rep
        The :class:`~railvib_hpc.log.Reporter`.
    petsc_options
        PETSc options, in PETSc's database only during a session.
    command
        What runs the stages, for the lock and ``run.json`` (a stage call may name its own).
    wait
        Wait for another command holding the folder instead of refusing.
    """

    def __init__(self, out_dir: str | Path, comm, rep, petsc_options=(), *, command: str,
                 wait: bool = False):
        self.out_dir = Path(out_dir)
        self.comm = comm
        self.rep = rep
        self.petsc_options = tuple(petsc_options)
        self.command = command
        self.wait = wait
        self._depth = 0

    @contextlib.contextmanager
    def session(self, command: str | None = None) -> Iterator[list[str]]:
        """Hold the folder's lock and the PETSc options' scope for the block.

        The outermost session takes them (``command`` names the holder; default the
        runner's); nested sessions share them. Yields the list that, after the outermost
        block, holds the PETSc options nothing used (empty for a nested session).
        """
        from ..petsc_env import options_scope

        if self._depth:
            yield []
            return
        scope = (options_scope(self.petsc_options) if self.petsc_options
                 else contextlib.nullcontext([]))
        with scope as unused, \
                output_lock(self.out_dir, self.comm, command or self.command,
                            wait=self.wait, rep=self.rep):
            self._depth += 1
            try:
                yield unused
            finally:
                self._depth -= 1

    def run(self, stage: Stage, case, *, command: str | None = None, record: bool = True,
            **options: Any) -> StageRun:
        """Run one stage (collective), in the open session or in one of its own.

        Starts PETSc for a stage that solves with it, records the call in ``run.json``
        (``command``: what ``run.json`` names, default the runner's; ``record=False``: not
        recorded, for a stage's own entry point called from a script) and times it.
        ``options`` reach ``compute`` as ``ctx.options``.

        Returns
        -------
        StageRun
            Rank 0's result, wall time and timings, on every rank.
        """
        from ..petsc_env import init_petsc
        from .run_record import record_stage

        command = command or self.command
        rep = self.rep
        with self.session(command):
            n0, t0 = len(rep.timings), time.perf_counter()
            ctx = StageContext(case, self.out_dir, self.comm, rep, self.petsc_options,
                               dict(options))
            recording = (record_stage(self.out_dir, self.comm, stage.name, case, rep, command)
                         if record else contextlib.nullcontext(None))
            with recording as call:
                if stage.petsc:
                    init_petsc(list(self.petsc_options))
                result = stage.compute(ctx)
                if call is not None:
                    call.done(result)
            seconds = time.perf_counter() - t0
        timings: dict[str, float] = {}
        for name, t in rep.timings[n0:]:
            timings[name] = timings.get(name, 0.0) + t
        if self.comm is not None and self.comm.size > 1:
            result, seconds, timings = self.comm.bcast((result, seconds, timings), root=0)
        return StageRun(stage.name, result, seconds, timings)
