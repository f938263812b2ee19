"""The study protocol: every study declared once (:class:`Study`), in its own module.

A study module declares one ``STUDY = Study(...)``: its name (``railvib study <name>``), its
help line, its settings (the ``[study.<name>]`` keys with their defaults and checks), its
variants (:attr:`Study.plan`), its analysis and verdict (:attr:`Study.analyse`), its
figures, and what it cannot do without a track. The optional hooks are what some studies
add: a model prepared once for every variant, a progress line after each variant, the
columns of ``--list``, result files of their own, or a computation of their own for a
variant (:attr:`Study.variant`: by default a variant runs the stages, the modal solution or,
with ``solver = direct``, the full-order one). Registered with one line
(:data:`railvib_hpc.studies.registry.STUDIES`), a study runs from the command line (its
name and help line are the choices and help of ``railvib study``) and from the Python API
(:func:`railvib_hpc.api.run_study`), through the one study runner
(:func:`railvib_hpc.studies.runner.execute_study`: folders, locks, ``result.json``,
resuming, the merged report). ``tests/example_study.py`` is a whole new study.

The callables take these arguments (``settings``: the validated study settings, a dict):

* ``plan(case, settings, root=None) -> StudyPlan``: the variants (``root``: the study's
  folder, for a study whose variants name files in it);
* ``analyse(plan, results, settings) -> dict``: ``title``, ``verdict`` (``text``, ``ok``:
  True, False or None when undetermined), ``tables`` (``{title, head, rows, note}``),
  ``rows`` and any data, from the finished variants' results ``{name: result}``;
* ``figures(analysis, settings, fig_dir, results=None) -> [paths]``: the report's PNGs.

Example
-------
>>> from railvib_hpc.studies.registry import study
>>> speed = study("speed")
>>> speed.name, speed.needs_track, "speeds" in speed.settings
('speed', None, True)
>>> study("modes").needs_track
"it compares numbers of the track's modes under the vehicle (the modal path)"
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..schema import SCHEMA, Param

__all__ = ["Study"]

#: One refusal: ``(key, value, allowed)``, for :class:`~railvib_hpc.errors.CaseError`.
Refusal = tuple[str, Any, str]


@dataclass(frozen=True)
class Study:
    """One study, declared once in its module (``STUDY = Study(...)``).

    Attributes
    ----------
    name
        ``railvib study <name>``; the folder ``<out>/<name>``; the ``study`` of its results.
    help
        One line: the command line's help of the study.
    title
        The report's title (when the analysis gives none).
    plan, analyse, figures
        The variants, the analysis with its verdict, the figures (signatures in the module
        notes).
    settings
        Its settings, ``{key: Param}`` (:class:`~railvib_hpc.schema.Param`: default, type,
        range, what it means); default (None): the case schema's ``[study.<name>]`` table,
        which a case file may hold. A study outside the schema takes its settings from
        the defaults, ``settings=`` and ``--study-set`` only.
    sorted_settings
        Settings whose lists are sorted (where their order does not matter).
    needs_track
        Why it needs a track (the sentence of its refusal of a case with ``track.count =
        0``); None: it runs such a case with ``solver = direct``.
    trackless_problem
        ``trackless_problem(settings) -> (key, value, allowed) | None``: what else it
        cannot do without a track (a mitigation measure on the track's keys).
    derive_settings
        ``derive_settings(settings, given) -> None``: fill settings that follow from the
        given ones (the reflection study's names of its domains), in place.
    check_settings
        ``check_settings(settings) -> [(key, value, allowed), ...]``: its cross-key checks
        beyond the schema's (:func:`~railvib_hpc.validation.check_studies`).
    variant
        ``variant(plan, variant, case, runner, settings) -> dict``: a variant's own
        computation in its folder (``runner``: the variant folder's
        :class:`~railvib_hpc.io.stage_protocol.StageRunner`, in its session; collective,
        the same dict on every rank), whose entries go into ``result.json``; None: the
        stages (the modal solution, or the full-order one with ``solver = direct``).
    prepare
        ``prepare(plan, case, root, comm, rep)``: what every variant needs, computed once
        before them (the uncertainty study's reduced model).
    progress
        ``progress(plan, results, settings) -> str``: a line after each variant.
    listing_columns
        ``listing_columns(plan, case, entries) -> (notes, head, cells)``: the columns of
        ``--list`` instead of the overrides.
    write_results
        ``write_results(analysis, root) -> {name: path}``: result files of its own.
    """

    name: str
    help: str
    title: str
    plan: Callable[..., Any]
    analyse: Callable[[Any, dict, dict], dict]
    figures: Callable[..., list]
    settings: Mapping[str, Param] | None = None
    sorted_settings: tuple[str, ...] = ()
    needs_track: str | None = None
    trackless_problem: Callable[[dict], Refusal | None] | None = None
    derive_settings: Callable[[dict, dict], None] | None = None
    check_settings: Callable[[dict], list[Refusal]] | None = None
    variant: Callable[..., dict] | None = None
    prepare: Callable[..., None] | None = None
    progress: Callable[[Any, dict, dict], str] | None = None
    listing_columns: Callable[..., tuple] | None = None
    write_results: Callable[[dict, Any], dict] | None = None
    in_schema: bool = field(init=False, default=False)

    def __post_init__(self) -> None:
        schema = SCHEMA["study"].get(self.name)
        object.__setattr__(self, "in_schema", self.settings is None and schema is not None)
        if self.settings is None:
            if schema is None:
                raise ValueError(f"study {self.name}: no settings given and no "
                                 f"[study.{self.name}] table in the case schema")
            object.__setattr__(self, "settings", schema)
        unknown = [k for k in self.sorted_settings if k not in self.settings]
        if unknown:
            raise ValueError(f"study {self.name}: sorted setting {unknown[0]!r} is not one "
                             "of its settings")
