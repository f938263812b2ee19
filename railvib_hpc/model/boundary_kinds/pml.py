"""``pml``: a fixed face with a perfectly matched layer inside the mesh (the time domain's).

The layer's stretching ``1 + d / (i omega)`` (Basu & Chopra 2003; its profile after Collino &
Tsogka 2001, :mod:`railvib_hpc.fem.pml`) is frequency dependent: the transient engines take
it (:mod:`railvib_hpc.transient.pml`), the modal path has no modes of it and refuses it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ...schema import PML_ENGINES
from ..boundary_kind import Refusal
from .fixed import Fixed


class Pml(Fixed):
    """Fixed, with the perfectly matched layer; ``railvib transient`` only."""

    name = "pml"
    modal = False
    engines = PML_ENGINES
    matched_layer = True
    reflection_variant = True
    # the layers need an explicit engine and its lumped mass; their thickness is added
    # outside each domain (railvib_hpc.studies.reflection.pml_overrides)
    reflection_overrides = ("modal.lumped_mass=true",)
    reflection_layer_outside = True
    time_domain_note = "the layers are time-domain only"
    no_modes = ("a perfectly matched layer is frequency dependent (its stretching 1 + d / (i "
                "omega))")

    def section_problems(self, boundary: Mapping[str, Any], faces: Sequence[str]
                         ) -> list[Refusal]:
        """A thickness, and a target reflection in (0, 1)."""
        out = super().section_problems(boundary, faces)
        if not 0.0 < boundary["pml_reflection"] < 1.0:
            out.append(("boundary.pml_reflection", boundary["pml_reflection"],
                        "must lie in (0, 1): the target reflection of the layer"))
        return out


KIND = Pml()
