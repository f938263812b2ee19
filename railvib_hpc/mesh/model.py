"""The mesh as numpy arrays, with quality, volume and connectivity checks.

Hexahedra use gmsh/VTK node order (bottom face 0-1-2-3 counter-clockwise seen
from above, top face 4-5-6-7). All checks are vectorised over elements.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..fem.reference import (
    GAUSS_GRADIENTS,
    GAUSS_WEIGHTS,
    HEX_EDGES,
    element_batches,
    hex_corner_determinants,
)
from ..schema import PART_ID, PARTS, SOIL_LAYER_PARTS

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
        used = np.zeros(self.n_nodes, dtype=bool)
        for p in PARTS:
            pid = PART_ID[p]
            hexes, lines = self.hexes[self.hex_part == pid], self.lines[self.line_part == pid]
            if hexes.size or lines.size or p not in SOIL_LAYER_PARTS:
                used[:] = False
                used[hexes] = True
                used[lines] = True
                out[p] = int(np.count_nonzero(used))
        return out

    def hex_volumes(self) -> np.ndarray:
        """Signed element volumes: :func:`railvib_hpc.fem.reference.hex_volumes` (the 2x2x2
        Gauss rule of det J, exact), to round-off, with the determinants as triple products
        (:func:`_hex_volumes`)."""
        out = np.empty(len(self.hexes))
        for s in element_batches(len(self.hexes)):
            out[s] = _hex_volumes(self.points[self.hexes[s]])
        return out

    def volume_per_part(self) -> dict[str, float]:
        vol = self.hex_volumes()
        return {p: float(vol[self.hex_part == PART_ID[p]].sum()) for p in PARTS
                if np.any(self.hex_part == PART_ID[p])}

    def scaled_jacobians(self) -> np.ndarray:
        """Minimum corner scaled Jacobian per hex (1 for a cube, <= 0 when inverted)."""
        return self.element_measures()[0]

    def element_measures(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per hex, in one pass over the elements: the minimum corner scaled Jacobian
        (:func:`~railvib_hpc.fem.reference.hex_corner_determinants`), the shortest and the
        longest edge, each shape (n_hexes,)."""
        ne = len(self.hexes)
        sj, shortest, longest = np.empty(ne), np.empty(ne), np.empty(ne)
        for s in element_batches(ne):
            x = self.points[self.hexes[s]]
            sj[s] = hex_corner_determinants(x, scaled=True).min(axis=1)
            lengths = _edge_lengths(x)
            shortest[s], longest[s] = lengths.min(axis=1), lengths.max(axis=1)
        return sj, shortest, longest

    def edge_lengths(self) -> np.ndarray:
        """(n_hexes, 12) edge lengths."""
        out = np.empty((len(self.hexes), len(HEX_EDGES)))
        for s in element_batches(len(self.hexes)):
            out[s] = _edge_lengths(self.points[self.hexes[s]])
        return out

    def aspect_ratios(self) -> np.ndarray:
        """Longest over shortest edge per hex."""
        _, shortest, longest = self.element_measures()
        return longest / np.maximum(shortest, 1e-300)

    def duplicate_nodes(self, tol: float = 1e-8) -> int:
        """Number of nodes that coincide (within ``tol``) with another node: nodes whose
        coordinates rounded to multiples of ``tol`` equal those of another node."""
        if self.n_nodes < 2:
            return 0
        key = np.round(self.points / tol).astype(np.int64)
        key = key[np.lexsort(key.T[::-1])]
        return int(np.count_nonzero((key[1:] == key[:-1]).all(axis=1)))

    def unused_nodes(self) -> int:
        used = np.zeros(self.n_nodes, dtype=bool)
        used[self.hexes.ravel()] = True
        used[self.lines.ravel()] = True
        return int((~used).sum())

    def quality(self, measures: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                ) -> dict[str, float]:
        """Summary: element counts, min scaled Jacobian, max aspect ratio, inverted count
        (``measures``: :meth:`element_measures` when already computed)."""
        sj, shortest, longest = self.element_measures() if measures is None else measures
        ar = longest / np.maximum(shortest, 1e-300)
        size = float(np.linalg.norm(np.ptp(self.points, axis=0))) if self.n_nodes else 0.0
        return {
            "n_nodes": self.n_nodes,
            "n_hexes": len(self.hexes),
            "n_lines": len(self.lines),
            "min_scaled_jacobian": float(sj.min()) if len(sj) else 1.0,
            "max_aspect_ratio": float(ar.max()) if len(ar) else 1.0,
            "n_inverted": int((sj <= 0).sum()),
            "min_edge": float(shortest.min()) if len(shortest) else 0.0,
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

    def nearest_nodes(self, xyz: np.ndarray) -> np.ndarray:
        """:meth:`nearest_node` of each point of ``xyz`` (m, 3): the same distances to the
        bit (``np.linalg.norm`` sums the squares in this order), the first node of a tie,
        from contiguous coordinate columns (no (n, 3) temporary per point)."""
        columns = [np.ascontiguousarray(self.points[:, i]) for i in range(3)]
        out = np.empty(len(xyz), dtype=np.int64)
        for k, c in enumerate(np.asarray(xyz, dtype=float).reshape(-1, 3)):
            d = [col - c[i] for i, col in enumerate(columns)]
            out[k] = np.argmin(np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]))
        return out


def _hex_volumes(x: np.ndarray) -> np.ndarray:
    """Signed volumes (nel,) of hexahedra with corners ``x`` (nel, 8, 3): the Jacobians at
    the 8 Gauss points in one matrix product, their determinants as triple products."""
    jac = np.tensordot(x, GAUSS_GRADIENTS, axes=([1], [1]))    # (nel, 3 j, 8 q, 3 i)
    a, b, c = jac[..., 0], jac[..., 1], jac[..., 2]            # rows dx/dxi_i: (nel, 3, 8)
    det = (a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
           + a[:, 1] * (b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2])
           + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]))
    return det @ GAUSS_WEIGHTS


def _edge_lengths(x: np.ndarray) -> np.ndarray:
    """(nel, 12) edge lengths of hexahedra with corners ``x`` (nel, 8, 3)."""
    d = x[:, HEX_EDGES[:, 1]] - x[:, HEX_EDGES[:, 0]]
    return np.sqrt(np.einsum("eki,eki->ek", d, d))


def renumbered(mesh: Mesh) -> Mesh:
    """The mesh with its nodes sorted by :func:`node_order` (a new Mesh)."""
    order = node_order(mesh.points)
    index = np.empty(mesh.n_nodes, dtype=np.int64)
    index[order] = np.arange(mesh.n_nodes)
    return replace(mesh, points=mesh.points[order], hexes=index[mesh.hexes],
                   lines=index[mesh.lines],
                   node_sets={k: np.sort(index[v]) for k, v in mesh.node_sets.items()})
