"""The check of one value against its schema entry (:func:`check_value`): type, range,
choices, and the tables of its own kinds (soil layers, probe lines, the second train's
vehicle).
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from ..schema import (
    MAX_ROTATION_DEG,
    MAX_SOIL_LAYERS,
    MIN_SOIL_LAYER_THICKNESS,
    PROBE_LINE_KEYS,
    PROBE_LINE_SIDES,
    SOIL_LAYER_KEYS,
    Param,
    iter_params,
)
from ..uncertain_inputs import check_uncertainty_tables

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
