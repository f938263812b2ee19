"""The one rule every key obeys (:attr:`railvib_hpc.schema.Param.applies`): where its
feature is off, a key keeps its default (:func:`feature_key_problems`), and the keys a
change switches off (:func:`switched_off`).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from ..schema import PRESETS, CaseView
from .values import ALL_KEYS


def _baseline(case: Any, key: str) -> Any:
    """The default of ``key``: the case's preset's value, else the schema's."""
    return PRESETS.get(case["case.preset"], {}).get(key, ALL_KEYS[key].default)


def _at_default(case: Any, key: str, value: Any) -> bool:
    """Whether ``value`` is a default of ``key``: the preset's or the schema's (a file that
    lists every key at the APDL values, with the preset ``table1``, sets them unused)."""
    return value == _baseline(case, key) or value == ALL_KEYS[key].default


def _off_text(condition: Any, case: Any, default: Any) -> str:
    part = condition.failing(case)
    return (f"applies to {part.text} only; here {part.here(case)}: leave it at its "
            f"default {default!r} (or leave it out)")


def feature_key_problems(case: CaseView) -> list[tuple[str, Any, str]]:
    """The one rule of the keys that belong to a feature (:attr:`Param.applies
    <railvib_hpc.schema.Param>`): where the feature is off, the key keeps its default.

    A key set to its default (the schema's, or its preset's) where its feature is off is
    accepted (a file may list every key, as ``jobs/thesis_baseline.toml`` does); any other
    value is refused, naming the
    condition that does not hold and the value that breaks it. The entries of
    ``train2.vehicle`` follow the rule of their ``[vehicle]`` key (its cars' keys apply
    to cars only). Derived keys are not checked (their value follows from others).

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> feature_key_problems(Case.defaults()) == []
    True
    """
    out: list[tuple[str, Any, str]] = []
    for key, param in ALL_KEYS.items():
        condition = param.applies
        if condition is None or param.derived:
            continue
        value, default = case[key], _baseline(case, key)
        if _at_default(case, key, value):
            continue
        if not condition.holds(case):
            out.append((key, value, _off_text(condition, case, default)))
        elif param.kind == "vehicle":
            for name, entry in value.items():
                inner = ALL_KEYS[f"vehicle.{name}"].applies
                if inner is not None and not inner.holds(case):
                    out.append((f"{key}.{name}", entry, _off_text(inner, case, "not given")))
    return out


def switched_off(case: CaseView, changes: Mapping[str, Any]) -> dict[str, Any]:
    """The keys whose feature ``changes`` (``{dotted key: value}``, e.g. a study variant's
    overrides) switch off while the case sets them: ``{key: default}`` to reset, so that
    a variant that replaces, say, the case's pml faces by rollers does not carry the
    layer's keys into a case that would refuse them. Keys that ``changes`` set themselves
    stay as given (the rule judges them)."""
    values = {k: case[k] for k in ALL_KEYS}
    values.update({k: v for k, v in changes.items() if k in values})
    out = {}
    for key, param in ALL_KEYS.items():
        condition = param.applies
        if condition is None or param.derived or key in changes:
            continue
        default = _baseline(case, key)
        if _at_default(case, key, values[key]) or not condition.holds(case):
            continue
        try:
            off = not condition.holds(values)
        except (TypeError, KeyError):      # a badly typed change: build_case names it
            continue
        if off:
            out[key] = copy.deepcopy(default)
    return out
