"""``absorbing``: a free face with Lysmer-Kuhlemeyer dashpots, and optionally springs.

The dashpots are ``rho c_P`` normal and ``rho c_S`` tangential per unit area (Lysmer &
Kuhlemeyer 1969), lumped to the nodes (:mod:`railvib_hpc.fem.boundary`) with the material
of the element behind each face; with ``boundary.virtual_thickness = t > 0`` also springs
``(lambda + 2 G) / t`` normal and ``G / t`` tangential, as if ``t`` metres of the same soil
lay behind the face. The domain must end in soil for the dashpots to stand for it
(:func:`absorbing_faces`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...fem.boundary import face_impedance, wave_speeds
from ...fem.material import lame_parameters
from ...mesh.model import Mesh
from ...problem import Problem
from ...schema import PART_ID, PARTS, SOIL_PARTS
from ..boundary import BoundaryError, FaceElements, face_elements, face_node_sets, kind_faces
from ..boundary_kind import BoundaryKind
from ..elements import SOLID_MATERIAL


def material_arrays(problem: Problem, part: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per element face ``(E, nu, rho)`` of the solid behind it (``part``: its part ids)."""
    mats = {int(p): problem.material(SOLID_MATERIAL[PARTS[int(p) - 1]])
            for p in np.unique(part)}
    return tuple(np.array([getattr(mats[int(p)], k) for p in part], dtype=float)
                 for k in ("E", "nu", "rho"))


def absorbing_faces(mesh: Mesh, problem: Problem) -> dict[str, FaceElements]:
    """The element faces of every absorbing face, checked.

    Raises
    ------
    BoundaryError
        An absorbing face with no element face on it, or with elements that are not soil
        behind it (the domain must end in soil for the dashpots to stand for it).
    """
    sets = face_node_sets(mesh)
    out = {}
    for face in kind_faces(problem).get(KIND.name, ()):
        fe = face_elements(mesh, sets[face])
        if len(fe.quads) == 0:
            raise BoundaryError(
                f"boundary.{face} = 'absorbing': the mesh has no element face on it, so there "
                "is no soil behind it to absorb waves; allowed: fixed, roller, free")
        bad = ~np.isin(fe.part, [PART_ID[p] for p in SOIL_PARTS])
        if bad.any():
            parts = sorted({PARTS[int(p) - 1] for p in fe.part[bad]})
            raise BoundaryError(
                f"boundary.{face} = 'absorbing': {int(bad.sum())} of its {len(fe.part)} "
                f"element faces have no soil behind them (part {', '.join(parts)}); an "
                "absorbing face must cut through soil only (enlarge the domain, [domain])")
        out[face] = fe
    return out


class Absorbing(BoundaryKind):
    """Dashpots (and springs) on the face's element faces; it holds the box dynamically in
    all three directions, statically only with its springs."""

    name = "absorbing"
    reflection_variant = True

    def restrained(self, face: str) -> tuple[int, ...]:
        return (0, 1, 2)

    def statically_held(self, face: str, boundary: Mapping[str, Any]) -> tuple[int, ...]:
        return (0, 1, 2) if boundary["virtual_thickness"] > 0 else ()

    def check(self, mesh: Mesh, problem: Problem, faces: Sequence[str]) -> None:
        absorbing_faces(mesh, problem)

    def node_blocks(self, mesh: Mesh, problem: Problem, faces: Sequence[str], which: str
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """``"dashpot"``: ``rho c_P``, ``rho c_S``; ``"spring"``: ``(lambda + 2 G) / t``,
        ``G / t`` with ``t = boundary.virtual_thickness`` (none when ``t = 0``)."""
        t = problem.boundary.virtual_thickness
        elements = absorbing_faces(mesh, problem)
        if not elements or (which == "spring" and t <= 0.0):
            return None
        quads, parts = (np.concatenate([getattr(f, a) for f in elements.values()])
                        for a in ("quads", "part"))
        e, nu, rho = material_arrays(problem, parts)
        if which == "dashpot":
            cp, cs = wave_speeds(e, nu, rho)
            blocks = face_impedance(mesh.points[quads], rho * cp, rho * cs)
        else:
            lam, g = lame_parameters(e, nu)
            blocks = face_impedance(mesh.points[quads], (lam + 2.0 * g) / t, g / t)
        nodes, inverse = np.unique(quads.ravel(), return_inverse=True)
        out = np.zeros((len(nodes), 3, 3))
        np.add.at(out, inverse.ravel(), blocks.reshape(-1, 3, 3))
        return nodes, out

    def summary(self, problem: Problem, elements: FaceElements) -> dict:
        """The dashpot constants ``rho c_P``, ``rho c_S`` of the face (distinct values)."""
        e, nu, rho = material_arrays(problem, elements.part)
        cp, cs = wave_speeds(e, nu, rho)
        return {"rho_cP": sorted({round(float(v), 1) for v in rho * cp}),
                "rho_cS": sorted({round(float(v), 1) for v in rho * cs})}


KIND = Absorbing()
