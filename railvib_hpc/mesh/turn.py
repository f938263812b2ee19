"""A building turned against the track (``building.rotation``): the twist of the mesh.

The structured layout is parallel to the track. A turned building is generated parallel
too, then the mesh is twisted about the plan centre: a point at distance ``r`` turns by
``angle * w(r)`` (:func:`railvib_hpc.config.twist_weight`), so the building and the soil
within ``r_in`` turn rigidly, the track, the embankment, a trench and the domain's faces
(beyond ``r_out``) stay where they are, and the ring between is sheared, never folded:
the map keeps every circle round the centre and every area (see
:class:`railvib_hpc.config.BuildingTurn`). The mesh stays conformal, its parts and node
sets keep their elements and nodes, and the probes move with the points they mark.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..config import BuildingTurn, Case, building_turn, twist_weight
from .model import Mesh, renumbered


def twist(points: np.ndarray, turn: BuildingTurn) -> np.ndarray:
    """``points`` (n, 3) turned by ``turn.angle * w(r)`` about ``turn.centre`` (a copy).

    Examples
    --------
    >>> import math
    >>> turn = BuildingTurn((0.0, 0.0), math.pi / 2, 1.0, 2.0, "a ring")
    >>> np.round(twist(np.array([[0.5, 0.0, 3.0], [3.0, 0.0, 0.0]]), turn), 12).tolist()
    [[0.0, 0.5, 3.0], [3.0, 0.0, 0.0]]
    """
    out = np.array(points, dtype=float, copy=True)
    dx, dy = out[:, 0] - turn.centre[0], out[:, 1] - turn.centre[1]
    phi = turn.angle * twist_weight(np.hypot(dx, dy), turn.r_in, turn.r_out)
    moving = phi != 0                    # beyond the ring the points stay bit for bit
    c, s, dx, dy = np.cos(phi[moving]), np.sin(phi[moving]), dx[moving], dy[moving]
    out[moving, 0] = turn.centre[0] + c * dx - s * dy
    out[moving, 1] = turn.centre[1] + s * dx + c * dy
    return out


def turn_building(mesh: Mesh, case: Case) -> Mesh:
    """The mesh with the case's building turned (the mesh itself when it is not turned).

    The nodes are renumbered by (x, y, z) afterwards, as the generated mesh's are.
    """
    turn = building_turn(case)
    if turn.angle == 0:
        return mesh
    names = list(mesh.probes)
    moved = twist(np.array([mesh.probes[k] for k in names], dtype=float).reshape(-1, 3), turn)
    probes = {k: tuple(float(v) for v in p) for k, p in zip(names, moved)}
    return renumbered(replace(mesh, points=twist(mesh.points, turn), probes=probes))


def turn_map(case: Case):
    """The turn as a map of points (n, 3) (None when the building is not turned)."""
    turn = building_turn(case)
    if turn.angle == 0:
        return None
    return lambda points: twist(points, turn)


def turn_line(case: Case) -> str:
    """One line on the turn for the mesh report and ``railvib check`` ('' when not turned)."""
    turn = building_turn(case)
    if turn.angle == 0:
        return ""
    return (f"building turned {case['building.rotation']:g} deg about ({turn.centre[0]:g}, "
            f"{turn.centre[1]:g}); soil twisted between {turn.r_in:.4g} and {turn.r_out:.4g} m "
            f"from it (to {turn.bound}), largest shear {turn.shear:.3f} (allowed "
            f"+-{np.degrees(turn.max_angle):.3g} deg)")
