"""A new boundary kind in one module: ``winkler``, a face on distributed springs
(tests/test_boundary_kinds.py).

The face rests on a Winkler foundation: springs of :data:`NORMAL_STIFFNESS` normal and
:data:`TANGENTIAL_STIFFNESS` tangential per unit area (N/m³), lumped to the nodes of its
element faces as the absorbing faces' dashpots are (:func:`railvib_hpc.fem.boundary.
face_impedance`), into the stiffness matrix. Its declaration is all a kind needs: its name,
its node blocks, what it holds and its check. Registered with one line
(``railvib_hpc.boundary_registry.BOUNDARY_KINDS["winkler"] = "example_boundary"``) it is
an allowed value of ``boundary.<face>`` and runs through the modal and the transient paths,
from the command line and the Python API.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from railvib_hpc.fem.boundary import face_impedance
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.model.boundary import BoundaryError, face_elements, face_node_sets
from railvib_hpc.model.boundary_kind import BoundaryKind
from railvib_hpc.problem import Problem

#: Spring stiffness per unit area normal to the face [N/m³].
NORMAL_STIFFNESS = 1.0e8
#: Spring stiffness per unit area in the face's plane [N/m³].
TANGENTIAL_STIFFNESS = 4.0e7


class Winkler(BoundaryKind):
    """Distributed springs on the face: it holds the soil box in all three directions,
    statically too, and constrains no DOF."""

    name = "winkler"

    def restrained(self, face: str) -> tuple[int, ...]:
        return (0, 1, 2)

    def check(self, mesh: Mesh, problem: Problem, faces: Sequence[str]) -> None:
        sets = face_node_sets(mesh)
        for face in faces:
            if len(face_elements(mesh, sets[face]).quads) == 0:
                raise BoundaryError(f"boundary.{face} = 'winkler': the mesh has no element "
                                    "face on it to carry the springs")

    def node_blocks(self, mesh: Mesh, problem: Problem, faces: Sequence[str], which: str
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        if which != "spring":
            return None
        sets = face_node_sets(mesh)
        quads = np.concatenate([face_elements(mesh, sets[f]).quads for f in faces])
        n = len(quads)
        blocks = face_impedance(mesh.points[quads], np.full(n, NORMAL_STIFFNESS),
                                np.full(n, TANGENTIAL_STIFFNESS))
        nodes, inverse = np.unique(quads.ravel(), return_inverse=True)
        out = np.zeros((len(nodes), 3, 3))
        np.add.at(out, inverse.ravel(), blocks.reshape(-1, 3, 3))
        return nodes, out

    def summary(self, problem: Problem, elements) -> dict:
        return {"k_normal_N_m3": NORMAL_STIFFNESS, "k_tangential_N_m3": TANGENTIAL_STIFFNESS}


KIND = Winkler()
