"""Read the modal basis of the rails from ``modes.h5`` (rank 0) for the multibody core."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..schema import PART_ID, PARTS
from .coupling import RailCoupling, contact_normal_rail


class RailModesError(UserError, ValueError):
    """The modes file cannot drive the multibody stage (e.g. a mesh without rails)."""


@dataclass
class RailModes:
    """Modal data the multibody simulation needs.

    Attributes
    ----------
    omega
        (m,) natural circular frequencies [rad/s], ascending.
    rails
        One :class:`RailCoupling` per rail, by increasing y (track 1's two rails, then
        track 2's), nodes sorted along x.
    rail_y
        (n_rails,) lateral position of each rail [m].
    rail_z
        Height of the rail axis [m].
    lateral
        Per rail ``(phi_v, phi_rz)``: lateral displacement and rotation about z at the
        same nodes, (m, k) each (for the inclined contact normal of coned wheels).
    """

    omega: np.ndarray
    rails: tuple[RailCoupling, ...]
    rail_y: np.ndarray
    rail_z: float
    lateral: tuple = ()

    def normal_rails(self, conicity: float) -> tuple[RailCoupling, ...]:
        """The rails seen along the contact normals of coned wheels (conicity ``lambda``).

        The rail of each track at the lower y gets ``phi_w + lambda phi_v``, the other
        ``phi_w - lambda phi_v`` (see :func:`.coupling.contact_normal_rail`): the normals
        lean towards the track's centre.
        """
        if conicity == 0.0 or not self.lateral:
            return self.rails
        out = []
        for k, (rail, (pv, prz)) in enumerate(zip(self.rails, self.lateral)):
            side = -1.0 if k % 2 == 0 else 1.0          # rails come in pairs, lower y first
            out.append(contact_normal_rail(rail, pv, prz, -side * conicity))
        return tuple(out)


def read_rail_modes(path: str | Path, n_modes: int | None = None) -> RailModes:
    """Rows of the mode shapes at the flexible-rail nodes: vertical displacement and ``ry``.

    Parameters
    ----------
    path
        A complete ``modes.h5`` written by ``railvib modal``.
    n_modes
        Use only the lowest ``n_modes`` modes (all by default).

    Raises
    ------
    ValueError
        When the file is incomplete or has no rail nodes.
    """
    import h5py

    with h5py.File(path, "r") as f:
        if int(f.attrs.get("complete", 0)) != 1:
            raise ValueError(f"{path} is not a complete modes file")
        m = f["modes/eigenvalue"].shape[0] if n_modes is None else int(n_modes)
        lam = f["modes/eigenvalue"][:m]
        rail_nodes = f["mesh/rail_nodes"][()]
        if rail_nodes.size == 0:
            ids = set(np.unique(f["mesh/hex_part"][()]).tolist()) | \
                set(np.unique(f["mesh/line_part"][()]).tolist())
            have = [p for p in PARTS if PART_ID[p] in ids]
            raise RailModesError(
                f"the multibody stage needs the flexible rails (part 'rail'), sleepers and "
                f"rail pads, which the mesh of {path} does not have (it has: "
                f"{', '.join(have) or 'nothing'}); 'railvib modal' works on such a mesh, "
                "'mbs' and 'run' do not")
        if np.any(rail_nodes < 0):
            raise ValueError(f"{path}: the rails must have the same number of nodes")
        points = f["mesh/points"][()]
        rot_nodes = f["mesh/rotation_nodes"][()]
        rails, ys, lateral = [], [], []
        for nodes in rail_nodes:
            order = np.argsort(nodes)                    # h5py wants increasing indices
            tr = np.empty((m, len(nodes), 3))
            tr[:, order] = f["modes/translation"][:m, nodes[order], :]
            pos = np.searchsorted(rot_nodes, nodes)
            if not np.array_equal(rot_nodes[np.minimum(pos, len(rot_nodes) - 1)], nodes):
                raise ValueError(f"{path}: rail nodes without rotations")
            rot = np.empty((m, len(nodes), 3))
            rot[:, order] = f["modes/rotation"][:m, pos[order], :]
            rails.append(RailCoupling(points[nodes, 0], tr[:, :, 2], rot[:, :, 1]))
            lateral.append((np.ascontiguousarray(tr[:, :, 1]), np.ascontiguousarray(rot[:, :, 2])))
            ys.append(float(points[nodes[0], 1]))
        rail_z = float(points[rail_nodes[0, 0], 2])
    return RailModes(np.sqrt(np.maximum(lam, 0.0)), tuple(rails), np.array(ys), rail_z,
                     tuple(lateral))
