"""What the spectral soil (``mesh.order > 1``) does not take yet: the refusals of the
stages that would run it, checked before meshing (``Stage(refuse=...)``,
:func:`railvib_hpc.validation.command_problems`).

The spectral hexahedra of order N (Komatitsch & Tromp 1999; docs/spectral.md) run in
``railvib transient`` with the explicit engine on the bare soil only
(:mod:`.spectral_system`): no track and no building (their coupling to the spectral soil
is not wired), the boundary kinds ``fixed``, ``roller``, ``free`` and ``absorbing``
(dashpots and springs on the GLL face nodes; no perfectly matched layer on spectral
elements), and no modal path (the modes are computed on the trilinear model). Each
function returns ``(key, value, allowed)`` problems (empty: none).

Examples
--------
>>> from railvib_hpc.config import Case
>>> spectral_refusals(Case.defaults(), "transient")
[]
>>> key, value, allowed = spectral_refusals(
...     Case.defaults().replace({"mesh.order": 4}), "transient")[0]
>>> key, value
('building.present', True)
"""

from __future__ import annotations

from typing import Any

from ..schema import BOUNDARY_FACES

Refusal = tuple[str, Any, str]

#: The boundary kinds the spectral soil takes.
SPECTRAL_BOUNDARY_KINDS = ("fixed", "roller", "free", "absorbing")
#: The engines that run the spectral soil.
SPECTRAL_ENGINES = ("explicit",)
#: The damping models the spectral soil takes.
SPECTRAL_DAMPING = ("none", "rayleigh")


def spectral_refusals(case, command: str) -> list[Refusal]:
    """The ``transient`` stage's refusals of a spectral soil (``mesh.order > 1``): a
    building, a track, an engine other than explicit, a boundary kind without a spectral
    form, in that order."""
    order = case["mesh.order"]
    if order <= 1:
        return []
    what = f"with mesh.order = {order} (spectral soil) railvib {command}"
    out: list[Refusal] = []
    if case["building.present"]:
        out.append(("building.present", True, f"{what} runs the bare soil only: false "
                    "(the building's coupling to spectral elements is not built; "
                    "mesh.order = 1 for a building)"))
    if case["track.count"] != 0:
        out.append(("track.count", case["track.count"], f"{what} runs the bare soil "
                    "loaded by [load] only: 0 (the track's coupling to spectral elements "
                    "is not built; mesh.order = 1 for a track)"))
    engine = case["transient.engine"]
    if engine not in SPECTRAL_ENGINES:
        out.append(("transient.engine", engine, f"{what} integrates with the explicit "
                    "engine only: 'explicit' (mesh.order = 1 for the direct and IMEX "
                    "engines)"))
    if case["damping.model"] not in SPECTRAL_DAMPING:
        out.append(("damping.model", case["damping.model"], f"{what} takes the damping "
                    "models " + ", ".join(SPECTRAL_DAMPING) + " (one alpha M + beta K "
                    "for the whole soil)"))
    if case["output.stress_times"]:
        out.append(("output.stress_times", case["output.stress_times"], f"{what} writes "
                    "no stresses yet: []"))
    for face in BOUNDARY_FACES:
        kind = case[f"boundary.{face}"]
        if kind not in SPECTRAL_BOUNDARY_KINDS:
            out.append((f"boundary.{face}", kind, f"{what} takes the boundary kinds "
                        + ", ".join(SPECTRAL_BOUNDARY_KINDS)
                        + " (no perfectly matched layer or Caughey layer on spectral "
                        "elements yet)"))
            break
    return out

