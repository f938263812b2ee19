"""The stage protocol: every stage declared once (:class:`Stage`), run by :class:`StageRunner`.

A stage module declares one :class:`Stage`, in one place: its name, its help line, its
products (:class:`~railvib_hpc.io.products.StageFile` rows: format version, the case keys
each adds to those of the products it extends, the upstream files it is computed from,
its companion files and its data check; declaring the stage adds them to the one table,
:data:`~railvib_hpc.io.products.STAGE_FILES`, and their checks to
:data:`~railvib_hpc.io.stage_checks.CHECKS`), the stages it needs (:attr:`Stage.needs`),
the upstream files it reads, what it refuses (:attr:`Stage.refuse`) and
``compute(ctx)``. The case keys it depends on are its products' rows'
(:attr:`Stage.case_keys`). Adding a stage is its module and one line of the registry
(:data:`railvib_hpc.pipeline.STAGES`).

The stages form a graph that the runner owns: a stage names the stages whose products it
reads (``Stage(needs=("mesh",))``) and gets them through its context,
:meth:`StageContext.input`, never by importing another stage's module. A stage that
*provides* its product (:attr:`Stage.provide`: the mesh) has it built or reused on
demand, by today's reuse rules (``reusing mesh.h5 (same mesh inputs)`` or built anew);
the products of any other stage are verified (current for the case, unchanged, sound;
else one line naming the file and the command to run). On demand: a stage whose own
products are current never touches its upstream (reused modes need no mesh). Before
anything runs, :meth:`StageRunner.run` checks the stage's refusals
(:meth:`Stage.refusals`: what the case asks of it that it cannot do), and the command
line collects those of every stage of a command first
(:func:`railvib_hpc.validation.command_problems`).

``compute`` gets a :class:`StageContext` (case, output folder, communicator, reporter,
PETSc options), built by the runner and passed on, never rebuilt, and returns a frozen
result (a :class:`StageOutput`). The context gives it its upstream products
(:meth:`StageContext.input`), the one reuse helper (:meth:`StageContext.reuse`: examine,
then ``reusing <file> (why)`` or ``recomputing <file>: reason`` and forget), the check of
the upstream files it reads (:meth:`StageContext.require`) and the provenance of what it
writes (:meth:`StageContext.provenance`), so no stage module calls the reuse,
provenance, lock or run-record layer itself, imports another stage's module or builds a
context (``tools/stage_rules.py``, run by ``make lint`` and
``tests/test_stage_protocol.py``).

:class:`StageRunner` does everything else, for any sequence of stages into one output
folder: it takes the folder's lock once (:meth:`StageRunner.session`; nested sessions share
it), keeps the PETSc options in PETSc's database for that session only (and collects the
ones nothing used), starts PETSc for the stages that solve with it, records each call in
``run.json`` (:func:`~railvib_hpc.io.run_record.record_stage`) and times it. The registry
of the package's stages, the pipelines and the loop over them are
:mod:`railvib_hpc.pipeline`; the runner resolves the stages a context asks for through it
(by name: this layer imports no stage).

Example
-------
The ``modal`` stage's declaration (``tests/example_stage.py`` is a whole new stage):

>>> from railvib_hpc.pipeline import stage
>>> modal = stage("modal")
>>> modal.products, modal.reads, modal.petsc
(('modes.h5', 'static.h5', 'modal_damping.h5', 'bands/index.json'), ('mesh.h5',), True)
>>> modal.needs, stage("mbs").needs
(('mesh',), ('modal',))
>>> [key for key, _ in modal.case_keys][:3]
['geometry', 'track', 'building']
>>> from railvib_hpc.config import Case
>>> pml = Case.defaults().replace({"boundary.base": "pml", "boundary.layer_thickness": 2.0})
>>> modal.refusals(pml)[0][:2], stage("transient").refusals(pml)
(('boundary.base', 'pml'), [])
"""

from __future__ import annotations

import contextlib
import importlib
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..errors import CaseError
from .digests import forget
from .locks import output_lock
from .products import REGISTRY, Selection, StageFile, declare, spec
from .provenance import Verdict, examine, provenance, require_inputs
from .stage_checks import CHECKS
from .stage_outputs import StageOutput

__all__ = ["NotReusable", "Refusal", "Reuse", "Stage", "StageContext", "StageInput",
           "StageOutput", "StageRun", "StageRunner", "declare_product"]

#: One refusal: ``(key, value, allowed)``, for :class:`~railvib_hpc.errors.CaseError`.
Refusal = tuple[str, Any, str]


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
    needs
        The stages whose products it reads (registry names): it gets them through
        :meth:`StageContext.input`, which refuses any other.
    provide
        ``provide(ctx) -> StageInput`` (rank 0): build or reuse this stage's product for a
        stage that needs it, and hand it over loaded (the mesh). None: a stage that needs
        this one gets its products verified (they are computed by its own command).
    refuse
        ``refuse(case, command) -> [(key, value, allowed), ...]``: what the case asks of
        this stage that it cannot do (``command`` names the command in the sentence);
        see :meth:`refusals`.
    """

    name: str
    help: str
    compute: Callable[[StageContext], Any]
    products: tuple[str | StageFile, ...] = ()
    reads: tuple[str, ...] = ()
    petsc: bool = False
    needs: tuple[str, ...] = ()
    provide: Callable[[StageContext], StageInput] | None = None
    refuse: Callable[[Any, str], list[Refusal]] | None = None

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
        if self.name in self.needs:
            raise ValueError(f"stage {self.name} cannot need itself")

    def refusals(self, case, command: str | None = None) -> list[Refusal]:
        """What ``case`` asks of this stage that it cannot do, in the order checked (empty:
        nothing); ``command``: the command the sentences name (default: the stage's).
        Checked before anything runs (:meth:`StageRunner.run`,
        :func:`railvib_hpc.validation.command_problems`)."""
        if self.refuse is None or case is None:
            return []
        return list(self.refuse(case, command or self.name))

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


@dataclass(frozen=True)
class StageInput:
    """An upstream stage's product as the runner hands it over (:meth:`StageContext.input`).

    Attributes
    ----------
    stage
        The stage that wrote it.
    digests
        ``{table name: content digest}`` of its files (what a product computed from them
        records as its upstream).
    paths
        ``{table name: path}`` of the same files.
    value
        The product loaded, when the stage provides one (the mesh); else None.
    detail
        What else the provider says of it (the mesh's quality report); else None.
    """

    stage: str
    digests: Mapping[str, str]
    paths: Mapping[str, Path]
    value: Any = None
    detail: Any = None

    @property
    def sha256(self) -> str:
        """The content digest of its one file.

        Raises
        ------
        ValueError
            When it has several (name the one: :attr:`digests`).
        """
        if len(self.digests) != 1:
            raise ValueError(f"the input of stage {self.stage} has {len(self.digests)} files: "
                             f"{', '.join(self.digests)}")
        return next(iter(self.digests.values()))


def registered_stage(name: str) -> Stage:
    """The registered stage ``name`` (:func:`railvib_hpc.pipeline.stage`, imported by
    name: this layer imports no stage)."""
    return importlib.import_module(REGISTRY).stage(name)


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
    stage
        The :class:`Stage` whose ``compute`` it is (None: a library call outside a
        stage); its :attr:`Stage.needs` bound :meth:`input`.
    stages
        ``stages(name) -> Stage``: the stages of the graph (the runner's; default the
        registry, :func:`registered_stage`).
    """

    case: Any
    out_dir: Path
    comm: Any = None
    rep: Any = None
    petsc_options: tuple[str, ...] = ()
    options: Mapping[str, Any] = field(default_factory=dict)
    stage: Stage | None = None
    stages: Callable[[str], Stage] | None = None

    def __post_init__(self) -> None:
        from ..log import Reporter

        self.out_dir = Path(self.out_dir)
        if self.rep is None:
            self.rep = Reporter(0)

    def path(self, product: str) -> Path:
        """Where ``product`` (a table name) lies in the output folder."""
        return self.out_dir / spec(product).filename

    def _stage(self, name: str) -> Stage:
        return (self.stages or registered_stage)(name)

    def input(self, stage: str, files: Sequence[str] | None = None) -> StageInput:
        """The product of the upstream stage ``stage``, which this context's stage needs
        (rank 0).

        A stage that provides its product (:attr:`Stage.provide`, the mesh) builds or
        reuses it now, by its reuse rules, and hands it over loaded. Of any other stage
        the files are verified (:meth:`require`): ``files`` (table names, upstream first;
        default: those of its products that this context's stage reads) must be current
        for the case, unchanged and sound.

        Raises
        ------
        ValueError
            For a stage this context's stage does not declare in :attr:`Stage.needs`, or
            a file that is not that stage's (a bug of the stage's declaration).
        StaleInputError
            For the first verified file that is missing, stale, foreign or corrupt.
        """
        reader = self.stage
        if reader is not None and stage not in reader.needs:
            raise ValueError(f"stage {reader.name} reads the products of stage {stage!r}, "
                             f"which it does not declare in its needs {reader.needs}")
        upstream = self._stage(stage)
        if upstream.provide is not None and files is None:
            return upstream.provide(replace(self, stage=upstream))
        if files is None:
            files = [p for p in upstream.products if reader is None or p in reader.reads]
        foreign = [f for f in files if f not in upstream.products]
        if foreign:
            raise ValueError(f"{foreign[0]} is not a product of stage {stage}")
        digests = self.require(files)
        return StageInput(stage, digests, {name: self.path(name) for name in digests})

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

        Notes
        -----
        Without ``context`` the data checks get what the files' rows ask for
        (:attr:`~railvib_hpc.io.products.StageFile.check_context`, e.g. ``mbs.h5``'s
        static wheel load).
        """
        if context is None:
            context = {}
            for name in products:
                row = spec(name)
                if row.check_context is not None and self.case is not None:
                    context.update(row.check_context(self.case, self.out_dir))
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
    stages
        ``stages(name) -> Stage``: the graph a stage's upstream products are resolved in
        (:meth:`StageContext.input`; default the registry, :func:`registered_stage`).
    """

    def __init__(self, out_dir: str | Path, comm, rep, petsc_options=(), *, command: str,
                 wait: bool = False, stages: Callable[[str], Stage] | None = None):
        self.out_dir = Path(out_dir)
        self.comm = comm
        self.rep = rep
        self.petsc_options = tuple(petsc_options)
        self.command = command
        self.wait = wait
        self.stages = stages
        self._depth = 0

    def context(self, case, stage: Stage | None = None, **options: Any) -> StageContext:
        """The context of a call into this runner's folder: of ``stage``'s ``compute``
        (:meth:`run`), or of a library call outside a stage (``stage`` None, e.g.
        :func:`~railvib_hpc.reconstruct.stage.reconstruct_outputs`); ``options`` become
        ``ctx.options``. The one place a context is made: it is passed on, never rebuilt."""
        return StageContext(case, self.out_dir, self.comm, self.rep, self.petsc_options,
                            dict(options), stage=stage, stages=self.stages)

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

        Refuses first what the case asks of the stage that it cannot do
        (:meth:`Stage.refusals`: the first one, in one line), before the lock is taken or
        anything is written. Starts PETSc for a stage that solves with it, records the
        call in ``run.json`` (``command``: what ``run.json`` names, default the runner's;
        ``record=False``: not recorded, for a stage's own entry point called from a
        script) and times it. ``options`` reach ``compute`` as ``ctx.options``.

        Returns
        -------
        StageRun
            Rank 0's result, wall time and timings, on every rank.

        Raises
        ------
        CaseError
            The stage's first refusal of the case (every rank).
        """
        from ..petsc_env import init_petsc
        from .run_record import record_stage

        refused = stage.refusals(case)
        if refused:
            raise CaseError(refused[:1])
        command = command or self.command
        rep = self.rep
        with self.session(command):
            n0, t0 = len(rep.timings), time.perf_counter()
            ctx = self.context(case, stage, **options)
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
