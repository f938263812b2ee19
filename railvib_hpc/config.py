"""Load, merge and validate case files.

A case is a TOML file whose keys are described in :mod:`railvib_hpc.schema`.
Loading merges, in this order: schema defaults, the chosen preset, the file,
then ``--set key=value`` overrides. Validation collects *all* problems and
raises one :class:`~railvib_hpc.errors.CaseError` naming key, value and what
is allowed for each.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import math
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomllib

from .errors import CaseError
from .schema import PRESETS, SCHEMA, Param, iter_params

ALL_KEYS: dict[str, Param] = dict(iter_params())
_SECTION_KEYS = {k.rsplit(".", 1)[0] for k in ALL_KEYS}


@dataclass
class Case:
    """A validated case.

    Attributes
    ----------
    data
        Nested dict with every schema key filled in.
    path
        The case file (``None`` for the built-in defaults).
    notes
        Things the user should know that are not errors (e.g. preset values
        overridden by the file).
    """

    data: dict[str, Any]
    path: Path | None = None
    notes: tuple[str, ...] = ()

    def __getitem__(self, dotted: str) -> Any:
        node: Any = self.data
        for part in dotted.split("."):
            node = node[part]
        return node

    def section(self, name: str) -> dict[str, Any]:
        """Return a copy of one section, e.g. ``case.section("geometry")``."""
        return copy.deepcopy(self[name])

    def digest(self, *sections: str, exclude: Collection[str] = ()) -> str:
        """SHA-256 of the given sections (all if none), for result reuse keys.

        Keys named in ``exclude`` are left out at every depth (e.g. damping ratios, which
        do not change the modes).
        """
        names = sections or tuple(sorted(self.data))

        def drop(node: Any) -> Any:
            if not isinstance(node, dict):
                return node
            return {k: drop(v) for k, v in node.items() if k not in exclude}

        payload = {n: drop(self[n]) for n in names}
        if "mesh" in names and self["mesh.file"]:
            mesh_file = self.resolve(self["mesh.file"])
            payload["mesh_file_sha256"] = hashlib.sha256(mesh_file.read_bytes()).hexdigest()
        text = json.dumps(payload, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()

    def resolve(self, relative: str) -> Path:
        """Resolve a path given in the case file relative to the file's folder."""
        p = Path(relative)
        if not p.is_absolute() and self.path is not None:
            p = self.path.parent / p
        return p

    def to_toml(self) -> str:
        """Serialise the full, merged case as TOML (for provenance)."""
        return dumps_toml(self.data)


def defaults() -> dict[str, Any]:
    """Nested dict of all schema defaults."""
    out: dict[str, Any] = {}
    for key, param in ALL_KEYS.items():
        _set(out, key, copy.deepcopy(param.default))
    return out


def _set(tree: dict[str, Any], dotted: str, value: Any) -> None:
    parts = dotted.split(".")
    for p in parts[:-1]:
        tree = tree.setdefault(p, {})
    tree[parts[-1]] = value


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            flat.update(_flatten(v, key + "."))
        else:
            flat[key] = v
    return flat


def _did_you_mean(key: str) -> str:
    candidates = list(ALL_KEYS) + sorted(_SECTION_KEYS)
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.6)
    if not close:
        # compare the last component only (e.g. a misspelt key in the right section)
        leaf = key.rsplit(".", 1)[-1]
        by_leaf = {k.rsplit(".", 1)[-1]: k for k in ALL_KEYS if k.startswith(key.rsplit(".", 1)[0])}
        m = difflib.get_close_matches(leaf, list(by_leaf), n=1, cutoff=0.6)
        close = [by_leaf[m[0]]] if m else []
    section = key.split(".")[0]
    known = ", ".join(sorted(SCHEMA)) if section not in SCHEMA else None
    if close:
        return f"unknown key; did you mean '{close[0]}'?"
    if known:
        return f"unknown section '{section}'; sections are: {known}"
    return f"unknown key; see the case-file reference in README.md (section [{section}])"


def parse_override(text: str) -> tuple[str, Any]:
    """Parse one ``--set key=value``; the value is read as a TOML value.

    Unquoted text that is not valid TOML is taken as a string, so
    ``--set vehicle.type=wheelset`` works without quotes.
    """
    if "=" not in text:
        raise CaseError([(text, None, "an override must look like key=value, "
                          "e.g. --set mesh.refinement=2")])
    key, raw = text.split("=", 1)
    key, raw = key.strip(), raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def _check_value(key: str, param: Param, value: Any, problems: list) -> Any:
    """Type-check and convert one value; append problems; return the converted value."""
    unit = "" if param.unit == "-" else f" in {param.unit}"
    kind = param.kind
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            problems.append((key, value, f"expected a number{unit} ({param.doc})"))
            return value
        value = float(value)
        if not math.isfinite(value):
            problems.append((key, value, "expected a finite number"))
            return value
    elif kind == "int":
        if isinstance(value, bool) or not (isinstance(value, int) or
                                           (isinstance(value, float) and value.is_integer())):
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
    elif kind == "strs":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            problems.append((key, value, "expected a list of strings"))
            return value
        bad = [v for v in value if param.choices and v not in param.choices]
        if bad:
            problems.append((key, value, f"unknown entries {bad}; allowed: "
                             + ", ".join(map(repr, param.choices))))
        return value
    elif kind == "floats":
        if not isinstance(value, list) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            problems.append((key, value, f"expected a list of numbers{unit}"))
            return value
        return [float(v) for v in value]
    check = param.check
    if check == "pos" and not value > 0:
        problems.append((key, value, f"must be > 0{unit} ({param.doc})"))
    elif check == "nonneg" and not value >= 0:
        problems.append((key, value, f"must be >= 0{unit} ({param.doc})"))
    elif check == "poisson" and not (0.0 <= value < 0.5):
        problems.append((key, value, "Poisson's ratio must satisfy 0 <= nu < 0.5"))
    elif check == "fraction" and not (0.0 <= value < 1.0):
        problems.append((key, value, "must satisfy 0 <= value < 1"))
    elif check == "unit" and not (0.0 <= value <= 1.0):
        problems.append((key, value, "must satisfy 0 <= value <= 1"))
    return value


def build_case(raw: dict[str, Any], overrides: list[str] | None = None,
               path: Path | None = None) -> Case:
    """Merge defaults, preset, ``raw`` (parsed TOML) and overrides; validate.

    Raises
    ------
    CaseError
        With every problem found.
    """
    problems: list[tuple[str, Any, str]] = []
    flat = _flatten(raw)
    for text in overrides or []:
        key, value = parse_override(text)
        flat[key] = value
    for key in list(flat):
        if key not in ALL_KEYS:
            problems.append((key, flat.pop(key), _did_you_mean(key)))

    preset = flat.get("case.preset", ALL_KEYS["case.preset"].default)
    data = defaults()
    if isinstance(preset, str) and preset in PRESETS:
        for key, value in PRESETS[preset].items():
            _set(data, key, value)
    for key, value in flat.items():
        _set(data, key, _check_value(key, ALL_KEYS[key], value, problems))
    if problems:
        raise CaseError(problems)
    notes = []
    if isinstance(preset, str) and PRESETS.get(preset):
        shadowed = [k for k, v in PRESETS[preset].items() if k in flat and flat[k] != v]
        if shadowed:
            notes.append(f"case.preset = '{preset}' sets {len(PRESETS[preset])} keys, but the "
                         f"file or --set gives other values for {len(shadowed)} of them, which "
                         f"win: {', '.join(shadowed)}")
    case = Case(data=data, path=path, notes=tuple(notes))
    problems.extend(check_consistency(case))
    if problems:
        raise CaseError(problems)
    return case


def load_case(path: str | Path | None, overrides: list[str] | None = None) -> Case:
    """Read a TOML case file (``None``: built-in defaults) and validate it.

    Raises
    ------
    CaseError
        Missing or unreadable file, TOML syntax errors, or invalid entries.
    """
    raw: dict[str, Any] = {}
    p: Path | None = None
    if path is not None:
        p = Path(path)
        if not p.is_file():
            raise CaseError([("case file", str(path), "file not found")])
        try:
            raw = tomllib.loads(p.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise CaseError([("case file", str(path), f"not valid TOML: {exc}")]) from None
        except UnicodeDecodeError:
            raise CaseError([("case file", str(path), "not a text (UTF-8) file")]) from None
        p = p.resolve()
    return build_case(raw, overrides, p)


def _close(a: float, b: float, tol: float = 1e-6) -> bool:
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


def check_consistency(case: Case) -> list[tuple[str, Any, str]]:
    """Geometric and cross-key checks; returns the list of problems."""
    g, t, b = case["geometry"], case["track"], case["building"]
    m = case["mesh"]
    out: list[tuple[str, Any, str]] = []

    def order(keys: list[str], values: list[float], what: str) -> None:
        for (k0, v0), (k1, v1) in zip(zip(keys, values), zip(keys[1:], values[1:])):
            if not v0 < v1:
                out.append((f"geometry.{k1}", v1, f"must be greater than {k0} = {v0} ({what})"))

    order(["x0", "x1", "x2", "x3", "x4"], [g[k] for k in ("x0", "x1", "x2", "x3", "x4")],
          "X0 < X1 < X2 < X3 < X4")
    order(["ys4", "ys3", "ys2", "ys1"], [g[k] for k in ("ys4", "ys3", "ys2", "ys1")],
          "YS4 < YS3 < YS2 < YS1 < 0 < YS0")
    if not g["ys1"] < 0:
        out.append(("geometry.ys1", g["ys1"], "must be < 0 (embankment toe on the building side)"))
    if not g["ys0"] > -g["ys1"]:
        out.append(("geometry.ys0", g["ys0"],
                    f"must be > |YS1| = {-g['ys1']} (soil must extend beyond the embankment)"))
    order(["z0", "z1", "z2", "z3", "z4"], [g[k] for k in ("z0", "z1", "z2", "z3", "z4")],
          "Z0 < Z1 < Z2 < Z3 < Z4")
    if out:
        return out

    # track
    if not _close(g["x1"] - g["x0"], t["rigid_length"]):
        out.append(("track.rigid_length", t["rigid_length"],
                    f"must equal X1 - X0 = {g['x1'] - g['x0']:g} m"))
    if not _close(g["x4"] - g["x1"], t["rail_length"]):
        out.append(("track.rail_length", t["rail_length"],
                    f"must equal X4 - X1 = {g['x4'] - g['x1']:g} m (the soil spans the "
                    "flexible rail)"))
    nbays = t["rail_length"] / t["sleeper_spacing"]
    if abs(nbays - round(nbays)) > 1e-6:
        out.append(("track.sleeper_spacing", t["sleeper_spacing"],
                    f"must divide the flexible rail length {t['rail_length']:g} m into whole bays"))
    elif t["n_sleepers"] != round(nbays) + 1:
        out.append(("track.n_sleepers", t["n_sleepers"],
                    f"must be rail_length / sleeper_spacing + 1 = {round(nbays) + 1}"))
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
    # building: its plan is the excavation [X2, X3] x [YS3, YS2]
    length, width = g["x3"] - g["x2"], g["ys2"] - g["ys3"]
    if not _close(g["xbb"], 0.5 * (g["x2"] + g["x3"])):
        out.append(("geometry.xbb", g["xbb"],
                    f"must be the centre of [X2, X3] = {0.5 * (g['x2'] + g['x3']):g} m"))
    if not _close(g["ybb"], 0.5 * (g["ys2"] + g["ys3"])):
        out.append(("geometry.ybb", g["ybb"],
                    f"must be the centre of [YS3, YS2] = {0.5 * (g['ys2'] + g['ys3']):g} m"))
    if not _close(length, width):
        out.append(("geometry.x3", g["x3"],
                    f"the building plan must be square: X3 - X2 = {length:g} m but "
                    f"YS2 - YS3 = {width:g} m"))
    if not g["z0"] < g["zbb"] < g["z1"]:
        out.append(("geometry.zbb", g["zbb"],
                    f"the building base must lie inside the subgrade: Z0 = {g['z0']:g} < ZBB < "
                    f"Z1 = {g['z1']:g} m"))
    half = 0.5 * min(length, width)
    fs, cs, wt = b["footing_size"], b["column_size"], b["wall_thickness"]
    if not fs < half:
        out.append(("building.footing_size", fs,
                    f"two footings must fit side by side: footing_size < {half:g} m"))
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
    basement = g["z1"] - g["zbb"]
    levels = [
        ("building.footing_height", b["footing_height"]),
        ("building.beam_depth", b["footing_height"] + b["beam_depth"]),
        ("geometry.zbb", basement),
        ("building.z_slab1_base", b["z_slab1_base"] - b["beam_depth"]),
        ("building.z_slab1_base", b["z_slab1_base"]),
        ("building.slab_thickness", b["z_slab1_base"] + b["slab_thickness"]),
        ("building.z_slab2_base", b["z_slab2_base"] - b["beam_depth"]),
        ("building.z_slab2_base", b["z_slab2_base"]),
    ]
    names = ["footing top", "grade-beam top", "ground level (Z1 - ZBB)", "storey-1 beam underside",
             "slab 1 underside", "slab 1 top", "storey-2 beam underside", "slab 2 underside"]
    for i in range(1, len(levels)):
        if not levels[i][1] >= levels[i - 1][1] - 1e-12 or (
                i not in (2, 3) and not levels[i][1] > levels[i - 1][1]):
            key = levels[i][0]
            out.append((key, case[key],
                        f"building levels overlap: {names[i]} ({levels[i][1]:g} m above ZBB) "
                        f"must be above {names[i - 1]} ({levels[i - 1][1]:g} m)"))
            break
    if g["x2"] <= g["x1"] or g["x3"] >= g["x4"]:
        out.append(("geometry.x2", g["x2"], "the building must lie inside the soil (X1 < X2, "
                    "X3 < X4)"))

    # mesh
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
    out.extend(_check_mbs(case))
    out.extend(_check_dynamics(case))
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
    return out


def _check_mbs(case: Case) -> list[tuple[str, Any, str]]:
    """Cross-key checks of [vehicle], [irregularity] and [mbs]."""
    out: list[tuple[str, Any, str]] = []
    v, irr, mbs = case["vehicle"], case["irregularity"], case["mbs"]
    if any(o > 0 for o in v["axle_offsets"]) or not v["axle_offsets"]:
        out.append(("vehicle.axle_offsets", v["axle_offsets"],
                    "must be a non-empty list of offsets <= 0 (behind the leading axle)"))
    if v["contact_span"] >= 2.0 * case["track.gauge"]:
        out.append(("vehicle.contact_span", v["contact_span"],
                    f"must be close to the track gauge ({case['track.gauge']:g} m)"))
    if v["wheelbase"] >= v["bogie_spacing"]:
        out.append(("vehicle.wheelbase", v["wheelbase"],
                    f"must be smaller than vehicle.bogie_spacing = {v['bogie_spacing']:g} m"))
    if v["bogie_spacing"] + v["wheelbase"] >= v["car_length"]:
        out.append(("vehicle.car_length", v["car_length"],
                    "must exceed bogie_spacing + wheelbase (the wheels of successive cars "
                    "must not overlap)"))
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


def dumps_toml(tree: dict[str, Any]) -> str:
    """Minimal TOML writer for nested dicts of scalars and lists (provenance only)."""
    lines: list[str] = []

    def scalar(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, float):
            return repr(v)
        if isinstance(v, list):
            return "[" + ", ".join(scalar(x) for x in v) + "]"
        return str(v)

    def walk(node: dict[str, Any], path: str) -> None:
        leaves = {k: v for k, v in node.items() if not isinstance(v, dict)}
        if leaves:
            if path:
                lines.append(f"[{path}]")
            lines.extend(f"{k} = {scalar(v)}" for k, v in leaves.items())
            lines.append("")
        for k, v in node.items():
            if isinstance(v, dict):
                walk(v, f"{path}.{k}" if path else k)

    walk(tree, "")
    return "\n".join(lines)
