"""Conditions on the truncation faces of the soil box (``[boundary]``), pure numpy.

Faces: ``x_min``, ``x_max`` (the planes normal to the track at the ends of the soil),
``y_min`` (beyond the building), ``y_max`` (the other side of the track) and ``base``
(the bottom of the subgrade). They are taken from the mesh's node sets (``x_faces`` split
at the middle of the x range, ``y_faces`` likewise, ``bottom``), so user meshes with the
same node sets work too.

Each face is

* ``fixed``: all displacements (and rotations, if any) zero;
* ``roller``: the normal displacement zero (the thesis's x and y faces);
* ``free``: nothing;
* ``absorbing``: free, plus Lysmer-Kuhlemeyer dashpots (``rho c_P`` normal, ``rho c_S``
  tangential per unit area, lumped to the nodes, :mod:`railvib_hpc.fem.boundary`) with the
  material of the element behind each face, and optionally springs
  (``boundary.virtual_thickness``);
* ``caughey``: fixed, with a graded Caughey absorbing layer (CALM, Semblat et al. 2011): the
  elements within ``boundary.layer_thickness`` of the face get Rayleigh damping whose ratio
  grows quadratically from 0 at the layer's inner edge to ``boundary.layer_damping`` at the
  face (:func:`layer_weights`; assembled by :func:`~.petsc.assemble_damping`).

The thesis defaults (rollers, fixed base) give exactly the constraint rules of
:data:`railvib_hpc.modal.dofmap.DEFAULT_RULES`, hence the same K, M and modes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import Case, solid_material
from ..errors import UserError
from ..fem.boundary import face_impedance, wave_speeds
from ..fem.material import lame_parameters
from ..mesh.model import Mesh
from ..mesh.search import HEX_FACES
from ..schema import BOUNDARY_FACES, PART_ID, PARTS, SOIL_PARTS
from .dofmap import COMPONENTS
from .elements import SOLID_MATERIAL

#: Normal displacement component of each face (roller).
_NORMAL = {"x_min": "ux", "x_max": "ux", "y_min": "uy", "y_max": "uy", "base": "uz"}


class BoundaryError(UserError):
    """A boundary condition the mesh cannot carry (e.g. an absorbing face without soil)."""


def face_types(case: Case) -> dict[str, str]:
    """``{face: type}`` from ``[boundary]``."""
    return {f: case[f"boundary.{f}"] for f in BOUNDARY_FACES}


def has_absorbing(case: Case) -> bool:
    """True when any face is absorbing."""
    return "absorbing" in face_types(case).values()


def face_node_sets(mesh: Mesh) -> dict[str, np.ndarray]:
    """Nodes of each truncation face, from the node sets ``x_faces``, ``y_faces``, ``bottom``.

    ``x_faces`` holds both planes normal to x: nodes below the middle of its x range go to
    ``x_min``, the others to ``x_max`` (likewise for y).
    """
    out: dict[str, np.ndarray] = {}
    ns = mesh.node_sets
    for axis, name in ((0, "x"), (1, "y")):
        nodes = np.asarray(ns.get(f"{name}_faces", np.zeros(0, np.int64)), dtype=np.int64)
        coord = mesh.points[nodes, axis] if nodes.size else np.zeros(0)
        mid = 0.5 * (coord.min() + coord.max()) if nodes.size else 0.0
        out[f"{name}_min"] = nodes[coord < mid]
        out[f"{name}_max"] = nodes[coord >= mid]
    out["base"] = np.asarray(ns.get("bottom", np.zeros(0, np.int64)), dtype=np.int64)
    return out


def constraint_rules(case: Case) -> dict[str, tuple[str, ...]]:
    """Constraint rules ``{face: components}`` for :func:`~.dofmap.build_dofmap`.

    ``fixed`` fixes every component (as the thesis's ``bottom`` rule), ``roller`` the
    normal displacement; ``free`` and ``absorbing`` nothing.
    """
    rules: dict[str, tuple[str, ...]] = {}
    for face, kind in face_types(case).items():
        if kind in ("fixed", "caughey"):
            rules[face] = COMPONENTS
        elif kind == "roller":
            rules[face] = (_NORMAL[face],)
    return rules


@dataclass
class FaceElements:
    """The element faces on one truncation face.

    Attributes
    ----------
    quads
        (nf, 4) nodes of each element face, outward oriented.
    hex_index
        (nf,) the hexahedron each face belongs to.
    part
        (nf,) its part id.
    """

    quads: np.ndarray
    hex_index: np.ndarray
    part: np.ndarray


def face_elements(mesh: Mesh, nodes: np.ndarray) -> FaceElements:
    """Unshared hexahedron faces whose four nodes all lie in ``nodes``."""
    ne = len(mesh.hexes)
    faces = mesh.hexes[:, HEX_FACES].reshape(-1, 4)
    owner = np.repeat(np.arange(ne), len(HEX_FACES))
    member = np.zeros(mesh.n_nodes, dtype=bool)
    member[nodes] = True
    on = member[faces].all(axis=1)
    faces, owner = faces[on], owner[on]
    if len(faces):
        key = np.sort(faces, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        single = counts[inverse.ravel()] == 1
        faces, owner = faces[single], owner[single]
    return FaceElements(faces, owner, mesh.hex_part[owner])


def absorbing_faces(mesh: Mesh, case: Case) -> dict[str, FaceElements]:
    """The element faces of every absorbing face, checked.

    Raises
    ------
    BoundaryError
        An absorbing face with no element face on it, or with elements that are not soil
        behind it (the domain must end in soil for the dashpots to stand for it).
    """
    sets = face_node_sets(mesh)
    out = {}
    for face, kind in face_types(case).items():
        if kind != "absorbing":
            continue
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


def _material_arrays(case: Case, part: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per-face (E, nu, rho) of the solid behind it."""
    mats = {int(p): solid_material(case, SOLID_MATERIAL[PARTS[int(p) - 1]])
            for p in np.unique(part)}
    return tuple(np.array([mats[int(p)][k] for p in part], dtype=float)
                 for k in ("E", "nu", "rho"))


def boundary_node_blocks(mesh: Mesh, case: Case, kind: str
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Lumped 3 x 3 blocks of the absorbing faces, summed per node.

    Parameters
    ----------
    mesh, case
        The model and its ``[boundary]``.
    kind
        ``"dashpot"`` (``rho c_P``, ``rho c_S``: the damping matrix) or ``"spring"``
        (``(lambda + 2 G) / t``, ``G / t`` with ``t = boundary.virtual_thickness``: the
        stiffness matrix; nothing when ``t = 0``).

    Returns
    -------
    nodes : ndarray (k,)
        Distinct nodes, ascending.
    blocks : ndarray (k, 3, 3)
        Their blocks on ``(ux, uy, uz)``.
    """
    if kind not in ("dashpot", "spring"):
        raise ValueError(f"kind must be 'dashpot' or 'spring', got {kind!r}")
    t = case["boundary.virtual_thickness"]
    faces = absorbing_faces(mesh, case)
    if not faces or (kind == "spring" and t <= 0.0):
        return np.zeros(0, np.int64), np.zeros((0, 3, 3))
    quads, parts = (np.concatenate([getattr(f, a) for f in faces.values()])
                    for a in ("quads", "part"))
    e, nu, rho = _material_arrays(case, parts)
    if kind == "dashpot":
        cp, cs = wave_speeds(e, nu, rho)
        blocks = face_impedance(mesh.points[quads], rho * cp, rho * cs)
    else:
        lam, g = lame_parameters(e, nu)
        blocks = face_impedance(mesh.points[quads], (lam + 2.0 * g) / t, g / t)
    nodes, inverse = np.unique(quads.ravel(), return_inverse=True)
    out = np.zeros((len(nodes), 3, 3))
    np.add.at(out, inverse.ravel(), blocks.reshape(-1, 3, 3))
    return nodes, out


def boundary_summary(mesh: Mesh, case: Case) -> dict[str, dict]:
    """Per face: type, element faces, area and (absorbing) the dashpot constants."""
    sets = face_node_sets(mesh)
    out = {}
    for face, kind in face_types(case).items():
        fe = face_elements(mesh, sets[face])
        entry: dict = {"type": kind, "element_faces": len(fe.quads)}
        if len(fe.quads):
            from ..fem.boundary import face_integrals

            area, _ = face_integrals(mesh.points[fe.quads])
            entry["area_m2"] = float(area.sum())
            if kind == "absorbing":
                e, nu, rho = _material_arrays(case, fe.part)
                cp, cs = wave_speeds(e, nu, rho)
                entry["rho_cP"] = sorted({round(float(v), 1) for v in rho * cp})
                entry["rho_cS"] = sorted({round(float(v), 1) for v in rho * cs})
        out[face] = entry
    return out


def case_dofmap(mesh: Mesh, case: Case, size: int = 1):
    """The DOF map of a case: its ``[boundary]`` constraints and the modal switches.

    Checks the absorbing faces first (:func:`absorbing_faces`), so a face without soil
    behind it stops the run before anything is computed or written.
    """
    from .dofmap import build_dofmap

    if has_absorbing(case):
        absorbing_faces(mesh, case)
    return build_dofmap(mesh, size, case["modal.fix_sleeper_rotations"],
                        case["modal.fix_rail_rotations_at_pads"], rules=constraint_rules(case),
                        node_sets=face_node_sets(mesh))


def layer_weights(mesh: Mesh, case: Case, centres: np.ndarray | None = None) -> np.ndarray:
    """Weight of hexahedra in the Caughey layers, in [0, 1].

    ``w = (1 - d / L)^2`` for an element centroid at distance ``d < L`` from a ``caughey``
    face (``L = boundary.layer_thickness``), the largest over the faces; 0 elsewhere.
    ``centres`` (k, 3): the centroids to weigh (default: every hexahedron's).
    """
    if centres is None:
        centres = mesh.points[mesh.hexes].mean(axis=1)
    out = np.zeros(len(centres))
    faces = [f for f, kind in face_types(case).items() if kind == "caughey"]
    if not faces:
        return out
    thickness = case["boundary.layer_thickness"]
    sets = face_node_sets(mesh)
    axis = {"x_min": 0, "x_max": 0, "y_min": 1, "y_max": 1, "base": 2}
    for face in faces:
        nodes = sets[face]
        if nodes.size == 0:
            raise BoundaryError(f"boundary.{face} = 'caughey': the mesh has no nodes on it")
        plane = float(mesh.points[nodes, axis[face]].mean())
        d = np.abs(centres[:, axis[face]] - plane)
        out = np.maximum(out, np.where(d < thickness, (1.0 - d / thickness) ** 2, 0.0))
    return out
