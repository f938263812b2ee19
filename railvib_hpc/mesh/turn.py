"""A building turned against the track (``building.rotation``): the twist of the mesh.

The structured layout is parallel to the track. A turn is split into whole quarter turns
and a rest within +-45 deg (:func:`railvib_hpc.config.quarter_turns`). The quarters are
exact: the layout is symmetric under them, so the building is generated already turned
by them (:class:`railvib_hpc.mesh.building.Building`). The rest twists the mesh about the
plan centre: a point at distance ``r`` turns by ``angle * w(r)`` (:func:`twist_weight`),
so the building and the soil within ``r_in`` turn rigidly, the track, the embankment, a
trench and the domain's faces (beyond ``r_out``) stay where they are, and the ring between
is sheared, never folded: the map keeps every circle round the centre and every area (see
:class:`railvib_hpc.config.BuildingTurn`). The mesh stays conformal, its parts and node
sets keep their elements and nodes, and the probes move with the points they mark.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from ..config import MAX_TWIST_SHEAR, BuildingTurn, Case, building_turn, quarter_turns
from ..errors import MeshError
from .model import Mesh, renumbered

#: Least scaled Jacobian a hexahedron may fall to by the twist (one that had less before
#: may not lose more): corner angles kept within 25-155 deg. A cube sheared by
#: cot(25 deg) = 2.14 reaches it (:data:`railvib_hpc.config.MAX_TWIST_SHEAR`); an element
#: long in the radial direction reaches it at a smaller shear, which this catches.
MIN_TWISTED_JACOBIAN = math.sin(math.radians(25.0))

#: Bisection steps for the largest twist a mesh's elements allow (2^-12 of the turn).
_BISECTION_STEPS = 12


def twist_weight(r: ArrayLike, r_in: float, r_out: float) -> np.ndarray:
    """Share of a turned building's twist at distance ``r`` from its centre.

    1 inside ``r_in`` (the building turns rigidly), 0 beyond ``r_out`` (the track-parallel
    mesh is untouched) and ``ln(r_out / r) / ln(r_out / r_in)`` between: the profile whose
    shear ``r |w'(r)| = 1 / ln(r_out / r_in)`` is the same across the ring, so the least
    largest shear for a given turn (a C1 smoothstep has 1.5 times more at the ring's
    middle, and twice the error for the same turn: ``docs/sites.md``).

    Examples
    --------
    >>> twist_weight([1.0, 2.0 ** 1.5, 5.0], 2.0, 4.0).round(12).tolist()
    [1.0, 0.5, 0.0]
    """
    r = np.clip(np.asarray(r, dtype=float), r_in, r_out)
    return np.log(r_out / r) / math.log(r_out / r_in)


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
    """The mesh with the case's building twisted by the turn's rest beyond its whole
    quarter turns (the mesh itself when there is none: the quarters are in the layout).

    The nodes are renumbered by (x, y, z) afterwards, as the generated mesh's are.

    Raises
    ------
    MeshError
        When a twisted element's scaled Jacobian falls below
        :data:`MIN_TWISTED_JACOBIAN` (or below its own, when that was less): one line with
        the largest twist this mesh allows.
    """
    turn = building_turn(case)
    if turn.angle == 0:
        return mesh
    floor = np.minimum(mesh.scaled_jacobians(), MIN_TWISTED_JACOBIAN) - 64 * np.finfo(float).eps

    def worst(angle: float) -> tuple[int, float]:
        """Elements below their floor at ``angle``, and the least scaled Jacobian."""
        sj = replace(mesh, points=twist(mesh.points, replace(turn, angle=angle))
                     ).scaled_jacobians()
        return int(np.count_nonzero(sj < floor)), float(sj.min())

    n_bad, least = worst(turn.angle)
    if n_bad:
        ok, bad = 0.0, 1.0                                # shares of the twist
        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (ok + bad)
            ok, bad = (mid, bad) if worst(mid * turn.angle)[0] == 0 else (ok, mid)
        k, _ = quarter_turns(case["building.rotation"])
        raise MeshError(
            f"building.rotation = {case['building.rotation']}: twisting the soil by "
            f"{math.degrees(turn.angle):+.4g} deg from {90 * k} deg leaves {n_bad} hexahedra "
            f"with corner angles beyond 25-155 deg (scaled Jacobian down to {least:.3g}, "
            f"allowed {MIN_TWISTED_JACOBIAN:.3f}): this mesh's elements across the ring allow "
            f"at most {math.degrees(ok * abs(turn.angle)):.3g} deg from a quarter turn; turn "
            "less, move the building away or widen the domain")
    names = list(mesh.probes)
    moved = twist(np.array([mesh.probes[k] for k in names], dtype=float).reshape(-1, 3), turn)
    probes = {k: tuple(float(v) for v in p) for k, p in zip(names, moved)}
    return renumbered(replace(mesh, points=twist(mesh.points, turn), probes=probes))


def turn_map(case: Case):
    """The twist as a map of points (n, 3) (None when the building is not twisted)."""
    turn = building_turn(case)
    if turn.angle == 0:
        return None
    return lambda points: twist(points, turn)


def turn_line(case: Case) -> str:
    """One line on the turn for the mesh report and ``railvib check`` ('' when not turned)."""
    angle = case["building.rotation"]
    if angle == 0:
        return ""
    k, _ = quarter_turns(angle)
    turn = building_turn(case)
    text = (f"building turned {angle:g} deg about ({turn.centre[0]:g}, {turn.centre[1]:g}): "
            f"{k} quarter turn{'' if k == 1 else 's'} (exact)")
    if turn.angle == 0:
        return text + ", no twist"
    return (text + f", then {np.degrees(turn.angle):g} deg twisting the soil between "
            f"{turn.r_in:.4g} and {turn.r_out:.4g} m from it (to {turn.bound}), shear "
            f"{turn.shear:.3f} (at most {MAX_TWIST_SHEAR:.3g}: +-{np.degrees(turn.max_angle):.3g} "
            "deg; the elements may allow less)")
