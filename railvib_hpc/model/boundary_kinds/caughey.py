"""``caughey``: a fixed face with a graded Caughey absorbing layer inside the mesh.

CALM (Semblat et al. 2011): the ground elements within ``boundary.layer_thickness`` of the
face get Rayleigh damping whose ratio grows quadratically from 0 at the layer's inner edge
to ``boundary.layer_damping`` at the face (:func:`railvib_hpc.model.boundary.layer_weights`,
checked by :func:`railvib_hpc.model.boundary.check_layers`).
"""

from __future__ import annotations

from collections.abc import Sequence

from ...mesh.model import Mesh
from ...problem import Problem
from ..boundary import check_layers
from .fixed import Fixed


class Caughey(Fixed):
    """Fixed, with the graded damping layer."""

    name = "caughey"
    graded_damping = True

    def check(self, mesh: Mesh, problem: Problem, faces: Sequence[str]) -> None:
        check_layers(mesh, problem)


KIND = Caughey()
