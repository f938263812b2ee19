"""The mesh as numpy arrays, with quality, volume and connectivity checks.

Hexahedra use gmsh/VTK node order (bottom face 0-1-2-3 counter-clockwise seen
from above, top face 4-5-6-7). All checks are vectorised over elements.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..fem.reference import hex_volumes
from ..schema import PART_ID, PARTS, SOIL_LAYER_PARTS

#: For each hex corner, its three edge neighbours in right-handed order.
_CORNER_NEIGHBOURS = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                               [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                   [0, 4], [1, 5], [2, 6], [3, 7]])

#: Decimals of the node coordinates in the ordering key (0.1 um: coincident nodes tie).
ORDER_DECIMALS = 7


def node_order(points: np.ndarray) -> np.ndarray:
    """Node order by (x, y, z), ties (coincident nodes) in their current order.

    Contiguous node ranges are then compact slabs along the track, which is how the
    parallel stages split ownership across ranks.
    """
    key = np.round(points, ORDER_DECIMALS)
    return np.lexsort((key[:, 2], key[:, 1], key[:, 0]))          # a stable sort


@dataclass
class Mesh:
    """Nodes, elements and node sets of the model.

    Attributes
    ----------
    points
        Node coordinates, shape (n, 3), in m.
    hexes, hex_part
        8-node hexahedra (ne, 8) and their part ids (see :data:`railvib_hpc.schema.PART_ID`).
    lines, line_part
        2-node beam and spring elements (nl, 2) and their part ids.
    node_sets
        Boundary node indices: ``bottom``, ``x_faces``, ``y_faces``.
    probes
        Named points: ``name -> (x, y, z)``.
    probe_roles
        ``name -> role`` of the named points (:data:`railvib_hpc.schema.PROBE_ROLES`).
    """

    points: np.ndarray
    hexes: np.ndarray
    hex_part: np.ndarray
    lines: np.ndarray
    line_part: np.ndarray
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    probes: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    probe_roles: dict[str, str] = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    def counts_per_part(self) -> dict[str, int]:
        """Number of elements in each part (the thesis's parts with no elements are listed with
        0, soil layers only when present)."""
        hex_counts = np.bincount(self.hex_part, minlength=len(PARTS) + 1)
        line_counts = np.bincount(self.line_part, minlength=len(PARTS) + 1)
        counts = {p: int(hex_counts[PART_ID[p]] + line_counts[PART_ID[p]]) for p in PARTS}
        return {p: n for p, n in counts.items() if n or p not in SOIL_LAYER_PARTS}

    def nodes_per_part(self) -> dict[str, int]:
        """Number of distinct nodes used by each part."""
        out = {}
        for p in PARTS:
            pid = PART_ID[p]
            conn = np.concatenate([self.hexes[self.hex_part == pid].ravel(),
                                   self.lines[self.line_part == pid].ravel()])
            if conn.size or p not in SOIL_LAYER_PARTS:
                out[p] = int(np.unique(conn).size)
        return out

    def hex_volumes(self) -> np.ndarray:
        """Signed element volumes (:func:`railvib_hpc.fem.reference.hex_volumes`, exact)."""
        return hex_volumes(self.points[self.hexes])

    def volume_per_part(self) -> dict[str, float]:
        vol = self.hex_volumes()
        return {p: float(vol[self.hex_part == PART_ID[p]].sum()) for p in PARTS
                if np.any(self.hex_part == PART_ID[p])}

    def scaled_jacobians(self) -> np.ndarray:
        """Minimum corner scaled Jacobian per hex (1 for a cube, <= 0 when inverted)."""
        x = self.points[self.hexes]                              # (ne, 8, 3)
        e = x[:, _CORNER_NEIGHBOURS, :] - x[:, :, None, :]       # (ne, 8, 3, 3)
        e /= np.maximum(np.linalg.norm(e, axis=-1, keepdims=True), 1e-300)
        return np.linalg.det(e).min(axis=1)

    def edge_lengths(self) -> np.ndarray:
        """(n_hexes, 12) edge lengths."""
        x = self.points[self.hexes]
        return np.linalg.norm(x[:, _EDGES[:, 1]] - x[:, _EDGES[:, 0]], axis=-1)

    def aspect_ratios(self) -> np.ndarray:
        """Longest over shortest edge per hex."""
        lengths = self.edge_lengths()
        return lengths.max(axis=1) / np.maximum(lengths.min(axis=1), 1e-300)

    def duplicate_nodes(self, tol: float = 1e-8) -> int:
        """Number of nodes that coincide (within ``tol``) with another node."""
        key = np.round(self.points / tol).astype(np.int64)
        _, counts = np.unique(key, axis=0, return_counts=True)
        return int((counts - 1).sum())

    def unused_nodes(self) -> int:
        used = np.zeros(self.n_nodes, dtype=bool)
        used[self.hexes.ravel()] = True
        used[self.lines.ravel()] = True
        return int((~used).sum())

    def quality(self) -> dict[str, float]:
        """Summary: element counts, min scaled Jacobian, max aspect ratio, inverted count."""
        sj = self.scaled_jacobians()
        edges = self.edge_lengths()
        ar = edges.max(axis=1) / np.maximum(edges.min(axis=1), 1e-300)
        size = float(np.linalg.norm(np.ptp(self.points, axis=0))) if self.n_nodes else 0.0
        return {
            "n_nodes": self.n_nodes,
            "n_hexes": len(self.hexes),
            "n_lines": len(self.lines),
            "min_scaled_jacobian": float(sj.min()) if len(sj) else 1.0,
            "max_aspect_ratio": float(ar.max()) if len(ar) else 1.0,
            "n_inverted": int((sj <= 0).sum()),
            "min_edge": float(edges.min()) if len(edges) else 0.0,
            "model_size": size,
        }

    def rail_nodes(self) -> np.ndarray:
        """Flexible-rail nodes, shape (n_rails, k): one row per rail by increasing y (track
        1's two rails, then track 2's), each sorted along x (padded with -1 when the rails
        have different node counts)."""
        nodes = np.unique(self.lines[self.line_part == PART_ID["rail"]])
        y = np.round(self.points[nodes, 1], 6)
        out = []
        for value in np.unique(y):
            n = nodes[y == value]
            out.append(n[np.argsort(self.points[n, 0], kind="stable")])
        if not out:
            return np.zeros((2, 0), dtype=np.int64)
        width = max(len(o) for o in out)
        out = [np.pad(o, (0, width - len(o)), constant_values=-1) for o in out]
        return np.array(out, dtype=np.int64)

    def nearest_node(self, xyz: tuple[float, float, float]) -> int:
        return int(np.argmin(np.linalg.norm(self.points - np.asarray(xyz), axis=1)))


def renumbered(mesh: Mesh) -> Mesh:
    """The mesh with its nodes sorted by :func:`node_order` (a new Mesh)."""
    order = node_order(mesh.points)
    index = np.empty(mesh.n_nodes, dtype=np.int64)
    index[order] = np.arange(mesh.n_nodes)
    return replace(mesh, points=mesh.points[order], hexes=index[mesh.hexes],
                   lines=index[mesh.lines],
                   node_sets={k: np.sort(index[v]) for k, v in mesh.node_sets.items()})
