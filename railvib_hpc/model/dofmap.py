"""Degrees of freedom: mixed 6/3 DOF per node, constraints, global numbering, ownership.

Nodes of beam elements (rails, sleepers) carry 6 DOFs ``ux uy uz rx ry rz``;
nodes used only by hexahedra (and springs) carry 3. Constrained DOFs are not
numbered at all (eliminated), so they produce no spurious eigenvalues.

The global numbering follows the mesh node order (nodes are sorted along the
track when the mesh is built), so it does not depend on the number of MPI
ranks: rank ``r`` owns a contiguous range of nodes and hence of DOFs, and the
assembled matrices are identical on 1 and N ranks.

Default constraints reproduce the thesis (Appendix A):

* bottom nodes fixed; nodes on the faces normal to x: ``ux = 0``; on the faces
  normal to y: ``uy = 0``;
* rigid rail nodes: all 6 DOFs fixed (this includes the rigid/flexible joints);
* all rotations of sleeper nodes fixed;
* all rotations of the rail nodes that carry a pad fixed;
* nodes that belong to no element (left over in a user's mesh) have no DOF.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.model import Mesh
from ..schema import PART_ID

COMPONENTS = ("ux", "uy", "uz", "rx", "ry", "rz")


@dataclass
class DofMap:
    """Global DOF numbers of every node component.

    Attributes
    ----------
    index
        (n_nodes, 6) global DOF number, -1 where the component is constrained or absent.
    has_rotations
        (n_nodes,) True for beam nodes (6 DOFs).
    node_offsets
        (size + 1,) first node owned by each rank (contiguous ranges), last entry n_nodes.
    dof_offsets
        (size + 1,) first global DOF owned by each rank.
    """

    index: np.ndarray
    has_rotations: np.ndarray
    node_offsets: np.ndarray
    dof_offsets: np.ndarray

    @property
    def n_dofs(self) -> int:
        return int(self.dof_offsets[-1])

    def owned_nodes(self, rank: int) -> slice:
        return slice(int(self.node_offsets[rank]), int(self.node_offsets[rank + 1]))

    def owned_dofs(self, rank: int) -> tuple[int, int]:
        return int(self.dof_offsets[rank]), int(self.dof_offsets[rank + 1])

    def node_arrays(self, columns: np.ndarray, rank: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, slice, slice]:
        """Reshape this rank's DOF rows of vectors into per-node translations and rotations.

        Parameters
        ----------
        columns
            (owned DOFs, m): this rank's rows of ``m`` global vectors (modes, static
            solutions), in the numbering of :attr:`index`.
        rank
            This rank.

        Returns
        -------
        translation : ndarray, shape (m, owned nodes, 3)
            ``ux uy uz`` of the owned nodes (0 where constrained).
        rotation : ndarray, shape (m, owned rotation nodes, 3)
            ``rx ry rz`` of the owned nodes that carry rotations.
        rotation_nodes : ndarray
            All nodes that carry rotations (global, sorted).
        rot_range : slice
            The part of ``rotation_nodes`` owned by ``rank``.
        nodes : slice
            The nodes owned by ``rank``.
        """
        nodes = self.owned_nodes(rank)
        r0, _ = self.owned_dofs(rank)
        idx = self.index[nodes]
        m = columns.shape[1]
        rotation_nodes = np.flatnonzero(self.has_rotations)
        lo, hi = np.searchsorted(rotation_nodes, [nodes.start, nodes.stop])
        owned_rot = rotation_nodes[lo:hi] - nodes.start
        translation = np.empty((m, idx.shape[0], 3))
        rotation = np.empty((m, owned_rot.size, 3))
        ok = idx >= 0
        rows = idx[ok] - r0
        for j in range(0, m, NODE_ARRAY_CHUNK):        # no n x 6 x m scratch array
            full = np.zeros((min(NODE_ARRAY_CHUNK, m - j), idx.shape[0], 6))
            full[:, ok] = columns[rows, j:j + NODE_ARRAY_CHUNK].T
            translation[j:j + NODE_ARRAY_CHUNK] = full[:, :, :3]
            rotation[j:j + NODE_ARRAY_CHUNK] = full[:, owned_rot, 3:]
        return translation, rotation, rotation_nodes, slice(int(lo), int(hi)), nodes


#: Vectors per step of :meth:`DofMap.node_arrays`: its scratch space is this many n x 6
#: arrays, not one per vector (1013 modes of the refinement-2 thesis model: 8.8 GB a rank).
NODE_ARRAY_CHUNK = 64


#: Appendix A: bottom fixed, u_x = 0 on faces normal to x, u_y = 0 on faces normal to y.
DEFAULT_RULES: dict[str, tuple[str, ...]] = {
    "bottom": COMPONENTS, "x_faces": ("ux",), "y_faces": ("uy",),
}


def constraint_mask(mesh: Mesh, fix_sleeper_rotations: bool = True,
                    fix_rail_rotations_at_pads: bool = True,
                    rules: dict[str, tuple[str, ...]] | None = None,
                    node_sets: dict[str, np.ndarray] | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Boolean (n_nodes, 6) mask of constrained components, and the beam-node mask.

    ``rules`` maps a node-set name of the mesh (or of ``node_sets``, extra named sets
    such as the truncation faces of :mod:`.boundary`) to the components fixed on it
    (default :data:`DEFAULT_RULES`); the set name ``"all"`` means every node.
    """
    n = mesh.n_nodes
    beam_ids = [PART_ID[p] for p in ("rail", "rigid_rail", "sleeper")]
    beam_nodes = np.zeros(n, dtype=bool)
    beam_nodes[mesh.lines[np.isin(mesh.line_part, beam_ids)].ravel()] = True
    fixed = np.zeros((n, 6), dtype=bool)
    fixed[~beam_nodes, 3:] = True                       # rotations do not exist there
    used = np.zeros(n, dtype=bool)                      # nodes of no element (a user mesh's
    used[mesh.hexes.ravel()] = True                     # leftovers) carry no DOF
    used[mesh.lines.ravel()] = True
    fixed[~used] = True
    ns = dict(mesh.node_sets, **(node_sets or {}), all=np.arange(n))
    for name, comps in (DEFAULT_RULES if rules is None else rules).items():
        if name in ns:
            fixed[np.ix_(ns[name], [COMPONENTS.index(c) for c in comps])] = True
    fixed[mesh.lines[mesh.line_part == PART_ID["rigid_rail"]].ravel(), :] = True
    if fix_sleeper_rotations:
        fixed[mesh.lines[mesh.line_part == PART_ID["sleeper"]].ravel(), 3:] = True
    if fix_rail_rotations_at_pads:
        pads = mesh.lines[np.isin(mesh.line_part, [PART_ID[p] for p in ("pad_x", "pad_y",
                                                                         "pad_z")])]
        fixed[pads.ravel(), 3:] = True
    return fixed, beam_nodes


def build_dofmap(mesh: Mesh, size: int = 1, fix_sleeper_rotations: bool = True,
                 fix_rail_rotations_at_pads: bool = True,
                 rules: dict[str, tuple[str, ...]] | None = None,
                 node_sets: dict[str, np.ndarray] | None = None) -> DofMap:
    """Number the free DOFs in node order and split nodes into ``size`` contiguous ranges.

    The split balances the number of DOFs per rank. ``rules``, ``node_sets``: see
    :func:`constraint_mask`.
    """
    fixed, beam_nodes = constraint_mask(mesh, fix_sleeper_rotations, fix_rail_rotations_at_pads,
                                        rules, node_sets)
    free = ~fixed
    index = np.full(fixed.shape, -1, dtype=np.int64)
    index[free] = np.arange(int(free.sum()))           # row-major: node by node
    per_node = free.sum(axis=1)
    cum = np.concatenate(([0], np.cumsum(per_node)))
    n_dofs = int(cum[-1])
    targets = np.arange(1, size) * n_dofs / size
    cuts = np.searchsorted(cum, targets)
    node_offsets = np.concatenate(([0], cuts, [mesh.n_nodes])).astype(np.int64)
    dof_offsets = cum[node_offsets].astype(np.int64)
    return DofMap(index=index, has_rotations=beam_nodes, node_offsets=node_offsets,
                  dof_offsets=dof_offsets)


def rigid_body_modes(points: np.ndarray, dofmap: DofMap, rank: int) -> np.ndarray:
    """The six rigid-body motions on this rank's DOF rows, (n_local, 6): the translations
    ``ux, uy, uz`` and the rotations about the axes through the nodes' centroid (``u =
    e_k x (x - x_c)`` on the translations, 1 on the rotation ``r_k`` of beam nodes), zero
    where a DOF is constrained. Not normalised. The near null space of K for an algebraic
    multigrid preconditioner (PETSc GAMG's ``MatSetNearNullSpace``): the static start of
    the explicit engines.

    >>> import numpy as np
    >>> pts = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    >>> dm = DofMap(np.array([[0, 1, 2, -1, -1, -1], [3, 4, 5, -1, -1, -1]]),
    ...             np.zeros(2, bool), np.array([0, 2]), np.array([0, 6]))
    >>> rigid_body_modes(pts, dm, 0)[:, 5].tolist()     # about z: u_y = x - x_c
    [0.0, -0.5, 0.0, 0.0, 0.5, 0.0]
    """
    r0, r1 = dofmap.owned_dofs(rank)
    own = dofmap.owned_nodes(rank)
    index = dofmap.index[own]
    x = points[own] - points.mean(axis=0)
    modes = np.zeros((r1 - r0, 6))
    spin = np.cross(np.eye(3)[:, None, :], x[None, :, :])     # (axis k, nodes, 3)
    for c in range(3):
        free = index[:, c] >= 0
        modes[index[free, c] - r0, c] = 1.0
        modes[index[free, c] - r0, 3:] = spin[:, free, c].T
        free = index[:, 3 + c] >= 0
        modes[index[free, 3 + c] - r0, 3 + c] = 1.0
    return modes
