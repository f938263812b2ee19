"""The Python API: cases, the pipeline as an object, studies; what the command line uses.

Three things make a script or a notebook out of what ``railvib`` does on the command
line:

* :class:`Case` -- a validated, immutable case: :meth:`Case.from_file`,
  :meth:`Case.from_dict`, :meth:`Case.defaults`, and :meth:`Case.replace` for variants
  (typed values, the same validation and the same one-line
  :class:`~railvib_hpc.errors.CaseError` as the command line);
* :class:`Pipeline` -- the problem (a case) bound to an output folder, a communicator and
  PETSc options; its methods :meth:`~Pipeline.mesh`, :meth:`~Pipeline.modal`,
  :meth:`~Pipeline.mbs`, :meth:`~Pipeline.reconstruct`, :meth:`~Pipeline.assess` and
  :meth:`~Pipeline.run` run the stages (reusing what is current, as the command line
  does) and return small frozen results: the files written, the key numbers and arrays,
  what was reused and the timings;
* :func:`run_study` -- a whole study (convergence, modes, reflection, speed, thesis, mitigation),
  returning a :class:`StudyResult`.

Everything is collective: run the same script under ``mpirun -n N`` and every rank gets
the same results (rank 0 prints). PETSc options given to a :class:`Pipeline` are in
PETSc's database only while a stage runs and removed afterwards; the options nothing used
are in ``result.unused_petsc_options``. Every stage call is recorded in
``<out>/run.json`` (:mod:`railvib_hpc.io.run_record`; :meth:`Pipeline.run_record`).

Example
-------
A coarse model (refinement 0.25, 8 modes; about 10 s on one core)::

    import railvib_hpc as rv

    case = rv.Case.from_file("jobs/thesis_baseline.toml").replace(
        {"mesh.refinement": 0.25, "modal.n_modes": 8, "modal.block_size": 8,
         "output.dt": 0.01})
    result = rv.Pipeline(case, "results/coarse").run()
    print(result.modal.frequencies_hz[:3], result.mbs.peak_contact_force.max())
    print(result.reconstruct.probes["slab1"].acc_vertical, result.assess.passed)

Errors are exceptions: :class:`~railvib_hpc.errors.UserError` (a bad value, a stale
input file, a locked folder, a full disk; its message is the command line's one line,
raised on every rank together) and its subclasses.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .config import Case
from .errors import CaseError, UserError
from .io.stage_outputs import (
    AssessmentOutput,
    FieldsOutput,
    MeshOutput,
    ModesOutput,
    PassageOutput,
    StageOutput,
)
from .io.stage_protocol import StageRun, StageRunner
from .log import Reporter
from .parallel import on_root, world
from .pipeline import PIPELINE_ORDER, run_stages, stage

if TYPE_CHECKING:
    from mpi4py import MPI

__all__ = [
    "AssessResult", "Case", "CaseError", "MBSResult", "MeshResult", "ModalResult",
    "Pipeline", "ProbePeak", "ReconstructResult", "RunResult", "StageResult", "StagesResult",
    "StudyResult", "StudyTable", "UserError", "VariantStatus", "run_study",
]

PetscOptions = Sequence[str] | Mapping[str, Any] | None


class _Silent:
    """A stream that drops everything (``quiet=True``)."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


def _reporter(comm, reporter: Reporter | None, quiet: bool) -> Reporter:
    if reporter is not None:
        return reporter
    return Reporter(comm.rank, _Silent() if quiet else None)


class FrozenDict(dict):
    """A read-only ``dict``: the mappings of the results (``verdict``, ``probes``,
    ``summary``, ...).

    Reading works as for a ``dict`` (and ``json.dumps``, pickling and ``==`` with a plain
    ``dict`` too); every change raises ``TypeError``. ``dict(d)`` or ``d.copy()`` gives a
    mutable copy.

    Examples
    --------
    >>> d = FrozenDict({"slab1": True})
    >>> d["slab1"], d == {"slab1": True}
    (True, True)
    >>> d["slab1"] = False
    Traceback (most recent call last):
    ...
    TypeError: a result's mapping is read-only (results are frozen); copy it with dict(...)
    """

    __slots__ = ()

    def _readonly(self, *args: Any, **kwargs: Any) -> Any:
        raise TypeError("a result's mapping is read-only (results are frozen); copy it "
                        "with dict(...)")

    __setitem__ = __delitem__ = __ior__ = _readonly
    clear = pop = popitem = setdefault = update = _readonly

    def __init__(self, *args: Any, **kwargs: Any):
        if len(self):                  # dict.__init__ would fill it again
            self._readonly()
        super().__init__(*args, **kwargs)

    def __reduce__(self):              # picklable (MPI broadcasts): rebuilt, not filled
        return (type(self), (dict(self),))

    def __copy__(self) -> FrozenDict:
        return self

    def __deepcopy__(self, memo: dict) -> FrozenDict:
        return self

    def __repr__(self) -> str:
        return f"FrozenDict({dict.__repr__(self)})"


def _freeze(value: Any) -> Any:
    """``value`` made deeply immutable: mappings as :class:`FrozenDict`, lists and tuples
    as tuples, sets as frozensets, numpy arrays as read-only copies (frozen dataclasses,
    paths, numbers and strings as they are)."""
    if isinstance(value, FrozenDict):
        return value
    if isinstance(value, Mapping):
        return FrozenDict({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    if isinstance(value, set | frozenset):
        return frozenset(_freeze(v) for v in value)
    if isinstance(value, np.ndarray):
        if not value.flags.writeable and value.flags.owndata:
            return value               # already frozen: no second copy
        arr = np.array(value, copy=True)
        arr.flags.writeable = False
        return arr
    return value


class _Frozen:
    """Mixin of the frozen result dataclasses: every field deeply immutable
    (:func:`_freeze`), so ``r.assess.verdict["slab1"] = False`` raises instead of changing
    ``r.passed``."""

    def __post_init__(self) -> None:
        import dataclasses

        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, _freeze(getattr(self, f.name)))

    def __reduce__(self):
        """Pickled (``comm.allgather``) and rebuilt through ``__init__``: frozen again."""
        import dataclasses

        return (type(self), tuple(getattr(self, f.name) for f in dataclasses.fields(self)))


def _as_case(case: Case | str | os.PathLike) -> Case:
    if isinstance(case, Case):
        return case
    if isinstance(case, str | os.PathLike):
        return Case.from_file(case)
    raise TypeError(f"case must be a Case or a case file, not {type(case).__name__}")


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True)
class StageResult(_Frozen):
    """What every stage call returns.

    Every result is deeply immutable: mappings are :class:`FrozenDict`, lists tuples and
    arrays read-only copies (``r.verdict["slab1"] = False`` raises ``TypeError``).

    Attributes
    ----------
    stage
        The stage's name.
    out_dir
        The output folder.
    reused
        What the stage reused instead of computing (a bool, or per file for
        ``reconstruct``; None for ``assess``, which gives no reuse verdict).
    seconds
        Wall time of the call [s] (rank 0).
    timings
        The timed parts of the call, ``{name: seconds}`` (e.g. ``assembly``, ``eigensolve``).
    summary
        The stage's full summary (that of the result object the stage returned).
    unused_petsc_options
        PETSc options of the pipeline that nothing used during the call (typos, or
        nothing was solved).
    """

    stage: str
    out_dir: Path
    reused: Any
    seconds: float
    timings: dict[str, float]
    summary: dict[str, Any]
    unused_petsc_options: tuple[str, ...]


@dataclass(frozen=True)
class MeshResult(MeshOutput, StageResult):
    """``mesh``: the model's files, its size and quality warnings (the fields of
    :class:`~railvib_hpc.io.stage_outputs.MeshOutput`, declared there once)."""


@dataclass(frozen=True)
class ModalResult(ModesOutput, StageResult):
    """``modal``: the mass-normalised modes (the fields of
    :class:`~railvib_hpc.io.stage_outputs.ModesOutput`; ``frequencies_hz`` read-only)."""

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return int(self.frequencies_hz.size)


@dataclass(frozen=True)
class MBSResult(PassageOutput, StageResult):
    """``mbs``: the vehicle's passage over the modal track (the fields of
    :class:`~railvib_hpc.io.stage_outputs.PassageOutput`; the arrays read-only)."""


@dataclass(frozen=True)
class ProbePeak(_Frozen):
    """Peak response at one probe (from ``probes.h5``).

    Attributes
    ----------
    name, role
        The probe and its role (``floor``, ``wall``, ``foundation``, ``ground`` ...).
    coords
        Its position [m].
    acc_vertical, acc_total
        Peak ``|a_z|`` and peak ``|a|`` [m/s²]; ``t_acc_total`` the time of the latter [s].
    vel_total, disp_total
        Peak ``|v|`` [m/s] and ``|u|`` [m].
    t_onset
        First time ``|a|`` reaches ``assessment.wave_threshold`` of its peak [s].
    """

    name: str
    role: str
    coords: tuple[float, float, float]
    acc_vertical: float
    acc_total: float
    t_acc_total: float
    vel_total: float
    disp_total: float
    t_onset: float | None


@dataclass(frozen=True)
class ReconstructResult(FieldsOutput, StageResult):
    """``reconstruct``: fields of every node, stresses, probe histories (the fields of
    :class:`~railvib_hpc.io.stage_outputs.FieldsOutput`; ``probes`` is
    ``{probe: ProbePeak}``)."""


@dataclass(frozen=True)
class AssessResult(AssessmentOutput, StageResult):
    """``assess``: verdicts per probe and standard, and the report (the fields of
    :class:`~railvib_hpc.io.stage_outputs.AssessmentOutput`)."""

    @property
    def passed(self) -> bool:
        """True when no probe exceeds a limit (undetermined verdicts do not count)."""
        return all(v is not False for v in self.verdict.values())

    @property
    def exceeded(self) -> tuple[str, ...]:
        """The probes where a limit is exceeded."""
        return tuple(k for k, v in self.verdict.items() if v is False)


#: The typed result of each of the pipeline's stages (built from the stage's own result
#: object, whose fields it inherits).
_RESULTS: dict[str, type[StageResult]] = {"mesh": MeshResult, "modal": ModalResult,
                                          "mbs": MBSResult, "reconstruct": ReconstructResult,
                                          "assess": AssessResult}


@dataclass(frozen=True)
class RunResult(_Frozen):
    """:meth:`Pipeline.run`: every stage's result.

    Attributes
    ----------
    mesh, modal, mbs, reconstruct, assess
        The stages' results.
    seconds
        Wall time of the whole run [s].
    run_json
        ``<out>/run.json``, the record of every stage call.
    unused_petsc_options
        PETSc options nothing used during the run.
    """

    mesh: MeshResult
    modal: ModalResult
    mbs: MBSResult
    reconstruct: ReconstructResult
    assess: AssessResult
    seconds: float
    run_json: Path
    unused_petsc_options: tuple[str, ...]

    @property
    def passed(self) -> bool:
        """True when no probe exceeds a limit."""
        return self.assess.passed

    @property
    def verdict(self) -> dict[str, bool | None]:
        """``{probe: passed}``."""
        return self.assess.verdict

    @property
    def timings(self) -> dict[str, float]:
        """``{stage: seconds}``."""
        return {s: getattr(self, s).seconds for s in PIPELINE_ORDER}


@dataclass(frozen=True)
class StagesResult(_Frozen):
    """:meth:`Pipeline.run_stages`: the results of a sequence of stages.

    Attributes
    ----------
    results
        ``{stage: result}`` in the order they ran.
    seconds, run_json, unused_petsc_options
        As for :class:`RunResult`.
    """

    results: dict[str, StageResult]
    seconds: float
    run_json: Path
    unused_petsc_options: tuple[str, ...]

    def __getitem__(self, stage: str) -> StageResult:
        return self.results[stage]


# ----------------------------------------------------------------------------- the pipeline
class Pipeline:
    """A case bound to an output folder: run its stages, get typed results.

    Parameters
    ----------
    case
        A :class:`Case`, or a case file.
    out_dir
        Output folder (created; every stage reads and writes its files there).
    comm
        MPI communicator (default ``COMM_WORLD``; under plain ``python``, one rank).
    petsc_options
        PETSc/SLEPc options: ``["-railvib_eig_st_ksp_type", "preonly"]`` or
        ``{"railvib_eig_st_ksp_type": "preonly"}``; copied (your list is not changed),
        checked, and in PETSc's database only while a stage runs.
    reporter
        Where progress goes (default: a :class:`~railvib_hpc.log.Reporter` printing on
        rank 0).
    quiet
        Print nothing (ignored when ``reporter`` is given).
    wait
        Wait for another command that uses ``out_dir`` instead of raising
        :class:`~railvib_hpc.errors.OutputLockedError`.
    command
        How this run is named in ``run.json`` (default: the Python call).

    Raises
    ------
    UserError
        For a word in ``petsc_options`` that is neither an option nor its value.

    Examples
    --------
    >>> import tempfile
    >>> p = Pipeline(Case.defaults(), tempfile.mkdtemp(), petsc_options={"log_view": None})
    >>> p.petsc_options, p.comm.size
    (('-log_view',), 1)

    The modes and the passage of a coarse model (a few seconds):

    >>> case = Case.defaults().replace({"mesh.refinement": 0.25, "modal.n_modes": 8,
    ...                                 "modal.block_size": 8})
    >>> p = Pipeline(case, tempfile.mkdtemp(), quiet=True)
    >>> modes = p.modal()                       # builds the mesh it needs
    >>> modes.n_modes, modes.reused, f"{modes.frequencies_hz[0]:.1f} Hz"
    (8, False, '10.9 Hz')
    >>> p.modal().reused                        # a second call reuses modes.h5
    True
    >>> passage = p.mbs()
    >>> f"{passage.static_wheel_load[0] / 1e3:.2f} kN", passage.loss_of_contact_steps
    ('7.69 kN', 0)
    >>> Pipeline(Case.defaults(), tempfile.mkdtemp(), petsc_options=["log_view"])
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    railvib_hpc.errors.UserError: 'log_view' after '--' is neither a PETSc option ...
    """

    def __init__(self, case: Case | str | os.PathLike, out_dir: str | os.PathLike,
                 comm: MPI.Comm | None = None, petsc_options: PetscOptions = None, *,
                 reporter: Reporter | None = None, quiet: bool = False, wait: bool = False,
                 command: str | None = None):
        from .petsc_env import check_option_words, option_words

        self.comm = comm if comm is not None else world()
        self.case = _as_case(case)
        self.out_dir = Path(out_dir)
        words = option_words(petsc_options)
        check_option_words(words)
        self.petsc_options: tuple[str, ...] = tuple(words)
        self.reporter = _reporter(self.comm, reporter, quiet)
        self.wait = wait
        self.command = command
        self._run_label: str | None = None
        self._runner = StageRunner(self.out_dir, self.comm, self.reporter, self.petsc_options,
                                   command=self._label("run"), wait=wait)

    def __repr__(self) -> str:
        return (f"Pipeline(case={self.case['case.name']!r}, out_dir={str(self.out_dir)!r}, "
                f"ranks={self.comm.size})")

    # --------------------------------------------------------------- running
    def _label(self, call: str) -> str:
        """What ``run.json`` and the lock record as the command of a call."""
        if self.command:
            return self.command
        if self._run_label:
            return self._run_label
        return (f"railvib_hpc.Pipeline({self.case['case.name']!r}, {str(self.out_dir)!r})"
                f".{call}()")

    def session(self, command: str | None = None):
        """Hold the output folder's lock and the PETSc options' scope for a block of calls
        (a context manager; the calls inside share them, as :meth:`run_stages` does).

        ``command`` names the holder of the lock (default: this pipeline's ``command``).
        The block gets the list that, after it, holds the PETSc options nothing used in it.
        """
        return self._runner.session(command or self._label("session"))

    def _check_command(self, name: str) -> None:
        """Refuse a stage the case cannot run (what the stage declares it refuses, e.g. a
        case without a track on the modal path:
        :func:`~railvib_hpc.validation.command_problems`), before anything is written.

        Raises
        ------
        CaseError
            One line naming the key, its value and what is allowed.
        """
        from .errors import CaseError
        from .validation import command_problems

        problems = command_problems(self.case, name)
        if problems:
            raise CaseError(problems)

    def _call(self, name: str) -> tuple[StageRun, tuple[str, ...]]:
        """Run stage ``name`` in a session of its own (or the open one); the options of
        that session nothing used."""
        declared = stage(name)
        self._check_command(name)
        label = self._label(name)
        with self._runner.session(label) as unused:
            run = self._runner.run(declared, self.case, command=label)
        return run, tuple(unused)

    def _result(self, run: StageRun, unused: tuple[str, ...]) -> StageResult:
        """The typed result of a stage call (:data:`_RESULTS`; others: a :class:`StageResult`)
        from the stage's own frozen result object (a
        :class:`~railvib_hpc.io.stage_outputs.StageOutput`: its attributes, no summary
        read again).

        Raises
        ------
        TypeError
            When the stage's ``compute`` returned something else.
        """
        import dataclasses

        out = run.result
        if not isinstance(out, StageOutput):
            raise TypeError(f"stage {run.stage!r}: compute returned {type(out).__name__}, "
                            "not a StageOutput")
        common = {"stage": run.stage, "out_dir": self.out_dir, "reused": out.reused,
                  "seconds": run.seconds, "timings": run.timings,
                  "summary": dict(out.summary), "unused_petsc_options": unused}
        cls = _RESULTS.get(run.stage, StageResult)
        fields = {f.name: getattr(out, f.name) for f in dataclasses.fields(cls)
                  if f.name not in common}
        if "probes" in fields:
            fields["probes"] = {name: ProbePeak(
                name=name, role=p["role"], coords=tuple(p["coords"]),
                acc_vertical=p["acc_vertical"], acc_total=p["acc_total"],
                t_acc_total=p["t_acc_total"], vel_total=p["vel_total"],
                disp_total=p["disp_total"], t_onset=p["t_onset"])
                for name, p in fields["probes"].items()}
        return cls(**common, **fields)

    def stage(self, name: str) -> StageResult:
        """Run any registered stage by name (:data:`railvib_hpc.pipeline.STAGES`); the
        pipeline's own stages return their typed results.

        Raises
        ------
        ValueError
            For a name that is not a stage.
        """
        return self._result(*self._call(name))

    def mesh(self) -> MeshResult:
        """Build (or reuse) the mesh: ``mesh.h5``, ``mesh.xdmf``, ``mesh.msh``."""
        return self.stage("mesh")

    def modal(self) -> ModalResult:
        """Compute (or reuse) the modes: ``modes.h5`` (and ``static.h5``)."""
        return self.stage("modal")

    def mbs(self) -> MBSResult:
        """Run (or reuse) the multibody simulation: ``mbs.h5`` and its plots."""
        return self.stage("mbs")

    def reconstruct(self) -> ReconstructResult:
        """Reconstruct (or reuse) fields, stresses and probe histories."""
        return self.stage("reconstruct")

    def assess(self) -> AssessResult:
        """Assess every probe against the standards of ``[assessment]``; write the report."""
        return self.stage("assess")

    def run(self) -> RunResult:
        """The whole pipeline (mesh, modal, mbs, reconstruct, assess) under one lock of the
        output folder; each stage reuses what is current."""
        done = self.run_stages(PIPELINE_ORDER)
        return RunResult(**done.results, seconds=done.seconds, run_json=done.run_json,
                         unused_petsc_options=done.unused_petsc_options)

    def run_stages(self, names: Sequence[str]) -> StagesResult:
        """Run the named stages in order under one lock of the output folder and one scope
        of the PETSc options, like :meth:`run` for another sequence (e.g. a full-order
        solution, then its assessment).

        Raises
        ------
        ValueError
            For a name that is not a stage (before anything runs).
        """
        from .io.files import RUN_FILE

        names = tuple(names)
        for name in names:
            stage(name)
            self._check_command(name)
        t0 = time.perf_counter()
        label = self._label("run")
        outer, self._run_label = self._run_label, label
        try:
            with self._runner.session(label) as unused:
                runs = run_stages(self._runner, names, self.case, command=label)
        finally:
            self._run_label = outer
        results = {name: self._result(run, ()) for name, run in runs.items()}
        seconds = time.perf_counter() - t0
        if self.comm.size > 1:
            seconds = self.comm.bcast(seconds, root=0)
        return StagesResult(results=results, seconds=seconds,
                            run_json=self.out_dir / RUN_FILE,
                            unused_petsc_options=tuple(unused))

    # --------------------------------------------------------------- reading
    def run_record(self) -> dict | None:
        """The output folder's ``run.json`` (None when no stage ran there yet)."""
        from .io.run_record import read_run_record

        return on_root(lambda: read_run_record(self.out_dir), self.comm)


# ----------------------------------------------------------------------------- studies
@dataclass(frozen=True)
class VariantStatus(_Frozen):
    """One variant of a study.

    Attributes
    ----------
    name, parameter, overrides
        The variant, its parameter values and its case overrides.
    folder
        Its folder.
    status
        ``finished``, ``failed``, ``stale`` or ``pending``.
    error
        Why it failed or is stale.
    """

    name: str
    parameter: dict[str, Any]
    overrides: tuple[str, ...]
    folder: Path
    status: str
    error: str | None = None


@dataclass(frozen=True)
class StudyTable(_Frozen):
    """A table of a study's report (the values as printed)."""

    title: str
    head: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def as_dicts(self) -> list[dict[str, str]]:
        """The rows as ``{column: value}``."""
        return [dict(zip(self.head, r)) for r in self.rows]


@dataclass(frozen=True)
class StudyResult(_Frozen):
    """:func:`run_study`: the variants, the verdict and the report.

    Attributes
    ----------
    kind
        The study (its name in :data:`railvib_hpc.studies.registry.STUDIES`).
    folder
        ``<out>/<kind>``.
    settings
        The validated study settings.
    variants
        Every variant with its status (after this call).
    computed, failed
        Names of the variants this call computed, and of those that failed (their
        ``failed.json`` says why).
    merged
        Whether the report was written (not for ``variants=``, ``prepare`` or ``list_only``).
    verdict
        The study's verdict: ``text`` and the numbers behind it (None when not merged);
        ``complete`` and ``missing`` (the variants not finished), ``band_warning`` (when a
        variant's modes end below the assessment band, else None).
    tables
        The report's tables.
    rows
        The analysis per variant (the numbers behind the tables).
    report
        ``{"markdown": path, "json": path}`` (empty when not merged).
    figures
        The report's figures.
    seconds
        Wall time [s].
    unused_petsc_options
        PETSc options nothing used.
    """

    kind: str
    folder: Path
    settings: dict[str, Any]
    variants: tuple[VariantStatus, ...]
    computed: tuple[str, ...]
    failed: tuple[str, ...]
    merged: bool
    verdict: dict[str, Any] | None
    tables: tuple[StudyTable, ...]
    rows: tuple[dict[str, Any], ...]
    report: dict[str, Path]
    figures: tuple[Path, ...]
    seconds: float
    unused_petsc_options: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        """True when no variant of this call failed."""
        return not self.failed

    @property
    def verdict_text(self) -> str | None:
        """The verdict's sentence."""
        return None if self.verdict is None else self.verdict.get("text")


def run_study(kind: str, case: Case | str | os.PathLike, out_dir: str | os.PathLike,
              comm: MPI.Comm | None = None, *, settings: Mapping[str, Any] | None = None,
              study_set: Sequence[str] = (), variants: Sequence[str | int] = (),
              merge_only: bool = False, prepare: bool = False, list_only: bool = False,
              petsc_options: PetscOptions = None, wait: bool = False,
              reporter: Reporter | None = None, quiet: bool = False) -> StudyResult:
    """Run a study (collective): its variants, then the report; resumable.

    Parameters
    ----------
    kind
        A registered study (:data:`railvib_hpc.studies.registry.STUDIES`: ``convergence``,
        ``modes``, ``reflection``, ``speed``, ``thesis``, ``mitigation``, ``uncertainty``,
        or one added with one line, :func:`railvib_hpc.studies.registry.register`).
    case
        The study's base case (a :class:`Case` or a case file); its ``[study.<kind>]``
        table holds the study's settings (those of the case schema's studies).
    out_dir
        Output folder; the study writes into ``<out_dir>/<kind>/``.
    comm
        MPI communicator (default ``COMM_WORLD``).
    settings
        Study settings with typed values (``{"speeds": [20.0, 40.0]}``), applied over the
        case's ``[study.<kind>]`` table and validated the same way.
    study_set
        Study settings as ``key=value`` strings (``--study-set``), applied last.
    variants
        Compute only these variants (names or 0-based indices); no report.
    merge_only, prepare, list_only
        Only write the report / only compute the shared model / only list the variants.
    petsc_options
        As for :class:`Pipeline` (copied, never changed; in PETSc's database only while
        the study runs).
    wait
        Wait for other commands holding a variant folder instead of failing that variant.
    reporter, quiet
        As for :class:`Pipeline`.

    Returns
    -------
    StudyResult
        The same on every rank. A variant that fails with a user error does not raise: it
        is in ``failed`` (and ``ok`` is False).

    Raises
    ------
    UserError
        Bad settings or variant names, an unknown study (one line, every rank), or what the
        study cannot do with the case (a case without a track and a study on the track's
        modes).
    """
    from .petsc_env import check_option_words, option_words, options_scope
    from .studies import execute_study

    if comm is None:
        comm = world()
    case = _as_case(case)
    words = option_words(petsc_options)
    check_option_words(words)
    rep = _reporter(comm, reporter, quiet)
    with options_scope(words) as unused:
        s = execute_study(kind, case, Path(out_dir), comm, rep,
                          variants=[str(v) for v in variants], merge_only=merge_only,
                          prepare=prepare, list_only=list_only, study_set=list(study_set),
                          settings=dict(settings) if settings else None,
                          petsc_options=list(words), wait=wait)
    return StudyResult(
        kind=s["kind"], folder=Path(s["folder"]), settings=dict(s["settings"]),
        variants=tuple(VariantStatus(name=e["name"], parameter=dict(e.get("parameter") or {}),
                                     overrides=tuple(e.get("overrides", ())),
                                     folder=Path(e["folder"]), status=e["status"],
                                     error=e.get("error")) for e in s["variants"]),
        computed=tuple(s["computed"]), failed=tuple(s["failed"]), merged=s["merged"],
        verdict=s["verdict"],
        tables=tuple(StudyTable(t.get("title", ""), tuple(t["head"]),
                                tuple(tuple(str(c) for c in r) for r in t["rows"]))
                     for t in s["tables"]),
        rows=tuple(s["rows"]), report={k: Path(v) for k, v in s["files"].items()},
        figures=tuple(Path(p) for p in s["figures"]), seconds=s["seconds"],
        unused_petsc_options=tuple(unused))
