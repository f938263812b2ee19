"""Block decomposition of the thesis model (pure Python, no gmsh).

The model is cut by planes at every sleeper, every building face and every
layer boundary into axis-aligned blocks; each block is a hexahedral gmsh
volume meshed as a structured (transfinite) grid. The number of divisions of
an interval depends only on the interval, so neighbouring blocks always share
their face grids: the mesh is conformal by construction. The embankment
shoulders are blocks whose outer vertices are moved onto the 1:1 slopes.

Two sets of divisions (``mesh.layout``):

``"thesis"``
    The divisions of the APDL script (Appendix A), which reproduce the element
    ranges of Appendix B exactly: ballast 2,688, subballast 2,688, track-zone
    subgrade 12,288, concrete 4,248 and building-side subgrade 19,968, i.e.
    41,880 hexahedra (see :data:`THESIS_DIVISIONS` and ``docs/thesis.md``). Along
    x: 2 elements per 0.6 m bay, 4 in line with the building (96 in all); across
    the track: 4 between the rails, 2 to each sleeper end, 3 over each shoulder,
    2 over the 4 m beyond the embankment on the far side, 5 over the 5.65 m
    between the embankment toe and the building, 0.3 m in line with the
    building, 3 over the 12 m beyond it; vertically 0.6 m in the subgrade (8 over
    its 4.8 m) and 2 elements through each embankment layer. Extensions of the
    domain (``domain.extra_*``) take the same sizes as the zone they extend.
``"refined"``
    The sizes of the ``mesh`` keys (``size_far`` across the track in the far
    field, ``size_deep`` below the building base, ``layer_elements`` through
    the embankment layers): a finer far field for engineering runs.

``mesh.refinement`` multiplies every element count of either layout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..config import Case
from ..fem.boundary import wave_speeds
from ..site import (
    building_turn,
    embankment_toe,
    placed_plan,
    soil_layers,
    solid_material,
    track_lift,
)
from .building import Building

_TOL = 1e-9
#: The plan ``(x_lo, x_hi, y_lo, y_hi)`` of a site without a building: empty (no interval
#: lies inside it, every one beside it).
NO_PLAN = (math.inf, -math.inf, -math.inf, -math.inf)


def _merge(values: list[float]) -> np.ndarray:
    v = np.sort(np.asarray(values, dtype=float))
    keep = np.concatenate(([True], np.diff(v) > 1e-7))
    return v[keep]


@dataclass
class Block:
    """One structured block: intervals ``i`` (x), ``j`` (y) and z from ``z0`` to ``z1``."""

    i: int
    j: int
    z0: float
    z1: float
    part: str


@dataclass
class Layout:
    """Breakpoints, divisions and labelled blocks of the model.

    Attributes
    ----------
    xb, yb
        Breakpoints along x and y.
    nx, ny
        Element divisions of each x / y interval.
    blocks
        The non-empty blocks.
    zdiv
        Divisions of each z interval, keyed by ``(z0, z1)`` rounded.
    sleeper_x
        x of every sleeper.
    rail_x
        x of the rail nodes that bound a rail *curve* (rigid ends and sleepers).
    rail_div
        Rail elements per sleeper bay.
    end_div
        Rail elements of each end section beyond the soil box (``track.ends =
        'supported'``: ``rail_div`` per bay; 0: the rigid rail, one element).
    rail_y
        y of every rail, increasing (track 1's two, then track 2's).
    sleeper_y
        (n_tracks, 4) y of each track's sleeper ends and rail seats.
    """

    xb: np.ndarray
    yb: np.ndarray
    nx: np.ndarray
    ny: np.ndarray
    blocks: list[Block]
    zdiv: dict[tuple[float, float], int]
    sleeper_x: np.ndarray
    rail_y: tuple[float, ...]
    rail_z: float
    rail_div: int
    rigid_ends: tuple[float, float]
    sleeper_y: np.ndarray
    sleeper_z: float
    end_div: int = 0
    deform: dict = field(default_factory=dict)
    bounds: tuple[float, float, float, float, float, float] = (0, 0, 0, 0, 0, 0)
    probes: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    probe_roles: dict[str, str] = field(default_factory=dict)

    def vertex(self, i: int, j: int, z: float) -> tuple[float, float, float]:
        """Coordinates of grid vertex (x index, y index, z), with shoulder slopes applied."""
        y = float(self.yb[j])
        hw = self.deform.get((j, round(z, 9)))
        if hw is not None:
            y = hw
        return float(self.xb[i]), y, float(z)


def _ndiv(length: float, size: float, refinement: float) -> int:
    return max(1, int(round(length * refinement / size - 1e-9)))


def resolved_frequency(case: Case) -> float:
    """The frequency the soil mesh must resolve: ``mesh.wavelength_hz``, else ``modal.f_max``
    (0: none)."""
    return case["mesh.wavelength_hz"] or case["modal.f_max"]


def shear_wave_speed(mat: dict[str, float]) -> float:
    """c_S of a material's ``E``, ``nu``, ``rho`` (:func:`railvib_hpc.fem.boundary.wave_speeds`)."""
    return float(wave_speeds(mat["E"], mat["nu"], mat["rho"])[1])


def _resolving_divisions(n: int, length: float, h_max: float, refinement: float) -> int:
    """``n``, or more so that the elements are at most ``h_max / refinement`` long."""
    if not np.isfinite(h_max):
        return n
    return max(n, int(np.ceil(length * refinement / h_max - 1e-9)))


#: Elements across the ring of soil twisted round a turned building, at least, for a twist
#: of 45 deg (in proportion below it): with one or two, a single element spans most of the
#: ring's width and takes most of the twist (on the thesis site the 4 m deep strips beyond
#: the building allowed 27.7 deg; with six, 34.8 deg; with ten, 36.2: docs/sites.md).
TWIST_RING_ELEMENTS = 6


def _ring_divisions(n: np.ndarray, lines: np.ndarray, centre: float, r_out: float,
                    h_ring: float) -> np.ndarray:
    """``n``, or more so that the intervals of ``lines`` within ``r_out`` of ``centre`` have
    elements at most ``h_ring`` long."""
    return np.array([_resolving_divisions(k, b - a, h_ring, 1.0)
                     if b > centre - r_out and a < centre + r_out else k
                     for k, a, b in zip(n, lines[:-1], lines[1:])])


def wavelength_size(case: Case, material: str) -> float:
    """Largest element size that keeps ``mesh.elements_per_wavelength`` elements per shear
    wavelength of ``material`` at ``mesh.wavelength_hz`` (inf: no wavelength sizing)."""
    n, f = case["mesh.elements_per_wavelength"], case["mesh.wavelength_hz"]
    if n <= 0 or f <= 0:
        return float("inf")
    return shear_wave_speed(solid_material(case, material)) / (f * n)


#: Divisions of the APDL script (Appendix A) that differ from the ``mesh`` keys' defaults,
#: as element sizes [m] so that extended domains keep them. Each cites its APDL line.
THESIS_DIVISIONS: dict[str, float] = {
    # LSEL,S,LINE,,Line_SLP_END+40,Line_SLP_END+41,1 / LESIZE,ALL,,,2: YS1..YS0 = 4 m
    "far_track_side": 2.0,
    # LSEL,S,LINE,,LINE_SOIL+10,LINE_SOIL+11,1 / LESIZE,ALL,,,5: YS2..YS1 = 5.65 m
    "toe_to_building": 5.65 / 5,
    # LSEL,S,LINE,,LINE_SOIL+2,LINE_SOIL+4,2 / LESIZE,ALL,,,3: YS4..YS3 = 12 m
    "beyond_building": 12.0 / 3,
    # LSEL,...,LENG,,Z1-Z0 / LESIZE,ALL,,,8 and the building-side verticals LESIZE,ALL,0.6
    "vertical_soil": 0.6,
    # LESIZE,ALL,,,2 on the vertical lines of the ballast and subballast at X1
    "layer_elements": 2,
}


@dataclass(frozen=True)
class _CrossSection:
    """The track across y: the track centre lines (track 1 at y = 0, track 2 track.spacing
    further from the building), half the sleeper length and the gauge, the embankment's toes
    on the ground (near side ``-toe``, far side ``toe_far``) and the fill's lift; without a
    track (``track.count = 0``) no centre line and no toe."""

    centres: tuple[float, ...]
    half_sleeper: float
    half_gauge: float
    toe: float
    toe_far: float
    lift: float

    @classmethod
    def of_case(cls, case: Case) -> _CrossSection:
        t = case["track"]
        # one embankment carries both tracks; a fill (track.embankment_height) lifts the
        # track bed by lift, its sides sloping in to the subballast's base half-width |YS1|
        if not t["count"]:             # the bare soil: no track, no embankment
            return cls((), t["sleeper_length"] / 2, t["gauge"] / 2, 0.0, 0.0, 0.0)
        centres = (0.0,) + ((t["spacing"],) if t["count"] == 2 else ())
        lift = track_lift(case)
        toe = embankment_toe(case)
        return cls(centres, t["sleeper_length"] / 2, t["gauge"] / 2, toe, centres[-1] + toe,
                   lift)


@dataclass(frozen=True)
class _Levels:
    """The z levels of the layout: below the ground (soil and basement), the embankment's
    layers above it (with their parts) and the building above the ground."""

    below: np.ndarray
    embank: list[float]
    embank_parts: tuple[str, ...]
    above: np.ndarray


def build_layout(case: Case) -> Layout:
    """Compute the block decomposition for a validated case."""
    g, t, m, d = (case[s] for s in ("geometry", "track", "mesh", "domain"))
    r = m["refinement"]
    # the building's lines: footing, column and wall faces (mesh.building), and its plan,
    # both turned by building.rotation's whole quarter turns (building.present = false:
    # none, the free field alone)
    bldg = Building.of_case(case) if case["building.present"] else None
    plan = placed_plan(case) if bldg is not None else NO_PLAN
    cross = _CrossSection.of_case(case)
    bounds = (g["x1"] - d["extra_length"], g["x4"] + d["extra_length"],
              g["ys4"] - d["extra_width"], g["ys0"], g["z0"] - d["extra_depth"], g["z1"])
    sp = t["sleeper_spacing"]
    sleeper_x = g["x1"] + sp * np.arange(int(round(t["rail_length"] / sp)) + 1)
    xb, yb = _lines(case, bldg, cross, sleeper_x, bounds)
    layers = soil_layers(case)
    nx, ny = _horizontal_divisions(case, xb, yb, plan, cross, layers)
    levels = _levels(case, bldg, layers, cross.lift, bounds[4])
    zdiv = _vertical_divisions(case, levels, layers)
    blocks = _blocks(case, bldg, plan, xb, yb, levels, cross, layers)
    probes, probe_roles = _named_probes(case, bldg, plan, cross, bounds)
    # track.count = 0: the bare soil (no rails, sleepers, pads, and none of their grid
    # lines: the grid is the soil's, _lines)
    centres = cross.centres
    hs, hg, lift = cross.half_sleeper, cross.half_gauge, cross.lift
    rail_div = max(1, round(m["rail_elements_per_bay"] * r))
    end_div = (rail_div * max(1, round(t["rigid_length"] / sp))
               if t["ends"] == "supported" else 0)
    return Layout(
        xb=xb, yb=yb, nx=nx, ny=ny, blocks=blocks, zdiv=zdiv, sleeper_x=sleeper_x,
        rail_y=tuple(c + s * hg for c in centres for s in (-1, 1)), rail_z=g["z4"] + lift,
        rail_div=rail_div, rigid_ends=(g["x0"], g["x4"] + t["rigid_length"]),
        sleeper_y=np.array([[c - hs, c - hg, c + hg, c + hs] for c in centres]).reshape(-1, 4),
        sleeper_z=g["z3"] + lift, end_div=end_div,
        deform=_shoulder_slopes(g, yb, cross) if centres else {},
        bounds=bounds, probes=probes, probe_roles=probe_roles)


def _lines(case: Case, bldg: Building | None, cross: _CrossSection, sleeper_x: np.ndarray,
           bounds: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The breakpoints along x (domain ends, sleepers, building) and y (domain edges,
    embankment toes, sleeper ends and rails of every track, building, the measures' faces);
    without a track no sleeper, rail or toe line, but the load's path and the probe lines
    (:func:`_bare_soil_lines`)."""
    g = case["geometry"]
    xmin, xmax, ymin = bounds[:3]
    track = bool(cross.centres)
    own_x = bldg.x_lines() if bldg is not None else []
    own_y = bldg.y_lines() if bldg is not None else []
    tr, wib = case["trench"], case["wib"]
    measure_y = []
    if tr["width"] > 0:            # the trench's faces (also with type 'none': same mesh)
        measure_y += [-tr["distance"], -tr["distance"] - tr["width"]]
    if wib["width"] > 0:
        measure_y += [-wib["width"] / 2, wib["width"] / 2]
    if not track:
        xb = _merge([xmin, xmax, *own_x])
        yb = _merge([ymin, g["ys0"], *own_y, *measure_y])
        return _bare_soil_lines(case, xb, yb)
    track_y = [c + s * w for c in cross.centres for w in (cross.half_sleeper, cross.half_gauge)
               for s in (-1, 1)]
    xb = _merge([xmin, xmax, *sleeper_x, *own_x])
    yb = _merge([ymin, g["ys0"], -cross.toe, cross.toe_far, *track_y, *own_y, *measure_y])
    return xb, yb


#: Smallest distance, in soil element sizes, between a line the bare soil's grid adds for
#: the load's path or a probe line and the grid's other lines: a closer one would make an
#: element shorter than half the size, which halves the explicit engines' stable step
#: (a point left off the lines is interpolated in its element, as every probe can be).
MIN_LINE_GAP = 0.5


def bare_soil_size(case: Case) -> float:
    """The horizontal element size of the bare soil's grid (``track.count = 0``) outside the
    building [m], before ``mesh.refinement``: ``mesh.size_far`` (layout 'refined') or the
    thesis layout's soil size between the track and the building (:data:`THESIS_DIVISIONS`,
    'toe_to_building'); the wavelength sizing may refine it."""
    if case["mesh.layout"] == "refined":
        return float(case["mesh.size_far"])
    return THESIS_DIVISIONS["vertical_soil"]


def _bare_soil_lines(case: Case, xb: np.ndarray, yb: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The soil's own lines and, where they keep :data:`MIN_LINE_GAP` from them, the load's
    path (``load.y``) and the probe lines' positions (x, and y of every point), so that the
    load runs on a line of nodes and the probes sit on nodes."""
    from ..site import line_probes

    gap = MIN_LINE_GAP * bare_soil_size(case) / case["mesh.refinement"]
    points = list(line_probes(case).values())
    for axis, lines, wanted in ((0, xb, [p.point[0] for p in points]),
                                (1, yb, [case["load.y"], *(p.point[1] for p in points)])):
        keep = list(lines)
        for v in wanted:
            if lines[0] < v < lines[-1] and min(abs(v - w) for w in keep) >= gap - _TOL:
                keep.append(float(v))
        if axis == 0:
            xb = _merge(keep)
        else:
            yb = _merge(keep)
    return xb, yb


def _y_divisions(m: dict, y0: float, y1: float, plan: tuple[float, float, float, float],
                 cross: _CrossSection) -> int:
    """Divisions of the y interval ``[y0, y1]`` with the ``mesh`` keys' sizes."""
    r = m["refinement"]
    _, _, plan_ys3, plan_ys2 = plan
    hs, hg = cross.half_sleeper, cross.half_gauge
    c = min(cross.centres, key=lambda v: abs(0.5 * (y0 + y1) - v))    # the nearest track
    if y0 - c >= -hg - _TOL and y1 - c <= hg + _TOL:
        return max(1, round(m["sleeper_middle_elements"] * r))
    if y0 - c >= -hs - _TOL and y1 - c <= hs + _TOL:
        return max(1, round(m["sleeper_outer_elements"] * r))
    if y0 >= -cross.toe - _TOL and y1 <= cross.toe_far + _TOL:
        return max(1, round(m["shoulder_elements"] * r))
    if y0 >= plan_ys3 - _TOL and y1 <= plan_ys2 + _TOL:
        return _ndiv(y1 - y0, m["size_building_y"], r)
    return _ndiv(y1 - y0, m["size_far"], r)


def _y_divisions_thesis(m: dict, y0: float, y1: float, plan: tuple[float, float, float, float],
                        cross: _CrossSection) -> int:
    """Divisions of the y interval ``[y0, y1]`` of the APDL script (:data:`THESIS_DIVISIONS`)."""
    r = m["refinement"]
    _, _, plan_ys3, plan_ys2 = plan
    if y0 >= -cross.toe - _TOL:
        if y1 <= cross.toe_far + _TOL:
            return _y_divisions(m, y0, y1, plan, cross)
        return _ndiv(y1 - y0, THESIS_DIVISIONS["far_track_side"], r)
    if y0 >= plan_ys2 - _TOL:
        return _ndiv(y1 - y0, THESIS_DIVISIONS["toe_to_building"], r)
    if y0 >= plan_ys3 - _TOL:
        return _y_divisions(m, y0, y1, plan, cross)
    return _ndiv(y1 - y0, THESIS_DIVISIONS["beyond_building"], r)


def _horizontal_divisions(case: Case, xb: np.ndarray, yb: np.ndarray,
                          plan: tuple[float, float, float, float], cross: _CrossSection,
                          layers: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """The element divisions of every x and y interval: the layout's sizes (without a track
    the soil's, :func:`bare_soil_size`), refined for the softest soil's wavelength and
    across the soil twisted round a turned building."""
    m = case["mesh"]
    r = m["refinement"]
    sp = case["track.sleeper_spacing"]
    plan_x2, plan_x3, plan_ys3, plan_ys2 = plan
    h_bldg = sp / m["soil_elements_per_bay_building"]
    if cross.centres:
        h_track = sp / m["soil_elements_per_bay"]
        ydiv = _y_divisions_thesis if m["layout"] == "thesis" else _y_divisions
        ny = np.array([ydiv(m, y0, y1, plan, cross) for y0, y1 in zip(yb[:-1], yb[1:])])
    else:                         # the bare soil: a grid of the soil's own size
        h_track = bare_soil_size(case)
        ny = np.array([_ndiv(y1 - y0, m["size_building_y"] if (
            y0 >= plan_ys3 - _TOL and y1 <= plan_ys2 + _TOL) else h_track, r)
            for y0, y1 in zip(yb[:-1], yb[1:])])
    nx = np.array([
        _ndiv(x1 - x0, h_bldg if (x0 >= plan_x2 - _TOL and x1 <= plan_x3 + _TOL) else h_track, r)
        for x0, x1 in zip(xb[:-1], xb[1:])])

    # wavelength sizing (mesh.elements_per_wavelength), horizontally: the softest soil (one
    # grid for all layers)
    soils = [x["part"] for x in layers] or ["subgrade"]
    bed = ("ballast", "subballast", *(("fill",) if cross.lift > 0 else ())) \
        if cross.centres else ()
    h_soft = min(wavelength_size(case, name) for name in (*soils, *bed))
    nx = np.array([_resolving_divisions(n, ln, h_soft, r) for n, ln in zip(nx, np.diff(xb))])
    ny = np.array([_resolving_divisions(n, ln, h_soft, r) for n, ln in zip(ny, np.diff(yb))])
    # a twisted building (building.rotation beyond whole quarter turns): the soil across
    # the twisted ring TWIST_RING_ELEMENTS elements deep at a 45 deg twist, in proportion
    # to the twist below it, so that no element carries a large share of the twist
    # (mesh.turn bounds the elements' corner angles)
    turn = building_turn(case)
    if turn.angle != 0 and turn.r_out > turn.r_in:
        n_ring = max(1, math.ceil(TWIST_RING_ELEMENTS * abs(turn.angle) / (math.pi / 4)
                                  - 1e-9))
        h_ring = (turn.r_out - turn.r_in) / n_ring
        nx = _ring_divisions(nx, xb, turn.centre[0], turn.r_out, h_ring)
        ny = _ring_divisions(ny, yb, turn.centre[1], turn.r_out, h_ring)
    return nx, ny


def _soil_part(layers: list[dict], z: float) -> str:
    """The soil part at level ``z`` below the ground."""
    for x in layers:
        if z > x["z_bottom"]:
            return x["part"]
    return layers[-1]["part"] if layers else "subgrade"


def _ground_part(case: Case, layers: list[dict], y: float, z: float) -> str | None:
    """The part of a block centred at ``(y, z)`` below the ground outside the building:
    the trench (None when open), the wave-impeding block, or the soil."""
    z1 = case["geometry.z1"]
    tr, wib = case["trench"], case["wib"]
    if tr["type"] != "none" and -tr["distance"] - tr["width"] < y < -tr["distance"] \
            and z > z1 - tr["depth"]:
        return None if tr["type"] == "open" else "trench_fill"
    if wib["type"] != "none" and abs(y) < wib["width"] / 2 and \
            z1 - wib["depth"] - wib["thickness"] < z < z1 - wib["depth"]:
        return "wib"
    return _soil_part(layers, z)


def _levels(case: Case, bldg: Building | None, layers: list[dict], lift: float,
            zbot: float) -> _Levels:
    """The z levels: soil layers, measures and basement below the ground, the embankment's
    layers and the building's storeys above it."""
    g = case["geometry"]
    tr, wib = case["trench"], case["wib"]
    interfaces = [x["z_bottom"] for x in layers[:-1]]
    if tr["width"] > 0:
        interfaces.append(g["z1"] - tr["depth"])
    if wib["width"] > 0:
        interfaces += [g["z1"] - wib["depth"], g["z1"] - wib["depth"] - wib["thickness"]]
    own_below = bldg.levels_below() if bldg is not None else []
    below = _merge([zbot, g["z0"], *own_below, g["z1"], *interfaces])
    below = below[(below <= g["z1"] + _TOL) & (below >= zbot - _TOL)]
    embank = [g["z1"], *([g["z1"] + lift] if lift > 0 else []), g["z2"] + lift, g["z3"] + lift]
    embank_parts = (*(("fill",) if lift > 0 else ()), "subballast", "ballast")
    above = _merge([g["z1"], *(bldg.levels_above() if bldg is not None else [])])
    above = above[above >= g["z1"] - _TOL]
    return _Levels(below, embank, embank_parts, above)


def _zkey(z0: float, z1: float) -> tuple[float, float]:
    """The key of the z interval ``[z0, z1]`` in :attr:`Layout.zdiv`."""
    return round(z0, 9), round(z1, 9)


def _vertical_divisions(case: Case, levels: _Levels,
                        layers: list[dict]) -> dict[tuple[float, float], int]:
    """The element divisions of every z interval, each refined for its layer's wavelength."""
    m = case["mesh"]
    r = m["refinement"]
    thesis = m["layout"] == "thesis"
    # the soil above the building base takes the building's vertical size (refined layout)
    zbb = case["geometry.zbb"] if case["building.present"] else math.inf
    below, embank, above = levels.below, levels.embank, levels.above
    zdiv: dict[tuple[float, float], int] = {}
    for z0, z1 in zip(below[:-1], below[1:]):
        if thesis:
            size = THESIS_DIVISIONS["vertical_soil"]
        else:
            size = m["size_deep"] if z1 <= zbb + _TOL else m["size_building_z"]
        # vertically: the layer's own wavelength
        zdiv[_zkey(z0, z1)] = _resolving_divisions(
            _ndiv(z1 - z0, size, r), z1 - z0,
            wavelength_size(case, _soil_part(layers, 0.5 * (z0 + z1))), r)
    n_layer = THESIS_DIVISIONS["layer_elements"] if thesis else m["layer_elements"]
    for (z0, z1), part in zip(zip(embank[:-1], embank[1:]), levels.embank_parts):
        n = (_ndiv(z1 - z0, THESIS_DIVISIONS["vertical_soil"] if thesis else m["size_deep"], r)
             if part == "fill" else max(1, round(n_layer * r)))
        zdiv[_zkey(z0, z1)] = _resolving_divisions(n, z1 - z0, wavelength_size(case, part), r)
    for z0, z1 in zip(above[:-1], above[1:]):
        zdiv[_zkey(z0, z1)] = _ndiv(z1 - z0, m["size_building_z"], r)
    return zdiv


def _blocks(case: Case, bldg: Building | None, plan: tuple[float, float, float, float],
            xb: np.ndarray, yb: np.ndarray, levels: _Levels, cross: _CrossSection,
            layers: list[dict]) -> list[Block]:
    """Every non-empty block, its part given by its centre."""
    plan_x2, plan_x3, plan_ys3, plan_ys2 = plan
    zbb = case["geometry.zbb"]
    below, embank, above = levels.below, levels.embank, levels.above
    blocks: list[Block] = []
    for i in range(len(xb) - 1):
        xc = 0.5 * (xb[i] + xb[i + 1])
        in_x = plan_x2 < xc < plan_x3
        for j in range(len(yb) - 1):
            yc = 0.5 * (yb[j] + yb[j + 1])
            in_plan = in_x and plan_ys3 < yc < plan_ys2
            for z0, z1 in zip(below[:-1], below[1:]):
                zc = 0.5 * (z0 + z1)
                part = (bldg.part(xc, yc, zc) if in_plan and zc > zbb
                        else _ground_part(case, layers, yc, zc))
                if part:
                    blocks.append(Block(i, j, float(z0), float(z1), part))
            if -cross.toe < yc < cross.toe_far and case["track.count"]:
                for (z0, z1), part in zip(zip(embank[:-1], embank[1:]), levels.embank_parts):
                    blocks.append(Block(i, j, float(z0), float(z1), part))
            if in_plan:
                for z0, z1 in zip(above[:-1], above[1:]):
                    part = bldg.part(xc, yc, 0.5 * (z0 + z1))
                    if part:
                        blocks.append(Block(i, j, float(z0), float(z1), part))
    return blocks


def _shoulder_slopes(g: dict, yb: np.ndarray,
                     cross: _CrossSection) -> dict[tuple[int, float], float]:
    """The shoulder slopes: the outer embankment vertices above Z1, moved to their slopes
    (:attr:`Layout.deform`)."""
    lift = cross.lift
    jlo = int(np.argmin(abs(yb + cross.toe)))
    jhi = int(np.argmin(abs(yb - cross.toe_far)))
    deform = {}
    slopes = (*(((g["z1"] + lift, -g["ys1"]),) if lift > 0 else ()),
              (g["z2"] + lift, g["ballast_bottom_half_width"]),
              (g["z3"] + lift, g["ballast_top_half_width"]))
    for z, hw in slopes:
        deform[(jlo, round(z, 9))] = -hw
        deform[(jhi, round(z, 9))] = cross.centres[-1] + hw
    return deform


def _named_probes(case: Case, bldg: Building | None, plan: tuple[float, float, float, float],
                  cross: _CrossSection, bounds: tuple[float, ...]
                  ) -> tuple[dict[str, tuple[float, float, float]], dict[str, str]]:
    """The named probes: the building's and the ground's, each point with its role
    (:data:`railvib_hpc.schema.PROBE_ROLES`). Without a building (``building.present =
    false``) the ground's alone, across the soil's middle (:func:`_free_field_probes`)."""
    g, tr = case["geometry"], case["trench"]
    if bldg is None:
        located = _free_field_probes(case, cross, bounds)
    else:
        _, _, plan_ys3, plan_ys2 = plan
        # (without a track the ground probes stay where the track's toes would be)
        toe, toe_far = ((cross.toe, cross.toe_far) if cross.centres
                        else (embankment_toe(case),) * 2)
        # the ground between the embankment and the building; with a trench's lines (any
        # type, so that a measure and its same-mesh reference share the point) in front of
        # the trench when the middle would fall into it
        y_mid = 0.5 * (-toe + plan_ys2)
        if tr["width"] > 0 and -tr["distance"] - tr["width"] <= y_mid <= -tr["distance"]:
            y_mid = -0.5 * (toe + tr["distance"])
        located = {
            **bldg.probes(),
            "ground_toe": ((g["xbb"], -toe, g["z1"]), "ground"),
            "ground_mid": ((g["xbb"], y_mid, g["z1"]), "ground"),
            "ground_building": ((g["xbb"], plan_ys2, g["z1"]), "ground"),
            "ground_far": ((g["xbb"], 0.5 * (plan_ys3 + bounds[2]), g["z1"]), "ground"),
            "ground_opposite": ((g["xbb"], 0.5 * (toe_far + g["ys0"]), g["z1"]), "ground"),
        }
    probes = {name: point for name, (point, _) in located.items()}
    probe_roles = {name: role for name, (_, role) in located.items()}
    return probes, probe_roles


def _free_field_probes(case: Case, cross: _CrossSection, bounds: tuple[float, ...]
                       ) -> dict[str, tuple[tuple[float, float, float], str]]:
    """The ground probes of a site without a building, at the soil's middle along x: at the
    embankment's toe (with a track), halfway from it to the soil's edge on the side y < 0
    (``ground_mid``) and to the edge on the other side (``ground_opposite``); a trench's
    middle moves ``ground_mid`` in front of it, as with a building."""
    g, tr = case["geometry"], case["trench"]
    x = 0.5 * (bounds[0] + bounds[1])
    z = g["z1"]
    y_mid = 0.5 * (-cross.toe + bounds[2])
    if tr["width"] > 0 and -tr["distance"] - tr["width"] <= y_mid <= -tr["distance"]:
        y_mid = -0.5 * (cross.toe + tr["distance"])
    out = {"ground_mid": ((x, y_mid, z), "ground"),
           "ground_opposite": ((x, 0.5 * (cross.toe_far + g["ys0"]), z), "ground")}
    if cross.centres:
        out = {"ground_toe": ((x, -cross.toe, z), "ground"), **out}
    return out
