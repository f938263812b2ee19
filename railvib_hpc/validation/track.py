"""Cross-key checks of the track and its loads: the tracks, the moving load on the bare
soil, the static start, the embankment and the track's ends.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..schema import CaseView
from ..site import (
    embankment_toe,
    load_path_crossing,
    placed_plan,
    quarter_turns,
    track_lift,
    train2_vehicle,
)
from .dynamics import _vehicle_problems


def _check_tracks(case: CaseView) -> list[tuple[str, Any, str]]:
    """A second track: its sleepers clear of the first's and inside the soil; the
    ``[train2]`` keys only with it."""
    g, t = case["geometry"], case["track"]
    if t["count"] > 2:
        return [("track.count", t["count"], "must be 1 or 2, or 0 (no track: the moving load "
                 "of [load] on the bare soil)")]
    if t["count"] < 2:               # ([train2] applies to a second track only: Param.applies)
        return []
    out = []
    own = case["train2.vehicle"]
    if own:
        v1, v2 = case["vehicle"], train2_vehicle(case)
        first = {k.rsplit(".", 1)[1] for k, _, _ in
                 _vehicle_problems(v1, case["track.gauge"], "vehicle")}
        out.extend(p for p in _vehicle_problems(v2, case["track.gauge"], "train2.vehicle")
                   if p[0].rsplit(".", 1)[1] not in first)
    if not t["spacing"] > t["sleeper_length"]:
        out.append(("track.spacing", t["spacing"],
                    f"the two tracks' sleepers must not touch: spacing > track.sleeper_length "
                    f"= {t['sleeper_length']:g} m"))
    elif not g["ys0"] > t["spacing"] + embankment_toe(case):
        far = t["spacing"] + embankment_toe(case)
        out.append(("geometry.ys0", g["ys0"],
                    f"must be > track.spacing + the embankment toe = {far:g} m (the soil "
                    "must extend beyond the embankment of the second track)"))
    return out


def _check_surface_load(case: CaseView) -> list[tuple[str, Any, str]]:
    """``track.count = 0`` (the bare soil) goes with the moving surface load of ``[load]``
    and nothing of the track or the vehicle; ``[load]`` goes with it only."""
    t, ld = case["track"], case["load"]
    if t["count"] != 0:          # ([load] applies to the bare soil only: Param.applies)
        return []
    if not ld["force"] > 0:
        return [("track.count", 0, "0 (no track) needs the moving surface load: set "
                 "load.force > 0 ([load]); with a track: 1 or 2")]
    out: list[tuple[str, Any, str]] = []
    bare = "with track.count = 0 (no track: the moving load of [load] on the bare soil)"
    if case["mesh.file"]:
        out.append(("mesh.file", case["mesh.file"], f"{bare} the mesh is the generated one "
                    "(its soil without the track bed): leave mesh.file out"))
    if any(o > 0 for o in ld["offsets"]) or not ld["offsets"]:
        out.append(("load.offsets", ld["offsets"],
                    "must be a non-empty list of offsets <= 0 (behind the leading load)"))
    g, d = case["geometry"], case["domain"]
    lo, hi = g["ys4"] - d["extra_width"], g["ys0"]
    if not lo < ld["y"] < hi:
        out.append(("load.y", ld["y"], f"the path must run on the soil: {lo:g} < y < "
                    f"{hi:g} m (geometry.ys4 - domain.extra_width to geometry.ys0)"))
    else:
        out.extend(_load_path_problems(case))
    if ld["frequency"] > case["transient.f_max"]:
        out.append(("load.frequency", ld["frequency"], f"must be <= transient.f_max = "
                    f"{case['transient.f_max']:g} Hz (the automatic step resolves f_max; "
                    "raise it with the load's frequency)"))
    last = ld["x_start"] + min(ld["offsets"] or [0.0])
    if ld["x_end"] and not ld["x_end"] > last:
        out.append(("load.x_end", ld["x_end"], f"must lie beyond the last load's start "
                    f"{last:g} m (load.x_start + the smallest offset), or be 0 (the soil's "
                    "end)"))
    return out


#: The truncation faces of the soil box: the axis of their normal and whether they lie at
#: its upper end (``[boundary]``).
_FACE_PLANES = {"x_min": (0, False), "x_max": (0, True), "y_min": (1, False),
                "y_max": (1, True), "base": (2, False)}


def _statically_held(case: CaseView, face: str) -> tuple[int, ...]:
    """The displacement components a face holds against a static load, its kind's
    (:meth:`~railvib_hpc.model.boundary_kind.BoundaryKind.statically_held`): fixed, caughey
    and pml faces all three, a roller its normal one, an absorbing face all three with
    its springs (``boundary.virtual_thickness > 0``) and none on dashpots alone (they
    hold no static load), a free face none."""
    from ..boundary_registry import BOUNDARY_KINDS, boundary_kind

    kind = case[f"boundary.{face}"]
    if kind not in BOUNDARY_KINDS:                # refused with the values
        return ()
    return boundary_kind(kind).statically_held(face, case["boundary"])


def _check_static_start(case: CaseView) -> list[tuple[str, Any, str]]:
    """``load.start = 'static'`` solves ``K u0 = f0``: the faces must hold the soil box
    against every rigid-body motion (else K is singular). The box's faces are planes, so
    their corners decide (a rigid-body motion is linear in the position)."""
    if case["track.count"] != 0 or case["load.start"] != "static":
        return []
    g, d = case["geometry"], case["domain"]
    lo = np.array([g["x1"] - d["extra_length"], g["ys4"] - d["extra_width"],
                   g["z0"] - d["extra_depth"]])
    hi = np.array([g["x4"] + d["extra_length"], g["ys0"], g["z1"]])
    centre, scale = 0.5 * (lo + hi), float(np.max(hi - lo))
    rows = []
    for face, (axis, upper) in _FACE_PLANES.items():
        others = [a for a in range(3) if a != axis]
        for c0 in (lo[others[0]], hi[others[0]]):
            for c1 in (lo[others[1]], hi[others[1]]):
                p = np.empty(3)
                p[axis], p[others[0]], p[others[1]] = (hi if upper else lo)[axis], c0, c1
                p = (p - centre) / scale
                for c in _statically_held(case, face):
                    # the motion t + w x p, its component c: t_c + (w x p)_c
                    row = np.zeros(6)
                    row[c] = 1.0
                    row[3:] = np.cross(p, np.eye(3)[c])      # (w x p)_c = w . (p x e_c)
                    rows.append(row)
    if rows and np.linalg.matrix_rank(np.array(rows), tol=1e-9) == 6:
        return []
    faces = ", ".join(f"{f} {case[f'boundary.{f}']}" for f in _FACE_PLANES)
    return [("load.start", "static",
             f"solves K u0 = f0 at t = 0 and needs the soil box held statically, which "
             f"its faces do not do ([boundary]: {faces}, virtual_thickness = "
             f"{case['boundary.virtual_thickness']:g} m: absorbing faces hold no static "
             "load on their dashpots alone); allowed: boundary.virtual_thickness > 0 "
             "(the absorbing faces' springs), a fixed or roller base, or load.start = "
             "'ramp'")]


def _load_path_problems(case: CaseView) -> list[tuple[str, Any, str]]:
    """The surface load's path on the ground: not through the building's plan (there the
    ground is the building, its walls and basement: the load would stand in a wall, and
    over the basement on nothing, switching off and on as a step) nor along an open
    trench (the whole length on nothing), as the probe lines (:func:`_check_line_points`)."""
    ld, g = case["load"], case["geometry"]
    y = ld["y"]
    tr = case["trench"]
    if tr["type"] == "open" and tr["width"] > 0 and \
            tr["distance"] < -y < tr["distance"] + tr["width"]:
        return [("load.y", y, f"the load's path runs along the open trench (y = "
                 f"{-tr['distance'] - tr['width']:g} to {-tr['distance']:g} m: trench.distance, "
                 "trench.width), a void with no ground to stand on: allowed y outside it")]
    crossing = load_path_crossing(case)
    if crossing is None:
        return []
    k, rest = quarter_turns(case["building.rotation"])
    th = math.radians(90.0 * k + rest)
    cy = 0.5 * (g["ys2"] + g["ys3"])
    half = (0.5 * (g["x3"] - g["x2"]) * abs(math.sin(th))
            + 0.5 * (g["ys2"] - g["ys3"]) * abs(math.cos(th)))
    lo, hi = round(cy - half, 6), round(cy + half, 6)
    return [("load.y", y, f"the load's path y = {y:g} m runs through the building's plan "
             f"(x {crossing[0]:g} to {crossing[1]:g} m, y {lo:g} to {hi:g} m: geometry.x2, "
             "x3, ys3, ys2 and building.rotation): the load would stand in its walls and on "
             f"nothing over the basement; allowed: load.y <= {lo:g} or >= {hi:g} m, or "
             "load.x_start, x_end, t_after that keep the loads off the plan")]


def _check_embankment(case: CaseView) -> list[tuple[str, Any, str]]:
    """A fill embankment's base stays clear of the building and inside the soil."""
    g, h = case["geometry"], track_lift(case)
    if h == 0 or case["track.count"] == 0:              # (no track: _check_surface_load)
        return []
    toe = embankment_toe(case)
    if not case["building.present"]:
        edge = -(g["ys4"] - case["domain.extra_width"])
        if not toe < edge:
            return [("track.embankment_height", h,
                     f"the embankment's toe ({toe:g} m from the track centre) reaches the "
                     f"soil's edge {edge:g} m from it (|YS4| + domain.extra_width); lower it "
                     "or widen the domain")]
    face = -placed_plan(case)[3] if case["building.present"] else math.inf
    if not toe < face:
        return [("track.embankment_height", h,
                 f"the embankment's toe ({toe:g} m from the track centre: |YS1| + "
                 f"embankment_slope x height) reaches the building face {face:g} m from it "
                 "(|YS2|, turned with building.rotation); lower it, steepen "
                 "track.embankment_slope or move the building")]
    if case["track.count"] == 1 and not g["ys0"] > toe:
        return [("geometry.ys0", g["ys0"],
                 f"must be > the embankment toe {toe:g} m (the soil must extend beyond the "
                 "fill)")]
    return []


def _check_track_ends(case: CaseView) -> list[tuple[str, Any, str]]:
    """``track.ends = 'supported'``: whole bays, a rail whose torsion something holds, the
    generated mesh, and wheels that start and end on the modelled rail."""
    t, g, v = case["track"], case["geometry"], case["vehicle"]
    if t["ends"] != "supported" or t["count"] == 0:     # (no track: _check_surface_load)
        return []
    out: list[tuple[str, Any, str]] = []
    bays = t["rigid_length"] / t["sleeper_spacing"]
    if abs(bays - round(bays)) > 1e-6:
        out.append(("track.rigid_length", t["rigid_length"],
                    "with track.ends = 'supported' it must be a whole number of sleeper bays "
                    f"(track.sleeper_spacing = {t['sleeper_spacing']:g} m): the supports "
                    "continue the sleeper grid"))
    if not case["modal.fix_rail_rotations_at_pads"]:
        out.append(("modal.fix_rail_rotations_at_pads", False,
                    "track.ends = 'supported' needs true: without rigid rail ends nothing "
                    "holds the rail's torsion (a singular stiffness matrix)"))
    if case["mesh.file"]:
        out.append(("track.ends", "supported",
                    f"needs the generated mesh (mesh.file = {case['mesh.file']!r} brings its "
                    "own rails); allowed with mesh.file: 'rigid'"))
    lo, hi = g["x0"], g["x4"] + t["rigid_length"]
    if not lo <= v["x_start"] < hi:
        out.append(("vehicle.x_start", v["x_start"],
                    f"must lie on the modelled rail [{lo:g}, {hi:g}) m with track.ends = "
                    "'supported' (the train's other wheels may trail behind it)"))
    if v["x_end"] and v["x_end"] > hi:
        out.append(("vehicle.x_end", v["x_end"],
                    f"must lie on the modelled rail (<= {hi:g} m, the end of the supported "
                    "exit rail) with track.ends = 'supported', or 0 (that end)"))
    return out
