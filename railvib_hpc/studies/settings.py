"""Study settings: the ``[study.KIND]`` tables of the case schema, ``--study-set`` overrides.

The settings of each study are ordinary case keys, ``study.<kind>.<key>``, declared in
:mod:`railvib_hpc.schema` (a study's ``Study.settings``, :mod:`.protocol`: the schema's
``[study.<kind>]`` table, or its own for a study outside the schema) and checked by the one
validation engine of :mod:`railvib_hpc.validation` (same types, ranges and error format:
key, value, allowed). A case file may hold the schema's as tables (``[study.convergence]``,
...); ``--study-set KEY=VALUE``
(repeatable, the value in TOML syntax, bare words allowed, e.g. ``--study-set
levels=[0.5,0.75,1]`` or ``--study-set probes=[slab1,slab2]``) overrides the study's
``study.<kind>.KEY`` on the command line. Every problem is reported at once
(:class:`StudySettingsError`, a :class:`~railvib_hpc.errors.CaseError`, exit code 2).
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Mapping, Sequence
from typing import Any

from ..config import Case, toml_value
from ..errors import CaseError
from ..schema import BUILDING_PROBES, SCHEMA, Param
from ..validation import check_studies, check_value
from .registry import STUDIES, UnknownStudy, study

__all__ = ["BUILDING_PROBES", "SETTINGS", "StudySettingsError", "describe",
           "parse_study_set", "study_settings"]

#: Settings of the studies in the case schema with their defaults: its ``study`` tables
#: (every registered study's are its ``Study.settings``).
SETTINGS: dict[str, dict[str, Param]] = SCHEMA["study"]


class StudySettingsError(CaseError):
    """Invalid study settings; each problem names key, value and what is allowed.

    Parameters
    ----------
    kind
        The study.
    problems
        ``(key, value, allowed)`` triples (keys ``study.<kind>.<key>``).
    """

    def __init__(self, kind: str, problems: list[tuple[str, object, str]]):
        super().__init__(problems)
        self.kind = kind
        lines = [f"{key} = {value!r}: {allowed}" for key, value, allowed in self.problems]
        header = f"invalid settings of the '{kind}' study"
        if len(lines) > 1:
            header += f" ({len(lines)} problems)"
        self.args = (header + ":\n  " + "\n  ".join(lines),)

    def __reduce__(self):  # picklable: broadcast to every MPI rank
        return (type(self), (self.kind, self.problems))


def parse_study_set(kind: str, text: str) -> tuple[str, Any]:
    """Parse one ``--study-set key=value`` (value in TOML syntax; bare words are strings,
    also in lists: ``probes=[slab1,slab2]``).

    Raises
    ------
    StudySettingsError
        When the text has no ``=``.
    """
    if "=" not in text:
        raise StudySettingsError(kind, [(text, None, "a study setting must look like "
                                         "key=value, e.g. --study-set levels=[0.5,1]")])
    key, raw = (x.strip() for x in text.split("=", 1))
    return key, toml_value(raw)


def _thaw(value: Any) -> Any:
    """Tuples as lists and read-only mappings as dicts: the frozen ``settings`` of a
    :class:`~railvib_hpc.api.StudyResult` given back as settings."""
    if isinstance(value, tuple | list):
        return [_thaw(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    return value


def study_settings(kind: str, overrides: Sequence[str] = (),
                   values: Mapping[str, Any] | None = None,
                   case: Case | None = None) -> dict[str, Any]:
    """The settings of a study: defaults, the case's ``[study.KIND]`` table, then ``values``,
    then ``overrides``; validated by the case schema's engine.

    Parameters
    ----------
    kind
        A registered study (:data:`~railvib_hpc.studies.registry.STUDIES`).
    overrides
        ``key=value`` strings (``--study-set``), keys without the ``study.<kind>.`` prefix.
    values
        Settings given programmatically (e.g. by tests).
    case
        The case whose ``[study.KIND]`` table is the starting point (None: the defaults).

    Returns
    -------
    dict
        Every setting of the study, converted (lists sorted where the order matters).

    Raises
    ------
    StudySettingsError
        With every problem found (unknown keys with a did-you-mean, wrong types, values
        out of range, inconsistent lists).
    """
    try:
        declared = study(kind)
    except UnknownStudy:
        raise StudySettingsError(kind, [("study", kind, "allowed: " + ", ".join(STUDIES))]) \
            from None
    spec = declared.settings
    prefix = f"study.{kind}."
    base = case.section(f"study.{kind}") if case is not None and declared.in_schema else {
        k: json.loads(json.dumps(p.default)) for k, p in spec.items()}
    given: dict[str, Any] = {k: _thaw(v) for k, v in (values or {}).items()}
    for text in overrides:
        key, value = parse_study_set(kind, text)
        given[key] = value
    problems: list[tuple[str, Any, str]] = []
    out = dict(base)
    for key, value in given.items():
        if key not in spec:
            close = difflib.get_close_matches(key, list(spec), n=1, cutoff=0.6)
            hint = f"; did you mean '{prefix}{close[0]}'?" if close else ""
            problems.append((prefix + key, value, f"unknown setting of the '{kind}' study; "
                             "allowed: " + ", ".join(spec) + hint))
            continue
        out[key] = check_value(prefix + key, spec[key], value, problems)
    if problems:
        raise StudySettingsError(kind, problems)
    if declared.derive_settings is not None:
        declared.derive_settings(out, given)
    problems = check_studies({kind: out}) + (
        declared.check_settings(out) if declared.check_settings is not None else [])
    if problems:
        raise StudySettingsError(kind, problems)
    for key in declared.sorted_settings:
        out[key] = sorted(out[key])
    return out


def describe(kind: str) -> str:
    """Markdown table of a study's settings and defaults (for ``jobs/README.md``)."""
    rows = [f"| `{k}` | `{json.dumps(s.default)}` | {s.doc} |"
            for k, s in study(kind).settings.items()]
    return "\n".join(["| setting | default | meaning |", "|---|---|---|", *rows])
