"""Study settings: per-study defaults, ``--study-set key=value`` overrides, validation.

Why not a ``[study]`` table in the case file: ``railvib`` validates the case file before it
dispatches any command, and the case schema (:mod:`railvib_hpc.schema`) rejects unknown
tables. Study settings therefore live next to the case, not in it: every study has
defaults (:data:`SETTINGS`, chosen for the thesis model) that ``--study-set KEY=VALUE``
overrides (repeatable, the value in TOML syntax, e.g. ``--study-set levels=[0.5,0.75,1]``).
The case files in ``jobs/`` stay plain case files that ``railvib check`` accepts.
Every problem is reported at once, each naming the key, the value and what is allowed
(:class:`StudySettingsError`, exit code 2).
"""

from __future__ import annotations

import difflib
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import tomllib

from ..errors import UserError

#: Probes of the building whose responses the studies compare (names of the mesh probes).
BUILDING_PROBES = ("footing", "basement_wall", "slab1", "slab2")


class StudySettingsError(UserError):
    """Invalid study settings; each problem names key, value and what is allowed.

    Parameters
    ----------
    kind
        The study.
    problems
        ``(key, value, allowed)`` triples.
    """

    def __init__(self, kind: str, problems: list[tuple[str, object, str]]):
        self.kind = kind
        self.problems = list(problems)
        lines = [f"{key} = {value!r}: {allowed}" for key, value, allowed in self.problems]
        header = f"invalid settings of the '{kind}' study"
        if len(lines) > 1:
            header += f" ({len(lines)} problems)"
        super().__init__(header + ":\n  " + "\n  ".join(lines))

    def __reduce__(self):  # picklable: broadcast to every MPI rank
        return (type(self), (self.kind, self.problems))


@dataclass(frozen=True)
class Setting:
    """One study setting.

    Attributes
    ----------
    default
        Default value.
    kind
        ``float``, ``int``, ``floats``, ``ints``, ``bools``, ``strs`` or ``triples``
        (a list of ``[a, b, c]`` number lists).
    doc
        What it means (shown in errors and in ``jobs/README.md``).
    check
        ``pos`` (> 0), ``nonneg`` (>= 0), ``refinement`` (0 < value <= 6), or empty.
    choices
        Allowed values of a ``str`` setting (or of the entries of a ``strs`` setting).
    """

    default: Any
    kind: str
    doc: str
    check: str = ""
    choices: tuple[str, ...] = ()


_PROBES = Setting(list(BUILDING_PROBES), "strs",
                  "mesh probes whose responses are compared (the building probes)")

#: Settings of each study with their defaults.
SETTINGS: dict[str, dict[str, Setting]] = {
    "convergence": {
        "levels": Setting([0.5, 0.75, 1.0, 1.25], "floats",
                          "mesh.refinement of each level (at least 2, coarse to fine)",
                          "refinement"),
        "tolerance": Setting(5.0, "float", "verdict: converged when the estimated error of "
                             "the finest level is at most this many percent", "pos"),
        "n_frequencies": Setting(5, "int", "lowest natural frequencies compared", "pos"),
        "formal_order": Setting(2.0, "float", "order assumed with two levels or when the "
                                "observed order is unreliable (trilinear hexahedra: 2)", "pos"),
        "probes": _PROBES,
    },
    "modes": {
        "n_modes": Setting([50, 100, 200, 300], "ints",
                           "numbers of modes used by the MBS (mbs.n_modes), from one modal "
                           "solve with the largest", "pos"),
        "static_correction": Setting([False, True], "bools",
                                     "run every mode count without and/or with the static "
                                     "correction"),
        "tolerance": Setting(5.0, "float", "accuracy asked for: modes needed to stay within "
                             "this many percent of the reference (most modes, corrected if "
                             "run)", "pos"),
        "probes": _PROBES,
    },
    "reflection": {
        "domains": Setting([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 2.0, 6.0],
                            [4.0, 4.0, 12.0]], "triples",
                           "[extra_depth, extra_length, extra_width] in m of each domain "
                           "(domain.extra_*), smallest first; the last is the reference", "nonneg"),
        "names": Setting(["model1", "model2", "model3", "larger"], "strs",
                         "variant names, one per domain"),
        "threshold": Setting(10.0, "float", "verdict: reflections matter when a building "
                             "peak acceleration differs from the reference domain by more "
                             "than this many percent", "pos"),
        "band_hz": Setting(0.0, "float", "0: every domain uses modal.n_modes of the case; "
                           "> 0: every domain uses all its modes below this frequency "
                           "(the same band for all domains)", "nonneg"),
        "boundaries": Setting(["case"], "strs",
                              "boundary conditions of the truncation faces, each run on every "
                              "domain: case (the case file's [boundary]), thesis (rollers, "
                              "fixed base), absorbing (all five faces absorbing)",
                              choices=("case", "thesis", "absorbing")),
        "solver": Setting("modal", "str",
                          "modal (modes + mbs, the thesis's method) or direct (railvib "
                          "transient: the full model in the time domain, causal; band_hz "
                          "does not apply)", choices=("modal", "direct")),
        "probes": _PROBES,
    },
    "speed": {
        "speeds": Setting([10.0, 20.0, 30.0, 40.0, 50.0, 60.0], "floats",
                          "vehicle speeds in m/s (one MBS run each on the same modes)", "pos"),
        "probes": _PROBES,
    },
}

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _check_scalar(key: str, s: Setting, v: Any, problems: list) -> Any:
    """Convert and check one scalar of kind float/int (also list elements)."""
    base = "int" if s.kind in ("int", "ints") else "float"
    if base == "int":
        if isinstance(v, bool) or not (isinstance(v, int) or
                                       (isinstance(v, float) and v.is_integer())):
            problems.append((key, v, f"expected an integer ({s.doc})"))
            return None
        v = int(v)
    else:
        if not _number(v):
            problems.append((key, v, f"expected a finite number ({s.doc})"))
            return None
        v = float(v)
    if s.check == "pos" and not v > 0:
        problems.append((key, v, f"must be > 0 ({s.doc})"))
    elif s.check == "nonneg" and not v >= 0:
        problems.append((key, v, f"must be >= 0 ({s.doc})"))
    elif s.check == "refinement" and not 0 < v <= 6:
        problems.append((key, v, f"must satisfy 0 < value <= 6 ({s.doc})"))
    return v


def _check(key: str, s: Setting, value: Any, problems: list) -> Any:
    """Type-check and convert one setting; append problems; return the converted value."""
    if s.kind in ("float", "int"):
        return _check_scalar(key, s, value, problems)
    if s.kind == "str":
        if not isinstance(value, str) or (s.choices and value not in s.choices):
            problems.append((key, value, "allowed: " + ", ".join(s.choices)))
        return value
    if not isinstance(value, list) or not value:
        problems.append((key, value, f"expected a non-empty list ({s.doc})"))
        return value
    if s.kind in ("floats", "ints"):
        n = len(problems)
        out = [_check_scalar(key, s, v, problems) for v in value]
        if len(problems) > n:
            return value
        if len(set(out)) != len(out):
            problems.append((key, value, "entries must be distinct"))
        return out
    if s.kind == "bools":
        if not all(isinstance(v, bool) for v in value):
            problems.append((key, value, "expected a list of true/false"))
        elif len(set(value)) != len(value):
            problems.append((key, value, "entries must be distinct"))
        return value
    if s.kind == "strs":
        bad = [v for v in value if not isinstance(v, str) or not _NAME.match(v)]
        if bad:
            problems.append((key, value, "expected a list of names (letters, digits, "
                             f"'_.+-'); bad entries: {bad}"))
        elif len(set(value)) != len(value):
            problems.append((key, value, "entries must be distinct"))
        elif s.choices and any(v not in s.choices for v in value):
            unknown = [v for v in value if v not in s.choices]
            problems.append((key, value, f"unknown entries {unknown}; allowed: "
                             + ", ".join(s.choices)))
        return value
    # triples
    ok = all(isinstance(t, list) and len(t) == 3 and all(_number(x) for x in t)
             for t in value)
    if not ok:
        problems.append((key, value, f"expected a list of [a, b, c] number triples ({s.doc})"))
        return value
    out = [[float(x) for x in t] for t in value]
    if s.check == "nonneg" and any(x < 0 for t in out for x in t):
        problems.append((key, value, f"entries must be >= 0 ({s.doc})"))
    return out


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
    return key, _toml_value(raw)


def _toml_value(raw: str) -> Any:
    """A TOML value; unquoted words are strings, also inside a flat list (``[a, b]``)."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        pass
    if raw.startswith("[") and raw.endswith("]") and "[" not in raw[1:-1]:
        return [_toml_value(x.strip()) for x in raw[1:-1].split(",") if x.strip()]
    return raw


def study_settings(kind: str, overrides: Sequence[str] = (),
                   values: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The settings of a study: defaults, then ``values``, then ``overrides``; validated.

    Parameters
    ----------
    kind
        ``convergence``, ``modes``, ``reflection`` or ``speed``.
    overrides
        ``key=value`` strings (``--study-set``).
    values
        Settings given programmatically (e.g. by tests).

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
    if kind not in SETTINGS:
        raise StudySettingsError(kind, [("study", kind, "allowed: " + ", ".join(SETTINGS))])
    spec = SETTINGS[kind]
    given: dict[str, Any] = dict(values or {})
    problems: list[tuple[str, Any, str]] = []
    for text in overrides:
        key, value = parse_study_set(kind, text)
        given[key] = value
    out = {k: (list(s.default) if isinstance(s.default, list) else s.default)
           for k, s in spec.items()}
    for key, value in given.items():
        if key not in spec:
            close = difflib.get_close_matches(key, list(spec), n=1, cutoff=0.6)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            problems.append((key, value, f"unknown setting of the '{kind}' study; allowed: "
                             + ", ".join(spec) + hint))
            continue
        out[key] = _check(key, spec[key], value, problems)
    if not problems:
        problems.extend(_cross_checks(kind, out, given))
    if problems:
        raise StudySettingsError(kind, problems)
    return out


def _cross_checks(kind: str, s: dict[str, Any], given: Mapping[str, Any]) -> list:
    """Checks across keys; also sorts the level lists."""
    out: list[tuple[str, Any, str]] = []
    if kind == "convergence":
        s["levels"] = sorted(s["levels"])
        if len(s["levels"]) < 2:
            out.append(("levels", s["levels"], "need at least 2 refinement levels "
                        "(3 for an observed order)"))
    elif kind == "modes":
        s["n_modes"] = sorted(s["n_modes"])
        s["static_correction"] = sorted(s["static_correction"])
    elif kind == "reflection":
        if "domains" in given and "names" not in given:
            s["names"] = [f"domain{i + 1}" for i in range(len(s["domains"]))]
        if len(s["names"]) != len(s["domains"]):
            out.append(("names", s["names"], f"needs one name per entry of domains "
                        f"({len(s['domains'])})"))
        if len(s["domains"]) < 2:
            out.append(("domains", s["domains"], "need at least 2 domains to compare"))
        if len({tuple(d) for d in s["domains"]}) != len(s["domains"]):
            out.append(("domains", s["domains"], "domains must be distinct"))
    elif kind == "speed":
        s["speeds"] = sorted(s["speeds"])
    return out


def describe(kind: str) -> str:
    """Markdown table of a study's settings and defaults (for ``jobs/README.md``)."""
    rows = [f"| `{k}` | `{json.dumps(s.default)}` | {s.doc} |"
            for k, s in SETTINGS[kind].items()]
    return "\n".join(["| setting | default | meaning |", "|---|---|---|", *rows])
