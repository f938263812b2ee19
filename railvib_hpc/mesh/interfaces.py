"""Elastic interfaces: under-sleeper pads, ballast mats and base isolation (pure numpy).

Each interface cuts the mesh along a surface, duplicates the nodes of the side above and
joins every pair (lower node, upper node) by three zero-length directional springs (parts
``<kind>_x``, ``<kind>_y``, ``<kind>_z``, :data:`railvib_hpc.schema.INTERFACE_PARTS`). A
spring's stiffness is the interface's bedding modulus (``modulus``, N/m^3; times
``shear_ratio`` along x and y) times the node's tributary area, so the interface acts like
a continuous elastic layer of that modulus (:func:`tributary_areas`).

``usp`` (under-sleeper pads)
    Between every sleeper and the ballast: the sleeper beams and the pads' lower ends move
    to the new nodes; the ballast keeps the old ones. Tributary area: the sleeper's bearing
    width ``usp.width`` times half the length of each sleeper element at the node.
``ballast_mat``
    Under the ballast, on the subballast (z = Z2): the ballast's nodes there are duplicated.
``isolation``
    Bearings under the building, at ``isolation.level``: ``"ground"`` (Z1; the building
    above the ground stands on bearings on top of its basement, i.e. under the ground-floor
    columns) or ``"footings"`` (ZBB; under the footings and whatever else of the building
    touches the base). With ``"footings"`` the basement walls stay bonded to the soil
    beside them, which bypasses part of the isolation (no gap is modelled).

The area of a plane interface is the exact nodal share of each face on it (a quarter of a
rectangle per corner); the springs of one interface add up to ``modulus`` times the area
of the interface (tested).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..config import Case
from ..schema import BUILDING_PARTS, INTERFACE_PARTS, PART_ID
from ..site import track_lift
from .model import Mesh, renumbered
from .search import HEX_FACES

#: Tolerance on the z of a node on an interface plane [m].
PLANE_TOL = 1e-7



def site_line(case: Case) -> str:
    """One line: the track at grade or on its fill, and the elastic interfaces switched on."""
    h = track_lift(case)
    bed = (f"on a {h:g} m fill embankment (slopes 1:{case['track.embankment_slope']:g})"
           if h > 0 else "at grade (the track bed on the ground)")
    kinds = active_interfaces(case)
    if not kinds:
        return bed + "; no elastic interfaces"
    text = ", ".join(f"{k} {case[f'{k}.modulus']:.3g} N/m^3" for k in kinds)
    if "isolation" in kinds:
        text += f" (bearings at the {case['isolation.level']} level)"
    return f"{bed}; elastic interfaces: {text}"


def active_interfaces(case: Case) -> list[str]:
    """The interfaces the case switches on (``modulus > 0``), in the order they are cut."""
    return [kind for kind in INTERFACE_PARTS if case[f"{kind}.modulus"] > 0]


def interface_plane(case: Case, kind: str) -> tuple[float, tuple[str, ...]]:
    """z of a plane interface and the parts above it."""
    if kind == "ballast_mat":
        return case["geometry.z2"] + track_lift(case), ("ballast",)
    level = case["isolation.level"]
    z = case["geometry.z1"] if level == "ground" else case["geometry.zbb"]
    return z, BUILDING_PARTS


def split_interfaces(mesh: Mesh, case: Case) -> Mesh:
    """The mesh with every active interface cut and joined by springs (a new Mesh).

    The nodes are numbered lexicographically by (x, y, z) again afterwards (a new node
    right after its partner), as :func:`~.gmsh_model.extract_mesh` numbers them: the
    parallel stages split the node ranges into slabs along the track.
    """
    kinds = active_interfaces(case)
    for kind in kinds:
        if kind == "usp":
            upper = _sleeper_side(mesh)
        else:
            upper = _plane_side(mesh, *interface_plane(case, kind))
        mesh = _duplicate(mesh, kind, *upper)
    return renumbered(mesh) if kinds else mesh


def _sleeper_side(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes to duplicate (the sleepers'), and the hex / line entries to re-point."""
    sleeper = mesh.line_part == PART_ID["sleeper"]
    nodes = np.unique(mesh.lines[sleeper])
    hex_entries = np.zeros(mesh.hexes.shape, dtype=bool)
    on = np.isin(mesh.lines, nodes)
    pads = np.isin(mesh.line_part, [PART_ID[p] for p in ("pad_x", "pad_y", "pad_z")])
    line_entries = on & (sleeper | pads)[:, None]
    return nodes, hex_entries, line_entries


def _plane_side(mesh: Mesh, z: float, parts: tuple[str, ...]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes on the plane ``z`` of the hexahedra of ``parts`` above it, and their entries."""
    above = np.isin(mesh.hex_part, [PART_ID[p] for p in parts]) & \
        (mesh.points[mesh.hexes, 2].mean(axis=1) > z)
    on_plane = np.abs(mesh.points[:, 2] - z) < PLANE_TOL
    hex_entries = above[:, None] & on_plane[mesh.hexes]
    nodes = np.unique(mesh.hexes[hex_entries])
    return nodes, hex_entries, np.zeros(mesh.lines.shape, dtype=bool)


def _duplicate(mesh: Mesh, kind: str, nodes: np.ndarray, hex_entries: np.ndarray,
               line_entries: np.ndarray) -> Mesh:
    """Append copies of ``nodes``, re-point the marked entries, add the springs."""
    n = mesh.n_nodes
    new = np.full(n, -1, dtype=np.int64)
    new[nodes] = n + np.arange(nodes.size)
    hexes, lines = mesh.hexes.copy(), mesh.lines.copy()
    hexes[hex_entries] = new[hexes[hex_entries]]
    lines[line_entries] = new[lines[line_entries]]
    pairs = np.stack([nodes, new[nodes]], axis=1)
    springs = np.concatenate([pairs] * 3)
    parts = np.repeat([PART_ID[p] for p in INTERFACE_PARTS[kind]], nodes.size)
    node_sets = {k: np.sort(np.concatenate([v, new[v[new[v] >= 0]]]))
                 for k, v in mesh.node_sets.items()}
    return replace(mesh, points=np.concatenate([mesh.points, mesh.points[nodes]]),
                   hexes=hexes, lines=np.concatenate([lines, springs]),
                   line_part=np.concatenate([mesh.line_part, parts.astype(mesh.line_part.dtype)]),
                   node_sets=node_sets)


def tributary_areas(mesh: Mesh, kind: str, width: float = 0.0) -> np.ndarray:
    """The area each node carries on an interface [m^2] (0 off it), per node of the mesh.

    Every upper node of the interface's springs counts (the faces between them), so each
    rank gets the same areas whatever part of the springs it assembles.

    Parameters
    ----------
    mesh
        The cut mesh.
    kind
        ``"usp"``, ``"ballast_mat"`` or ``"isolation"``.
    width
        ``usp``: the sleeper's bearing width [m].
    """
    share = np.zeros(mesh.n_nodes)
    upper = np.unique(mesh.lines[mesh.line_part == PART_ID[INTERFACE_PARTS[kind][2]], 1])
    if upper.size == 0:
        return share
    if kind == "usp":
        conn = mesh.lines[mesh.line_part == PART_ID["sleeper"]]
        length = np.linalg.norm(np.diff(mesh.points[conn], axis=1)[:, 0], axis=1)
        np.add.at(share, conn.ravel(), np.repeat(0.5 * length * width, 2))
        out = np.zeros(mesh.n_nodes)
        out[upper] = share[upper]
        return out
    is_upper = np.zeros(mesh.n_nodes, dtype=bool)
    is_upper[upper] = True
    cand = mesh.hexes[is_upper[mesh.hexes].any(axis=1)]
    faces = cand[:, HEX_FACES].reshape(-1, 4)
    faces = faces[is_upper[faces].all(axis=1)]
    p = mesh.points[faces]
    flat = np.ptp(p[:, :, 2], axis=1) < PLANE_TOL
    faces, p = faces[flat], p[flat]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1]), axis=1)
    np.add.at(share, faces.ravel(), np.repeat(area / 4, 4))
    return share


def interface_nodes(mesh: Mesh) -> np.ndarray:
    """Every node of an interface spring (both sides)."""
    ids = [PART_ID[p] for parts in INTERFACE_PARTS.values() for p in parts]
    return np.unique(mesh.lines[np.isin(mesh.line_part, ids)])
