"""The declarations of the time-domain engines of ``railvib transient`` (``transient.engine``).

One table, :data:`ENGINES`, names every engine with what the layers below the transient
stage need to know of it without importing it: whether it takes perfectly matched layers,
whether it needs the lumped mass, how its soil is integrated (for the dispersion check,
:mod:`railvib_hpc.mesh.dispersion_check`), the assessment's line on it, and where its
implementation lives (``"module:factory"``, imported only when a run builds it,
:func:`railvib_hpc.transient.engine.build_engine`). The schema's choices
(``schema.TRANSIENT_ENGINES``, ``schema.PML_ENGINES``), the validation and the assessment's
text derive from it, so a new engine is one module and one line here (as SPECFEM3D's
time schemes or Firedrake's ``TimeStepper`` registry are declared once and looked up).

This module imports nothing from the package: the lowest layer (``.importlinter``).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class EngineDeclaration:
    """What the package knows of a time-domain engine before building it.

    Attributes
    ----------
    name
        The value of ``transient.engine``.
    description
        One line on the scheme, for the run's log and the assessment (ends with ``", "``
        when it is followed by the step: ``"central differences (explicit), "``).
    factory
        ``"module:attribute"`` of the engine class (the
        :class:`~railvib_hpc.transient.engine.Engine` protocol), imported lazily.
    takes_pml
        Whether the engine takes ``pml`` faces (the refusals of a layer name the others).
    lumped_mass
        Whether it needs the diagonal mass (``modal.lumped_mass = true``).
    soil_scheme
        How its soil is integrated, for the dispersion check: ``"central"`` (central
        differences, the step capped at the explicit safety of the critical Courant
        number), ``"generalized_alpha"`` (unconditionally stable, the Courant number of
        the run's step) or ``"none"`` (no scheme error predicted).
    report
        The assessment's text on the scheme (``str.format`` with the run statistics'
        ``rho_inf``).
    """

    name: str
    description: str
    factory: str
    takes_pml: bool = True
    lumped_mass: bool = False
    soil_scheme: str = "central"
    report: str = ""


#: Every engine, by name (the order of the schema's choices). A new engine: one line.
ENGINES: dict[str, EngineDeclaration] = {d.name: d for d in (
    EngineDeclaration(
        "direct", "generalized-alpha, one MUMPS factor of K_eff",
        "railvib_hpc.transient.direct_engine:DirectEngine", soil_scheme="generalized_alpha",
        report="generalized-alpha rho_inf {rho_inf}, "),
    EngineDeclaration(
        "explicit", "central differences (explicit), ",
        "railvib_hpc.transient.explicit_engine:ExplicitEngine", lumped_mass=True,
        report="central differences (explicit), lumped mass, "),
    EngineDeclaration(
        "imex", "implicit-explicit Newmark (Hughes-Liu), ",
        "railvib_hpc.transient.imex_engine:ImexEngine", lumped_mass=True,
        report="implicit-explicit Newmark (track and building implicit, soil explicit), "
               "lumped mass, "),
)}
#: The engine of results recorded before there were others.
DEFAULT_ENGINE = "direct"


class EngineNames(Sequence):
    """The names of the engines of :data:`ENGINES` that satisfy ``keep`` (all by default),
    read from the table each time (an engine registered later is in it): a sequence that
    compares equal to the tuple of its names."""

    def __init__(self, keep=None):
        self._keep = keep

    def _names(self) -> tuple[str, ...]:
        return tuple(k for k, d in ENGINES.items() if self._keep is None or self._keep(d))

    def __getitem__(self, index):
        return self._names()[index]

    def __len__(self) -> int:
        return len(self._names())

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __eq__(self, other) -> bool:
        return isinstance(other, Sequence) and self._names() == tuple(other)

    def __hash__(self) -> int:
        return hash(self._names())

    def __repr__(self) -> str:
        return repr(self._names())


#: ``transient.engine``'s choices, and those of them that take ``pml`` faces.
ENGINE_NAMES = EngineNames()
PML_ENGINE_NAMES = EngineNames(lambda d: d.takes_pml)


def declaration(name: str | None) -> EngineDeclaration:
    """The declaration of engine ``name`` (:data:`DEFAULT_ENGINE` for None).

    Raises
    ------
    KeyError
        ``name`` is no engine of :data:`ENGINES`.
    """
    return ENGINES[DEFAULT_ENGINE if name is None else name]


def needs_lumped_mass() -> tuple[str, ...]:
    """The engines that need the diagonal mass."""
    return tuple(k for k, d in ENGINES.items() if d.lumped_mass)


__all__ = [
    "DEFAULT_ENGINE",
    "ENGINES",
    "ENGINE_NAMES",
    "PML_ENGINE_NAMES",
    "EngineDeclaration",
    "EngineNames",
    "declaration",
    "needs_lumped_mass",
]
