"""The site geometry derived from a case: soil layers, embankment, building plan and turn.

Functions of a validated case that the mesh, the stages and the case checks
(:mod:`railvib_hpc.validation`) share: the soil layers' levels and moduli, the
embankment's lift and toe, the building's plan turned by whole quarter turns and the
twist of the soil round it, the slab levels, the second train's vehicle and each solid
part's material; the keys a case need not give (:func:`derive_keys`: what ``[site]``
sets, X4, the sleepers and the building's centre) and the points of its probe lines
(:func:`line_probes`, :func:`line_ranges`). They read the case with ``case[key]`` only
(duck-typed: anything indexed like a :class:`~railvib_hpc.config.Case` serves), so this
module imports no case module.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .schema import MAX_ROTATION_DEG, SOIL_LAYER_PARTS, CaseView, iter_params


def rayleigh_speed(c_s: float, nu: float) -> float:
    """Rayleigh-wave speed of an elastic half-space [m/s]: the real root in (0, c_s) of
    Rayleigh's equation ``x^3 - 8 x^2 + (24 - 16 k) x - 16 (1 - k) = 0`` in ``x = (c_R /
    c_S)^2``, ``k = (c_S / c_P)^2`` (Achenbach, Wave propagation in elastic solids, 1973,
    eq. 5.62).

    >>> round(rayleigh_speed(100.0, 0.25) / 100.0, 4)     # 0.9194 (Achenbach, Table 5.1)
    0.9194
    """
    k = (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))
    roots = np.roots([1.0, -8.0, 24.0 - 16.0 * k, -16.0 * (1.0 - k)])
    real = roots[(np.abs(roots.imag) < 1e-12) & (roots.real > 0) & (roots.real < 1)].real
    return float(c_s * np.sqrt(real.min()))


def ground_rayleigh_speeds(case: CaseView) -> dict[str, float]:
    """Rayleigh speed [m/s] of each ground material: the soil layers, or the subgrade."""
    layers = soil_layers(case)
    mats = ({name: (lay["c_s"], lay["nu"]) for name, lay in zip(SOIL_LAYER_PARTS, layers)}
            if layers else None)
    if mats is None:
        m = case["materials.subgrade"]
        mats = {"subgrade": (float(np.sqrt(m["E"] / (2.0 * (1.0 + m["nu"]) * m["rho"]))),
                             m["nu"])}
    return {name: rayleigh_speed(c_s, nu) for name, (c_s, nu) in mats.items()}


def soil_layers(case: CaseView) -> list[dict[str, float]]:
    """The case's soil layers, top down, with ``E``, ``c_s``, ``nu``, ``rho``, ``damping_ratio``,
    ``thickness`` and their levels ``z_top``, ``z_bottom`` (m; the last one ends at the base).

    Empty for a homogeneous subgrade (``soil.layers = []``).

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> case = Case.defaults().replace({"soil.layers": [
    ...     {"thickness": 2.0, "c_s": 150.0, "nu": 0.3, "rho": 1800.0},
    ...     {"thickness": 0.0, "E": 4e8, "nu": 0.25, "rho": 2000.0}]})
    >>> [(round(x["z_top"], 2), round(x["z_bottom"], 2), round(x["c_s"], 1)) for x in
    ...  soil_layers(case)]
    [(4.8, 2.8, 150.0), (2.8, 0.0, 282.8)]
    >>> round(soil_layers(case)[0]["E"] / 1e6, 1)  # 2 rho c_s^2 (1 + nu), in MPa
    105.3
    """
    out = []
    z = case["geometry.z1"]
    base = case["geometry.z0"] - case["domain.extra_depth"]
    layers = case["soil.layers"]
    for k, entry in enumerate(layers):
        layer = dict(entry)
        nu, rho = layer["nu"], layer["rho"]
        if "c_s" in layer:
            layer["E"] = 2.0 * rho * layer["c_s"] ** 2 * (1.0 + nu)
        else:
            layer["c_s"] = math.sqrt(layer["E"] / (2.0 * (1.0 + nu) * rho))
        bottom = z - layer["thickness"]
        if k == len(layers) - 1 and layer["thickness"] == 0.0:
            bottom = base
        layer.update(z_top=z, z_bottom=bottom, part=SOIL_LAYER_PARTS[k])
        out.append(layer)
        z = bottom
    return out


def track_lift(case: CaseView) -> float:
    """How far a fill embankment lifts the track bed above ``geometry.z2, z3, z4`` [m]."""
    return case["track.embankment_height"]


def embankment_toe(case: CaseView) -> float:
    """Half-width of the embankment's base on the ground on the building side [m]: |YS1|,
    plus the fill's slope run."""
    return -case["geometry.ys1"] + case["track.embankment_slope"] * track_lift(case)


#: Largest shear ``r dtheta/dr`` of the soil twisted round a turned building
#: (``building.rotation`` beyond whole quarter turns): a cube sheared by cot(25 deg) = 2.14
#: has corner angles of 25 and 155 deg, the least the mesh may keep
#: (:data:`railvib_hpc.mesh.turn.MIN_TWISTED_JACOBIAN`, checked on the mesh's own elements,
#: which are seldom cubes). Measured on a homogeneous soil box (30 modes, docs/sites.md):
#: shear 1 changes the eigenfrequencies by 0.66 times the mesh's own error (h against
#: h/2), shear 2 by 4.2 times.
MAX_TWIST_SHEAR = 1.0 / math.tan(math.radians(25.0))


#: Smallest twist [deg]: a rest beyond whole quarter turns below it is no twist (the turn
#: line of ``railvib check`` and the mesh report says so). A micro-degree moves the corners
#: of the thesis's plan (5.1 m from its centre) by 0.09 um, less than the 0.1 um within
#: which the layouts merge levels (:func:`railvib_hpc.mesh.layout._merge`). (Such twists
#: divided the ring into 0 elements: a ZeroDivisionError.)
TWIST_RESOLUTION_DEG = 1e-6


def quarter_turns(angle_deg: float) -> tuple[int, float]:
    """``building.rotation`` split into whole quarter turns (0-3, counter-clockwise) and
    the rest, within +-45 deg: the quarters turn the building's plan exactly (the
    structured layout is symmetric under them), only the rest twists the soil. A rest
    below :data:`TWIST_RESOLUTION_DEG` is 0.

    Within the schema's +-:data:`~railvib_hpc.schema.MAX_ROTATION_DEG` the split is exact
    (``90 k`` and the rest are exact in floating point).

    Raises
    ------
    ValueError
        For an angle beyond +-:data:`~railvib_hpc.schema.MAX_ROTATION_DEG` or not finite,
        where a floating-point remainder is no longer exact (a validated case has none).

    Examples
    --------
    >>> [quarter_turns(a) for a in (0.0, 30.0, 100.0, -100.0, 270.0, 1e-9)]
    [(0, 0.0), (0, 30.0), (1, 10.0), (3, -10.0), (3, 0.0), (0, 0.0)]
    """
    if not abs(angle_deg) <= MAX_ROTATION_DEG:
        raise ValueError(f"building.rotation = {angle_deg!r}: beyond +-{MAX_ROTATION_DEG:g} deg")
    k = round(angle_deg / 90.0)
    rest = angle_deg - 90.0 * k
    return k % 4, (0.0 if abs(rest) < TWIST_RESOLUTION_DEG else rest)


def turn_quarters(x: Any, y: Any, k: int, centre: tuple[float, float]) -> tuple[Any, Any]:
    """``(x, y)`` turned by ``k`` quarter turns counter-clockwise about ``centre``, with
    no round-off beyond the subtraction and addition of the centre (none at all for
    ``k % 4 == 0``: the points come back as they are).

    Examples
    --------
    >>> turn_quarters(3.0, 1.0, 1, (1.0, 1.0))
    (1.0, 3.0)
    """
    if k % 4 == 0:
        return x, y
    dx, dy = x - centre[0], y - centre[1]
    for _ in range(k % 4):
        dx, dy = -dy, dx
    return centre[0] + dx, centre[1] + dy


def placed_plan(case: CaseView) -> tuple[float, float, float, float]:
    """``(x_lo, x_hi, y_lo, y_hi)``: the building's excavation as meshed, i.e. ``[X2, X3]
    x [YS3, YS2]`` turned by ``building.rotation``'s whole quarter turns about its centre
    (:func:`quarter_turns`; an odd number exchanges its length and width)."""
    g = case["geometry"]
    k, _ = quarter_turns(case["building.rotation"])
    if k % 2 == 0:
        return g["x2"], g["x3"], g["ys3"], g["ys2"]
    cx, cy = 0.5 * (g["x2"] + g["x3"]), 0.5 * (g["ys2"] + g["ys3"])
    hx, hy = 0.5 * (g["x3"] - g["x2"]), 0.5 * (g["ys2"] - g["ys3"])
    return cx - hy, cx + hy, cy - hx, cy + hx


@dataclass(frozen=True)
class BuildingTurn:
    """The twist of the soil round a turned building: the part of the turn beyond its
    whole quarter turns (:func:`quarter_turns`), about the plan centre.

    Every point at distance ``r`` from ``centre`` turns by ``angle * w(r)`` about it
    (:func:`railvib_hpc.mesh.turn.twist_weight`): the building and the soil within
    ``r_in`` rigidly, nothing beyond ``r_out``. The map keeps every circle round the
    centre and is area-preserving (polar Jacobian ``[[1, 0], [r theta'(r), 1]]``), so it
    cannot fold the mesh; its shear ``r theta'(r) = angle / ln(r_out / r_in)`` is what
    limits the angle.

    Attributes
    ----------
    centre
        ``(XBB, YBB)``, the plan centre.
    angle
        Counter-clockwise seen from above [rad], within +-pi/4.
    r_in
        Distance of the plan's corners from the centre [m].
    r_out
        Distance to the nearest straight line the twist must not bend [m].
    bound
        What ``r_out`` reaches (for messages).
    """

    centre: tuple[float, float]
    angle: float
    r_in: float
    r_out: float
    bound: str

    @property
    def shear_per_radian(self) -> float:
        """``r |w'(r)| = 1 / ln(r_out / r_in)``: the soil's shear per radian of turn
        (inf: no room)."""
        if not self.r_out > self.r_in:
            return math.inf
        return 1.0 / math.log(self.r_out / self.r_in)

    @property
    def max_angle(self) -> float:
        """The largest twist [rad] that keeps the shear within :data:`MAX_TWIST_SHEAR`."""
        return MAX_TWIST_SHEAR / self.shear_per_radian

    @property
    def shear(self) -> float:
        """The soil's shear at this turn."""
        return abs(self.angle) * self.shear_per_radian if self.angle else 0.0


def building_turn(case: CaseView) -> BuildingTurn:
    """The twist of a validated case's turned building (``building.rotation`` beyond its
    whole quarter turns) and its ring.

    The ring ends at the nearest of the lines that must stay straight: the embankment's
    toe (or a trench's far face beyond it) on the building side, and the domain's sides
    and ends.
    """
    g, d = case["geometry"], case["domain"]
    cx, cy = g["xbb"], g["ybb"]
    near, what = embankment_toe(case), "the embankment toe"
    tr = case["trench"]
    if tr["width"] > 0 and tr["distance"] + tr["width"] > near:
        near, what = tr["distance"] + tr["width"], "the trench's far face"
    reach = [(-near - cy, what),
             (cy - (g["ys4"] - d["extra_width"]), "the domain's side at YS4 - domain.extra_width"),
             (cx - (g["x1"] - d["extra_length"]), "the domain's end at X1 - domain.extra_length"),
             (g["x4"] + d["extra_length"] - cx, "the domain's end at X4 + domain.extra_length")]
    r_out, bound = min(reach)
    _, rest = quarter_turns(case["building.rotation"])
    return BuildingTurn(centre=(cx, cy), angle=math.radians(rest),
                        r_in=0.5 * math.hypot(g["x3"] - g["x2"], g["ys2"] - g["ys3"]),
                        r_out=r_out, bound=bound)


def slab_bases(case: CaseView) -> list[float]:
    """Underside of every slab above ZBB, bottom up [m]: ``building.slab_bases``, or
    ``z_slab1_base`` and each further storey ``z_slab2_base - z_slab1_base`` higher."""
    b = case["building"]
    if b["slab_bases"]:
        return [float(z) for z in b["slab_bases"]]
    storey = b["z_slab2_base"] - b["z_slab1_base"]
    return [b["z_slab1_base"] + k * storey for k in range(b["storeys"])]


def train2_vehicle(case: CaseView) -> dict[str, Any]:
    """The second train's vehicle: ``[vehicle]`` with ``[train2.vehicle]``'s keys."""
    return {**case["vehicle"], **case["train2.vehicle"]}


def solid_material(case: CaseView, name: str) -> dict[str, float]:
    """``E``, ``nu``, ``rho``, ``damping_ratio`` of a material: ``materials.<name>``, or a
    soil layer's (``name`` = ``soil_layer_<k>``, :func:`soil_layers`)."""
    if name in SOIL_LAYER_PARTS:
        layers = soil_layers(case)
        k = SOIL_LAYER_PARTS.index(name)
        if k >= len(layers):
            raise KeyError(f"{name}: the case gives {len(layers)} soil layer(s)")
        return {key: layers[k][key] for key in ("E", "nu", "rho", "damping_ratio")}
    return case[f"materials.{name}"]


# --------------------------------------------------------------------------------------
# the keys a case need not give: the site keys and the derived geometry keys

#: Decimals to which computed lengths are rounded (1 nm, far below the 0.1 um within
#: which the layouts merge lines): X1 + 21.6 is then the APDL script's X4 = 24.6 exactly.
DERIVED_DECIMALS = 9
#: The keys each ``[site]`` key sets (docs/sites.md); a case giving one of them with another
#: value is refused.
SITE_SETS: dict[str, tuple[str, ...]] = {
    "site.building_distance": ("geometry.ys2", "geometry.ys3", "geometry.ybb", "geometry.ys4"),
    "site.building_width": ("geometry.ys3", "geometry.ybb", "geometry.ys4"),
    "site.building_length": ("geometry.x2", "geometry.x3", "geometry.xbb"),
    "site.track_length": ("track.rail_length", "geometry.x4", "geometry.x2", "geometry.x3",
                          "geometry.xbb"),
    "site.soil_depth": ("geometry.z0", "domain.extra_depth"),
}
_DEFAULTS = {key: param.default for key, param in iter_params()}
#: The geometry keys of the building's plan (set by the site keys only with a building).
BUILDING_KEYS = ("geometry.x2", "geometry.x3", "geometry.xbb", "geometry.ys2", "geometry.ys3",
                 "geometry.ybb")

Problem = tuple[str, Any, str]


def _round(x: float) -> float:
    return round(float(x), DERIVED_DECIMALS)


def _close(a: float, b: float, tol: float = 1e-6) -> bool:
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


def frame_problems(values: Mapping[str, Any], axis: str, key: str, plan: float
                   ) -> list[Problem]:
    """Whether the building's frame fits a plan ``plan`` m long along ``axis`` (``x``:
    along the track, ``y``: across it), for the problems of the key ``key`` that sets it.

    The column lines sit ``footing_size / 2`` inside the plan; the spans between them are
    ``building.spans_<axis>`` (their sum plus a footing is the plan) or ``bays`` equal ones,
    each wider than a footing: the plan must exceed ``(bays + 1) x footing_size``.

    Examples
    --------
    >>> from railvib_hpc.config import defaults
    >>> from railvib_hpc.io.products import flat_case
    >>> [(key, value, text)] = frame_problems(flat_case(defaults()), "y",
    ...                                       "site.building_width", 0.01)
    >>> print(key, value, text[:60])
    site.building_width 0.01 must be > 2.4 m: the building's frame across the track needs
    """
    fs, bays = values["building.footing_size"], values[f"building.bays_{axis}"]
    spans = list(values[f"building.spans_{axis}"])
    where = "along the track" if axis == "x" else "across the track"
    if spans:
        need = sum(spans) + fs
        if _close(plan, need):
            return []
        return [(key, plan, f"must be {need:g} m: building.spans_{axis} add up to "
                 f"{sum(spans):g} m between the outer column lines, which sit footing_size/2 "
                 f"= {fs / 2:g} m inside the plan (or leave building.spans_{axis} empty for "
                 "equal spans)")]
    need = (bays + 1) * fs
    if plan > need:
        return []
    return [(key, plan, f"must be > {need:g} m: the building's frame {where} needs "
             f"{bays + 1} column lines (building.bays_{axis} = {bays} bay"
             f"{'s' if bays > 1 else ''}) with footings of building.footing_size = {fs:g} m "
             f"and a span wider than a footing between them; allowed: > {need:g} m, or "
             "fewer bays or smaller footings")]


def _site_y(values: Mapping[str, Any], active: dict[str, float], base) -> tuple[dict, list]:
    """ys2, ys3, ybb, ys4 of ``site.building_distance`` / ``building_width``."""
    out: dict[str, float] = {}
    problems: list[Problem] = []
    dist, width = active.get("site.building_distance"), active.get("site.building_width")
    if (dist is None and width is None) or not values["building.present"]:
        return out, problems           # (no building: its site keys are refused as off)
    ys2 = -dist if dist is not None else base("geometry.ys2")
    if width is None:
        width = base("geometry.ys2") - base("geometry.ys3")
    margin = base("geometry.ys3") - base("geometry.ys4")
    toe = embankment_toe(values)
    if dist is not None and not dist > toe:
        problems.append(("site.building_distance", dist,
                         f"must be > {toe:g} m, the embankment toe (|geometry.ys1| + "
                         "track.embankment_slope x track.embankment_height): the building "
                         "stands beside the embankment"))
    if "site.building_width" in active:
        problems.extend(frame_problems(values, "y", "site.building_width", width))
    if dist is not None:
        out["geometry.ys2"] = _round(ys2)
    out.update({"geometry.ys3": _round(ys2 - width), "geometry.ybb": _round(ys2 - width / 2),
                "geometry.ys4": _round(ys2 - width - margin)})
    return out, problems


def _site_x(values: Mapping[str, Any], active: dict[str, float], base,
            rail_length: float) -> tuple[dict, list]:
    """x2, x3, xbb of ``site.building_length`` / ``track_length`` (the building centred on
    the track with the latter), its start on a sleeper."""
    out: dict[str, float] = {}
    track, length = active.get("site.track_length"), active.get("site.building_length")
    if (track is None and length is None) or not values["building.present"]:
        return out, []                  # (no building: site.track_length sets the soil only)
    x1, sp = values["geometry.x1"], values["track.sleeper_spacing"]
    if length is None:
        length = base("geometry.x3") - base("geometry.x2")
    centre = x1 + rail_length / 2 if track is not None else base("geometry.xbb")
    x2 = x1 + sp * round((centre - length / 2 - x1) / sp)
    out = {"geometry.x2": _round(x2), "geometry.x3": _round(x2 + length),
           "geometry.xbb": _round(x2 + length / 2)}
    if "site.building_length" in active:
        frame = frame_problems(values, "x", "site.building_length", length)
        if frame:
            return out, frame
    if not (x2 > x1 and x2 + length < x1 + rail_length):
        key = "site.track_length" if track is not None else "site.building_length"
        return out, [(key, active[key],
                      f"the building ({length:g} m long, its start on a sleeper) must lie "
                      f"beside the flexible track of {rail_length:g} m, inside the soil: "
                      f"give site.track_length >= {length + 2 * sp:g} m or a shorter "
                      "building")]
    return out, []


def _site_z(values: Mapping[str, Any], active: dict[str, float], base) -> tuple[dict, list]:
    """z0 and ``domain.extra_depth`` of ``site.soil_depth`` (the reflection study's rule:
    deeper than Z1 - Z0 adds extra depth, shallower raises the base)."""
    depth = active.get("site.soil_depth")
    if depth is None:
        return {}, []
    z1, z0 = values["geometry.z1"], base("geometry.z0")
    out = ({"geometry.z0": z0, "domain.extra_depth": _round(depth - (z1 - z0))}
           if depth >= z1 - z0 else {"geometry.z0": _round(z1 - depth), "domain.extra_depth": 0.0})
    basement = z1 - values["geometry.zbb"]
    if values["building.present"] and not depth > basement:
        return out, [("site.soil_depth", depth,
                      f"must be > {basement:g} m, the depth of the building's base below the "
                      "ground (geometry.z1 - geometry.zbb)")]
    return out, []


def derive_keys(values: Mapping[str, Any], given: Collection[str]
                ) -> tuple[dict[str, Any], list[Problem]]:
    """The values of the keys a case need not give: what its ``[site]`` keys set
    (:data:`SITE_SETS`), and the derived keys it leaves out (:attr:`Param.derived
    <railvib_hpc.schema.Param>`: X4 from the rail length, or the rail length from X4; the
    sleepers; the building's centre).

    Parameters
    ----------
    values
        The flat case (``{dotted key: value}``: defaults, preset and the given entries,
        type-checked).
    given
        The keys the case gives.

    Returns
    -------
    derived : dict
        ``{key: value}`` to set (lengths rounded to :data:`DERIVED_DECIMALS`).
    problems : list
        A given key that a site key sets to another value (one line naming both), and site
        keys the site cannot take.

    Examples
    --------
    >>> from railvib_hpc.config import defaults
    >>> from railvib_hpc.io.products import flat_case
    >>> flat = flat_case(defaults())
    >>> derive_keys({**flat, "track.rail_length": 30.0}, {"track.rail_length"})[0]
    {'geometry.x4': 33.0, 'track.n_sleepers': 51, 'geometry.xbb': 16.2, 'geometry.ybb': -13.5}
    >>> flat["site.building_distance"] = 12.0
    >>> derive_keys(flat, {"site.building_distance", "geometry.ys2"})[1]  # doctest: +ELLIPSIS
    [('geometry.ys2', -9.9, 'site.building_distance = 12 m sets it to -12: ...')]
    """
    active = {s: float(values[s]) for s in SITE_SETS if values[s] > 0}
    set_by: dict[str, str] = {}
    for s in active:
        for key in SITE_SETS[s]:
            set_by.setdefault(key, s)

    def base(key: str) -> float:                  # what a site key starts from
        return _DEFAULTS[key] if key in set_by else values[key]

    x1 = values["geometry.x1"]
    if "site.track_length" in active:
        rail = active["site.track_length"]
    elif "geometry.x4" in given and "track.rail_length" not in given:
        rail = values["geometry.x4"] - x1
    else:
        rail = values["track.rail_length"]
    out: dict[str, Any] = {}
    problems: list[Problem] = []
    sp = values["track.sleeper_spacing"]
    if "site.track_length" in active:
        bays = rail / sp
        if abs(bays - round(bays)) > 1e-6:
            lo, hi = math.floor(bays) * sp, math.ceil(bays) * sp
            problems.append(("site.track_length", rail,
                             f"must be a whole number of sleeper bays (track.sleeper_spacing "
                             f"= {sp:g} m), e.g. {_round(lo):g} or {_round(hi):g} m"))
        out["track.rail_length"] = rail
    for part in (_site_y(values, active, base), _site_x(values, active, base, rail),
                 _site_z(values, active, base)):
        out.update(part[0])
        problems.extend(part[1])
    if "track.rail_length" not in given and "track.rail_length" not in out:
        out["track.rail_length"] = _round(rail)
    if "geometry.x4" not in given or "geometry.x4" in set_by:
        out["geometry.x4"] = _round(x1 + rail)
    if "track.n_sleepers" not in given:
        out["track.n_sleepers"] = int(round(rail / sp)) + 1
    now = {**values, **out}
    for key, pair in (("geometry.xbb", ("geometry.x2", "geometry.x3")),
                      ("geometry.ybb", ("geometry.ys2", "geometry.ys3"))):
        if key not in given and key not in out:
            out[key] = _round(0.5 * (now[pair[0]] + now[pair[1]]))
    for key, s in set_by.items():
        if key in given and key in out and not _close(values[key], out[key]):
            problems.append((key, values[key], f"{s} = {active[s]:g} m sets it to "
                             f"{out[key]:g}: give one of them (docs/sites.md)"))
    return {k: v for k, v in out.items() if k not in given or k in set_by}, problems


# --------------------------------------------------------------------------------------
# probe lines ([[probes.line]]): free-field points on the ground


@dataclass(frozen=True)
class LineProbe:
    """One point of a probe line: a probe of role ``free_field`` on the ground.

    Attributes
    ----------
    name
        ``<line>_<d>m`` (:func:`line_probe_name`).
    line
        The line's name.
    distance
        From the centreline of track 1, across the track [m].
    side
        ``"building"`` (y = -distance) or ``"away"`` (y = +distance).
    point
        ``(x, y, z)``, z the ground level ``geometry.z1`` [m].
    """

    name: str
    line: str
    distance: float
    side: str
    point: tuple[float, float, float]


def line_probe_name(line: str, distance: float) -> str:
    """The probe name of a line's point: ``<line>_<d>m``, d in :func:`format` ``g``.

    Examples
    --------
    >>> line_probe_name("ff", 10.0), line_probe_name("ff", 12.5)
    ('ff_10m', 'ff_12.5m')
    """
    return f"{line}_{distance:g}m"


def line_x(case: CaseView, entry: Mapping[str, Any]) -> float:
    """The position of a probe line along the track: its ``x``, or the middle of the
    flexible track."""
    if "x" in entry:
        return float(entry["x"])
    return case["geometry.x1"] + 0.5 * case["track.rail_length"]


def line_probes(case: CaseView) -> dict[str, LineProbe]:
    """The points of every ``[[probes.line]]`` of a validated case, by probe name, in the
    order of the lines and their distances."""
    out = {}
    z = case["geometry.z1"]
    for entry in case["probes.line"]:
        x, sign = line_x(case, entry), (-1.0 if entry["side"] == "building" else 1.0)
        for d in entry["distances"]:
            name = line_probe_name(entry["name"], d)
            out[name] = LineProbe(name, entry["name"], float(d), entry["side"],
                                  (x, sign * float(d), z))
    return out


def _plan_chord(case: CaseView, point: tuple[float, float], direction: tuple[float, float]
                ) -> tuple[float, float] | None:
    """The open interval of ``t`` where the line ``point + t direction`` runs through the
    building's plan ``[X2, X3] x [YS3, YS2]`` turned by ``building.rotation`` about its
    centre; None where it passes by (the case read by dotted keys: a flat mapping will do)."""
    g = {k: case[f"geometry.{k}"] for k in ("x2", "x3", "ys2", "ys3")}
    cx, cy = 0.5 * (g["x2"] + g["x3"]), 0.5 * (g["ys2"] + g["ys3"])
    hx, hy = 0.5 * (g["x3"] - g["x2"]), 0.5 * (g["ys2"] - g["ys3"])
    th = math.radians(case["building.rotation"])
    c, s = math.cos(th), math.sin(th)
    px, py = point[0] - cx, point[1] - cy
    dx, dy = direction
    lo, hi = -math.inf, math.inf
    # the line in the building's own frame: q = R(-th) (p - centre), affine in t
    for a, b, h in ((c * px + s * py, c * dx + s * dy, hx),
                    (-s * px + c * py, -s * dx + c * dy, hy)):
        if abs(b) < 1e-12:
            if not abs(a) < h - 1e-9 * max(h, 1.0):      # on a face: beside the plan
                return None
            continue
        t0, t1 = sorted(((-h - a) / b, (h - a) / b))
        lo, hi = max(lo, t0), min(hi, t1)
    return (lo, hi) if lo < hi else None


def _footprint(case: CaseView, x: float) -> tuple[float, float] | None:
    """The open interval of distances (building side, y = -d) where the line at ``x`` runs
    through the building's plan (turned by ``building.rotation``); None where it passes
    by."""
    return _plan_chord(case, (x, 0.0), (0.0, -1.0))


def load_path_crossing(case: CaseView) -> tuple[float, float] | None:
    """Where the moving surface load's path (``track.count = 0``: the line ``y = load.y``
    on the ground) runs through the building's plan: the interval of x [m] that the loads
    pass over there (their spreading ``load.half_width`` included), None where they never
    reach it.

    The loads cover x from the last one's start (``load.x_start`` + the smallest offset)
    to where the leading one is at the end of the run (``load.x_end``, 0: the soil's end,
    plus the offsets' length and ``load.speed`` x ``load.t_after``).

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> flat = Case.defaults().flat()            # (the case refuses such a path)
    >>> load_path_crossing({**flat, "track.count": 0, "load.y": -13.0})
    (12.6, 19.8)
    >>> print(load_path_crossing({**flat, "track.count": 0, "load.y": -13.0,
    ...                           "load.x_end": 10.0}))
    None
    """
    if not case["building.present"]:
        return None
    ld = {k: case[f"load.{k}"] for k in ("y", "offsets", "x_start", "x_end", "half_width",
                                          "speed", "t_after")}
    chord = _plan_chord(case, (0.0, ld["y"]), (1.0, 0.0))
    if chord is None:
        return None
    first = min(ld["offsets"] or [0.0])
    x_end = ld["x_end"] or case["geometry.x4"] + case["domain.extra_length"]
    lo = ld["x_start"] + first - ld["half_width"]
    hi = x_end - first + ld["speed"] * ld["t_after"] + ld["half_width"]
    a, b = max(lo, chord[0]), min(hi, chord[1])
    return (_round(chord[0]), _round(chord[1])) if a < b else None


def line_ranges(case: CaseView, x: float, side: str) -> list[tuple[float, float]]:
    """The distances [m] a probe line at ``x`` may reach on ``side``: closed intervals of
    the ground between the embankment toe and the soil's edge, without the building's plan
    and an open trench (building side).

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> line_ranges(Case.defaults(), 13.8, "building")
    [(4.25, 9.9), (17.1, 29.1)]
    >>> line_ranges(Case.defaults(), 5.0, "away")
    [(4.25, 8.25)]
    """
    toe = embankment_toe(case) if case["track.count"] else 0.0    # 0: the bare soil
    if side == "away":
        near = (case["track.spacing"] if case["track.count"] == 2 else 0.0) + toe
        return [(near, case["geometry.ys0"])] if near < case["geometry.ys0"] else []
    out = [(toe, -(case["geometry.ys4"] - case["domain.extra_width"]))]
    tr = case["trench"]
    holes = [_footprint(case, x) if case["building.present"] else None]
    if tr["type"] == "open" and tr["width"] > 0:
        holes.append((tr["distance"], tr["distance"] + tr["width"]))
    for hole in holes:
        if hole is None:
            continue
        out = [piece for lo, hi in out for piece in ((lo, min(hi, hole[0])),
                                                      (max(lo, hole[1]), hi))
               if piece[0] < piece[1]]
    return [(_round(lo), _round(hi)) for lo, hi in out]


def site_lines(case: CaseView) -> list[str]:
    """What ``railvib check`` says of the ``[site]`` keys given (and the geometry they set)
    and of the probe lines.

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> case = Case.defaults().replace({"site.building_distance": 15.0, "probes.line": [
    ...     {"name": "ff", "distances": [5.0, 30.0]}]})
    >>> for line in site_lines(case):
    ...     print(line)  # doctest: +NORMALIZE_WHITESPACE
    site: building_distance 15 m -> ys2 -15, ys3 -22.2, ybb -18.6, ys4 -34.2 m
    probe line ff: 2 free-field points 5-30 m from track 1 (building side) at x = 13.8 m:
    ff_5m, ff_30m
    """
    out = []
    given = [s for s in SITE_SETS if case[s] > 0]
    if given:
        keys = list(dict.fromkeys(k for s in given for k in SITE_SETS[s]
                                  if case["building.present"] or k not in BUILDING_KEYS))
        out.append("site: " + ", ".join(f"{s.split('.')[1]} {case[s]:g}" for s in given)
                   + " m -> " + ", ".join(f"{k.split('.')[1]} {case[k]:g}" for k in keys)
                   + " m")
    for entry in case["probes.line"]:
        d = entry["distances"]
        names = [line_probe_name(entry["name"], v) for v in d]
        out.append(f"probe line {entry['name']}: {len(d)} free-field points {min(d):g}-"
                   f"{max(d):g} m from track 1 ({entry['side']} side) at x = "
                   f"{line_x(case, entry):g} m: {', '.join(names)}")
    return out
