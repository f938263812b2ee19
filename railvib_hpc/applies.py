"""When a case key applies: the conditions the schema declares next to its keys.

A key that belongs to a feature (the cars of ``vehicle.type = 'vehicle'``, the layer of a
``pml`` face, the second train of ``track.count = 2`` ...) declares the condition under
which the feature is on (:attr:`railvib_hpc.schema.Param.applies`). One rule, in
:func:`railvib_hpc.validation.feature_key_problems`, holds every key to it: a key whose
feature is off must keep its default value (a file may list it at its default, as
``jobs/thesis_baseline.toml`` lists every key), else the case is refused with one line
"applies to ... only".

The conditions are a small algebra of the case's own values: :func:`is_` (a key has one
of some values), :func:`is_not`, :func:`above` (a number above a bound),
:func:`not_empty` (a list or a string given), :func:`includes` (a list holds an item),
:func:`all_of` and :func:`any_of`. Each reads the case (or any mapping of dotted keys)
through ``values[key]`` and says in words what it asks (:attr:`Condition.text`) and what
the case has instead (:meth:`Condition.here`).

Examples
--------
>>> cars = all_of(above("track.count", 0, what="the train on a track"),
...               is_("vehicle.type", "vehicle"))
>>> cars.text
"the train on a track (track.count > 0) and vehicle.type = 'vehicle'"
>>> values = {"track.count": 1, "vehicle.type": "wheelset"}
>>> cars.holds(values), cars.failing(values).text, cars.here(values)
(False, "vehicle.type = 'vehicle'", "vehicle.type = 'wheelset'")
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["Condition", "above", "all_of", "any_of", "includes", "is_", "is_not",
           "not_empty"]


class Condition:
    """A condition on the values of a case (read as ``values[key]``)."""

    #: The keys it reads (for :meth:`here`).
    keys: tuple[str, ...] = ()

    def holds(self, values: Mapping[str, Any]) -> bool:
        """Whether the feature is on for these values."""
        raise NotImplementedError

    @property
    def text(self) -> str:
        """What it asks, in words (``"vehicle.type = 'vehicle'"``)."""
        raise NotImplementedError

    def failing(self, values: Mapping[str, Any]) -> Condition:
        """The part that does not hold (itself for a single test or :func:`any_of`)."""
        return self

    def here(self, values: Mapping[str, Any]) -> str:
        """What the case has instead: its values of the keys the failing part reads."""
        part = self.failing(values)
        return ", ".join(f"{k} = {values[k]!r}" for k in part.keys)


def _described(what: str, expr: str) -> str:
    return f"{what} ({expr})" if what else expr


@dataclass(frozen=True)
class _Is(Condition):
    key: str
    values: tuple[Any, ...]
    negate: bool = False
    what: str = ""

    @property
    def keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return (self.key,)

    def holds(self, values: Mapping[str, Any]) -> bool:
        return (values[self.key] in self.values) != self.negate

    @property
    def text(self) -> str:
        shown = " or ".join(map(repr, self.values))
        return _described(self.what, f"{self.key} {'!=' if self.negate else '='} {shown}")


@dataclass(frozen=True)
class _Above(Condition):
    key: str
    bound: float
    inclusive: bool = False
    what: str = ""

    @property
    def keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return (self.key,)

    def holds(self, values: Mapping[str, Any]) -> bool:
        v = values[self.key]
        return v >= self.bound if self.inclusive else v > self.bound

    @property
    def text(self) -> str:
        return _described(self.what,
                          f"{self.key} {'>=' if self.inclusive else '>'} {self.bound:g}")


@dataclass(frozen=True)
class _NotEmpty(Condition):
    key: str
    what: str = ""

    @property
    def keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return (self.key,)

    def holds(self, values: Mapping[str, Any]) -> bool:
        return bool(values[self.key])

    @property
    def text(self) -> str:
        return _described(self.what, f"{self.key} given")


@dataclass(frozen=True)
class _Includes(Condition):
    key: str
    item: Any
    what: str = ""

    @property
    def keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return (self.key,)

    def holds(self, values: Mapping[str, Any]) -> bool:
        return self.item in values[self.key]

    @property
    def text(self) -> str:
        return _described(self.what, f"{self.key} with {self.item!r}")


@dataclass(frozen=True)
class _AllOf(Condition):
    parts: tuple[Condition, ...]

    @property
    def keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(dict.fromkeys(k for p in self.parts for k in p.keys))

    def holds(self, values: Mapping[str, Any]) -> bool:
        return all(p.holds(values) for p in self.parts)

    @property
    def text(self) -> str:
        return " and ".join(p.text for p in self.parts)

    def failing(self, values: Mapping[str, Any]) -> Condition:
        return next((p.failing(values) for p in self.parts if not p.holds(values)), self)


@dataclass(frozen=True)
class _AnyOf(Condition):
    parts: tuple[Condition, ...]
    what: str = ""

    @property
    def keys(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(dict.fromkeys(k for p in self.parts for k in p.keys))

    def holds(self, values: Mapping[str, Any]) -> bool:
        return any(p.holds(values) for p in self.parts)

    @property
    def text(self) -> str:
        return self.what or " or ".join(p.text for p in self.parts)


def is_(key: str, *values: Any, what: str = "") -> Condition:
    """``key`` has one of ``values`` (``what``: the feature in words, shown first)."""
    return _Is(key, tuple(values), False, what)


def is_not(key: str, *values: Any, what: str = "") -> Condition:
    """``key`` has none of ``values``."""
    return _Is(key, tuple(values), True, what)


def above(key: str, bound: float, *, inclusive: bool = False, what: str = "") -> Condition:
    """``key`` > ``bound`` (``>=`` with ``inclusive``)."""
    return _Above(key, float(bound), inclusive, what)


def not_empty(key: str, what: str = "") -> Condition:
    """``key`` (a list or a string) is given: not empty."""
    return _NotEmpty(key, what)


def includes(key: str, item: Any, what: str = "") -> Condition:
    """``key`` (a list) holds ``item``."""
    return _Includes(key, item, what)


def all_of(*parts: Condition) -> Condition:
    """Every part holds (the message names the first that does not)."""
    flat: list[Condition] = []
    for p in parts:
        flat.extend(p.parts if isinstance(p, _AllOf) else (p,))
    return _AllOf(tuple(flat))


def any_of(*parts: Condition, what: str = "") -> Condition:
    """At least one part holds (``what``: the whole in words, else the parts joined)."""
    return _AnyOf(tuple(parts), what)
