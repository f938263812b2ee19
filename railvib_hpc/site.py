"""The site geometry derived from a case: soil layers, embankment, building plan and turn.

Functions of a validated case that the mesh, the stages and the case checks
(:mod:`railvib_hpc.validation`) share: the soil layers' levels and moduli, the
embankment's lift and toe, the building's plan turned by whole quarter turns and the
twist of the soil round it, the slab levels, the second train's vehicle and each solid
part's material. They read the case with ``case[key]`` only (duck-typed: anything
indexed like a :class:`~railvib_hpc.config.Case` serves), so this module imports no
case module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .schema import MAX_ROTATION_DEG, SOIL_LAYER_PARTS

if TYPE_CHECKING:
    from .config import Case

def soil_layers(case: Case) -> list[dict[str, float]]:
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


def track_lift(case: Case) -> float:
    """How far a fill embankment lifts the track bed above ``geometry.z2, z3, z4`` [m]."""
    return case["track.embankment_height"]


def embankment_toe(case: Case) -> float:
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
#: divided the ring into 0 elements: a ZeroDivisionError, issue 26.)
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


def placed_plan(case: Case) -> tuple[float, float, float, float]:
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


def building_turn(case: Case) -> BuildingTurn:
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


def slab_bases(case: Case) -> list[float]:
    """Underside of every slab above ZBB, bottom up [m]: ``building.slab_bases``, or
    ``z_slab1_base`` and each further storey ``z_slab2_base - z_slab1_base`` higher."""
    b = case["building"]
    if b["slab_bases"]:
        return [float(z) for z in b["slab_bases"]]
    storey = b["z_slab2_base"] - b["z_slab1_base"]
    return [b["z_slab1_base"] + k * storey for k in range(b["storeys"])]


def train2_vehicle(case: Case) -> dict[str, Any]:
    """The second train's vehicle: ``[vehicle]`` with ``[train2.vehicle]``'s keys."""
    return {**case["vehicle"], **case["train2.vehicle"]}


def solid_material(case: Case, name: str) -> dict[str, float]:
    """``E``, ``nu``, ``rho``, ``damping_ratio`` of a material: ``materials.<name>``, or a
    soil layer's (``name`` = ``soil_layer_<k>``, :func:`soil_layers`)."""
    if name in SOIL_LAYER_PARTS:
        layers = soil_layers(case)
        k = SOIL_LAYER_PARTS.index(name)
        if k >= len(layers):
            raise KeyError(f"{name}: the case gives {len(layers)} soil layer(s)")
        return {key: layers[k][key] for key in ("E", "nu", "rho", "damping_ratio")}
    return case[f"materials.{name}"]
