"""Check a case: every value against the schema, then the whole case for consistency.

Every check appends ``(key, value, what is allowed)`` problems to a list instead of
raising, so that :func:`railvib_hpc.config.build_case` reports them all in one
:class:`~railvib_hpc.errors.CaseError`. The geometry the cross-key checks measure
(embankment toe, the building's turned plan and twist, slab levels) is
:mod:`railvib_hpc.site`'s.
"""

from __future__ import annotations

import copy
import importlib
import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .schema import (
    IMPLICIT_GROUPS,
    MAX_ROTATION_DEG,
    MAX_SOIL_LAYERS,
    MIN_SOIL_LAYER_THICKNESS,
    PARTS,
    PRESETS,
    PROBE_LINE_KEYS,
    PROBE_LINE_SIDES,
    SOIL_LAYER_KEYS,
    Param,
    iter_params,
)
from .site import (
    MAX_TWIST_SHEAR,
    building_turn,
    embankment_toe,
    ground_rayleigh_speeds,
    line_probe_name,
    line_ranges,
    line_x,
    load_path_crossing,
    placed_plan,
    quarter_turns,
    slab_bases,
    track_lift,
    train2_vehicle,
)
from .time_engines import needs_lumped_mass
from .uncertain_inputs import check_uncertainty, check_uncertainty_tables

if TYPE_CHECKING:
    from .config import Case

#: Every case key (dotted) and its schema entry, in schema order.
ALL_KEYS: dict[str, Param] = dict(iter_params())


_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as the Python values a TOML file gives (``np.int64(20)``
    -> 20, ``np.float32`` -> float, ``np.bool_`` -> bool, an array -> a list), also inside
    lists and tables; anything else as it is."""
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _integer(v: Any) -> bool:
    return (isinstance(v, int) and not isinstance(v, bool)) or (
        isinstance(v, float) and v.is_integer())


def _range_problem(param: Param, value: Any) -> str | None:
    """What is wrong with one (scalar or list entry) value under ``param.check``."""
    unit = "" if param.unit in ("-", "%") else f" in {param.unit}"
    check = param.check
    if check == "pos" and not value > 0:
        return f"must be > 0{unit} ({param.doc})"
    if check == "nonneg" and not value >= 0:
        return f"must be >= 0{unit} ({param.doc})"
    if check == "poisson" and not (0.0 <= value < 0.5):
        return "Poisson's ratio must satisfy 0 <= nu < 0.5"
    if check == "fraction" and not (0.0 <= value < 1.0):
        return "must satisfy 0 <= value < 1"
    if check == "unit" and not (0.0 <= value <= 1.0):
        return "must satisfy 0 <= value <= 1"
    if check == "refinement" and not (0.0 < value <= 6.0):
        return f"must satisfy 0 < value <= 6 ({param.doc})"
    if check == "angle" and not abs(value) <= MAX_ROTATION_DEG:
        return (f"must satisfy -{MAX_ROTATION_DEG:g} <= value <= {MAX_ROTATION_DEG:g} "
                f"{param.unit} (one whole turn either way)")
    if param.maximum is not None and not value <= param.maximum:
        return f"must be <= {param.maximum:g}{unit} ({param.doc})"
    if check == "name" and not _NAME.match(value):
        return "must be a name (letters, digits, '_.+-')"
    return None


def _check_list(key: str, param: Param, value: Any, problems: list) -> Any:
    """The list kinds: type of every entry, its range, and ``unique``."""
    unit = "" if param.unit in ("-", "%") else f" in {param.unit}"
    kind = param.kind
    entry_ok, convert, what = {
        "floats": (_number, float, f"a list of numbers{unit}"),
        "ints": (_integer, int, "a list of integers"),
        "bools": (lambda v: isinstance(v, bool), bool, "a list of true/false"),
        "strs": (lambda v: isinstance(v, str), str, "a list of strings"),
        "triples": (lambda v: isinstance(v, list) and len(v) == 3 and all(map(_number, v)),
                    lambda v: [float(x) for x in v], f"a list of [a, b, c] number triples{unit}"),
    }[kind]
    if not isinstance(value, list) or not all(entry_ok(v) for v in value):
        problems.append((key, value, f"expected {what} ({param.doc})"))
        return value
    out = [convert(v) for v in value]
    bad = [v for v in out if param.choices and v not in param.choices]
    if bad:
        problems.append((key, value, f"unknown entries {bad}; allowed: "
                         + ", ".join(map(repr, param.choices))))
        return value
    scalars = [x for v in out for x in (v if kind == "triples" else [v])]
    wrong = next(((x, m) for x in scalars if (m := _range_problem(param, x))), None)
    if wrong:
        problems.append((key, value, f"entry {wrong[0]!r} {wrong[1]}"))
        return value
    if param.unique:
        keys = [tuple(v) if kind == "triples" else v for v in out]
        if not keys:
            problems.append((key, value, f"expected a non-empty list ({param.doc})"))
        elif len(set(keys)) != len(keys):
            problems.append((key, value, "entries must be distinct"))
    return out


def _check_vehicle_table(key: str, param: Param, value: Any, problems: list) -> Any:
    """The ``vehicle`` kind: a table of [vehicle] keys (``param.choices``), each checked
    as [vehicle]'s own."""
    if not isinstance(value, dict):
        problems.append((key, value, f"expected a table of [vehicle] keys ([{key}])"))
        return value
    out = {}
    for name, entry in value.items():
        if name not in param.choices:
            problems.append((f"{key}.{name}", entry,
                             "not a key of the second train's own vehicle (its speed, cars "
                             "and delay are train2.speed, n_cars, t_start; the model type and "
                             "the wheel-rail contact law are [vehicle]'s); allowed: "
                             + ", ".join(param.choices)))
            continue
        out[name] = check_value(f"{key}.{name}", ALL_KEYS[f"vehicle.{name}"], entry, problems)
    return out


#: Damping ratio of a soil layer that gives none (the materials' default).
SOIL_LAYER_DAMPING_RATIO = 0.03


def _check_layers(key: str, value: Any, problems: list) -> Any:
    """The ``layers`` kind: a list of tables (:data:`~railvib_hpc.schema.SOIL_LAYER_KEYS`).

    Returns the entries with floats, ``damping_ratio`` filled in; E stays as given (the
    derived layer properties are :func:`railvib_hpc.site.soil_layers`).
    """
    allowed = ", ".join(SOIL_LAYER_KEYS)
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        problems.append((key, value, "expected a list of tables ([[soil.layers]] with "
                         f"{allowed})"))
        return value
    if len(value) > MAX_SOIL_LAYERS:
        problems.append((key, f"{len(value)} layers", f"at most {MAX_SOIL_LAYERS} layers"))
        return value
    out = []
    n_before = len(problems)
    for k, entry in enumerate(value):
        where = f"{key}[{k + 1}]"
        unknown = sorted(set(entry) - set(SOIL_LAYER_KEYS))
        if unknown:
            problems.append((f"{where}.{unknown[0]}", entry[unknown[0]],
                             f"unknown key; allowed: {allowed}"))
        for name, (required, _) in SOIL_LAYER_KEYS.items():
            if required and name not in entry:
                problems.append((f"{where}.{name}", None,
                                 f"missing ({SOIL_LAYER_KEYS[name][1]})"))
        if ("E" in entry) == ("c_s" in entry):
            problems.append((f"{where}.E", entry.get("E"),
                             "give exactly one of E (Pa) and c_s (m/s)"))
        layer = {"damping_ratio": SOIL_LAYER_DAMPING_RATIO}
        for name, v in entry.items():
            if name not in SOIL_LAYER_KEYS:
                continue
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                problems.append((f"{where}.{name}", v, f"expected a number: "
                                 f"{SOIL_LAYER_KEYS[name][1]}"))
                continue
            v = float(v)
            last = k == len(value) - 1
            bad = {"thickness": not (v >= MIN_SOIL_LAYER_THICKNESS or (last and v == 0)),
                   "nu": not 0.0 <= v < 0.5, "damping_ratio": not 0.0 <= v < 1.0,
                   }.get(name, not v > 0)
            if bad:
                problems.append((f"{where}.{name}", v, SOIL_LAYER_KEYS[name][1]))
            layer[name] = v
        out.append(layer)
    if not value:
        return []
    return value if len(problems) > n_before else out


def _check_probe_line(where: str, entry: dict, problems: list) -> dict:
    """One ``[[probes.line]]`` table: its keys, types and ranges; the entry with floats and
    ``side`` filled in."""
    out: dict[str, Any] = {}
    for name in sorted(set(entry) - set(PROBE_LINE_KEYS)):
        problems.append((f"{where}.{name}", entry[name],
                         "unknown key; allowed: " + ", ".join(PROBE_LINE_KEYS)))
    for name, (required, meaning) in PROBE_LINE_KEYS.items():
        if required and name not in entry:
            problems.append((f"{where}.{name}", None, f"missing ({meaning})"))
    if "name" in entry:
        if not isinstance(entry["name"], str) or not _NAME.match(entry["name"]):
            problems.append((f"{where}.name", entry["name"], PROBE_LINE_KEYS["name"][1]))
        out["name"] = entry["name"]
    if "distances" in entry:
        d = entry["distances"]
        if not isinstance(d, list) or not d or not all(_number(v) and v > 0 for v in d) \
                or len(set(d)) != len(d):
            problems.append((f"{where}.distances", d, PROBE_LINE_KEYS["distances"][1]))
        else:
            out["distances"] = [float(v) for v in d]
    if "side" in entry and entry["side"] not in PROBE_LINE_SIDES:
        problems.append((f"{where}.side", entry["side"], "allowed values: "
                         + ", ".join(map(repr, PROBE_LINE_SIDES))))
    out["side"] = entry.get("side", PROBE_LINE_SIDES[0])
    if "x" in entry:
        if not _number(entry["x"]):
            problems.append((f"{where}.x", entry["x"],
                             f"expected a number: {PROBE_LINE_KEYS['x'][1]}"))
        else:
            out["x"] = float(entry["x"])
    return out


def _check_probe_lines(key: str, value: Any, problems: list) -> Any:
    """The ``probe_lines`` kind: a list of tables (:data:`~railvib_hpc.schema.PROBE_LINE_KEYS`)
    with distinct names; where the points lie is :func:`_check_line_points`'s."""
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        problems.append((key, value, "expected a list of tables ([[probes.line]] with "
                         + ", ".join(PROBE_LINE_KEYS) + ")"))
        return value
    n_before = len(problems)
    out = [_check_probe_line(f"{key}[{k + 1}]", entry, problems)
           for k, entry in enumerate(value)]
    names = [e.get("name") for e in out]
    for k, name in enumerate(names):
        if name is not None and name in names[:k]:
            problems.append((f"{key}[{k + 1}].name", name, "must differ from the names of the "
                             "lines before it"))
    return value if len(problems) > n_before else out


def _check_line_points(case: Case) -> list[tuple[str, Any, str]]:
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


def check_value(key: str, param: Param, value: Any, problems: list) -> Any:
    """Type-check and convert one value; append problems; return the converted value.

    numpy scalars count as the Python numbers they hold (:func:`_plain`; a numpy bool is
    still no number)."""
    unit = "" if param.unit in ("-", "%") else f" in {param.unit}"
    kind = param.kind
    value = _plain(value)
    if kind in ("floats", "ints", "bools", "strs", "triples"):
        return _check_list(key, param, value, problems)
    if kind == "layers":
        return _check_layers(key, value, problems)
    if kind == "probe_lines":
        return _check_probe_lines(key, value, problems)
    if kind == "vehicle":
        return _check_vehicle_table(key, param, value, problems)
    if kind in ("uncertain_parameters", "random_fields", "matrix"):
        return check_uncertainty_tables(key, kind, value, problems)
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            problems.append((key, value, f"expected a number{unit} ({param.doc})"))
            return value
        value = float(value)
        if not math.isfinite(value):
            problems.append((key, value, "expected a finite number"))
            return value
    elif kind == "int":
        if isinstance(value, bool) or not _integer(value):
            problems.append((key, value, f"expected an integer ({param.doc})"))
            return value
        value = int(value)
    elif kind == "bool":
        if not isinstance(value, bool):
            problems.append((key, value, "expected true or false"))
            return value
    elif kind == "str":
        if (isinstance(value, int) and not isinstance(value, bool)
                and str(value) in param.choices):
            value = str(value)                     # e.g. track_class = 6
        if not isinstance(value, str):
            problems.append((key, value, f"expected a string ({param.doc})"))
            return value
        if param.choices and value not in param.choices:
            problems.append((key, value, "allowed values: " + ", ".join(map(repr, param.choices))))
            return value
    wrong = _range_problem(param, value)
    if wrong:
        problems.append((key, value, wrong))
    return value


def _close(a: float, b: float, tol: float = 1e-6) -> bool:
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


def check_consistency(case: Case) -> list[tuple[str, Any, str]]:
    """Geometric and cross-key checks; returns the list of problems."""
    g, t, b = case["geometry"], case["track"], case["building"]
    out: list[tuple[str, Any, str]] = []

    def order(keys: list[str], values: list[float], what: str) -> None:
        for (k0, v0), (k1, v1) in zip(zip(keys, values), zip(keys[1:], values[1:])):
            if not v0 < v1:
                out.append((f"geometry.{k1}", v1, f"must be greater than {k0} = {v0} ({what})"))

    if b["present"]:
        order(["x0", "x1", "x2", "x3", "x4"], [g[k] for k in ("x0", "x1", "x2", "x3", "x4")],
              "X0 < X1 < X2 < X3 < X4")
        order(["ys4", "ys3", "ys2", "ys1"], [g[k] for k in ("ys4", "ys3", "ys2", "ys1")],
              "YS4 < YS3 < YS2 < YS1 < 0 < YS0")
    else:                          # no building: its lines do not apply
        order(["x0", "x1", "x4"], [g[k] for k in ("x0", "x1", "x4")], "X0 < X1 < X4")
        order(["ys4", "ys1"], [g[k] for k in ("ys4", "ys1")], "YS4 < YS1 < 0 < YS0")
    if not g["ys1"] < 0:
        out.append(("geometry.ys1", g["ys1"], "must be < 0 (embankment toe on the building side)"))
    if not g["ys0"] > -g["ys1"]:
        out.append(("geometry.ys0", g["ys0"],
                    f"must be > |YS1| = {-g['ys1']} (soil must extend beyond the embankment)"))
    order(["z0", "z1", "z2", "z3", "z4"], [g[k] for k in ("z0", "z1", "z2", "z3", "z4")],
          "Z0 < Z1 < Z2 < Z3 < Z4")
    if out:
        return out
    out.extend(feature_key_problems(case))

    # track
    if not _close(g["x1"] - g["x0"], t["rigid_length"]):
        out.append(("track.rigid_length", t["rigid_length"],
                    f"must equal X1 - X0 = {g['x1'] - g['x0']:g} m"))
    if not _close(g["x4"] - g["x1"], t["rail_length"]):
        out.append(("track.rail_length", t["rail_length"],
                    f"must equal geometry.x4 - x1 = {g['x4'] - g['x1']:g} m (the soil spans "
                    "the flexible rail): give one of track.rail_length and geometry.x4, the "
                    "other follows"))
    nbays = t["rail_length"] / t["sleeper_spacing"]
    if abs(nbays - round(nbays)) > 1e-6:
        out.append(("track.sleeper_spacing", t["sleeper_spacing"],
                    f"must divide the flexible rail length {t['rail_length']:g} m into whole bays"))
    elif t["n_sleepers"] != round(nbays) + 1:
        out.append(("track.n_sleepers", t["n_sleepers"],
                    f"must be rail_length / sleeper_spacing + 1 = {round(nbays) + 1} (it is "
                    "derived: leave it out)"))
    half_sleeper = t["sleeper_length"] / 2
    if not t["gauge"] / 2 < half_sleeper:
        out.append(("track.gauge", t["gauge"],
                    f"the rails must sit on the sleepers: gauge/2 < sleeper_length/2 = "
                    f"{half_sleeper:g} m"))
    if not half_sleeper < g["ballast_top_half_width"]:
        out.append(("track.sleeper_length", t["sleeper_length"],
                    f"sleepers must lie on the ballast crest: length/2 < "
                    f"geometry.ballast_top_half_width = {g['ballast_top_half_width']:g} m"))
    if not g["ballast_top_half_width"] <= g["ballast_bottom_half_width"] < -g["ys1"]:
        out.append(("geometry.ballast_bottom_half_width", g["ballast_bottom_half_width"],
                    f"must lie between ballast_top_half_width = {g['ballast_top_half_width']:g} "
                    f"and |YS1| = {-g['ys1']:g} m (sloped shoulders)"))
    out.extend(_check_tracks(case))
    out.extend(_check_surface_load(case))
    out.extend(_check_static_start(case))
    out.extend(_check_track_ends(case))
    out.extend(_check_embankment(case))
    out.extend(_check_interfaces(case))
    if b["present"]:
        out.extend(_check_building(case))
    out.extend(_check_mesh_keys(case))
    out.extend(check_studies(case["study"]))
    out.extend(_check_dynamics(case))
    out.extend(_check_soil(case))
    out.extend(_check_measures(case))
    out.extend(_check_line_points(case))
    out.extend(check_uncertainty(case))
    return out


def _check_building(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_mesh_keys(case: Case) -> list[tuple[str, Any, str]]:
    """The mesh file, the refinement and the modal settings."""
    m = case["mesh"]
    out: list[tuple[str, Any, str]] = []
    if m["file"]:
        f = case.resolve(m["file"])
        if not f.is_file():
            out.append(("mesh.file", m["file"], f"file not found (looked for {f})"))
        elif f.suffix != ".msh":
            out.append(("mesh.file", m["file"], "must be a gmsh .msh file"))
    if m["refinement"] > 6:
        out.append(("mesh.refinement", m["refinement"],
                    "must be <= 6 (refinement 3 is already ~1.5M nodes)"))
    if case["modal.f_max"] == 0 and case["modal.n_modes"] < 1:
        out.append(("modal.n_modes", case["modal.n_modes"], "must be >= 1"))
    out.extend(_check_bands(case))
    need = case["modal.n_modes"] + 2 * case["modal.block_size"]
    if case["modal.method"] == "block_lanczos" and case["modal.f_max"] == 0 \
            and 0 < case["modal.max_basis"] < need:
        out.append(("modal.max_basis", case["modal.max_basis"],
                    f"must be 0 (automatic) or at least modal.n_modes + 2 modal.block_size = "
                    f"{need} (the Lanczos basis holds the wanted modes and two blocks)"))
    out.extend(_check_mbs(case))
    return out


def _baseline(case: Any, key: str) -> Any:
    """The default of ``key``: the case's preset's value, else the schema's."""
    return PRESETS.get(case["case.preset"], {}).get(key, ALL_KEYS[key].default)


def _at_default(case: Any, key: str, value: Any) -> bool:
    """Whether ``value`` is a default of ``key``: the preset's or the schema's (a file that
    lists every key at the APDL values, with the preset ``table1``, sets them unused)."""
    return value == _baseline(case, key) or value == ALL_KEYS[key].default


def _off_text(condition: Any, case: Any, default: Any) -> str:
    part = condition.failing(case)
    return (f"applies to {part.text} only; here {part.here(case)}: leave it at its "
            f"default {default!r} (or leave it out)")


def feature_key_problems(case: Case) -> list[tuple[str, Any, str]]:
    """The one rule of the keys that belong to a feature (:attr:`Param.applies
    <railvib_hpc.schema.Param>`): where the feature is off, the key keeps its default.

    A key set to its default (the schema's, or its preset's) where its feature is off is
    accepted (a file may list every key, as ``jobs/thesis_baseline.toml`` does); any other
    value is refused, naming the
    condition that does not hold and the value that breaks it. The entries of
    ``train2.vehicle`` follow the rule of their ``[vehicle]`` key (its cars' keys apply
    to cars only). Derived keys are not checked (their value follows from others).

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> feature_key_problems(Case.defaults()) == []
    True
    """
    out: list[tuple[str, Any, str]] = []
    for key, param in ALL_KEYS.items():
        condition = param.applies
        if condition is None or param.derived:
            continue
        value, default = case[key], _baseline(case, key)
        if _at_default(case, key, value):
            continue
        if not condition.holds(case):
            out.append((key, value, _off_text(condition, case, default)))
        elif param.kind == "vehicle":
            for name, entry in value.items():
                inner = ALL_KEYS[f"vehicle.{name}"].applies
                if inner is not None and not inner.holds(case):
                    out.append((f"{key}.{name}", entry, _off_text(inner, case, "not given")))
    return out


def switched_off(case: Case, changes: Mapping[str, Any]) -> dict[str, Any]:
    """The keys whose feature ``changes`` (``{dotted key: value}``, e.g. a study variant's
    overrides) switch off while the case sets them: ``{key: default}`` to reset, so that
    a variant that replaces, say, the case's pml faces by rollers does not carry the
    layer's keys into a case that would refuse them. Keys that ``changes`` set themselves
    stay as given (the rule judges them)."""
    values = {k: case[k] for k in ALL_KEYS}
    values.update({k: v for k, v in changes.items() if k in values})
    out = {}
    for key, param in ALL_KEYS.items():
        condition = param.applies
        if condition is None or param.derived or key in changes:
            continue
        default = _baseline(case, key)
        if _at_default(case, key, values[key]) or not condition.holds(case):
            continue
        try:
            off = not condition.holds(values)
        except (TypeError, KeyError):      # a badly typed change: build_case names it
            continue
        if off:
            out[key] = copy.deepcopy(default)
    return out


def _check_tracks(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_surface_load(case: Case) -> list[tuple[str, Any, str]]:
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


def _statically_held(case: Case, face: str) -> tuple[int, ...]:
    """The displacement components a face holds against a static load: fixed, caughey
    and pml faces all three, a roller its normal one, an absorbing face all three with
    its springs (``boundary.virtual_thickness > 0``) and none on dashpots alone (they
    hold no static load), a free face none."""
    kind = case[f"boundary.{face}"]
    if kind in ("fixed", "caughey", "pml") or (
            kind == "absorbing" and case["boundary.virtual_thickness"] > 0):
        return (0, 1, 2)
    return (_FACE_PLANES[face][0],) if kind == "roller" else ()


def _check_static_start(case: Case) -> list[tuple[str, Any, str]]:
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


def _load_path_problems(case: Case) -> list[tuple[str, Any, str]]:
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


def command_problems(case: Case, command: str) -> list[tuple[str, Any, str]]:
    """What a case asks of a command that the command cannot do (empty: nothing).

    Each stage declares its own refusals (``Stage(refuse=...)``,
    :meth:`~railvib_hpc.io.stage_protocol.Stage.refusals`: a case without a track on the
    modal path, ``modal.damping`` with supported track ends, a perfectly matched layer on
    the modal path); this collects those of the stages ``command`` runs
    (:func:`railvib_hpc.pipeline.refusals`: a pipeline's stages, a stage's own, none for
    ``check`` and ``study``), the first one in the stages' order, so the command line and
    the API refuse in one line before anything runs (before meshing). The registry is
    imported by name, as the product table imports it (this layer imports no stage).

    Parameters
    ----------
    case
        The validated case.
    command
        The ``railvib`` command (``run``, ``modal``, ``transient``, ...).

    Returns
    -------
    list
        ``(key, value, allowed)`` problems, for :class:`~railvib_hpc.errors.CaseError`.
    """
    from .io.products import REGISTRY

    return importlib.import_module(REGISTRY).refusals(case, command)


def _check_embankment(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_rotation(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_turned_plan(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_interfaces(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_levels(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_spans(case: Case, axis: str, plan: float, plan_text: str
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


def _sizes_given(case: Case, section: str, keys: Sequence[str]) -> list[tuple[str, Any, str]]:
    """A measure's sizes that are not > 0 (its type or its width asks for it)."""
    kind = case[f"{section}.type"]
    return [(f"{section}.{key}", case[f"{section}.{key}"],
             f"must be > 0 m for {section}.type = '{kind}' (and the {section}'s mesh lines)")
            for key in keys if not case[f"{section}.{key}"] > 0]


def _check_measures(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_soil(case: Case) -> list[tuple[str, Any, str]]:
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


def check_studies(tables: dict[str, dict[str, Any]]) -> list[tuple[str, Any, str]]:
    """Cross-key checks of the ``[study.KIND]`` tables; returns the problems.

    ``tables`` maps study kinds to their (type-checked) settings; keys in the problems are
    ``study.<kind>.<key>``.
    """
    out: list[tuple[str, Any, str]] = []
    conv = tables.get("convergence")
    if conv is not None and len(conv["levels"]) < 2:
        out.append(("study.convergence.levels", conv["levels"],
                    "need at least 2 refinement levels (3 for an observed order)"))
    refl = tables.get("reflection")
    if refl is not None:
        if len(refl["names"]) != len(refl["domains"]):
            out.append(("study.reflection.names", refl["names"],
                        f"needs one name per entry of domains ({len(refl['domains'])})"))
        if len(refl["domains"]) < 2:
            out.append(("study.reflection.domains", refl["domains"],
                        "need at least 2 domains to compare"))
        if any(x < 0 for d in refl["domains"] for x in d[1:]):
            out.append(("study.reflection.domains", refl["domains"],
                        "length and width changes must be >= 0 (only the depth change may be "
                        "negative: it raises the fixed base)"))
    return out


def _check_bands(case: Case) -> list[tuple[str, Any, str]]:
    """Cross-key checks of the band-sliced eigensolve settings."""
    out: list[tuple[str, Any, str]] = []
    md = case["modal"]
    edges = list(md["bands"])
    # (modal.f_max = 0: the rule of Param.applies refuses the bands)
    if edges and md["f_max"] > 0 and (any(not 0 < e < md["f_max"] for e in edges) or
                                      any(b <= a for a, b in zip(edges, edges[1:]))):
        out.append(("modal.bands", edges, f"must be strictly ascending inside (0, "
                                          f"modal.f_max = {md['f_max']!r})"))
    if (md["bands"] or md["band_only"] or md["band_groups"] > 1) and \
            md["method"] != "block_lanczos":
        out.append(("modal.method", md["method"], "band settings need 'block_lanczos'"))
    return out


def _check_dynamics(case: Case) -> list[tuple[str, Any, str]]:
    """Cross-key checks of [damping] and [transient]."""
    out: list[tuple[str, Any, str]] = []
    d, tr = case["damping"], case["transient"]
    faces = [f for f in ("x_min", "x_max", "y_min", "y_max", "base")
             if case[f"boundary.{f}"] == "caughey"]
    if faces and not case["boundary.layer_thickness"] > 0:
        out.append(("boundary.layer_thickness", case["boundary.layer_thickness"],
                    f"must be > 0 m for the caughey face(s) {', '.join(faces)}"))
    pml = [f for f in ("x_min", "x_max", "y_min", "y_max", "base")
           if case[f"boundary.{f}"] == "pml"]
    if pml and not case["boundary.layer_thickness"] > 0:
        out.append(("boundary.layer_thickness", case["boundary.layer_thickness"],
                    f"must be > 0 m for the pml face(s) {', '.join(pml)}"))
    if pml and not 0.0 < case["boundary.pml_reflection"] < 1.0:
        out.append(("boundary.pml_reflection", case["boundary.pml_reflection"],
                    "must lie in (0, 1): the target reflection of the layer"))
    if not d["f1"] < d["f2"]:
        out.append(("damping.f2", d["f2"], f"must be greater than damping.f1 = {d['f1']:g} Hz "
                    "(the two frequencies of the Rayleigh damping)"))
    odt = case["output.dt"]
    if tr["dt"] > 0 and odt > 0:
        ratio = odt / tr["dt"]
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
            out.append(("transient.dt", tr["dt"],
                        f"must divide output.dt = {odt:g} s into whole steps (or be 0: "
                        "automatic)"))
    if tr["engine"] in needs_lumped_mass() and not case["modal.lumped_mass"]:
        out.append(("transient.engine", tr["engine"],
                    "needs a diagonal mass: set modal.lumped_mass = true (or use "
                    "transient.engine = \"direct\")"))
    unknown = [p for p in tr["implicit_parts"] if p not in IMPLICIT_GROUPS and p not in PARTS]
    if unknown:
        out.append(("transient.implicit_parts", unknown[0],
                    "must be a part name or one of the groups "
                    + ", ".join(IMPLICIT_GROUPS) + " (parts: " + ", ".join(PARTS) + ")"))
    return out


def _vehicle_problems(v: dict[str, Any], gauge: float, section: str
                      ) -> list[tuple[str, Any, str]]:
    """Cross-key checks of one vehicle's keys (``[vehicle]`` or the second train's)."""
    out: list[tuple[str, Any, str]] = []
    if any(o > 0 for o in v["axle_offsets"]) or not v["axle_offsets"]:
        out.append((f"{section}.axle_offsets", v["axle_offsets"],
                    "must be a non-empty list of offsets <= 0 (behind the leading axle)"))
    if v["contact_span"] >= 2.0 * gauge:
        out.append((f"{section}.contact_span", v["contact_span"],
                    f"must be close to the track gauge ({gauge:g} m)"))
    if v["wheelbase"] >= v["bogie_spacing"]:
        out.append((f"{section}.wheelbase", v["wheelbase"],
                    f"must be smaller than {section}.bogie_spacing = {v['bogie_spacing']:g} m"))
    if v["bogie_spacing"] + v["wheelbase"] >= v["car_length"]:
        out.append((f"{section}.car_length", v["car_length"],
                    "must exceed bogie_spacing + wheelbase (the wheels of successive cars "
                    "must not overlap)"))
    return out


def _speed_problems(case: Case) -> list[tuple[str, Any, str]]:
    """A train at or above the ground's lowest Rayleigh speed, unless vehicle.supercritical
    accepts it."""
    if case["vehicle.supercritical"]:
        return []
    try:
        speeds = ground_rayleigh_speeds(case)
    except (KeyError, ValueError, ZeroDivisionError):
        return []                        # (bad materials are reported by their own checks)
    part, c_r = min(speeds.items(), key=lambda kv: kv[1])
    trains = [("vehicle.speed", case["vehicle.speed"]) if case["track.count"]
              else ("load.speed", case["load.speed"])]           # the surface load's
    if case["track.count"] == 2 and case["train2.speed"] > 0:
        trains.append(("train2.speed", case["train2.speed"]))
    return [(key, v, f"is at or above the ground's Rayleigh speed c_R = {c_r:.1f} m/s "
             f"({part}; " + ", ".join(f"{k} {c:.1f}" for k, c in speeds.items())
             + " m/s): the track's critical speed, where the response grows and forms a "
             f"Mach cone; allowed: < {c_r:.1f} m/s, or set vehicle.supercritical = true "
             "to run it")
            for key, v in trains if v >= c_r]


def _check_track_ends(case: Case) -> list[tuple[str, Any, str]]:
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


def _check_mbs(case: Case) -> list[tuple[str, Any, str]]:
    """Cross-key checks of [vehicle], [irregularity] and [mbs]."""
    out: list[tuple[str, Any, str]] = []
    v, irr, mbs = case["vehicle"], case["irregularity"], case["mbs"]
    out.extend(_vehicle_problems(v, case["track.gauge"], "vehicle"))
    out.extend(_speed_problems(case))
    if v["x_end"] and v["x_end"] <= v["x_start"]:
        out.append(("vehicle.x_end", v["x_end"],
                    f"must be 0 (end of the rigid exit rail) or > vehicle.x_start = "
                    f"{v['x_start']:g} m"))
    if irr["type"] == "file":
        if not irr["file"]:
            out.append(("irregularity.file", "", "irregularity.type = 'file' needs a file"))
        elif not case.resolve(irr["file"]).is_file():
            out.append(("irregularity.file", irr["file"],
                        f"file not found (looked for {case.resolve(irr['file'])})"))
    classes = {"fra": "123456", "iso8608": "ABCDEFGH"}
    if irr["type"] in classes and irr["track_class"] not in classes[irr["type"]]:
        out.append(("irregularity.track_class", irr["track_class"],
                    f"{irr['type']} classes are " + ", ".join(classes[irr["type"]])))
    if irr["wavelength_min"] >= irr["wavelength_max"]:
        out.append(("irregularity.wavelength_min", irr["wavelength_min"],
                    f"must be < irregularity.wavelength_max = {irr['wavelength_max']:g} m"))
    if any(w < 0 or not float(w).is_integer() for w in irr["flat_wheels"]):
        out.append(("irregularity.flat_wheels", irr["flat_wheels"],
                    "must be wheel indices (integers >= 0)"))
    o = case["output"]
    if o["window"] and (len(o["window"]) != 2 or o["window"][0] >= o["window"][1]
                        or o["window"][0] < 0):
        out.append(("output.window", o["window"], "must be empty or [t0, t1] with 0 <= t0 < t1"))
    if len(o["probes"]) % 3:
        out.append(("output.probes", o["probes"],
                    "must be a flat list of x, y, z triples (length a multiple of 3)"))
    elif o["probe_roles"] and len(o["probe_roles"]) != len(o["probes"]) // 3:
        out.append(("output.probe_roles", o["probe_roles"],
                    f"must be empty or give one role per point of output.probes "
                    f"({len(o['probes']) // 3})"))
    if any(t < 0 for t in o["stress_times"]):
        out.append(("output.stress_times", o["stress_times"], "times must be >= 0"))
    modes, ratios = mbs["damping_modes"], mbs["damping_ratios"]
    if len(modes) != len(ratios):
        out.append(("mbs.damping_ratios", ratios,
                    f"needs one ratio per entry of mbs.damping_modes ({len(modes)})"))
    if any(k < 1 or not float(k).is_integer() for k in modes):
        out.append(("mbs.damping_modes", modes, "must be mode numbers (integers >= 1)"))
    if any(not 0.0 <= r < 1.0 for r in ratios):
        out.append(("mbs.damping_ratios", ratios, "must satisfy 0 <= ratio < 1"))
    return out
