"""A building turned against the track (``building.rotation``): the twist of the mesh.

The structured layout is parallel to the track. A turn is split into whole quarter turns
and a rest within +-45 deg (:func:`railvib_hpc.site.quarter_turns`). The quarters are
exact: the layout is symmetric under them, so the building is generated already turned
by them (:class:`railvib_hpc.mesh.building.Building`). The rest twists the mesh about the
plan centre: a point at distance ``r`` turns by ``angle * w(r)`` (:func:`twist_weight`),
so the building and the soil within ``r_in`` turn rigidly, the track, the embankment, a
trench and the domain's faces (beyond ``r_out``) stay where they are, and the ring between
is sheared, never folded: the map keeps every circle round the centre and every area (see
:class:`railvib_hpc.site.BuildingTurn`). Where that leaves soil cells with corner angles
beyond 25-155 deg, the ring's nodes are relaxed (:func:`relax`, :class:`TwistMap`). The
mesh stays conformal, its parts and node sets keep their elements and nodes, and the
probes move with the points they mark.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from ..config import Case
from ..errors import CaseError, MeshError
from ..site import (
    MAX_TWIST_SHEAR,
    TWIST_RESOLUTION_DEG,
    BuildingTurn,
    building_turn,
    placed_plan,
    quarter_turns,
)
from .layout import Layout, build_layout
from .model import Mesh, renumbered

#: Least scaled Jacobian a hexahedron may fall to by the twist (one that had less before
#: may not lose more): corner angles kept within 25-155 deg. A cube sheared by
#: cot(25 deg) = 2.14 reaches it (:data:`railvib_hpc.site.MAX_TWIST_SHEAR`); an element
#: long in the radial direction reaches it at a smaller shear, which this catches.
MIN_TWISTED_JACOBIAN = math.sin(math.radians(25.0))

#: Bisection steps for the largest twist a mesh's elements allow (2^-8 of the twist).
_BISECTION_STEPS = 8

#: Sweeps of the ring's relaxation (each moves every free node once, four colours).
_RELAX_SWEEPS = 200

#: The relaxation stops once every cell keeps corner angles within 30-150 deg (a margin
#: over :data:`MIN_TWISTED_JACOBIAN`), or when the least cell gains less than
#: :data:`_RELAX_STALL` in :data:`_RELAX_WINDOW` sweeps.
_RELAX_TARGET = math.sin(math.radians(30.0))
_RELAX_STALL, _RELAX_WINDOW = 1e-3, 10

#: Steps the relaxation tries for a node, in units of its shortest edge.
_RELAX_STEPS = (0.5, 0.25, 0.1, 0.05, 0.02, 0.01)

#: Tolerance [m] for finding a node on the soil's plan grid (gmsh's round-off is ~1e-14).
_GRID_TOL = 1e-7

#: Step [deg] of the largest twist a site allows (:func:`largest_twist`): the limit the mesh
#: error states is a multiple of it, found by bisection over 0-45 deg in these steps.
TWIST_LIMIT_STEP_DEG = 0.1

#: :func:`largest_twist` per (case without its rotation, quarter turns, direction).
_LARGEST_TWISTS: dict[tuple[str, int, int], float] = {}


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


def plan_grid(layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """The soil's plan grid lines: every node x and y of the structured layout (uniform
    divisions of each interval, as gmsh's transfinite lines place them)."""
    def lines(b: np.ndarray, n: np.ndarray) -> np.ndarray:
        return np.unique(np.concatenate([np.linspace(lo, hi, k + 1)
                                         for lo, hi, k in zip(b[:-1], b[1:], n)]))
    return lines(layout.xb, layout.nx), lines(layout.yb, layout.ny)


def quad_jacobians(p: np.ndarray) -> np.ndarray:
    """Least corner scaled Jacobian of every cell of a structured plan grid ``p`` (nx, ny,
    2), counter-clockwise in (i, j): (nx - 1, ny - 1). A vertical prism on such a cell (the
    soil's hexahedra) has the same."""
    c00, c10, c11, c01 = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]

    def corner(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        u, v = a - o, b - o
        cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
        return cross / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1),
                                  1e-300)
    return np.minimum.reduce([corner(c00, c10, c01), corner(c10, c11, c00),
                              corner(c11, c01, c10), corner(c01, c00, c11)])


def _node_worst(q: np.ndarray) -> np.ndarray:
    """Least of the (up to four) cells round every node: (nx, ny)."""
    pad = np.pad(q, 1, constant_values=np.inf)
    return np.minimum.reduce([pad[:-1, :-1], pad[1:, :-1], pad[:-1, 1:], pad[1:, 1:]])


def _shortest_edge(p: np.ndarray) -> np.ndarray:
    """Shortest grid edge at every node: (nx, ny)."""
    ex = np.linalg.norm(np.diff(p, axis=0), axis=-1)
    ey = np.linalg.norm(np.diff(p, axis=1), axis=-1)
    out = np.full(p.shape[:2], np.inf)
    out[:-1] = np.minimum(out[:-1], ex)
    out[1:] = np.minimum(out[1:], ex)
    out[:, :-1] = np.minimum(out[:, :-1], ey)
    out[:, 1:] = np.minimum(out[:, 1:], ey)
    return out


def relax(p: np.ndarray, free: np.ndarray, sweeps: int = _RELAX_SWEEPS) -> np.ndarray:
    """Move the ``free`` nodes of a plan grid ``p`` (nx, ny, 2) to raise the least scaled
    Jacobian round each: per sweep, the nodes of each of the four colours (i, j mod 2: no
    two share a cell) at once, each along its own ascent direction (finite differences)
    by the best of :data:`_RELAX_STEPS` shortest edges, only where that raises its worst
    cell. No cell round a moved node gets worse than that node's worst before, so the
    least Jacobian of the grid never falls (a copy; ``p`` is kept). Stops at
    :data:`_RELAX_TARGET`, or when the least cell stalls.
    """
    p = np.array(p, dtype=float, copy=True)
    ii, jj = np.meshgrid(np.arange(p.shape[0]), np.arange(p.shape[1]), indexing="ij")
    colours = [free & (ii % 2 == a) & (jj % 2 == b) for a in (0, 1) for b in (0, 1)]
    h = 1e-6 * float(np.nanmax(np.abs(p)) or 1.0)
    history = [float(quad_jacobians(p).min())]
    for _ in range(sweeps):
        if history[-1] >= _RELAX_TARGET or (len(history) > _RELAX_WINDOW and history[-1]
                                            - history[-1 - _RELAX_WINDOW] < _RELAX_STALL):
            break
        moved = 0
        for sel in colours:
            worst = _node_worst(quad_jacobians(p))
            grad = np.zeros_like(p)
            for d in (0, 1):
                for sign in (1.0, -1.0):
                    trial = p.copy()
                    trial[sel, d] += sign * h
                    grad[..., d] += sign * _node_worst(quad_jacobians(trial)) / (2 * h)
            norm = np.linalg.norm(grad, axis=-1)
            direction = grad / np.maximum(norm, 1e-300)[..., None]
            length = _shortest_edge(p)
            best, best_worst = p.copy(), worst.copy()
            for step in _RELAX_STEPS:
                trial = p.copy()
                trial[sel] += step * length[sel][:, None] * direction[sel]
                trial_worst = _node_worst(quad_jacobians(trial))
                better = sel & (norm > 0) & (trial_worst > best_worst)
                best[better], best_worst[better] = trial[better], trial_worst[better]
            take = sel & (best_worst > worst)
            p[take] = best[take]
            moved += int(np.count_nonzero(take))
        if moved == 0:
            break
        history.append(float(quad_jacobians(p).min()))
    return p


class TwistMap:
    """The twist of a turned building's ring, on a given layout: a map of points (n, 3).

    Every point turns by :func:`twist`. When that leaves a cell of the soil's plan grid
    with corner angles beyond 25-155 deg (:data:`MIN_TWISTED_JACOBIAN`), the grid's nodes
    between the building's plan and ``r_out`` are then relaxed (:func:`relax`): the twist
    is their start, the building (rotated rigidly) and everything beyond ``r_out`` (not
    moved) hold them. The relaxed map no longer keeps areas cell by cell, but it keeps the
    ring's area (its boundary is held), so every soil layer's volume, and it moves the
    soil's nodes in plan only (the layers stay horizontal).

    Attributes
    ----------
    turn
        The twist.
    relaxed
        Whether the ring's nodes were relaxed.
    """

    def __init__(self, case: Case, layout: Layout, turn: BuildingTurn | None = None):
        self.turn = building_turn(case) if turn is None else turn
        self.xs, self.ys = plan_grid(layout)
        gx, gy = np.meshgrid(self.xs, self.ys, indexing="ij")
        grid = np.stack([gx, gy, np.zeros_like(gx)], axis=-1).reshape(-1, 3)
        p = twist(grid, self.turn)[:, :2].reshape(*gx.shape, 2)
        x_lo, x_hi, y_lo, y_hi = placed_plan(case)
        in_plan = ((gx >= x_lo - _GRID_TOL) & (gx <= x_hi + _GRID_TOL)
                   & (gy >= y_lo - _GRID_TOL) & (gy <= y_hi + _GRID_TOL))
        r = np.hypot(gx - self.turn.centre[0], gy - self.turn.centre[1])
        self.free = ~in_plan & (r < self.turn.r_out - _GRID_TOL)
        self.free[[0, -1], :] = self.free[:, [0, -1]] = False
        self.relaxed = bool(quad_jacobians(p).min() < MIN_TWISTED_JACOBIAN)
        self.grid = relax(p, self.free) if self.relaxed else p

    def __call__(self, points: np.ndarray) -> np.ndarray:
        out = twist(points, self.turn)
        if not self.relaxed:
            return out
        i = np.clip(np.searchsorted(self.xs, points[:, 0]), 1, len(self.xs) - 1)
        i -= np.abs(points[:, 0] - self.xs[i - 1]) < np.abs(points[:, 0] - self.xs[i])
        j = np.clip(np.searchsorted(self.ys, points[:, 1]), 1, len(self.ys) - 1)
        j -= np.abs(points[:, 1] - self.ys[j - 1]) < np.abs(points[:, 1] - self.ys[j])
        on = ((np.abs(points[:, 0] - self.xs[i]) < _GRID_TOL)
              & (np.abs(points[:, 1] - self.ys[j]) < _GRID_TOL) & self.free[i, j])
        out[on, :2] = self.grid[i[on], j[on]]
        return out


def _twist_meshes(case: Case, k: int, sign: int, steps: int) -> bool:
    """Whether ``k`` quarter turns and a rest of ``sign * steps`` :data:`TWIST_LIMIT_STEP_DEG`
    keep every soil cell of that turn's own layout (its ring divided for that twist) within
    corner angles of 25-155 deg, relaxed where needed (:class:`TwistMap`), and within the
    ring's shear bound (a case ``railvib check`` refuses does not mesh). The soil's
    hexahedra in the ring are vertical prisms on the plan grid's cells, so their scaled
    Jacobians are the cells'; the building turns rigidly."""
    if steps == 0:
        return True
    try:
        trial = case.replace({"building.rotation":
                              90.0 * k + sign * steps * TWIST_LIMIT_STEP_DEG})
    except CaseError:                  # beyond the ring's shear bound (railvib check)
        return False
    grid = TwistMap(trial, build_layout(trial)).grid
    return bool(quad_jacobians(grid).min() >= MIN_TWISTED_JACOBIAN - 64 * np.finfo(float).eps)


def largest_twist(case: Case) -> float:
    """The largest rest beyond the case's whole quarter turns, in the direction of its own
    [deg, >= 0, a multiple of :data:`TWIST_LIMIT_STEP_DEG`], that the site's soil elements
    allow, each twist on its own layout (the ring divided for it).

    It depends on the site, the mesh settings, the quarter turns and the direction only,
    not on the rest asked for: a bisection over 0-45 deg in steps of
    :data:`TWIST_LIMIT_STEP_DEG` (45 deg taken as too far), every step checked on the twist's
    plan grid; the value it returns was checked (at most 44.9 deg). Cached per site (a
    failed mesh and its rerun ask twice in one process).
    """
    k, rest = quarter_turns(case["building.rotation"])
    sign = 1 if rest >= 0 else -1
    key = (case.digest(exclude=("rotation",)), k, sign)
    if key not in _LARGEST_TWISTS:
        ok, bad = 0, round(45.0 / TWIST_LIMIT_STEP_DEG)
        while bad - ok > 1:
            mid = (ok + bad) // 2
            ok, bad = (mid, bad) if _twist_meshes(case, k, sign, mid) else (ok, mid)
        _LARGEST_TWISTS[key] = round(ok * TWIST_LIMIT_STEP_DEG, 6)
    return _LARGEST_TWISTS[key]


def turn_building(mesh: Mesh, case: Case, layout: Layout,
                  twist_map: TwistMap | None = None) -> Mesh:
    """The mesh with the case's building twisted by the turn's rest beyond its whole
    quarter turns (the mesh itself when there is none: the quarters are in the layout).

    The nodes are renumbered by (x, y, z) afterwards, as the generated mesh's are. The
    probes move by :func:`twist` (points, not nodes). ``twist_map``: the case's
    :class:`TwistMap` when already made (the one that moved ``mesh.msh``).

    Raises
    ------
    MeshError
        When a twisted element's scaled Jacobian falls below
        :data:`MIN_TWISTED_JACOBIAN` (or below its own, when that was less), also after
        the ring's relaxation: one line with the largest twist the site allows in that
        direction (:func:`largest_twist`, the same whatever twist was asked for).
    """
    turn = building_turn(case)
    if turn.angle == 0:
        return mesh
    floor = np.minimum(mesh.scaled_jacobians(), MIN_TWISTED_JACOBIAN) - 64 * np.finfo(float).eps

    twist_map = TwistMap(case, layout, turn) if twist_map is None else twist_map

    def worst(points: np.ndarray) -> tuple[int, float]:
        """Elements below their floor with the nodes at ``points``, and the least scaled
        Jacobian."""
        sj = replace(mesh, points=points).scaled_jacobians()
        return int(np.count_nonzero(sj < floor)), float(sj.min())

    def twisted_by(angle: float) -> np.ndarray:
        return TwistMap(case, layout, replace(turn, angle=angle))(mesh.points)

    points = twist_map(mesh.points)
    n_bad, least = worst(points)
    if n_bad:
        k, _ = quarter_turns(case["building.rotation"])
        way = "counter-clockwise" if turn.angle > 0 else "clockwise"
        limit = largest_twist(case)
        if limit < math.degrees(abs(turn.angle)):
            allow = (f"the site's soil elements across the ring allow at most {limit:.1f} deg "
                     f"{way} from a quarter turn (each twist on its own ring divisions, this "
                     f"mesh.refinement, to {TWIST_LIMIT_STEP_DEG:g} deg)")
        else:       # the plan grid allows what the mesh did not: this mesh's own limit
            ok, bad = 0.0, 1.0                            # shares of the twist
            for _ in range(_BISECTION_STEPS):
                mid = 0.5 * (ok + bad)
                ok, bad = (mid, bad) if worst(twisted_by(mid * turn.angle))[0] == 0 \
                    else (ok, mid)
            allow = (f"this mesh's elements across the ring allow at most "
                     f"{math.floor(10 * math.degrees(ok * abs(turn.angle))) / 10:.1f} deg "
                     f"{way} from a quarter turn")
        raise MeshError(
            f"building.rotation = {case['building.rotation']}: twisting the soil by "
            f"{math.degrees(turn.angle):+.4g} deg from {90 * k} deg leaves {n_bad} hexahedra "
            f"with corner angles beyond 25-155 deg (scaled Jacobian down to {least:.3g}, "
            f"allowed {MIN_TWISTED_JACOBIAN:.3f}), also with the ring relaxed: {allow}; turn "
            "less, move the building away or widen the domain")
    names = list(mesh.probes)
    moved = twist(np.array([mesh.probes[k] for k in names], dtype=float).reshape(-1, 3), turn)
    probes = {k: tuple(float(v) for v in p) for k, p in zip(names, moved)}
    return renumbered(replace(mesh, points=points, probes=probes))


def turn_map(case: Case, layout: Layout):
    """The twist as a map of points (n, 3) (None when the building is not twisted)."""
    turn = building_turn(case)
    if turn.angle == 0:
        return None
    return TwistMap(case, layout, turn)


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
        rest = angle - 90.0 * round(angle / 90.0)
        return text + (", no twist" if rest == 0 else f", no twist (the rest, {rest:g} deg, "
                       f"is below the {TWIST_RESOLUTION_DEG:g} deg a twist needs)")
    return (text + f", then {np.degrees(turn.angle):g} deg twisting the soil between "
            f"{turn.r_in:.4g} and {turn.r_out:.4g} m from it (to {turn.bound}), shear "
            f"{turn.shear:.3f} (at most {MAX_TWIST_SHEAR:.3g}: +-{np.degrees(turn.max_angle):.3g} "
            "deg; the elements may allow less)")
