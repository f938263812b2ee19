"""The spectral soil's outputs in the trilinear path's files: probes through the GLL basis
at any point, and the field at the hex8 mesh's nodes (docs/spectral.md).

* :class:`GllSampler`: each probe is located in the hex8 mesh (the spectral element's shape
  is the trilinear map of its corners, so the reference point is the same) and read as
  ``sum_a phi_a(xi) u_a`` over the element's ``(N + 1)^3`` GLL nodes
  (:func:`~railvib_hpc.fem.gll.hex_interpolation`), by the rank that holds the element
  (the others add zero: the stage sums the ranks' values);
* :class:`CornerDofMap` and :func:`corner_values`: ``fields.h5`` holds the hex8 mesh's
  nodes, the GLL nodes that keep the corners' numbers (:mod:`railvib_hpc.fem.spectral_mesh`),
  gathered to rank 0 (which writes them all) at every output step: ``3 n_corner`` doubles
  per field and output step through one ``Reduce``.
"""

from __future__ import annotations

import numpy as np

from ..fem.gll import hex_interpolation
from ..mesh.search import locate
from .spectral_system import SpectralSoil

__all__ = ["CornerDofMap", "GllSampler", "corner_values"]


class GllSampler:
    """Values of the spectral field at points, as this rank's partial sums.

    Parameters
    ----------
    mesh
        The hex8 mesh (locates the points).
    soil
        The spectral soil.
    coords, names
        (p, 3) points and their names (error messages).

    Raises
    ------
    railvib_hpc.reconstruct.probes.ProbeError
        A point outside every hexahedron.
    """

    def __init__(self, mesh, soil: SpectralSoil, coords: np.ndarray, names: list[str]):
        from ..reconstruct.probes import ProbeError

        coords = np.asarray(coords, dtype=float).reshape(-1, 3)
        self.n = len(coords)
        self.elem, self.xi = np.zeros(0, np.int64), np.zeros((0, 3))
        self.weights = np.zeros((0, (soil.order + 1) ** 3))
        self.nodes = np.zeros((0, (soil.order + 1) ** 3), np.int64)
        self.mine = np.zeros(0, bool)
        if self.n == 0:
            return
        elem, xi = locate(coords, mesh)
        bad = np.flatnonzero(elem < 0)
        if bad.size:
            where = ", ".join(f"'{names[i]}' at {tuple(float(v) for v in coords[i])}"
                              for i in bad)
            raise ProbeError(f"probe point(s) outside the hexahedral mesh: {where}")
        self.elem, self.xi = elem, np.clip(xi, -1.0, 1.0)
        local = soil.g2l_element(elem)
        self.mine = local >= 0
        self.weights = hex_interpolation(soil.order, self.xi)
        self.nodes = np.where(self.mine[:, None], soil.local_elements[np.maximum(local, 0)],
                              0)

    def sample(self, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """(3, p, 3): displacement, velocity, acceleration at the points (zero at the
        points of the other ranks' elements)."""
        out = np.zeros((3, self.n, 3))
        if not self.mine.any():
            return out
        w = self.weights[self.mine]
        nodes = self.nodes[self.mine]
        for i, x in enumerate((u, v, a)):
            out[i, self.mine] = np.einsum("pq,pqc->pc", w, x[nodes])
        return out


class CornerDofMap:
    """The DOF map :class:`~.output.FieldWriter` reads, for the hex8 mesh's nodes gathered
    on rank 0 (every node owned by rank 0, three DOFs each, numbered as the nodes)."""

    def __init__(self, n_nodes: int, size: int):
        self.n_dofs = 3 * n_nodes
        self.index = np.arange(3 * n_nodes, dtype=np.int64).reshape(n_nodes, 3)
        self.node_offsets = np.array([0] + [n_nodes] * size)
        self.dof_offsets = 3 * self.node_offsets

    def owned_nodes(self, rank: int) -> slice:
        return slice(int(self.node_offsets[rank]), int(self.node_offsets[rank + 1]))

    def owned_dofs(self, rank: int) -> tuple[int, int]:
        return int(self.dof_offsets[rank]), int(self.dof_offsets[rank + 1])


def corner_values(soil: SpectralSoil, x: np.ndarray, n_corner: int) -> np.ndarray:
    """The hex8 nodes' values of a local field, flat, on rank 0 (collective: one
    ``Reduce``; the other ranks get an empty array)."""
    comm = soil.comm
    if not hasattr(soil, "_corner_rows"):
        corner = (soil.nodes < n_corner) & soil.owned
        soil._corner_rows = (np.flatnonzero(corner), soil.nodes[corner])
    rows, ids = soil._corner_rows
    out = np.zeros((n_corner, 3))
    out[ids] = x[rows]
    if comm.size == 1:
        return out.ravel()
    total = np.zeros_like(out) if comm.rank == 0 else None
    comm.Reduce(out, total, root=0)
    return total.ravel() if comm.rank == 0 else np.zeros(0)
