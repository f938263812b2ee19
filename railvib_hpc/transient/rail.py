"""Wheel-rail coupling on the full-order model's rail DOFs (pure numpy).

The flexible rails are beams whose nodes carry ``uz, ry`` (vertical bending) and
``uy, rz`` (lateral bending). Exactly as in the modal multibody coupling
(:mod:`railvib_hpc.mbs.coupling`), the rail displacement under a wheel at ``x`` is the cubic
Hermite interpolation of the element containing ``x`` (``dw/dx = -ry``, ``dv/dx = rz``),
along the contact normal ``(0, a, 1)`` of a coned wheel (``w + a v``, ``a = -sign(y_rail)
conicity``: the wheel pushes its rail outwards), and a wheel force is distributed to the
same DOFs with the same weights (virtual work). Each wheel touches at most 8 DOFs
(4 components of 2 nodes); positions off the flexible rail give zero weights (the rigid
rail).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mbs.coupling import shape_functions
from ..mesh.model import Mesh

#: Node components used by the coupling: uz, ry, uy, rz (indices into the 6 node DOFs).
RAIL_COMPONENTS = np.array([2, 4, 1, 5])


@dataclass(frozen=True)
class RailDofs:
    """The flexible rails' nodes and DOF numbers.

    Attributes
    ----------
    nodes
        (r, k) node ids, one row per rail by increasing y (2 per track), sorted along x.
    x
        (r, k) node positions along the track [m].
    y
        (r,) lateral positions of the rails [m].
    dofs
        (r, k, 4) global DOF numbers of ``uz, ry, uy, rz`` (-1 where constrained).
    """

    nodes: np.ndarray
    x: np.ndarray
    y: np.ndarray
    dofs: np.ndarray

    @classmethod
    def from_mesh(cls, mesh: Mesh, dof_index: np.ndarray) -> RailDofs:
        """Rails of ``mesh`` with the DOF numbers of ``dof_index`` (n_nodes, 6)."""
        nodes = mesh.rail_nodes()
        if nodes.size == 0 or np.any(nodes < 0):
            raise ValueError("the model needs two flexible rails with the same number of nodes")
        x = mesh.points[nodes, 0]
        y = mesh.points[nodes[:, 0], 1]
        return cls(nodes, x, y, dof_index[nodes][:, :, RAIL_COMPONENTS])

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[1]


class WheelCoupling:
    """DOFs and weights of moving wheels (or moving loads) on the rails.

    Parameters
    ----------
    rails
        The rails.
    wheel_rail
        (n_wheels,) rail index of every wheel.
    conicity
        Equivalent conicity of coned wheels (0: vertical contact only).
    """

    def __init__(self, rails: RailDofs, wheel_rail, conicity: float = 0.0):
        self.rails = rails
        self.wheel_rail = np.asarray(wheel_rail, dtype=np.int64)
        # the normals lean towards the track's centre: rails come in pairs, lower y first
        side = np.where(np.arange(len(rails.y)) % 2 == 0, -1.0, 1.0)
        self.lateral = -side[self.wheel_rail] * float(conicity)

    @property
    def n_wheels(self) -> int:
        return self.wheel_rail.size

    def at(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Coupling of wheels at positions ``x`` (n_wheels,).

        Returns
        -------
        dofs : ndarray (n_wheels, 8)
            Global DOF numbers (-1: constrained or off the flexible rail).
        coef : ndarray (n_wheels, 8)
            Weights: the rail displacement under wheel j is ``sum coef[j] u[dofs[j]]``; a
            downward force F on it is the load ``-F coef[j]`` on those DOFs.
        elem : ndarray (n_wheels,)
            Rail element under each wheel (-1 off the flexible rail).
        """
        x = np.asarray(x, dtype=float)
        nw = self.n_wheels
        dofs = np.full((nw, 8), -1, dtype=np.int64)
        coef = np.zeros((nw, 8))
        elem_out = np.full(nw, -1, dtype=np.int64)
        for r in np.unique(self.wheel_rail):
            sel = np.flatnonzero(self.wheel_rail == r)
            elem, w, inside = shape_functions(self.rails.x[r], x[sel], True)
            a = self.lateral[sel]
            # node e: uz, ry, uy, rz; node e+1: the same (w + a v along the normal)
            c = np.stack([w[:, 0], -w[:, 1], a * w[:, 0], a * w[:, 1],
                          w[:, 2], -w[:, 3], a * w[:, 2], a * w[:, 3]], axis=1)
            d = np.concatenate([self.rails.dofs[r, elem], self.rails.dofs[r, elem + 1]], axis=1)
            c[~inside] = 0.0
            c[d < 0] = 0.0
            d[c == 0.0] = -1
            dofs[sel], coef[sel] = d, c
            elem_out[sel] = np.where(inside, elem, -1)
        return dofs, coef, elem_out


__all__ = ["RAIL_COMPONENTS", "RailDofs", "WheelCoupling"]
