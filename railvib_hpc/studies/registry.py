"""The registry of the studies: name -> the module that declares its ``STUDY``.

The one list of the studies (:data:`STUDIES`): the command line takes the choices and help
lines of ``railvib study`` from it, the Python API (:func:`railvib_hpc.api.run_study`) and
the study runner (:func:`railvib_hpc.studies.runner.execute_study`) resolve a study's name
through it. Adding a study is one module with its ``STUDY``
(:class:`~railvib_hpc.studies.protocol.Study`) and one line here (or :func:`register`);
the modules are imported by name on first use.

Example
-------
>>> from railvib_hpc.studies.registry import STUDIES, study, study_helps
>>> list(STUDIES)
['convergence', 'modes', 'reflection', 'speed', 'thesis', 'mitigation', 'uncertainty']
>>> study("speed").help
'speed sweep: peak building response and contact force against the running speed'
>>> len(study_helps()) == len(STUDIES)
True
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from types import ModuleType

from .protocol import Study

#: The registry: study name -> the module declaring its ``STUDY``, in the order the
#: command line lists them.
STUDIES: dict[str, str] = {
    "convergence": "railvib_hpc.studies.convergence",
    "modes": "railvib_hpc.studies.modes",
    "reflection": "railvib_hpc.studies.reflection",
    "speed": "railvib_hpc.studies.speed",
    "thesis": "railvib_hpc.studies.thesis",
    "mitigation": "railvib_hpc.studies.mitigation",
    "uncertainty": "railvib_hpc.studies.uncertainty",
}


class UnknownStudy(ValueError):
    """A name that is not in :data:`STUDIES`."""


def register(name: str, module: str) -> None:
    """Add study ``name``, declared by ``module`` (its ``STUDY``), to the registry."""
    STUDIES[name] = module


def study_module(name: str) -> ModuleType:
    """The module that declares study ``name`` (imported on first use).

    Raises
    ------
    UnknownStudy
        For a name that is not in the registry.
    """
    if name not in STUDIES:
        raise UnknownStudy(f"unknown study {name!r}; studies: {', '.join(STUDIES)}")
    return importlib.import_module(STUDIES[name])


def study(name: str) -> Study:
    """The declaration of study ``name``.

    Raises
    ------
    UnknownStudy
        For a name that is not in the registry.
    ValueError
        When its module declares another study.
    """
    declared = study_module(name).STUDY
    if declared.name != name:
        raise ValueError(f"{STUDIES[name]} declares study {declared.name!r}, not {name!r}")
    return declared


def study_helps() -> dict[str, str]:
    """Every registered study's help line, in registry order."""
    return {name: study(name).help for name in STUDIES}


class _Modules(Mapping):
    """The study modules by name, read through the registry (so a study added to it is
    here too)."""

    def __getitem__(self, name: str) -> ModuleType:
        if name not in STUDIES:
            raise KeyError(name)
        return study_module(name)

    def __iter__(self) -> Iterator[str]:
        return iter(dict(STUDIES))

    def __len__(self) -> int:
        return len(STUDIES)


#: The study modules by name (a view of :data:`STUDIES`: each module's own functions, e.g.
#: ``STUDY_MODULES["speed"].analyse``).
STUDY_MODULES: Mapping[str, ModuleType] = _Modules()
