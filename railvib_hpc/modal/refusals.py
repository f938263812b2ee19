"""What the modal path (``modal``, ``mbs``, ``reconstruct``, ``run`` and the modal studies)
cannot do with a case: its stages' refusals (``Stage(refuse=...)``).

Each function returns ``(key, value, allowed)`` problems in the order they are checked
(empty: none); ``command`` is the command the sentence names (``railvib <command>``). The
runner checks a stage's refusals before anything runs
(:meth:`~railvib_hpc.io.stage_protocol.StageRunner.run`), and the command line those of
every stage of a command (:func:`railvib_hpc.validation.command_problems`), before
meshing.

Example
-------
>>> from railvib_hpc.config import Case
>>> bare = Case.defaults().replace({"track.count": 0, "load.force": 1e5})
>>> print(needs_track(bare, "mbs")[0][2])  # doctest: +ELLIPSIS
railvib mbs needs a track (the modal path runs the vehicle on the track's modes): 1 or 2; ...
>>> needs_track(Case.defaults(), "mbs"), no_pml(Case.defaults())
([], [])
"""

from __future__ import annotations

from typing import Any

from ..boundary_registry import BOUNDARY_KINDS, boundary_kind
from ..schema import BOUNDARY_FACES

Refusal = tuple[str, Any, str]


def needs_track(case, command: str) -> list[Refusal]:
    """A case without a track (``track.count = 0``, the moving load of ``[load]`` on the
    bare soil): the modal path runs the vehicle on the track's modes. (``railvib
    transient`` takes it, and ``railvib study`` with ``solver = direct``: the study decides,
    :func:`railvib_hpc.studies.runner.trackless_problem`.)"""
    if case["track.count"] != 0:
        return []
    return [("track.count", 0, f"railvib {command} needs a track (the modal path runs the "
             "vehicle on the track's modes): 1 or 2; the bare soil with the moving load of "
             "[load] runs with railvib transient (or railvib study with solver = direct)")]


def supported_ends_damping(case) -> list[Refusal]:
    """Supported track ends on the modal path need ``modal.damping = 'full'``: the supports'
    graded dashpots are no proportional damping, so only their projection on the modes
    keeps them."""
    if case["track.ends"] != "supported" or case["modal.damping"] == "full":
        return []
    return [("modal.damping", case["modal.damping"],
             "track.ends = 'supported' in the modal path (modal, mbs, run and the modal "
             "studies) needs 'full': the supports' graded dashpots, which absorb the rail's "
             "bending waves, are no proportional damping, so only their projection on the "
             "modes keeps them")]


def no_pml(case) -> list[Refusal]:
    """A boundary kind with no modes (a perfectly matched layer: the kinds whose
    :attr:`~railvib_hpc.model.boundary_kind.BoundaryKind.modal` is False): the first face
    with one."""
    for face in BOUNDARY_FACES:
        name = case[f"boundary.{face}"]
        if name in BOUNDARY_KINDS and not (kind := boundary_kind(name)).modal:
            allowed = [k for k in BOUNDARY_KINDS if boundary_kind(k).modal]
            return [(f"boundary.{face}", name, kind.modal_refusal(allowed))]
    return []


def trilinear_soil(case, command: str) -> list[Refusal]:
    """The modal path computes its modes on the trilinear model: ``mesh.order = 1`` (the
    spectral soil, docs/spectral.md, runs with ``railvib transient``)."""
    order = case["mesh.order"]
    if order <= 1:
        return []
    return [("mesh.order", order, f"railvib {command} (the modal path) runs the trilinear "
             "soil only: 1; the spectral soil (2..8) runs with railvib transient "
             "(explicit engine, bare soil)")]


def modal_refusals(case, command: str) -> list[Refusal]:
    """The ``modal`` stage's refusals: a track, then the damping of supported ends, then no
    perfectly matched layer, then the trilinear soil."""
    return (needs_track(case, command) + supported_ends_damping(case) + no_pml(case)
            + trilinear_soil(case, command))
