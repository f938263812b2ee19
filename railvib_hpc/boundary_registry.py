"""The registry of the boundary kinds of a truncation face: names, and modules loaded lazily.

:data:`BOUNDARY_KINDS` maps each kind of ``boundary.<face>`` to the module that declares it
(its ``KIND``, a :class:`railvib_hpc.model.boundary_kind.BoundaryKind`). A new kind is one
such module and one line here. The schema takes its allowed values from
:data:`BOUNDARY_KIND_NAMES`, a live view of the registry's names, so this module imports
nothing of the package: the model's modules are imported only when a kind is first asked
for (:func:`boundary_kind`), as the stage registry does (:mod:`railvib_hpc.pipeline`). The
declared kinds follow the boundary-parameter classes of STEM
(``stem/boundary.py``, ``BoundaryParametersABC``: one class per condition, holding what it
constrains and what it adds to the model).

Example
-------
>>> tuple(BOUNDARY_KIND_NAMES)
('fixed', 'roller', 'free', 'absorbing', 'caughey', 'pml')
>>> boundary_kind("roller").constrained("base")
('uz',)
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Sequence
from typing import Any

#: ``{kind: module declaring its KIND}``, in the order the schema lists them (and in which
#: the kinds' checks run).
BOUNDARY_KINDS: dict[str, str] = {
    "fixed": "railvib_hpc.model.boundary_kinds.fixed",
    "roller": "railvib_hpc.model.boundary_kinds.roller",
    "free": "railvib_hpc.model.boundary_kinds.free",
    "absorbing": "railvib_hpc.model.boundary_kinds.absorbing",
    "caughey": "railvib_hpc.model.boundary_kinds.caughey",
    "pml": "railvib_hpc.model.boundary_kinds.pml",
}


class KindNames(Sequence):
    """The names of :data:`BOUNDARY_KINDS`, read from the registry at each use (a kind
    registered later is among them)."""

    def __getitem__(self, index):
        return tuple(BOUNDARY_KINDS)[index]

    def __len__(self) -> int:
        return len(BOUNDARY_KINDS)

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(BOUNDARY_KINDS))

    def __contains__(self, name: object) -> bool:
        return name in BOUNDARY_KINDS

    def __repr__(self) -> str:
        return repr(tuple(BOUNDARY_KINDS))


#: The allowed values of ``boundary.<face>`` (:data:`railvib_hpc.schema.BOUNDARY_TYPES`).
BOUNDARY_KIND_NAMES = KindNames()


def boundary_kind(name: str) -> Any:
    """The declared kind ``name`` (its module's ``KIND``), imported on first use.

    Raises
    ------
    ValueError
        An unknown name, or a module that declares another kind.
    """
    if name not in BOUNDARY_KINDS:
        raise ValueError(f"unknown boundary kind {name!r}; kinds: {', '.join(BOUNDARY_KINDS)}")
    declared = importlib.import_module(BOUNDARY_KINDS[name]).KIND
    if declared.name != name:
        raise ValueError(f"{BOUNDARY_KINDS[name]} declares boundary kind {declared.name!r}, "
                         f"not {name!r}")
    return declared


def boundary_kinds() -> list[Any]:
    """Every registered kind, in registry order."""
    return [boundary_kind(name) for name in BOUNDARY_KINDS]
