"""Cross-key checks of the site's layout: the building (its turn, plan, frame and levels),
the elastic interfaces, the mitigation measures, the soil layers and the probe lines.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from ..schema import MIN_SOIL_LAYER_THICKNESS, CaseView
from ..site import (
    MAX_TWIST_SHEAR,
    building_turn,
    embankment_toe,
    line_probe_name,
    line_ranges,
    line_x,
    placed_plan,
    quarter_turns,
    slab_bases,
)
from .values import ALL_KEYS, _close


def _check_line_points(case: CaseView) -> list[tuple[str, Any, str]]:
    """Every point of a probe line on the ground of the model: along the soil, between
    the embankment and the soil's edge, outside the building and an open trench
    (:func:`railvib_hpc.site.line_ranges`); distinct probe names."""
    out: list[tuple[str, Any, str]] = []
    g, d = case["geometry"], case["domain"]
    x_lo, x_hi = g["x1"] - d["extra_length"], g["x4"] + d["extra_length"]
    seen: set[str] = set()
    for k, entry in enumerate(case["probes.line"]):
        where = f"probes.line[{k + 1}]"
        x = line_x(case, entry)
        if not x_lo <= x <= x_hi:
            out.append((f"{where}.x", x, f"must lie along the soil, {x_lo:g} to {x_hi:g} m "
                        "(geometry.x1 - domain.extra_length to geometry.x4 + "
                        "domain.extra_length)"))
            continue
        ranges = line_ranges(case, x, entry["side"])
        bad = [v for v in entry["distances"]
               if not any(lo - 1e-9 <= v <= hi + 1e-9 for lo, hi in ranges)]
        if bad:
            allowed = " or ".join(f"{lo:g} to {hi:g} m" for lo, hi in ranges) or "none"
            out.append((f"{where}.distances", bad[0] if len(bad) == 1 else bad,
                        f"outside the soil's ground on the {entry['side']} side at x = {x:g} "
                        f"m: allowed {allowed} from the centreline of track 1 (the ground "
                        "between the embankment toe and the soil's edge, outside the "
                        "building's plan and an open trench)"))
        names = [line_probe_name(entry["name"], v) for v in entry["distances"]]
        clash = sorted({n for n in names if n in seen or names.count(n) > 1})
        if clash:
            out.append((f"{where}.distances", entry["distances"],
                        f"the probe names {clash} occur twice: give distances (or line "
                        "names) that differ in their first 6 digits"))
        seen.update(names)
    return out


def _check_building(case: CaseView) -> list[tuple[str, Any, str]]:
    """The building's turn, plan, frame and levels (``building.present``)."""
    g, b = case["geometry"], case["building"]
    out = _check_rotation(case)
    # building: its plan is the excavation [X2, X3] x [YS3, YS2]
    length, width = g["x3"] - g["x2"], g["ys2"] - g["ys3"]
    if not _close(g["xbb"], 0.5 * (g["x2"] + g["x3"])):
        out.append(("geometry.xbb", g["xbb"],
                    f"must be the centre of [X2, X3] = {0.5 * (g['x2'] + g['x3']):g} m (it is "
                    "derived: leave it out)"))
    if not _close(g["ybb"], 0.5 * (g["ys2"] + g["ys3"])):
        out.append(("geometry.ybb", g["ybb"],
                    f"must be the centre of [YS3, YS2] = {0.5 * (g['ys2'] + g['ys3']):g} m (it "
                    "is derived: leave it out)"))
    if not g["z0"] < g["zbb"] < g["z1"]:
        out.append(("geometry.zbb", g["zbb"],
                    f"the building base must lie inside the subgrade: Z0 = {g['z0']:g} < ZBB < "
                    f"Z1 = {g['z1']:g} m"))
    fs, cs, wt = b["footing_size"], b["column_size"], b["wall_thickness"]
    out.extend(_check_spans(case, "x", length, "X3 - X2"))
    out.extend(_check_spans(case, "y", width, "YS2 - YS3"))
    if not cs < fs:
        out.append(("building.column_size", cs,
                    f"must be smaller than building.footing_size = {fs:g} m"))
    if not _close(b["beam_width"], cs):
        out.append(("building.beam_width", b["beam_width"],
                    f"beams run between the column faces: must equal column_size = {cs:g} m"))
    if not wt <= (fs - cs) / 2 + 1e-12:
        out.append(("building.wall_thickness", wt,
                    f"the wall must not overlap the columns: wall_thickness <= "
                    f"(footing_size - column_size)/2 = {(fs - cs) / 2:g} m"))
    out.extend(_check_levels(case))
    if g["x2"] <= g["x1"] or g["x3"] >= g["x4"]:
        out.append(("geometry.x2", g["x2"], "the building must lie inside the soil (X1 < X2, "
                    "X3 < X4)"))
    out.extend(_check_turned_plan(case))
    return out


def _check_rotation(case: CaseView) -> list[tuple[str, Any, str]]:
    """A turned building: a generated mesh, and room for the soil round it to twist by the
    turn's rest beyond whole quarter turns."""
    angle = case["building.rotation"]
    if angle == 0:
        return []
    if case["mesh.file"]:
        return [("building.rotation", angle, "turns the generated mesh's building; it cannot "
                 "turn mesh.file's (leave it at 0 or leave mesh.file out)")]
    turn = building_turn(case)
    if turn.angle == 0:
        return []
    k, _ = quarter_turns(angle)
    rest = (f"{math.degrees(turn.angle):+.4g} deg from the nearest whole quarter turn, "
            f"{90 * k} deg, twists the soil")
    if not turn.r_out > turn.r_in:
        return [("building.rotation", angle,
                 f"{rest}, and there is no room for it: the building's corners "
                 f"({turn.r_in:.4g} m from its centre) reach {turn.bound} ({turn.r_out:.4g} m "
                 "from it); turn it by whole quarter turns only (0, 90, 180, 270 deg), move "
                 "it away or widen the domain")]
    limit = math.degrees(turn.max_angle)
    if abs(turn.angle) > turn.max_angle * (1 + 1e-12):
        return [("building.rotation", angle,
                 f"{rest}; at most +-{limit:.3g} deg here: the soil between the building's "
                 f"corners ({turn.r_in:.4g} m from its centre) and {turn.bound} "
                 f"({turn.r_out:.4g} m from it) twists to meet the track-parallel mesh, with "
                 f"shear <= {MAX_TWIST_SHEAR:.3g} (corner angles 25-155 deg); move the "
                 "building away or widen the domain")]
    return []


def _check_turned_plan(case: CaseView) -> list[tuple[str, Any, str]]:
    """A building turned by an odd number of quarter turns: its plan, length and width
    exchanged, still inside the soil and clear of the embankment."""
    k, _ = quarter_turns(case["building.rotation"])
    if k % 2 == 0:
        return []
    g = case["geometry"]
    x_lo, x_hi, y_lo, y_hi = placed_plan(case)
    toe = embankment_toe(case)
    room = [(x_lo > g["x1"], f"it reaches x = {x_lo:g} m, past X1 = {g['x1']:g} m"),
            (x_hi < g["x4"], f"it reaches x = {x_hi:g} m, past X4 = {g['x4']:g} m"),
            (y_lo > g["ys4"], f"it reaches y = {y_lo:g} m, past YS4 = {g['ys4']:g} m"),
            (-y_hi > toe, f"its face comes to {-y_hi:g} m from the track, within the "
                          f"embankment toe at {toe:g} m")]
    short = [text for ok, text in room if not ok]
    if short:
        return [("building.rotation", case["building.rotation"],
                 f"the plan turned by {k} quarter turn{'s' if k > 1 else ''} ({x_hi - x_lo:g} "
                 f"x {y_hi - y_lo:g} m about its centre) must lie inside the soil and clear of "
                 f"the embankment: {'; '.join(short)}; move the building or widen the "
                 "domain")]
    return []


def _check_interfaces(case: CaseView) -> list[tuple[str, Any, str]]:
    """The elastic interfaces cut the generated mesh: not a user's ``mesh.file``; the
    under-sleeper pads bear on a sleeper's underside, narrower than the sleeper spacing
    (wider, the pads of neighbouring sleepers would overlap and their area, ``usp.width``
    times the sleeper length, would count ground that no sleeper covers)."""
    spacing = case["track.sleeper_spacing"]
    if case["usp.modulus"] > 0 and not case["usp.width"] < spacing:
        return [("usp.width", case["usp.width"],
                 f"the sleeper's bearing width must be less than track.sleeper_spacing = "
                 f"{spacing:g} m (the sleepers would overlap; the thesis's sleeper is "
                 f"{ALL_KEYS['usp.width'].default:g} m wide)")]
    if not case["mesh.file"]:
        return []
    return [(f"{kind}.modulus", case[f"{kind}.modulus"],
             "an elastic interface cuts the generated mesh; it cannot be added to mesh.file "
             "(set the modulus to 0 or leave mesh.file out)")
            for kind in ("usp", "ballast_mat", "isolation") if case[f"{kind}.modulus"] > 0]


def _check_levels(case: CaseView) -> list[tuple[str, Any, str]]:
    """The building's levels bottom up: footing, grade beam, ground, then per storey the
    beam underside, slab underside and slab top; the first overlap gets one line."""
    g, b = case["geometry"], case["building"]
    own = bool(b["slab_bases"])
    if own and len(b["slab_bases"]) != b["storeys"]:
        return [("building.slab_bases", b["slab_bases"],
                 f"one slab per storey: {b['storeys']} entries (building.storeys)")]
    levels = [("building.footing_height", b["footing_height"], "footing top"),
              ("building.beam_depth", b["footing_height"] + b["beam_depth"], "grade-beam top"),
              ("geometry.zbb", g["z1"] - g["zbb"], "ground level (Z1 - ZBB)")]
    for k, z in enumerate(slab_bases(case), start=1):
        key = ("building.slab_bases" if own else
               "building.z_slab1_base" if k == 1 else "building.z_slab2_base")
        levels += [(key, z - b["beam_depth"], f"storey-{k} beam underside"),
                   (key, z, f"slab {k} underside"),
                   ("building.slab_thickness" if k == 1 else key, z + b["slab_thickness"],
                    f"slab {k} top")]
    for i in range(1, len(levels)):
        (key, z, name), (_, below, name_below) = levels[i], levels[i - 1]
        # the grade beams may reach the ground, and the storey-1 beams start at it
        if not z >= below - 1e-12 or (i not in (2, 3) and not z > below):
            return [(key, case[key],
                     f"building levels overlap: {name} ({z:g} m above ZBB) must be above "
                     f"{name_below} ({below:g} m)")]
    return []


#: The geometry keys that set the building's plan along each axis (its far ends).
_PLAN_KEYS = {"x": ("geometry.x3", "geometry.x2"), "y": ("geometry.ys3", "geometry.ys2")}


def _check_spans(case: CaseView, axis: str, plan: float, plan_text: str
                 ) -> list[tuple[str, Any, str]]:
    """The building's spans along ``axis``: as many as bays, adding up to the plan between
    the outer column lines, each wider than a footing. A plan too small for the frame
    blames the key the case gave: the plan's (``geometry.*``) when it gives the plan and
    not the frame, else the footings."""
    b, given = case["building"], case.given or {}
    fs, bays, spans = b["footing_size"], b[f"bays_{axis}"], list(b[f"spans_{axis}"])
    inner = plan - fs
    if spans:
        if len(spans) != bays:
            return [(f"building.spans_{axis}", spans,
                     f"must give one span per bay: {bays} (building.bays_{axis}), or none for "
                     "equal spans")]
        if not _close(sum(spans), inner):
            return [(f"building.spans_{axis}", spans,
                     f"must add up to {plan_text} - footing_size = {inner:g} m (the column "
                     f"lines sit footing_size/2 inside the plan); they add up to "
                     f"{sum(spans):g} m")]
    span = min(spans) if spans else inner / bays
    if fs < span:
        return []
    if spans:
        return [(f"building.spans_{axis}", spans,
                 f"the footings must fit between the column lines: every span must be > "
                 f"building.footing_size = {fs:g} m")]
    # what the case changed (a file may list every key at its default: the baseline)
    touched = {k for k in given if k in ALL_KEYS and case[k] != ALL_KEYS[k].default}
    frame = {"building.footing_size", f"building.bays_{axis}"}
    plan_keys = [k for k in _PLAN_KEYS[axis] if k in touched]
    if plan_keys and not frame & touched:
        return [(plan_keys[0], case[plan_keys[0]],
                 f"makes the building's plan {plan_text} = {plan:g} m, too small for its "
                 f"frame: it must be > {(bays + 1) * fs:g} m ({bays + 1} column lines, "
                 f"building.bays_{axis} = {bays}, with footings of building.footing_size = "
                 f"{fs:g} m and a span wider than a footing between them)")]
    return [("building.footing_size", fs,
             f"the footings must fit between the column lines: must be < ({plan_text}) / "
             f"(bays_{axis} + 1) = {plan / (bays + 1):g} m ({plan_text} = {plan:g} m, "
             f"{bays} bay{'s' if bays > 1 else ''}: a span wider than a footing between "
             "them)")]


def _sizes_given(case: CaseView, section: str, keys: Sequence[str]) -> list[tuple[str, Any, str]]:
    """A measure's sizes that are not > 0 (its type or its width asks for it)."""
    kind = case[f"{section}.type"]
    return [(f"{section}.{key}", case[f"{section}.{key}"],
             f"must be > 0 m for {section}.type = '{kind}' (and the {section}'s mesh lines)")
            for key in keys if not case[f"{section}.{key}"] > 0]


def _check_measures(case: CaseView) -> list[tuple[str, Any, str]]:
    """The trench and the wave-impeding block: sizes given, inside the soil, clear of the
    embankment and the building."""
    out: list[tuple[str, Any, str]] = []
    g = case["geometry"]
    building = case["building.present"]
    toe = embankment_toe(case)
    face = -placed_plan(case)[3] if building else -(g["ys4"] - case["domain.extra_width"])
    soil_depth = g["z1"] - (g["z0"] - case["domain.extra_depth"])
    tr = case["trench"]
    if tr["type"] != "none" or tr["width"] > 0:
        out.extend(_sizes_given(case, "trench", ("width", "depth")))
        if tr["distance"] < toe - 1e-9:
            out.append(("trench.distance", tr["distance"],
                        f"the trench's near face must lie beyond the embankment toe "
                        f"({toe:g} m from the track centreline: |geometry.ys1| plus a "
                        "fill's slope)"))
        elif tr["distance"] + tr["width"] > face + 1e-9:
            where = ("would cut through the building: its face is {:g} m from the track "
                     "(|geometry.ys2|, turned with building.rotation)" if building else
                     "would reach past the soil's edge {:g} m from the track "
                     "(|geometry.ys4| + domain.extra_width)")
            out.append(("trench.width", tr["width"],
                        f"the trench (from {tr['distance']:g} to "
                        f"{tr['distance'] + tr['width']:g} m) " + where.format(face)))
        if tr["depth"] >= soil_depth - 1e-9:
            out.append(("trench.depth", tr["depth"],
                        f"must be less than the soil depth ({soil_depth:g} m to the base)"))
    wib = case["wib"]
    if wib["type"] != "none" or wib["width"] > 0:
        out.extend(_sizes_given(case, "wib", ("width", "thickness")))
        if wib["width"] > 2 * toe + 1e-9:
            out.append(("wib.width", wib["width"],
                        f"must be at most the embankment base, 2 |geometry.ys1| = {2 * toe:g} m"))
        if wib["depth"] + wib["thickness"] >= soil_depth - 1e-9:
            out.append(("wib.thickness", wib["thickness"],
                        f"the block (top {wib['depth']:g} m deep) must end above the base "
                        f"({soil_depth:g} m below the ground)"))
    return out


def _check_soil(case: CaseView) -> list[tuple[str, Any, str]]:
    """The wavelength sizing needs its frequency; the soil layers must reach the base of the
    model and start above it (a ``mesh.file`` brings its own layer parts, named
    ``soil_layer_<k>``, and is not checked)."""
    out = []
    if case["mesh.elements_per_wavelength"] > 0 and not case["mesh.wavelength_hz"] > 0:
        out.append(("mesh.elements_per_wavelength", case["mesh.elements_per_wavelength"],
                    "needs mesh.wavelength_hz > 0 (the frequency whose shear wavelengths the "
                    "soil elements must resolve)"))
    layers = case["soil.layers"]
    if not layers or case["mesh.file"]:
        return out
    depth = case["geometry.z1"] - (case["geometry.z0"] - case["domain.extra_depth"])
    slack = 1e-9 * max(depth, 1.0)
    total = sum(x["thickness"] for x in layers)
    below = (f"{depth:g} m below the ground (geometry.z1 - geometry.z0 + "
             "domain.extra_depth)")
    if layers[-1]["thickness"] > 0 and total < depth - slack:
        out.append(("soil.layers", f"{len(layers)} layer(s), {total:g} m thick",
                    f"do not reach the base: it lies {below}; make the last layer "
                    "thicker or give it thickness = 0 (down to the base)"))
        return out
    top = 0.0
    for k, x in enumerate(layers[:-1]):
        top += x["thickness"]
        if top >= depth - slack:
            out.append((f"soil.layers[{k + 2}]", f"starts {top:g} m deep",
                        f"lies below the base ({depth:g} m below the ground): remove it or "
                        "make the layers above thinner"))
            return out
    # what the mesh gets of the last layer: down to the base, never cut
    last, rest = len(layers), depth - top
    if len(layers) > 1 and rest < MIN_SOIL_LAYER_THICKNESS - slack:
        out.append((f"soil.layers[{last}]", f"starts {top:g} m deep",
                    f"leaves {rest:g} m down to the base ({depth:g} m below the ground), "
                    f"thinner than a soil layer may be ({MIN_SOIL_LAYER_THICKNESS:g} m): "
                    "remove it or make the layers above thinner"))
    elif layers[-1]["thickness"] > 0 and total > depth + slack:
        out.append((f"soil.layers[{last}].thickness", layers[-1]["thickness"],
                    f"the layers reach {total:g} m deep, past the base {below}, where they "
                    f"would be cut; give the last layer thickness = {rest:g} m, or 0 (down "
                    "to the base)"))
    return out
