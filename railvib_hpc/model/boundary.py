"""Conditions on the truncation faces of the soil box (``[boundary]``), pure numpy.

Faces: ``x_min``, ``x_max`` (the planes normal to the track at the ends of the soil),
``y_min`` (beyond the building), ``y_max`` (the other side of the track) and ``base``
(the bottom of the subgrade). They are taken from the mesh's node sets (``x_faces`` split
at the middle of the x range, ``y_faces`` likewise, ``bottom``), so user meshes with the
same node sets work too.

Each face has a kind, a registered object (:data:`railvib_hpc.boundary_registry.BOUNDARY_KINDS`,
one module of :mod:`railvib_hpc.model.boundary_kinds` each, :class:`~.boundary_kind.BoundaryKind`)
that declares its constraints, node blocks, layer and checks; this module runs them over
the faces. The kinds:

* ``fixed``: all displacements (and rotations, if any) zero;
* ``roller``: the normal displacement zero (the thesis's x and y faces);
* ``free``: nothing;
* ``absorbing``: free, plus Lysmer-Kuhlemeyer dashpots (``rho c_P`` normal, ``rho c_S``
  tangential per unit area, lumped to the nodes, :mod:`railvib_hpc.fem.boundary`) with the
  material of the element behind each face, and optionally springs
  (``boundary.virtual_thickness``);
* ``pml``: fixed, with a perfectly matched layer (:mod:`railvib_hpc.transient.pml`; the
  transient engines only);
* ``caughey``: fixed, with a graded Caughey absorbing layer (CALM, Semblat et al. 2011): the
  ground elements (:data:`LAYER_PARTS`) within ``boundary.layer_thickness`` of the face get
  Rayleigh damping whose ratio grows quadratically from 0 at the layer's inner edge to
  ``boundary.layer_damping`` at the face (:func:`layer_weights`; assembled by
  :func:`~.petsc.assemble_damping`). The building, the track bed (ballast, subballast,
  embankment fill) and the mitigation measures are never damped by a layer, however thick;
  a layer that holds no ground element is refused (:func:`check_layers`): the face would
  be a plain fixed face; so is a layer that reaches the building, which would damp the
  ground under and beside it.

The thesis defaults (rollers, fixed base) give exactly the constraint rules of
:data:`railvib_hpc.model.dofmap.DEFAULT_RULES`, hence the same K, M and modes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..boundary_registry import BOUNDARY_KINDS, boundary_kind
from ..errors import UserError
from ..mesh.model import Mesh
from ..mesh.search import HEX_FACES
from ..problem import Problem
from ..schema import (
    BOUNDARY_FACES,
    BUILDING_PARTS,
    PART_ID,
    PARTS,
    SOIL_LAYER_PARTS,
)
from .dofmap import COMPONENTS

#: Coordinate axis normal to each face.
FACE_AXIS = {"x_min": 0, "x_max": 0, "y_min": 1, "y_max": 1, "base": 2}
#: Parts a Caughey layer may damp: the ground (the subgrade or the soil layers), which the
#: layer stands in for. Not the building, the track bed (ballast, subballast, embankment
#: fill) or the mitigation measures, which are the model, not its truncation.
LAYER_PARTS = ("subgrade", *SOIL_LAYER_PARTS)


class BoundaryError(UserError):
    """A boundary condition the mesh cannot carry (e.g. an absorbing face without soil)."""


def face_types(problem: Problem) -> dict[str, str]:
    """``{face: type}`` from ``[boundary]``."""
    return {f: problem.boundary.faces[f] for f in BOUNDARY_FACES}


def kind_faces(problem: Problem) -> dict[str, list[str]]:
    """``{kind: its faces}`` of the kinds on the faces, in registry order (the order their
    checks run in), each kind's faces in :data:`BOUNDARY_FACES` order."""
    types = face_types(problem)
    return {name: faces for name in BOUNDARY_KINDS
            if (faces := [f for f in BOUNDARY_FACES if types[f] == name])}


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


def constraint_rules(problem: Problem) -> dict[str, tuple[str, ...]]:
    """Constraint rules ``{face: components}`` for :func:`~.dofmap.build_dofmap`: each
    face's kind's :meth:`~.boundary_kind.BoundaryKind.constrained` components.

    ``fixed`` (and ``caughey``, ``pml``, whose layers end at a fixed face) fixes every
    component (as the thesis's ``bottom`` rule), ``roller`` the
    normal displacement; ``free`` and ``absorbing`` nothing.
    """
    rules: dict[str, tuple[str, ...]] = {}
    for face, kind in face_types(problem).items():
        components = boundary_kind(kind).constrained(face)
        if components:
            rules[face] = components
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


def boundary_node_blocks(mesh: Mesh, problem: Problem, kind: str
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Lumped 3 x 3 blocks of the faces' kinds (:meth:`~.boundary_kind.BoundaryKind.node_blocks`:
    the absorbing faces') and of the supported track ends
    (:func:`.track_ends.support_blocks`), summed per node.

    Parameters
    ----------
    mesh, problem
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
    from .track_ends import support_blocks

    ends = support_blocks(mesh, problem, kind)
    if kind not in ("dashpot", "spring"):
        raise ValueError(f"kind must be 'dashpot' or 'spring', got {kind!r}")
    faces = [blocks for name, on in kind_faces(problem).items()
             if (blocks := boundary_kind(name).node_blocks(mesh, problem, on, kind))
             is not None]
    nodes, inverse = np.unique(np.concatenate([np.zeros(0, np.int64), *(f[0] for f in faces),
                                               ends[0]]), return_inverse=True)
    out = np.zeros((len(nodes), 3, 3))
    np.add.at(out, inverse, np.concatenate([np.zeros((0, 3, 3)), *(f[1] for f in faces),
                                            ends[1]]))
    return nodes, out


#: Relative size of an off-diagonal entry that makes the dashpots' node blocks "not diagonal"
#: (faces normal to the axes give exactly diagonal blocks; anything else keeps them coupled).
DIAGONAL_TOL = 1e-12


def dashpot_diagonal(mesh: Mesh, problem: Problem, dofmap, rank: int) -> np.ndarray | None:
    """This rank's rows of the absorbing faces' dashpots as a diagonal, or None.

    The explicit engine takes the dashpots at the full-step velocity (trapezoidal on a
    diagonal matrix: no factor, unconditionally stable) when their node blocks
    (:func:`boundary_node_blocks`) are diagonal, which faces normal to the coordinate axes
    give (edges and corners sum diagonal blocks). Returns None when there are no dashpots
    or a block couples its directions (more than :data:`DIAGONAL_TOL` of its diagonal off
    it): then they stay in the damping matrix.
    """
    nodes, blocks = boundary_node_blocks(mesh, problem, "dashpot")
    if len(nodes) == 0:
        return None
    diag = np.einsum("kii->ki", blocks)
    off = np.abs(blocks - np.einsum("ki,ij->kij", diag, np.eye(3))).max()
    if off > DIAGONAL_TOL * np.abs(diag).max():
        return None
    r0, r1 = dofmap.owned_dofs(rank)
    out = np.zeros(r1 - r0)
    dofs = dofmap.index[nodes, :3]
    own = (dofs >= r0) & (dofs < r1)
    np.add.at(out, dofs[own] - r0, diag[own])
    return out


def boundary_summary(mesh: Mesh, problem: Problem) -> dict[str, dict]:
    """Per face: type, element faces, area and its kind's entries
    (:meth:`~.boundary_kind.BoundaryKind.summary`: an absorbing face's dashpot constants)."""
    sets = face_node_sets(mesh)
    out = {}
    for face, kind in face_types(problem).items():
        fe = face_elements(mesh, sets[face])
        entry: dict = {"type": kind, "element_faces": len(fe.quads)}
        if len(fe.quads):
            from ..fem.boundary import face_integrals

            area, _ = face_integrals(mesh.points[fe.quads])
            entry["area_m2"] = float(area.sum())
            entry.update(boundary_kind(kind).summary(problem, fe))
        out[face] = entry
    return out


def problem_dofmap(mesh: Mesh, problem: Problem, size: int = 1):
    """The DOF map of a problem: its ``[boundary]`` constraints and the modal switches.

    Runs the faces' kinds' checks first (:meth:`~.boundary_kind.BoundaryKind.check`: the
    absorbing faces', the Caughey layers', :func:`check_layers`), so a face without soil
    behind it, or a layer without an element, stops the run before anything is computed or
    written.
    """
    from .dofmap import build_dofmap

    for name, faces in kind_faces(problem).items():
        boundary_kind(name).check(mesh, problem, faces)
    from .track_ends import FAR_ENDS, far_end_nodes

    rules, sets = constraint_rules(problem), face_node_sets(mesh)
    if problem.track_ends.supported:             # the supported rail's far ends: clamped
        rules[FAR_ENDS] = COMPONENTS
        sets[FAR_ENDS] = far_end_nodes(mesh, problem.track_ends)
    return build_dofmap(mesh, size, problem.fix_sleeper_rotations,
                        problem.fix_rail_rotations_at_pads, rules=rules, node_sets=sets)


def _layer_distances(mesh: Mesh, problem: Problem, centres: np.ndarray | None
                     ) -> dict[str, np.ndarray]:
    """``{face with a graded damping layer: distance of each centroid to its plane}``
    (default: every hexahedron)."""
    if centres is None:
        centres = mesh.points[mesh.hexes].mean(axis=1)
    sets = face_node_sets(mesh)
    out = {}
    for face, kind in face_types(problem).items():
        if not boundary_kind(kind).graded_damping:
            continue
        nodes = sets[face]
        if nodes.size == 0:
            raise BoundaryError(f"boundary.{face} = {kind!r}: the mesh has no nodes on it")
        plane = float(mesh.points[nodes, FACE_AXIS[face]].mean())
        out[face] = np.abs(centres[:, FACE_AXIS[face]] - plane)
    return out


def layer_weights(mesh: Mesh, problem: Problem, centres: np.ndarray | None = None,
                  parts: np.ndarray | None = None) -> np.ndarray:
    """Weight of hexahedra in the Caughey layers, in [0, 1].

    ``w = (1 - d / L)^2`` for a ground element (:data:`LAYER_PARTS`) whose centroid lies at
    distance ``d < L`` from a ``caughey`` face (``L = boundary.layer_thickness``), the
    largest over the faces; 0 elsewhere, and 0 for every other part (building, track bed,
    mitigation measures) whatever its distance.

    Parameters
    ----------
    mesh, problem
        The model and its ``[boundary]``.
    centres
        (k, 3) centroids to weigh (default: every hexahedron's).
    parts
        (k,) part ids of those elements (default: ``mesh.hex_part`` when ``centres`` is
        None; with ``centres`` given and no ``parts``, the caller has chosen ground
        elements only).

    Returns
    -------
    ndarray (k,)
        The weights.
    """
    if centres is None and parts is None:
        parts = mesh.hex_part
    distances = _layer_distances(mesh, problem, centres)
    n = len(mesh.hexes) if centres is None else len(centres)
    out = np.zeros(n)
    thickness = problem.boundary.layer_thickness
    for d in distances.values():
        out = np.maximum(out, np.where(d < thickness, (1.0 - d / thickness) ** 2, 0.0))
    if parts is not None:
        out[~np.isin(parts, [PART_ID[p] for p in LAYER_PARTS])] = 0.0
    return out


def check_layers(mesh: Mesh, problem: Problem) -> dict[str, dict]:
    """Check the Caughey layers against the mesh and describe them.

    Returns
    -------
    dict
        ``{face: {"elements": ground elements in its layer, "skipped": {part: elements
        within the thickness that are not ground, left undamped}}}`` per caughey face.

    Raises
    ------
    BoundaryError
        A layer that holds no ground element (its centroids all lie at least
        ``boundary.layer_thickness`` from the face): the face would silently act as a
        fixed one. Names the thickness that reaches the first element layer. Or a layer
        that reaches the building (a building element's centroid within the thickness):
        it would damp the ground under and beside the building, the response the model
        is for, as the perfectly matched layers refuse the like
        (:func:`~railvib_hpc.transient.pml.pml_geometry`). Names the thickness allowed.
    """
    thickness = problem.boundary.layer_thickness
    ground = np.isin(mesh.hex_part, [PART_ID[p] for p in LAYER_PARTS])
    building = np.isin(mesh.hex_part, [PART_ID[p] for p in BUILDING_PARTS])
    out = {}
    for face, d in _layer_distances(mesh, problem, None).items():
        inside = d < thickness
        if not (inside & ground).any():
            if not ground.any():
                raise BoundaryError(f"boundary.{face} = 'caughey': the model has no ground "
                                    "element (subgrade or soil layer) for a Caughey layer "
                                    "to damp; allowed: fixed, roller, free, absorbing")
            nearest = float(d[ground].min())
            raise BoundaryError(
                f"boundary.layer_thickness = {thickness:g}: the Caughey layer of "
                f"boundary.{face} holds no ground element (the nearest centroid lies "
                f"{nearest:.4g} m from the face), so the face would act as a plain fixed "
                f"face; allowed: more than {nearest:.4g} m (several element layers absorb "
                "better), or another face type")
        near = inside & building
        if near.any():
            gap = float(d[building].min())
            raise BoundaryError(
                f"boundary.layer_thickness = {thickness:g}: the Caughey layer of "
                f"boundary.{face} reaches the building (its nearest element's centroid lies "
                f"{gap:.4g} m from the face), so it would damp the ground under and beside "
                f"the building ({int((inside & ground).sum())} of {int(ground.sum())} ground "
                f"elements); a layer stands in for the ground beyond the model; allowed: "
                f"0 < boundary.layer_thickness < {gap:.4g} m, or a larger domain "
                "(domain.extra_length, domain.extra_width, domain.extra_depth)")
        skipped = {PARTS[int(p) - 1]: int(c) for p, c in
                   zip(*np.unique(mesh.hex_part[inside & ~ground], return_counts=True))}
        out[face] = {"elements": int((inside & ground).sum()), "skipped": skipped}
    return out


def layer_line(mesh: Mesh, problem: Problem) -> str:
    """One line on the Caughey layers (empty without caughey faces), after
    :func:`check_layers`: the ground elements damped, the other parts left undamped."""
    info = check_layers(mesh, problem)
    if not info:
        return ""
    parts = sorted({p for v in info.values() for p in v["skipped"]})
    n_skip = sum(c for v in info.values() for c in v["skipped"].values())
    text = (f"Caughey layers ({problem.boundary.layer_thickness:g} m): "
            + ", ".join(f"{face} {v['elements']} ground elements" for face, v in info.items()))
    if parts:
        text += (f"; {n_skip} elements of {', '.join(parts)} within the thickness are not "
                 "damped (a layer damps the ground only)")
    return text


#: The six rigid-body motions of the soil box (rotations about axes through its centre).
RIGID_MOTIONS = ("translation along x", "translation along y", "translation along z",
                 "rotation about x", "rotation about y", "rotation about z")
#: A rigid-body motion counts as restrained when it moves a restrained DOF of a face by
#: more than this share of its largest displacement over the box (relative round-off of
#: the node coordinates is far smaller; a face's extent far larger).
SUPPORT_TOL = 1e-6


def restrained_components(problem: Problem) -> dict[str, tuple[int, ...]]:
    """Displacement components (0, 1, 2 = x, y, z) each face restrains.

    Each face's kind's :meth:`~.boundary_kind.BoundaryKind.restrained`: ``fixed``,
    ``caughey`` and ``pml`` all three, ``roller`` its normal one, ``absorbing`` all three
    (dashpots normal and tangential, springs too when ``boundary.virtual_thickness > 0``),
    ``free`` none.
    """
    return {face: boundary_kind(kind).restrained(face)
            for face, kind in face_types(problem).items()}


def unsupported_motions(mesh: Mesh, problem: Problem) -> list[str]:
    """The rigid-body motions of the soil box that no truncation face restrains.

    The restrained DOFs of the faces (:func:`restrained_components`) are tested against
    the six rigid-body motions ``t + w x (p - c)`` (``c``: the centre of the model's
    nodes). Only the faces count: the fixed ends of the rigid rails hold the box through
    the rail pads alone, which lets it float and drift under the loads.

    Returns
    -------
    list of str
        Names from :data:`RIGID_MOTIONS` of the canonical motions left free, then
        ``"k other rigid-body motion(s)"`` for free combinations not among them; empty
        when the faces support the box in every direction.
    """
    used = np.unique(mesh.hexes)
    pts = mesh.points[used] if used.size else mesh.points
    centre = pts.mean(axis=0)
    scale = float(np.ptp(pts, axis=0).max()) or 1.0
    sets = face_node_sets(mesh)
    rows = []
    for face, comps in restrained_components(problem).items():
        p = (mesh.points[sets[face]] - centre) / scale
        for c in comps:
            r = np.zeros((len(p), 6))
            r[:, c] = 1.0                                  # translation along c
            e = np.zeros(3)
            e[c] = 1.0
            for k in range(3):                             # (w_k e_k x p)_c
                w = np.zeros(3)
                w[k] = 1.0
                r[:, 3 + k] = np.cross(w, p) @ e
            rows.append(r)
    a = np.concatenate(rows) if rows else np.zeros((0, 6))
    if a.shape[0] == 0:
        return list(RIGID_MOTIONS)
    free = [RIGID_MOTIONS[j] for j in range(6) if np.abs(a[:, j]).max() <= SUPPORT_TOL]
    sv = np.linalg.svd(a, compute_uv=False)
    n_free = int(np.sum(sv <= SUPPORT_TOL * sv.max())) + 6 - len(sv)
    if n_free > len(free):
        k = n_free - len(free)
        free.append(f"{k} other rigid-body motion{'s' if k > 1 else ''}")
    return free


def support_warning(mesh: Mesh, problem: Problem) -> str | None:
    """A one-line warning when the faces leave a rigid-body motion of the box free (else
    None; :func:`unsupported_motions`)."""
    free = unsupported_motions(mesh, problem)
    if not free:
        return None
    faces = ", ".join(f"{f} {k}" for f, k in face_types(problem).items())
    what = ("rigid-body motions (translations and rotations)" if len(free) == len(RIGID_MOTIONS)
            else ", ".join(free))
    return (f"warning: no truncation face restrains the soil box's {what} "
            f"([boundary]: {faces}): it rests on the rails' fixed ends alone, floats and "
            "drifts under the loads, and its response is not that of supported ground; "
            "make the base (or enough faces) fixed, roller, absorbing or caughey")
