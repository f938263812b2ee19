"""The case-file schema: every key, its default, type, unit and meaning.

Defaults reproduce the model the thesis actually solved (the ANSYS APDL script
of its Appendix A). Where the thesis's Table I disagrees, Table I's values are
available as the preset ``table1`` (see :data:`PRESETS`).

Conventions
-----------
* x runs along the track, y across it (the building lies at negative y),
  z upwards; the origin is at the start of the first rigid rail, ground
  bottom at ``z0``.
* Building coordinates (``building.*``) are measured from the building base
  point (``geometry.xbb``, ``geometry.ybb``, ``geometry.zbb``), like the APDL
  script's local system 11.
* Beam sections: ``iyy`` is the second moment of area for bending in the
  vertical plane (about the horizontal axis normal to the beam axis), ``izz``
  for bending in the horizontal plane, ``j`` the torsion constant.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

from .applies import Condition, above, all_of, any_of, includes, is_, is_not, not_empty
from .assess.standards import BUILDING_USES, FTA_EVENTS, PERIODS, STANDARDS
from .sections import APDL_RAIL, APDL_SLEEPER, SectionProperties
from .uncertainty.reduced import MODELS as UQ_MODELS
from .uncertainty.reduced import REDUCED_TOL
from .uncertainty.sampling import METHODS as SAMPLING_METHODS


@dataclass(frozen=True)
class Param:
    """One case-file key.

    Parameters
    ----------
    default
        Default value (the thesis's APDL value where one exists).
    kind
        ``"float"``, ``"int"``, ``"str"``, ``"bool"``, ``"floats"`` (list of
        numbers), ``"ints"`` (list of integers), ``"bools"`` (list of true/false),
        ``"strs"`` (list of strings) or ``"triples"`` (list of ``[a, b, c]`` numbers).
    unit
        SI unit, ``"-"`` for dimensionless.
    doc
        One-line meaning (shown in the README reference and in errors).
    check
        ``"pos"`` (> 0), ``"nonneg"`` (>= 0), ``"poisson"`` (0 <= nu < 0.5),
        ``"fraction"`` (0 <= x < 1), ``"unit"`` (0 <= x <= 1), ``"refinement"`` (0 < x <= 6),
        ``"angle"`` (``|x| <=`` :data:`MAX_ROTATION_DEG`), ``"name"`` (letters, digits and
        ``_.+-``) or ``None``; applied to every entry of a list.
    choices
        Allowed values for strings (or list items).
    unique
        Lists only: at least one entry, all distinct.
    maximum
        Largest allowed value (numbers; ``None``: no bound beyond ``check``); its reason
        belongs in ``doc``.
    source
        Where the default comes from (the thesis's APDL script, its tables, the literature),
        shown in the case reference; ``""`` for the numerical settings of this program
        (solver tolerances, output steps...). A preset's values carry their own
        (:data:`PRESET_SOURCES`).
    derived
        How the value follows from other keys when the case does not give it (``""``: it
        does not; :func:`railvib_hpc.site.derive_keys` computes it; a given value must
        agree). The baseline case lists such a key commented out.
    applies
        The condition under which the key's feature is on (:mod:`railvib_hpc.applies`;
        ``None``: always). Where it does not hold, the key must keep its default (the
        preset's value): :func:`railvib_hpc.validation.feature_key_problems` refuses any
        other with "applies to ... only", the one rule every key obeys.
    """

    default: Any
    kind: str
    unit: str
    doc: str
    check: str | None = None
    choices: tuple[str, ...] = field(default_factory=tuple)
    unique: bool = False
    maximum: float | None = None
    source: str = ""
    derived: str = ""
    applies: Condition | None = None


_APDL = "thesis App. A (APDL)"
_T1 = "thesis Table I"
_T2 = "thesis Table II"
_RAIL_SEC = "App. A SECTYPE,1,BEAM,I / SECDATA,0.1524,0.07,0.19,0.0165,0.045,0.0175"
_SLP_SEC = "App. A SECTYPE,2,BEAM,QUAD / SECDATA,-0.135,-0.11,.135,-.11,.090,.11,-.090,.11"
_MANCHESTER = "Manchester Benchmark vehicle 1 (Iwnicki, Veh. Syst. Dyn. 30 (1998) 295-313)"
#: The modal damping of the thesis, the source of every material's damping ratio.
_THESIS_DAMPING = "thesis §2.1: 3 % modal damping"
_OTHER_DAMPING = "not in the thesis: the 3 % of the other materials"


#: Probes of the building whose responses the studies compare (names of the mesh probes).
BUILDING_PROBES = ("footing", "basement_wall", "slab1", "slab2")


def _study_probes() -> Param:
    return Param(list(BUILDING_PROBES), "strs", "-",
                 "mesh probes whose responses are compared (the building probes)", "name",
                 unique=True)


def _study_solver(what: str) -> Param:
    """``study.<kind>.solver`` of the studies that can run their variants either way."""
    return Param("modal", "str", "-",
                 "modal (modes + mbs, the thesis's method) or direct (railvib transient: the "
                 "full model in the time domain, causal, resolved up to transient.f_max where "
                 f"the mesh resolves it, else less, as its dispersion check says; {what})",
                 choices=("modal", "direct"))


def _mat(e: float, nu: float, rho: float, what: str, source: str | tuple[str, str, str],
         damping_source: str = _THESIS_DAMPING, applies: Condition | None = None
         ) -> dict[str, Param]:
    """``materials.<name>``: ``source`` of E, nu and rho (one for all three, or each its
    own); ``applies``: when the material is in the model (all four keys)."""
    e_src, nu_src, rho_src = (source,) * 3 if isinstance(source, str) else source
    return {
        "E": Param(e, "float", "Pa", f"Young's modulus of the {what}", "pos", source=e_src,
                   applies=applies),
        "nu": Param(nu, "float", "-", f"Poisson's ratio of the {what}", "poisson",
                    source=nu_src, applies=applies),
        "rho": Param(rho, "float", "kg/m^3", f"density of the {what}", "pos", source=rho_src,
                     applies=applies),
        "damping_ratio": Param(0.03, "float", "-",
                               f"damping ratio of the {what}, used when modal.damping = "
                               "'strain_energy'", "fraction", source=damping_source,
                               applies=applies),
    }


def _mp(number: int, ex: str, prxy: str, dens: str) -> tuple[str, str, str]:
    """The sources of E, nu and rho of APDL material ``number``: its MP commands, as written."""
    return (f"{_APDL}: MP,EX,{number},{ex}", f"{_APDL}: MP,PRXY,{number},{prxy}",
            f"{_APDL}: MP,DENS,{number},{dens}")


def _section(section: SectionProperties, what: str, horizontal: str,
             secdata: str) -> dict[str, Param]:
    """``sections.<name>``: the APDL section's properties, each citing its ``SECDATA``
    (the track's: they apply with a track only)."""
    src = f"{secdata} (railvib_hpc.sections)"
    return {key: Param(p.default, p.kind, p.unit, p.doc, p.check, source=p.source,
                       applies=ON_TRACK)
            for key, p in _section_params(section, what, horizontal, src).items()}


def _section_params(section: SectionProperties, what: str, horizontal: str,
                    src: str) -> dict[str, Param]:
    return {
        "area": Param(section.area, "float", "m^2", f"{what} cross-section area", "pos",
                      source=src),
        "iyy": Param(section.iyy, "float", "m^4", f"{what} second moment, vertical bending",
                     "pos", source=src),
        "izz": Param(section.izz, "float", "m^4", f"{what} second moment, {horizontal} bending",
                     "pos", source=src),
        "j": Param(section.j, "float", "m^4", f"{what} torsion constant", "pos", source=src),
        "shear_coefficient_y": Param(section.shear_coefficient_y, "float", "-",
                                     "Timoshenko shear coefficient, vertical bending", "pos",
                                     source=src),
        "shear_coefficient_z": Param(section.shear_coefficient_z, "float", "-",
                                     f"Timoshenko shear coefficient, {horizontal} bending",
                                     "pos", source=src),
    }


def _apdl_coordinate(name: str, value: float, what: str,
                     applies: Condition | None = None) -> Param:
    """``geometry.<name>``: the APDL script's coordinate ``name`` (cited with its value)."""
    return Param(value, "float", "m", f"{name}: {what}", source=f"{_APDL}: {name}={value:g}",
                 applies=applies)


#: Most soil layers a case may give (``[[soil.layers]]``); each is a part of its own.
MAX_SOIL_LAYERS = 8
#: Thinnest soil layer [m] (``[[soil.layers]]``, also the last one's share down to the
#: base): a program limit. A layer is at least one band of elements; thinner than 0.1 m
#: it would be a band of hexahedra flatter than 1:3 even at the 0.3 m the layouts use
#: across the building (``mesh.size_building_y``), 1:6 at the far field's 0.6 m
#: (``mesh.size_far``). (Below 0.1 um the layouts merged it away: it vanished.)
MIN_SOIL_LAYER_THICKNESS = 0.1
#: Largest ``|building.rotation|`` [deg]: one whole turn either way. Beyond it a float no
#: longer holds the angle to a degree (at 1e17 deg the spacing of floats is 16 deg), so
#: the whole quarter turns and the rest (:func:`railvib_hpc.site.quarter_turns`) would
#: be wrong; within it they are exact.
MAX_ROTATION_DEG = 360.0
#: Most storeys of the building (``building.storeys``): a program limit. The layout's
#: cost grows with the square of the storeys (``railvib check``: about 4 s at 100, 25 s at
#: 300, 107 s at 1000, out of memory at 1e8: issue 26), and 100 storeys (380 m at the
#: thesis's storey height) is far beyond what the model's frame, one column size and one
#: slab thickness for every storey, represents.
MAX_STOREYS = 100
#: Parts of the layered soil, top down (they replace ``subgrade`` when layers are given).
SOIL_LAYER_PARTS = tuple(f"soil_layer_{k}" for k in range(1, MAX_SOIL_LAYERS + 1))
#: Parts of the model, in the order of their part ids (id = index + 1); the soil layers come
#: last so that the thesis's part ids stay what they were.
#: Elastic interfaces (``[usp]``, ``[ballast_mat]``, ``[isolation]``): three zero-length
#: directional springs per node pair (:mod:`railvib_hpc.mesh.interfaces`).
INTERFACE_PARTS: dict[str, tuple[str, str, str]] = {
    kind: (f"{kind}_x", f"{kind}_y", f"{kind}_z") for kind in ("usp", "ballast_mat",
                                                               "isolation")}
PARTS: tuple[str, ...] = (
    "rail", "rigid_rail", "sleeper", "pad_x", "pad_y", "pad_z",
    "ballast", "subballast", "subgrade", "footing", "column", "beam", "slab", "wall",
    *SOIL_LAYER_PARTS, "trench_fill", "wib",
    *(p for parts in INTERFACE_PARTS.values() for p in parts), "fill",
)
#: Mitigation measures in the soil (``[trench]``, ``[wib]``): parts of their own material.
MEASURE_PARTS = ("trench_fill", "wib")
SOLID_PARTS = ("ballast", "subballast", "subgrade", "footing", "column", "beam", "slab", "wall",
               *SOIL_LAYER_PARTS, *MEASURE_PARTS, "fill")
BUILDING_PARTS = ("footing", "column", "beam", "slab", "wall")
#: Material of each solid part: ``materials.<name>``, or the soil layer of the same name
#: (:func:`railvib_hpc.site.solid_material`).
SOLID_MATERIAL = {"ballast": "ballast", "subballast": "subballast", "subgrade": "subgrade",
                  **{p: "concrete" for p in BUILDING_PARTS}, **{p: p for p in SOIL_LAYER_PARTS},
                  "trench_fill": "trench_fill", "wib": "wib", "fill": "fill"}
#: The soil parts (absorbing faces may cut only these).
SOIL_PARTS = ("ballast", "subballast", "subgrade", *SOIL_LAYER_PARTS, *MEASURE_PARTS, "fill")
#: Keys of one ``[[soil.layers]]`` entry: (required, meaning). Exactly one of E and c_s.
SOIL_LAYER_KEYS: dict[str, tuple[bool, str]] = {
    "thickness": (True, f"thickness in m (>= {MIN_SOIL_LAYER_THICKNESS:g}; the last layer may "
                        "give 0: down to the base)"),
    "E": (False, "Young's modulus in Pa (> 0; or c_s)"),
    "c_s": (False, "shear-wave speed in m/s (> 0; or E): E = 2 rho c_s^2 (1 + nu)"),
    "nu": (True, "Poisson's ratio (0 <= nu < 0.5)"),
    "rho": (True, "density in kg/m^3 (> 0)"),
    "damping_ratio": (False, "damping ratio (0 <= x < 1; default 0.03), used by "
                             "modal.damping = 'strain_energy' and damping.model = 'per_material'"),
}
#: Sides of the track a probe line may run to (``[[probes.line]]``, ``side``).
PROBE_LINE_SIDES = ("building", "away")
#: Keys of one ``[[probes.line]]`` entry: (required, meaning).
PROBE_LINE_KEYS: dict[str, tuple[bool, str]] = {
    "name": (True, "name of the line (letters, digits and _.+-); its points are the probes "
                   "<name>_<d>m"),
    "distances": (True, "distances in m from the centreline of track 1, across the track, "
                        "on the ground surface (a non-empty list of distinct numbers > 0)"),
    "side": (False, "side of the track: 'building' (default: towards the building, y < 0) or "
                    "'away' (y > 0)"),
    "x": (False, "position along the track in m (default: the middle of the flexible track, "
                 "geometry.x1 + track.rail_length / 2)"),
}
#: Foundations of the building (``building.foundation``).
FOUNDATION_TYPES = ("pad", "strip", "raft")
BEAM_PARTS = ("rail", "rigid_rail", "sleeper")
PAD_PARTS = ("pad_x", "pad_y", "pad_z")
#: Groups of parts that ``transient.implicit_parts`` may name (the IMEX engine's implicit
#: partition): the track's beams and springs, the building and its base isolation.
IMPLICIT_GROUPS: dict[str, tuple[str, ...]] = {
    "track": (*BEAM_PARTS, *PAD_PARTS, *INTERFACE_PARTS["usp"], *INTERFACE_PARTS["ballast_mat"]),
    "building": (*BUILDING_PARTS, *INTERFACE_PARTS["isolation"]),
}
PART_ID = {name: i + 1 for i, name in enumerate(PARTS)}
#: Roles of probe points, carried as metadata from where a probe is defined (the mesh
#: layout's named probes, ``output.probe_roles`` for the user's): ``floor`` a floor slab
#: (DIN 4150-3 floor limit), ``wall`` a building wall, ``foundation`` a footing or
#: foundation, ``ground`` the ground surface, ``free_field`` a point of a probe line
#: (``[[probes.line]]``, :func:`railvib_hpc.site.line_probes`) on the ground.
PROBE_ROLES = ("floor", "wall", "foundation", "ground", "free_field")
#: Role of a user probe without one.
DEFAULT_PROBE_ROLE = "ground"
#: Conditions of a truncation face of the soil box (``[boundary]``).
BOUNDARY_TYPES = ("fixed", "roller", "free", "absorbing", "caughey", "pml")
#: Default frequency shift of the perfectly matched layers [1/s]: 2 pi x 0.5 Hz, half the
#: lowest one-third-octave band assessed (1 Hz); there omega / |i omega + alpha| = 0.89.
PML_ALPHA = 3.14159
#: The truncation faces of the soil box: x = min/max, y = min/max, z = min.
BOUNDARY_FACES = ("x_min", "x_max", "y_min", "y_max", "base")
#: The time integration engines of ``railvib transient`` (``transient.engine``).
from .time_engines import ENGINE_NAMES as TRANSIENT_ENGINES, PML_ENGINE_NAMES as PML_ENGINES  # noqa: E402, F401, I001
#: The engines that take ``pml`` faces, which the refusals of a layer name: all of them
#: (the direct engine's layer is implicit, the explicit and imex engines' explicit with
#: ``M_e1`` and ``M_e2`` at the full step or in K_eff; docs/transient.md). An engine left
#: out here is refused with a layer (both read railvib_hpc.time_engines.ENGINES).


def _face(default: str, where: str) -> Param:
    return Param(default, "str", "-",
                 f"{where}: fixed (all displacements 0), roller (normal displacement 0), free, "
                 "absorbing (Lysmer-Kuhlemeyer dashpots rho c_P normal, rho c_S tangential "
                 "per unit area, from the soil behind the face), caughey (fixed, with a "
                 "graded Caughey absorbing layer inside the mesh, boundary.layer_*) or pml "
                 "(fixed, with a perfectly matched layer of boundary.layer_thickness inside "
                 "the mesh, boundary.pml_*; railvib transient only, any engine)",
                 choices=BOUNDARY_TYPES)

# The features keys belong to (Param.applies, railvib_hpc.applies): where one is off, its
# keys keep their defaults (railvib_hpc.validation.feature_key_problems).
#: The track and the train on it (track.count = 0: the bare soil with the load of [load]).
ON_TRACK = above("track.count", 0, what="a case with a track")
#: The moving surface load of [load] on the bare soil.
BARE_SOIL = is_("track.count", 0, what="the moving load on the bare soil")
SECOND_TRACK = is_("track.count", 2, what="a second track")
SECOND_TRAIN = all_of(SECOND_TRACK, is_("train2.enabled", True, what="a second train"))
SECOND_TRAIN_CARS = all_of(SECOND_TRAIN, is_("vehicle.type", "vehicle"))
#: The vehicle models: moving forces have no wheels (no contact, no irregularity).
MOVING_FORCES = all_of(ON_TRACK, is_("vehicle.type", "moving_force"))
WHEELS = all_of(ON_TRACK, is_not("vehicle.type", "moving_force",
                                 what="wheels on the rails"))
WHEELSET = all_of(ON_TRACK, is_("vehicle.type", "wheelset"))
CARS = all_of(ON_TRACK, is_("vehicle.type", "vehicle"))
#: The wheelset's mass: its own, and the moving forces' default (mass g / 2).
WHEELSET_MASS = all_of(ON_TRACK, any_of(
    is_("vehicle.type", "wheelset"),
    all_of(is_("vehicle.type", "moving_force"), is_("vehicle.force", 0.0)),
    what="vehicle.type = 'wheelset', or 'moving_force' with vehicle.force = 0"))
PROFILE_FILE = all_of(WHEELS, is_("irregularity.type", "file"))
RANDOM_PROFILE = all_of(WHEELS, is_("irregularity.type", "fra", "iso8608"))
WHEEL_FLATS = all_of(WHEELS, above("irregularity.flat_depth", 0))
SUPPORTED_ENDS = all_of(ON_TRACK, is_("track.ends", "supported"))
EMBANKMENT = all_of(ON_TRACK, above("track.embankment_height", 0))
#: The building of the site (building.present = false: the free field alone).
BUILDING = is_("building.present", True, what="a building")
OWN_HEIGHTS_NOT_GIVEN = is_("building.slab_bases", [], what="storeys of one height")
STOREY_2 = all_of(OWN_HEIGHTS_NOT_GIVEN, above("building.storeys", 2, inclusive=True))
REFINED_LAYOUT = is_("mesh.layout", "refined")
#: The embankment's layers in the refined layout (their elements: mesh.layer_elements).
REFINED_TRACK_BED = all_of(ON_TRACK, REFINED_LAYOUT)
#: A trench's or a block's lines are in the mesh with a type, or a width (its reference).
TRENCH = any_of(is_not("trench.type", "none"), above("trench.width", 0))
FILLED_TRENCH = is_("trench.type", "filled")
WIB = any_of(is_not("wib.type", "none"), above("wib.width", 0))
WIB_BLOCK = is_("wib.type", "block")
USP = all_of(ON_TRACK, above("usp.modulus", 0))
BALLAST_MAT = all_of(ON_TRACK, above("ballast_mat.modulus", 0))
ISOLATION = all_of(BUILDING, above("isolation.modulus", 0))


def in_building(params: dict[str, Param]) -> dict[str, Param]:
    """``params`` that belong to the building: each applies with it (and its own
    condition, if any)."""
    return {key: replace(p, applies=BUILDING if p.applies is None else all_of(BUILDING,
                                                                                p.applies))
            for key, p in params.items()}


def _faces(kind: str, what: str, study: bool = False) -> Condition:
    """A truncation face of type ``kind`` (or, with ``study``, the reflection study's
    variants of that type, whose faces it sets)."""
    faces = [is_(f"boundary.{f}", kind) for f in BOUNDARY_FACES]
    text = f"{what} (boundary.x_min, x_max, y_min, y_max or base = {kind!r}"
    if study:
        faces.append(includes("study.reflection.boundaries", kind))
        text += f", or study.reflection.boundaries with {kind!r}"
    return any_of(*faces, what=text + ")")


ABSORBING_FACES = _faces("absorbing", "an absorbing face", study=True)
CAUGHEY_FACES = _faces("caughey", "a caughey face")
PML_FACES = _faces("pml", "a perfectly matched layer", study=True)
LAYER_FACES = any_of(CAUGHEY_FACES, _faces("pml", "a perfectly matched layer"),
                     what="a caughey or pml face (boundary.x_min, x_max, y_min, y_max or "
                          "base)")
BAND_SLICED = above("modal.f_max", 0, what="the band-sliced eigensolve")
BLOCK_LANCZOS = is_("modal.method", "block_lanczos")
STATIC_CORRECTION = is_("mbs.static_correction", True)
DIRECT_ENGINE = is_("transient.engine", "direct")
IMEX_ENGINE = is_("transient.engine", "imex")
FTA = includes("assessment.standards", "fta")
DIN4150_2 = includes("assessment.standards", "din4150-2")
REDUCED_MODEL = is_("uncertainty.model", "reduced")
REDUCED_BASIS = not_empty("uncertainty.basis", what="a reduced basis")
RANDOM_FIELDS = not_empty("uncertainty.field", what="random fields")

SCHEMA: dict[str, dict[str, Any]] = {
    "case": {
        "name": Param("thesis_baseline", "str", "-", "name of the case (used in reports)"),
        "description": Param("", "str", "-", "free text"),
        "preset": Param("apdl", "str", "-",
                        "parameter set for values not given in the file: 'apdl' (what the thesis "
                        "solved, Appendix A) or 'table1' (the thesis's Table I)",
                        choices=("apdl", "table1")),
    },
    # The site as an engineer gives it (docs/sites.md): each key 0 = not given; a given one
    # computes the geometry keys it names (railvib_hpc.site.derive_keys), and a case that
    # also gives one of those with another value is refused.
    "site": {
        "building_distance": Param(
            0.0, "float", "m",
            "distance from the centreline of track 1 to the building's near face; sets "
            "geometry.ys2 = -distance and moves ys3, ybb, ys4 with it (0: not given)",
            "nonneg", applies=BUILDING),
        "building_width": Param(
            0.0, "float", "m",
            "building plan across the track, near face to far face; sets geometry.ys3, ybb "
            "and ys4 (the soil beyond the building stays 12 m wide: more with "
            "domain.extra_width) (0: not given)", "nonneg", applies=BUILDING),
        "building_length": Param(
            0.0, "float", "m",
            "building plan along the track; sets geometry.x2, x3 and xbb about the building's "
            "centre (the middle of the track with site.track_length), its start on a sleeper "
            "(0: not given)", "nonneg", applies=BUILDING),
        "track_length": Param(
            0.0, "float", "m",
            "length of the flexible track (and of the soil along it), a whole number of "
            "sleeper bays; sets track.rail_length, geometry.x4 and centres the building along "
            "it (geometry.x2, x3, xbb, with a building) (0: not given)", "nonneg"),
        "soil_depth": Param(
            0.0, "float", "m",
            "depth of the soil below the ground level (geometry.z1) down to the base; sets "
            "domain.extra_depth (deeper than Z1 - Z0) or geometry.z0 (shallower) (0: not "
            "given)", "nonneg"),
    },
    "geometry": {
        "x0": _apdl_coordinate("X0", 0.0, "start of the first rigid rail"),
        "x1": _apdl_coordinate("X1", 3.0, "start of the flexible rail and of the soil"),
        "x2": _apdl_coordinate("X2", 12.6, "building (and its excavation) starts",
                              BUILDING),
        "x3": _apdl_coordinate("X3", 19.8, "building ends", BUILDING),
        "x4": Param(24.6, "float", "m", "X4: end of the flexible rail and of the soil",
                    source=f"{_APDL}: X4=24.6", derived="geometry.x1 + track.rail_length"),
        "ys0": Param(8.25, "float", "m", "YS0: soil edge on the side away from the building",
                     source=f"{_APDL}: YSO=8.25"),
        "ys1": _apdl_coordinate("YS1", -4.25,
                                "toe of the embankment (subballast base half-width is |YS1|)"),
        "ys2": _apdl_coordinate("YS2", -9.9, "building face nearest the track", BUILDING),
        "ys3": _apdl_coordinate("YS3", -17.1, "building face farthest from the track",
                               BUILDING),
        "ys4": _apdl_coordinate("YS4", -29.1, "soil edge beyond the building (without one: "
                               "the soil edge on the side y < 0)"),
        "z0": _apdl_coordinate("Z0", 0.0, "bottom of the subgrade (fixed base)"),
        "z1": _apdl_coordinate("Z1", 4.8, "top of the subgrade = ground level"),
        "z2": _apdl_coordinate("Z2", 5.3, "top of the subballast"),
        "z3": _apdl_coordinate("Z3", 5.8, "top of the ballast = sleeper axis"),
        "z4": _apdl_coordinate("Z4", 6.00424, "rail axis height"),
        "xbb": Param(16.2, "float", "m", "XBB: x of the building base point (centre of its plan)",
                     source=f"{_APDL}: XBB=16.2", derived="(geometry.x2 + geometry.x3) / 2"),
        "ybb": Param(-13.5, "float", "m", "YBB: y of the building base point (centre of its plan)",
                     source=f"{_APDL}: YBB=-13.5", derived="(geometry.ys2 + geometry.ys3) / 2"),
        "zbb": _apdl_coordinate("ZBB", 2.4, "z of the building base (underside of footings)",
                               BUILDING),
        "ballast_top_half_width": Param(3.25, "float", "m",
                                        "half-width of the ballast crest (top of the shoulder)",
                                        "pos", source=f"{_APDL}: K,KP_SLP_END+9,X1,3.25,Z3"),
        "ballast_bottom_half_width": Param(3.75, "float", "m",
                                           "half-width of the ballast at the subballast top",
                                           "pos", source=f"{_APDL}: K,KP_SLP_END+10,X1,3.75,Z2"),
    },
    "track": {
        "rigid_length": Param(3.0, "float", "m",
                              "length of each end section of the rail beyond the soil box: "
                              "rigid rail, or with track.ends = 'supported' the supported rail "
                              "(then a whole number of sleeper bays)", "pos",
                              source=f"{_APDL}: Rigid=3; {_T1}"),
        "ends": Param("rigid", "str", "-",
                      "the rail beyond the soil box: 'rigid' (the thesis's rigid rail, DOFs "
                      "fixed) or 'supported' (the flexible rail continues for "
                      "track.rigid_length on springs and graded dashpots to fixed ground at "
                      "every sleeper position, fitted to the modelled track's static "
                      "receptance, its far ends clamped: no rigid-to-flexible drop at the "
                      "box, trains of any length pass; the modal path needs modal.damping = "
                      "'full', which projects the supports' dashpots on the modes)",
                      choices=("rigid", "supported"),
                      source=f"{_APDL}: rigid rail sections (Rigid=3)", applies=ON_TRACK),
        "end_stiffness": Param(0.0, "float", "N/m",
                               "track.ends = 'supported': vertical spring per rail at each "
                               "support (the longitudinal and lateral ones in the pads' "
                               "proportions); 0: fitted so that a beam on the equivalent "
                               "elastic foundation has the modelled track's static point "
                               "receptance at its middle (one static solve)", "nonneg",
                               source="not in the thesis (rigid ends): the model's own static "
                                      "receptance, beam on an elastic foundation (Hetenyi "
                                      "1946)", applies=SUPPORTED_ENDS),
        "end_damping": Param(1.0, "float", "-",
                             "track.ends = 'supported': damping ratio of the supports at the far "
                             "ends, relative to critical (2 sqrt(k m) with the rail mass of a "
                             "bay), graded with the square of the distance from the soil box "
                             "(zero at the box): an absorbing track end; 0: no dashpots",
                             "nonneg",
                             source="not in the thesis (rigid ends): critical damping at the "
                                    "far end, graded as a quadratic sponge layer",
                             applies=SUPPORTED_ENDS),
        "rail_length": Param(21.6, "float", "m", "length of the flexible rail", "pos",
                             source=f"{_APDL}: Rail_length=21.6; {_T1}"),
        "gauge": Param(1.5113, "float", "m", "distance between the rail axes (2 x 0.75565)", "pos",
                       source=f"{_APDL}: R_Gage=2*0.75565; {_T1}"),
        "sleeper_spacing": Param(0.6, "float", "m", "distance between sleepers", "pos",
                                 source=f"{_APDL}: Distance_betw_sleepers=0.6; {_T1}"),
        "n_sleepers": Param(37, "int", "-", "number of sleepers (first at X1, last at X4)", "pos",
                            source=f"{_APDL}: No_sleeper_div_total=36 (+1)",
                            derived="track.rail_length / track.sleeper_spacing + 1"),
        "sleeper_length": Param(2.5, "float", "m", "sleeper length across the track", "pos",
                                source=f"{_APDL}: K,...,Rigid,+-1.25,Z3; {_T1}"),
        "embankment_height": Param(0.0, "float", "m",
                                   "a fill embankment under the track bed: it lifts the "
                                   "subballast, ballast, sleepers and rails (geometry.z2, z3, "
                                   "z4) by this height (0: the thesis's track bed directly on "
                                   "the ground, a track at grade)", "nonneg",
                                   source=f"{_APDL}: the track bed on the ground (Z1 = top of the "
                                          "subgrade), no fill", applies=ON_TRACK),
        "embankment_slope": Param(1.5, "float", "-",
                                  "horizontal run of the fill's side slopes per unit height "
                                  "(1.5: 1V:1.5H); the fill's top is the subballast's base "
                                  "(half-width |YS1|)", "pos",
                                  source="not in the thesis: 1V:1.5H, the usual fill slope",
                                  applies=EMBANKMENT),
        "count": Param(1, "int", "-",
                       "tracks on the embankment: 1, or 2 (the second one track.spacing further "
                       "from the building, on the same embankment), or 0: no track, no "
                       "embankment and no vehicle, the bare soil (and the building) loaded by "
                       "the moving surface load of [load] (railvib transient, and railvib study "
                       "with solver = direct: the modal path needs a track)", "nonneg",
                       source=f"{_APDL}: one track"),
        "spacing": Param(4.0, "float", "m",
                         "distance between the two tracks' centre lines (track.count = 2)",
                         "pos",
                         source="not in the thesis (one track): 4.0 m, the usual track centre "
                                "distance of European main lines (DB Ril 800.0130: >= 4.0 m)",
                         applies=SECOND_TRACK),
    },
    "building": {
        "present": Param(True, "bool", "-",
                         "a building on the site (the parametric frame of the building.* "
                         "keys in its excavation geometry.x2..x3 x ys3..ys2); false: no "
                         "building, the free field alone (the ground probes and "
                         "[[probes.line]]): its keys (building.*, materials.concrete, "
                         "geometry.x2, x3, ys2, ys3, zbb, site.building_*, "
                         "mesh.size_building_*, mesh.soil_elements_per_bay_building, "
                         "[isolation]) do not apply",
                         source=f"{_APDL}: one building (local system 11)"),
        **in_building({
        "footing_size": Param(1.2, "float", "m", "plan size of the square corner footings", "pos",
                              source=f"{_APDL}: FX1=2.4, FX4=3.6 (local system 11)"),
        "footing_height": Param(0.6, "float", "m", "HSF: footing height", "pos",
                                source=f"{_APDL}: HSF=0.6 (the text's 1.2 m is not used)"),
        "column_size": Param(0.6, "float", "m", "square column side", "pos",
                             source=f"{_APDL}: CX1=2.7, CX2=3.3"),
        "beam_width": Param(0.6, "float", "m", "BEAM_WIDTH: width of beams and grade beams", "pos",
                            source=f"{_APDL}: BEAM_WIDTH=0.6"),
        "beam_depth": Param(0.6, "float", "m", "depth of beams and grade beams", "pos",
                            source=f"{_APDL}: VEXT,A_BEAM1+1,...,0.6"),
        "slab_thickness": Param(0.2, "float", "m", "thickness of both slabs", "pos",
                                source=f"{_APDL}: VEXT,A_SLAB1+1,,0,,,0.2"),
        "wall_thickness": Param(0.3, "float", "m", "WALL_WIDTH: basement wall thickness", "pos",
                                source=f"{_APDL}: WALL_WIDTH=0.3"),
        "z_slab1_base": Param(4.2, "float", "m", "Z_SLAB1_BASE: underside of slab 1 above ZBB",
                              "pos", source=f"{_APDL}: Z_SLAB1_BASE=4.2",
                              applies=OWN_HEIGHTS_NOT_GIVEN),
        "z_slab2_base": Param(8.0, "float", "m",
                              "Z_SLAB2_BASE: underside of slab 2 above ZBB (each storey above "
                              "repeats storey 2's height)", "pos",
                              source=f"{_APDL}: Z_SLAB2_BASE=8", applies=STOREY_2),
        "storeys": Param(2, "int", "-",
                         f"storeys above the basement, one slab on top of each; at most "
                         f"{MAX_STOREYS}, a program limit",
                         "pos", maximum=MAX_STOREYS,
                         source=f"{_APDL}: two slabs (A_SLAB1, A_SLAB2); thesis Fig. 13"),
        "slab_bases": Param([], "floats", "m",
                            "underside of every slab above ZBB, one per storey, bottom up, "
                            "for storeys of their own heights (empty: z_slab1_base, then each "
                            "storey z_slab2_base - z_slab1_base higher)", "pos",
                            source=f"{_APDL}: Z_SLAB1_BASE=4.2, Z_SLAB2_BASE=8 (z_slab*_base)"),
        "bays_x": Param(1, "int", "-", "bays along the track (x); bays_x + 1 column lines",
                        "pos", source=f"{_APDL}: one bay, four columns (CX1..CX2 at the corners)"),
        "bays_y": Param(1, "int", "-", "bays across the track (y); bays_y + 1 column lines",
                        "pos", source=f"{_APDL}: one bay, four columns (CX1..CX2 at the corners)"),
        "spans_x": Param([], "floats", "m",
                         "column-centre spans along x, from X2 (empty: bays_x equal spans; they "
                         "add up to X3 - X2 - footing_size)", "pos",
                         source=f"{_APDL}: one span, X3 - X2 - FX1 = 6 m"),
        "spans_y": Param([], "floats", "m",
                         "column-centre spans along y, from the face nearest the track YS2 "
                         "(empty: bays_y equal spans; they add up to YS2 - YS3 - footing_size)",
                         "pos", source=f"{_APDL}: one span, X3 - X2 - FX1 = 6 m"),
        "foundation": Param("pad", "str", "-",
                            "pad footings under the columns, strip footings along every column "
                            "line, or a raft under the whole plan (footing_height thick)",
                            choices=FOUNDATION_TYPES,
                            source=f"{_APDL}: four pad footings (FX1, FX4) with grade beams"),
        "rotation": Param(0.0, "float", "deg",
                          f"turn of the building about its plan centre (XBB, YBB), "
                          f"counter-clockwise seen from above, -{MAX_ROTATION_DEG:g} to "
                          f"{MAX_ROTATION_DEG:g}; the soil round it twists to meet the "
                          f"track-parallel mesh beyond whole quarter turns (docs/sites.md)",
                          "angle",
                          source=f"{_APDL}: the walls are parallel to the track (no rotation)"),
        }),
    },
    "materials": {
        "rail": _mat(210e9, 0.30, 7700.0, "flexible rail", _mp(1, "210e9", "0.30", "7700"),
                     applies=ON_TRACK),
        "rigid_rail": _mat(210e10, 0.30, 7700.0, "rigid rail (its DOFs are fixed)",
                           _mp(2, "210e10", "0.30", "7700"), applies=ON_TRACK),
        "sleeper": _mat(64e9, 0.25, 2570.0, "sleepers", _mp(3, "64e9", "0.25", "2570"),
                        applies=ON_TRACK),
        "ballast": _mat(260e6, 0.25, 1800.0, "ballast", _mp(4, "260e6", "0.25", "1800"),
                        applies=ON_TRACK),
        "subballast": _mat(200e6, 0.20, 1850.0, "subballast",
                           _mp(5, "200e06", "0.2", "1850"), applies=ON_TRACK),
        "subgrade": _mat(200e6, 0.20, 1850.0, "subgrade", _mp(6, "200e6", "0.2", "1850")),
        "concrete": _mat(31e9, 0.25, 2500.0, "concrete building",
                         _mp(10, "31e9", "0.25", "2500"), applies=BUILDING),
        # mitigation materials: not in the thesis (its future work); typical values
        "trench_fill": _mat(5e6, 0.10, 20.0, "in-filled trench ([trench], type = 'filled')",
                            "not in the thesis: EPS geofoam EPS 20 (EN 14933, E 3-8 MPa, "
                            "rho ~20 kg/m^3), the usual soft trench fill", _OTHER_DAMPING,
                            FILLED_TRENCH),
        "wib": _mat(2e9, 0.25, 2100.0, "wave-impeding block ([wib])",
                    "not in the thesis: jet-grouted / cement-stabilised soil (E 0.5-5 GPa, "
                    "rho 2000-2200 kg/m^3)", _OTHER_DAMPING, WIB_BLOCK),
        "fill": _mat(1.5e8, 0.30, 1900.0, "embankment fill (track.embankment_height)",
                     "not in the thesis: compacted granular embankment fill (E 50-200 MPa, "
                     "rho 1800-2000 kg/m^3)", _OTHER_DAMPING, EMBANKMENT),
    },
    "sections": {
        "rail": _section(APDL_RAIL, "rail", "lateral", _RAIL_SEC),
        "sleeper": _section(APDL_SLEEPER, "sleeper", "horizontal", _SLP_SEC),
    },
    "pads": {
        "kx": Param(70e8, "float", "N/m", "rail pad stiffness along the track", "pos",
                    source=f"{_APDL}: R,7,70e8,5e5 (COMBIN14 KEYOPT(2)=1)", applies=ON_TRACK),
        "ky": Param(70e8, "float", "N/m", "rail pad stiffness across the track", "pos",
                    source=f"{_APDL}: R,8,70e8,5e5 (COMBIN14 KEYOPT(2)=2)", applies=ON_TRACK),
        "kz": Param(70e8, "float", "N/m", "rail pad stiffness, vertical", "pos",
                    source=f"{_APDL}: R,9,70e8,5e5 (COMBIN14 KEYOPT(2)=3)", applies=ON_TRACK),
        "cx": Param(5e5, "float", "N s/m", "rail pad damping along the track", "nonneg",
                    source=f"{_APDL}: R,7,70e8,5e5 (COMBIN14 KEYOPT(2)=1)", applies=ON_TRACK),
        "cy": Param(5e5, "float", "N s/m", "rail pad damping across the track", "nonneg",
                    source=f"{_APDL}: R,8,70e8,5e5 (COMBIN14 KEYOPT(2)=2)", applies=ON_TRACK),
        "cz": Param(5e5, "float", "N s/m", "rail pad damping, vertical", "nonneg",
                    source=f"{_APDL}: R,9,70e8,5e5 (COMBIN14 KEYOPT(2)=3)", applies=ON_TRACK),
    },
    "mesh": {
        "layout": Param("thesis", "str", "-",
                        "element divisions: 'thesis' reproduces the APDL script's divisions "
                        "(Appendix A/B: 41,880 hexahedra, coarse soil across the track; the "
                        "size_far, size_deep and layer_elements keys do not apply), 'refined' "
                        "uses the mesh.size_* keys (finer far field, for engineering runs)",
                        choices=("thesis", "refined"),
                        source="thesis App. A/B: divisions of the APDL script, 41,880 hexahedra "
                               "(App. B element ranges)"),
        "refinement": Param(1.0, "float", "-",
                            "multiplies every element count (1: the layout's own size; "
                            "2: ~8x the elements)", "pos"),
        "file": Param("", "str", "-",
                      "use this gmsh .msh (same physical-group names) instead of generating; "
                      "relative to the case file"),
        "rail_elements_per_bay": Param(5, "int", "-", "rail beam elements between sleepers",
                                       "pos", source=f"{_APDL}: No_rail_ele_betwn_sleeper=5",
                                       applies=ON_TRACK),
        "soil_elements_per_bay": Param(2, "int", "-",
                                       "soil elements along x per sleeper bay, away from "
                                       "building (without a track the soil's grid is its own: "
                                       "mesh.size_far, or 0.6 m cubes in the thesis layout)",
                                       "pos", source=f"{_APDL}: No_soil_ele_betwn_sleeper_NB=2",
                                       applies=ON_TRACK),
        "soil_elements_per_bay_building": Param(4, "int", "-",
                                                "soil elements along x per bay in line with the "
                                                "building", "pos",
                                                source=f"{_APDL}: No_soil_ele_betwn_sleeper_B=4",
                                                applies=BUILDING),
        "sleeper_outer_elements": Param(2, "int", "-",
                                        "sleeper elements between its end and the rail", "pos",
                                        source=f"{_APDL}: SLP_OUT_ELE=2", applies=ON_TRACK),
        "sleeper_middle_elements": Param(4, "int", "-", "sleeper elements between the rails",
                                         "pos", source=f"{_APDL}: SLP_MID_ELE=4", applies=ON_TRACK),
        "shoulder_elements": Param(3, "int", "-", "elements across each ballast shoulder", "pos",
                                   source=f"{_APDL}: LESIZE,ALL,,,3 (shoulder lines at X1)",
                                   applies=ON_TRACK),
        "size_far": Param(0.6, "float", "m",
                          "layout 'refined': element size across the track in the far field "
                          "(without a track: the soil's size along x and y, a grid sized by "
                          "the soil alone)", "pos", applies=REFINED_LAYOUT),
        "size_deep": Param(0.8, "float", "m",
                           "layout 'refined': vertical element size below the building base "
                           "(without a building: of the whole soil)",
                           "pos", applies=REFINED_LAYOUT),
        "size_building_y": Param(0.3, "float", "m",
                                 "building and soil element size across the track in line with "
                                 "the building", "pos",
                                 source=f"{_APDL}: LESIZE,ALL,0.3 (building and soil across)",
                                 applies=BUILDING),
        "size_building_z": Param(0.6, "float", "m",
                                 "building element size vertically (layout 'refined': also "
                                 "of the soil above the building base)", "pos",
                                 source=f"{_APDL}: EXTOPT,ESIZE,6 over 3.6 m (columns), "
                                        "walls 0.6 m", applies=BUILDING),
        "layer_elements": Param(1, "int", "-",
                                "layout 'refined': elements through each of the ballast and "
                                "subballast layers", "pos", applies=REFINED_TRACK_BED),
        "elements_per_wavelength": Param(0.0, "float", "-",
                                         "if > 0: soil element sizes at most c_S / (f n) "
                                         "(f = mesh.wavelength_hz, which must then be > 0; "
                                         "n this value): vertically "
                                         "per soil layer, horizontally for the softest soil; "
                                         "0: the layout's sizes. A warning names every soil "
                                         "part whose elements resolve the band with fewer "
                                         "(mesh.min_elements_per_wavelength)", "nonneg"),
        "wavelength_hz": Param(0.0, "float", "Hz",
                               "frequency the soil mesh must resolve: sizes with "
                               "mesh.elements_per_wavelength, and the mesh check (0: the check "
                               "uses modal.f_max when > 0, else none)", "nonneg"),
        "min_elements_per_wavelength": Param(6.0, "float", "-",
                                             "fewest linear elements per shear wavelength at "
                                             "mesh.wavelength_hz before the mesh stage warns "
                                             "(the frequency error of trilinear hexahedra with "
                                             "consistent mass is (k h)^2 / 24: 4.6 % at 6, "
                                             "1.6 % at 10)",
                                             "pos"),
        "max_dispersion_error": Param(0.0, "float", "-",
                                      "with mesh.wavelength_hz > 0: the largest predicted "
                                      "peak-velocity error at the farthest probe (numerical "
                                      "dispersion of the soil grid over the distance from the "
                                      "track, a conservative bound) the mesh stage accepts, "
                                      "e.g. 0.05, and railvib transient at transient.f_max "
                                      "(its own check, always run); 0: no limit. The "
                                      "prediction is reported, warned about above 5 %, and a "
                                      "band the mesh cannot resolve there (the wave half a "
                                      "period off) is refused at mesh.wavelength_hz whatever "
                                      "this value (warned about at transient.f_max)",
                                      "unit",
                                      source="issue 28, item 2: accuracy that holds over "
                                             "distance (docs/transient.md, numerical "
                                             "dispersion)"),
    },
    "soil": {
        "layers": Param([], "layers", "-",
                        "horizontal soil layers from the ground level (geometry.z1) down, as "
                        "[[soil.layers]] tables with thickness, E or c_s, nu, rho and "
                        "damping_ratio; they replace materials.subgrade below the ground; the "
                        "layers must reach the base (geometry.z0 - domain.extra_depth), the "
                        "last may give thickness = 0 (down to the base); [] = one homogeneous "
                        "subgrade (the thesis)"),
    },
    "trench": {
        "type": Param("none", "str", "-",
                      "mitigation: a trench along the whole soil length between the track and "
                      "the building: open (a void), filled (materials.trench_fill) or none "
                      "(with width > 0 the mesh keeps the trench's lines and the soil stays: "
                      "the reference for insertion loss on the same mesh)",
                      choices=("none", "open", "filled")),
        "distance": Param(0.0, "float", "m",
                          "distance from the track centreline (y = 0) to the trench's near "
                          "face, towards the building (beyond the embankment toe |YS1|, before "
                          "the building face |YS2|)", "nonneg", applies=TRENCH),
        "width": Param(0.0, "float", "m", "trench width across the track", "nonneg"),
        "depth": Param(0.0, "float", "m", "trench depth below the ground (geometry.z1)",
                       "nonneg", applies=TRENCH),
    },
    "wib": {
        "type": Param("none", "str", "-",
                      "mitigation: a wave-impeding block (materials.wib: jet grout, stabilised "
                      "soil) under the track along the whole soil length, or none (with "
                      "width > 0 the mesh keeps its lines: the reference on the same mesh)",
                      choices=("none", "block")),
        "width": Param(0.0, "float", "m",
                       "block width across the track, centred on it (at most the embankment "
                       "base, 2 |YS1|)", "nonneg"),
        "depth": Param(0.0, "float", "m", "depth of the block's top below the ground",
                       "nonneg", applies=WIB),
        "thickness": Param(0.0, "float", "m", "block thickness", "nonneg", applies=WIB),
    },
    "usp": {
        "modulus": Param(0.0, "float", "N/m^3",
                         "under-sleeper pads: bedding modulus, vertical stiffness per unit area of"
                         " the sleeper's bearing (EN 16730: soft 0.05-0.1e9, medium 0.1-0.2e9, "
                         "stiff 0.2-0.3e9) (0: none)", "nonneg", applies=ON_TRACK),
        "shear_ratio": Param(0.3, "float", "-",
                             "stiffness along x and y over the vertical one (an elastomer's "
                             "shear stiffness is a fraction of its compression stiffness)",
                             "pos", applies=USP),
        "loss_factor": Param(0.1, "float", "-",
                             "loss factor eta of the pads: damping ratio eta/2 of its strain "
                             "energy (modal.damping = 'strain_energy'); 0.1 is typical of "
                             "elastomers", "fraction", applies=USP),
        "width": Param(0.27, "float", "m",
                       "bearing width of the sleeper on the pads (its underside; less than "
                       "track.sleeper_spacing)", "pos",
                       source=f"{_SLP_SEC}: the trapezoid's base, 2 x 0.135 m", applies=USP),
    },
    "ballast_mat": {
        "modulus": Param(0.0, "float", "N/m^3",
                         "ballast mat under the ballast (on the subballast, z = Z2): bedding "
                         "modulus (typical 0.02-0.1e9) (0: none)", "nonneg", applies=ON_TRACK),
        "shear_ratio": Param(0.3, "float", "-",
                             "stiffness along x and y over the vertical one (an elastomer's "
                             "shear stiffness is a fraction of its compression stiffness)",
                             "pos", applies=BALLAST_MAT),
        "loss_factor": Param(0.1, "float", "-",
                             "loss factor eta of the mat: damping ratio eta/2 of its strain "
                             "energy (modal.damping = 'strain_energy'); 0.1 is typical of "
                             "elastomers", "fraction", applies=BALLAST_MAT),
    },
    "isolation": {
        "modulus": Param(0.0, "float", "N/m^3",
                         "base isolation of the building: bedding modulus of the bearings over the"
                         " area they carry (a vertical building frequency f needs about m (2 pi "
                         "f)^2 / area) (0: none)", "nonneg", applies=BUILDING),
        "shear_ratio": Param(0.3, "float", "-",
                             "stiffness along x and y over the vertical one (an elastomer's "
                             "shear stiffness is a fraction of its compression stiffness)",
                             "pos", applies=ISOLATION),
        "loss_factor": Param(0.1, "float", "-",
                             "loss factor eta of the bearings: damping ratio eta/2 of its strain "
                             "energy (modal.damping = 'strain_energy'); 0.1 is typical of "
                             "elastomers", "fraction", applies=ISOLATION),
        "level": Param("ground", "str", "-",
                       "where the bearings are: 'ground' (on top of the basement, under the "
                       "ground-floor columns, Z1) or 'footings' (under everything of the "
                       "building at its base ZBB; the basement walls stay bonded to the soil "
                       "beside them)", choices=("ground", "footings"), applies=ISOLATION),
    },
    "domain": {
        "extra_depth": Param(0.0, "float", "m", "extra subgrade depth below Z0", "nonneg"),
        "extra_width": Param(0.0, "float", "m", "extra soil width beyond the building (below YS4)",
                             "nonneg"),
        "extra_length": Param(0.0, "float", "m",
                              "extra soil length before X1 and after X4 (track unchanged)",
                              "nonneg"),
    },
    "boundary": {
        "x_min": _face("roller", "soil face at the start of the domain (x = min; the thesis: "
                       "roller)"),
        "x_max": _face("roller", "soil face at the end of the domain (x = max; the thesis: "
                       "roller)"),
        "y_min": _face("roller", "soil face beyond the building (y = min; the thesis: roller)"),
        "y_max": _face("roller", "soil face on the other side of the track (y = max; the "
                       "thesis: roller)"),
        "base": _face("fixed", "bottom of the subgrade (z = min; the thesis: fixed)"),
        "virtual_thickness": Param(0.0, "float", "m",
                                   "absorbing faces: add springs (lambda + 2 G) / t normal and "
                                   "G / t tangential per unit area, as if t metres of the same "
                                   "soil lay behind the face; they give the truncated model "
                                   "static support (0: dashpots only, the model may drift under "
                                   "a static load). For a static load the half-space's "
                                   "compliance needs t of 1.5-2.3 times the distance from the "
                                   "load to the faces (bench/spring_static_study.py, "
                                   "docs/verification.md)", "nonneg", applies=ABSORBING_FACES),
        "layer_thickness": Param(0.0, "float", "m",
                                 "caughey and pml faces: thickness of the absorbing layer, "
                                 "measured "
                                 "into the mesh from the face (part of the model: enlarge the "
                                 "domain by it, [domain])", "nonneg", applies=LAYER_FACES),
        "layer_damping": Param(0.3, "float", "-",
                               "caughey faces: Rayleigh damping ratio at the face (at "
                               "damping.f1 and f2), decreasing quadratically to 0 at the inner "
                               "edge of the layer", "fraction", applies=CAUGHEY_FACES),
        "pml_reflection": Param(1e-4, "float", "-",
                                "pml faces: target reflection coefficient R of the continuous "
                                "layer for a P wave at normal incidence; sets the profile's "
                                "largest damping d_max = (p + 1) c_P ln(1 / R) / (2 L) "
                                "(Collino & Tsogka 2001)", "fraction", applies=PML_FACES),
        "pml_power": Param(2.0, "float", "-",
                           "pml faces: exponent p of the damping profile d = d_max (xi / L)^p "
                           "over the depth xi into the layer (2 to 3: Collino & Tsogka 2001)",
                           "pos", applies=PML_FACES),
        "pml_alpha": Param(PML_ALPHA, "float", "1/s",
                           "pml faces: frequency shift alpha of the stretching 1 + d / (i omega "
                           "+ alpha) (complex frequency shifted PML, Kuzuoglu & Mittra 1996): "
                           "no memory grows under a static or slowly varying load; waves "
                           "below alpha / (2 pi) are absorbed less (default pi 1/s: 0.5 Hz, "
                           "half the lowest assessed band, where the attenuation is 89 % of "
                           "the classical layer's); 0: the classical PML", "nonneg",
                           applies=PML_FACES),
    },
    "damping": {
        "model": Param("rayleigh", "str", "-",
                       "damping matrix C of the full-order model (railvib transient, and "
                       "modal.damping = 'full'): rayleigh = alpha M + beta K with "
                       "modal.damping_ratio at damping.f1 and damping.f2; per_material = the "
                       "same per material with materials.*.damping_ratio (the rail pads: "
                       "modal.damping_ratio); none. Absorbing faces add their dashpots",
                       choices=("rayleigh", "per_material", "none")),
        "f1": Param(8.0, "float", "Hz",
                    "lower frequency at which the Rayleigh damping equals the damping ratio "
                    "(default: below the first soil mode of the thesis model, 9.1 Hz)", "pos"),
        "f2": Param(40.0, "float", "Hz",
                    "upper frequency at which the Rayleigh damping equals the damping ratio "
                    "(default: the 300-mode band of the thesis model, 42.7 Hz; above it the "
                    "damping grows in proportion to the frequency)", "pos"),
        "pads": Param(False, "bool", "-",
                      "add the rail pads' dashpots (pads.cx, cy, cz) to C (the thesis's 3 % "
                      "modal damping does not use them)", applies=ON_TRACK),
    },
    "modal": {
        "n_modes": Param(300, "int", "-", "number of modes to extract", "pos",
                         source=f"{_APDL}: MODOPT,LANB,300; thesis §3"),
        "f_max": Param(0.0, "float", "Hz",
                       "if > 0: extract all modes below this frequency instead of n_modes "
                       "(block Lanczos: band-sliced, Sylvester inertia counts prove none is "
                       "missed; krylovschur: SLEPc spectrum slicing)", "nonneg"),
        "bands": Param([], "floats", "Hz",
                       "f_max: inner band edges, ascending in (0, f_max); [] = automatic split "
                       "from the inertia count at f_max (about modal.band_modes per band)",
                       applies=BAND_SLICED),
        "band_modes": Param(250, "int", "-",
                            "f_max, automatic split: target number of modes per band", "pos",
                            applies=BAND_SLICED),
        "band_groups": Param(1, "int", "-",
                             "f_max: bands solved concurrently, each on its own sub-communicator "
                             "of size ranks / band_groups (1: one band after the other on all "
                             "ranks)", "pos", applies=BAND_SLICED),
        "band_only": Param(0, "int", "-",
                           "f_max, array jobs: compute only band k (1-based) into <out>/bands/ "
                           "and stop; a run with 0 merges the cached bands (computing the "
                           "missing ones)", "nonneg", applies=BAND_SLICED),
        "damping_ratio": Param(0.03, "float", "-",
                               "modal damping ratio for all modes (modal.damping = 'uniform'; "
                               "with 'strain_energy': the rail pads' share)", "fraction",
                               source=_THESIS_DAMPING),
        "damping": Param("uniform", "str", "-",
                         "modal damping: the same ratio for every mode (the thesis), or per "
                         "material from each mode's strain-energy shares, zeta_i = sum_g "
                         "zeta_g E_ig / sum_g E_ig (ANSYS MP,DMPR; materials.*.damping_ratio), "
                         "Rayleigh (zeta_i = alpha / (2 omega_i) + beta omega_i / 2 with "
                         "modal.damping_ratio at damping.f1, damping.f2: exactly the damping "
                         "of the full-order model with damping.model = 'rayleigh' and no "
                         "absorbing faces), or full (the projected damping matrix Phi^T C Phi "
                         "of [damping] and the absorbing faces' dashpots, coupled modal "
                         "equations)",
                         choices=("uniform", "strain_energy", "rayleigh", "full")),
        "lumped_mass": Param(False, "bool", "-", "use lumped instead of consistent mass"),
        "hex_formulation": Param("bbar", "str", "-",
                                 "stiffness of the 8-node hexahedra: B-bar (ANSYS SOLID185 "
                                 "default, the thesis; too soft in bending when a slab or wall "
                                 "is one element thick), incompatible modes (SOLID185 "
                                 "KEYOPT(2)=3; bends correctly one element thick) or plain full "
                                 "integration", choices=("bbar", "incompatible", "full"),
                                 source=f"{_APDL}: ET,2,SOLID185 (default KEYOPT(2)=0: B-bar)"),
        "method": Param("block_lanczos", "str", "-",
                        "eigensolver: block shift-invert Lanczos (fast, many right-hand sides "
                        "per MUMPS solve) or SLEPc Krylov-Schur (with f_max: SLEPc spectrum "
                        "slicing)", choices=("block_lanczos", "krylovschur"),
                        source=f"{_APDL}: MODOPT,LANB (block Lanczos)"),
        "block_size": Param(32, "int", "-", "block Lanczos: right-hand sides per solve", "pos",
                            applies=BLOCK_LANCZOS),
        "out_of_core": Param("auto", "str", "-",
                             "MUMPS factor on disk (ICNTL(22)): auto = only when the in-core "
                             "factor would not fit in the available memory but the out-of-core "
                             "one does (block Lanczos); always; never (then a model too large "
                             "stops with a clear message)", choices=("auto", "always", "never")),
        "max_basis": Param(0, "int", "-",
                           "block Lanczos: basis size before a thick restart (0: 3 n_modes, "
                           "capped at 4 GB of basis vectors)", "nonneg", applies=BLOCK_LANCZOS),
        "shift_hz": Param(0.0, "float", "Hz",
                          "shift of the spectral transformation (modes nearest to it)",
                          "nonneg"),
        "tol": Param(1e-8, "float", "-", "relative residual tolerance of the eigenpairs", "pos"),
        "max_restarts": Param(100, "int", "-", "maximum restarts of the eigensolver", "pos"),
        "fix_sleeper_rotations": Param(True, "bool", "-",
                                       "fix all rotations of sleeper nodes (thesis, App. A)",
                                       source=f"{_APDL}: ESEL,S,MAT,,3 / D,ALL,ROTX..ROTZ,0",
                                       applies=ON_TRACK),
        "fix_rail_rotations_at_pads": Param(True, "bool", "-",
                                            "fix all rotations of rail nodes above the pads "
                                            "(thesis, App. A)",
                                            source=f"{_APDL}: NSEL,S,NODE,,7,177,5 / D,ALL,ROT*,0",
                                            applies=ON_TRACK),
    },
    "vehicle": {
        "type": Param("wheelset", "str", "-",
                      "load model: constant moving forces, the thesis's suspended wheelset "
                      "(Table II), or cars with 2 bogies and 4 wheelsets each",
                      choices=("moving_force", "wheelset", "vehicle"),
                      source="thesis §4.4: suspended wheelset (SAMS)", applies=ON_TRACK),
        "speed": Param(30.0, "float", "m/s", "running speed", "pos",
                       source="thesis §4.4: 30 m/s (67 mph)", applies=ON_TRACK),
        "x_start": Param(0.0, "float", "m",
                         "position of the leading wheel at t = 0 (on the rigid entry rail; 0: "
                         "its start, the thesis's time origin)",
                         source="thesis §2.2 and §6.6: wheel starts at x = 0 on the rigid rail",
                         applies=ON_TRACK),
        "x_end": Param(0.0, "float", "m",
                       "the run ends when the last wheel reaches this position (0: the end of "
                       "the rigid exit rail)", "nonneg", applies=ON_TRACK),
        "t_after": Param(0.0, "float", "s",
                         "extra time simulated after the last wheel reaches x_end", "nonneg",
                         applies=ON_TRACK),
        "force": Param(0.0, "float", "N",
                       "moving_force: force per wheel (0: the wheelset's static wheel load, "
                       "mass * g / 2)", "nonneg", applies=MOVING_FORCES),
        "axle_offsets": Param([0.0], "floats", "m",
                              "moving_force: axle positions relative to the leading axle "
                              "(<= 0, one force per rail and axle)", applies=MOVING_FORCES),
        "wheelset_mass": Param(1568.0, "float", "kg", "wheelset mass (thesis Table II)", "pos",
                               source=f"{_T2}: mass 1568 kg", applies=WHEELSET_MASS),
        "wheelset_roll_inertia": Param(656.0, "float", "kg m^2",
                                       "wheelset roll inertia Ixx (thesis Table II)", "pos",
                                       source=f"{_T2}: Ixx 656 kg m^2", applies=WHEELSET),
        "wheel_radius": Param(0.46, "float", "m", "wheel rolling radius (Hertz constant)", "pos",
                              source="Jenkins et al. (1974) / benchmarks.md: R = 0.46 m",
                              applies=WHEELS),
        "contact_span": Param(1.5, "float", "m",
                              "lateral distance of the two wheel-rail contact points", "pos",
                              applies=WHEELS),
        "suspension_span": Param(2.0, "float", "m",
                                 "wheelset: lateral distance of the two suspension springs",
                                 "pos", applies=WHEELSET),
        "k_suspension": Param(25_000.0, "float", "N/m",
                              "wheelset: suspension stiffness per side (thesis Table II)",
                              "nonneg",
                              source=f"{_T2}: K_l1 = k_l2 = 25000 (read as vertical, per side)",
                              applies=WHEELSET),
        "c_suspension": Param(1_000.0, "float", "N s/m",
                              "wheelset: suspension damping per side (thesis Table II)",
                              "nonneg",
                              source=f"{_T2}: K_t1 = k_t2 = 1000 N.s/m (read as damping, per side; "
                                     "see docs/thesis.md for the other reading)", applies=WHEELSET),
        "preload": Param(0.0, "float", "N",
                         "wheelset: static downward force of the frame per side (share of a "
                         "car body; 0 in the thesis)", "nonneg", applies=WHEELSET),
        "k_lateral": Param(25_000.0, "float", "N/m",
                           "wheelset: lateral suspension stiffness (not in Table II: the vertical "
                           "value)", "nonneg", applies=WHEELSET),
        "c_lateral": Param(1_000.0, "float", "N s/m", "wheelset: lateral suspension damping",
                           "nonneg", applies=WHEELSET),
        "conicity": Param(0.025, "float", "-",
                          "wheelset: equivalent tread conicity (UIC 1:40); the contact normals "
                          "lean inwards and couple lateral motion and the rails' lateral modes",
                          "nonneg", source="UIC 1:40 tread inclination", applies=WHEELSET),
        "k_hertz": Param(0.0, "float", "N/m^1.5",
                         "Hertz constant K_H (0: Jenkins' formula from wheel_radius)", "nonneg",
                         applies=WHEELS),
        "contact_damping": Param(0.0, "float", "N s/m^2",
                                 "Hertz contact damping C in F = K_H d^1.5 - C d' |d| (the "
                                 "thesis's formula; it gives no value)", "nonneg",
                                 source="thesis §4.2 formula F = K_H d^1.5 + C d' |d|; C not "
                                        "given", applies=WHEELS),
        "supercritical": Param(False, "bool", "-",
                               "accept a train at or above the ground's Rayleigh speed "
                               "(the critical speed of a track on soft soil: the response "
                               "grows and forms a Mach cone; without this key such a speed "
                               "is refused)",
                               source="issue 28: reaching the soil's Rayleigh speed must be "
                                      "handled"),
        "drop_height": Param(0.0, "float", "m",
                             "initial condition: 0 starts the vehicle at rest in static "
                             "equilibrium; > 0 drops it: at t = 0 the track is at rest and "
                             "every body hangs rigidly lifted from its static equilibrium so "
                             "that the wheels are this far above the rail (the thesis's "
                             "wheelset is 'dropped from a small distance', unspecified)",
                             "nonneg",
                             source="thesis §2.2: 'dropped from a small distance'; not given",
                             applies=WHEELS),
        "n_cars": Param(1, "int", "-", "vehicle: number of coupled cars in the train", "pos",
                        applies=CARS),
        "car_mass": Param(32_000.0, "float", "kg", "vehicle: car body mass (defaults: Manchester "
                          "Benchmark passenger coach, Iwnicki 1998)", "pos", source=_MANCHESTER,
                          applies=CARS),
        "car_pitch_inertia": Param(1.97e6, "float", "kg m^2", "vehicle: car body pitch inertia",
                                   "pos", source=_MANCHESTER, applies=CARS),
        "car_roll_inertia": Param(5.68e4, "float", "kg m^2", "vehicle: car body roll inertia",
                                  "pos", source=_MANCHESTER, applies=CARS),
        "bogie_mass": Param(2_615.0, "float", "kg", "vehicle: bogie frame mass", "pos",
                            source=_MANCHESTER, applies=CARS),
        "bogie_pitch_inertia": Param(1_476.0, "float", "kg m^2", "vehicle: bogie pitch inertia",
                                     "pos", source=_MANCHESTER, applies=CARS),
        "bogie_roll_inertia": Param(1_722.0, "float", "kg m^2", "vehicle: bogie roll inertia",
                                    "pos", source=_MANCHESTER, applies=CARS),
        "car_wheelset_mass": Param(1_813.0, "float", "kg", "vehicle: wheelset mass", "pos",
                                   source=_MANCHESTER, applies=CARS),
        "car_wheelset_roll_inertia": Param(1_120.0, "float", "kg m^2",
                                           "vehicle: wheelset roll inertia", "pos",
                                           source=_MANCHESTER, applies=CARS),
        "k_primary": Param(1.22e6, "float", "N/m",
                           "vehicle: primary suspension stiffness per axle box", "nonneg",
                           source=f"{_MANCHESTER}: 1.22 MN/m per axle box (TTB-2D, "
                                  "github.com/DanielCanteroNTNU/TTB-2D "
                                  "TrainProp_Manchester_BenchMark.m, uses 1.20 MN/m)",
                           applies=CARS),
        "c_primary": Param(4.0e3, "float", "N s/m",
                           "vehicle: primary suspension damping per axle box", "nonneg",
                           source=_MANCHESTER, applies=CARS),
        "k_secondary": Param(4.3e5, "float", "N/m",
                             "vehicle: secondary suspension stiffness per side", "nonneg",
                             source=_MANCHESTER, applies=CARS),
        "c_secondary": Param(2.0e4, "float", "N s/m",
                             "vehicle: secondary suspension damping per side", "nonneg",
                             source=_MANCHESTER, applies=CARS),
        "k_antiroll": Param(940e3, "float", "N m/rad",
                            "vehicle: anti-roll bar stiffness per bogie (roll moment between "
                            "car body and bogie frame per radian of relative roll)", "nonneg",
                            source=f"{_MANCHESTER}: anti-roll bar 940 kN m/rad per bogie",
                            applies=CARS),
        "primary_span": Param(2.0, "float", "m",
                              "vehicle: lateral distance of the primary springs", "pos",
                              source=_MANCHESTER, applies=CARS),
        "secondary_span": Param(2.0, "float", "m",
                                "vehicle: lateral distance of the secondary springs", "pos",
                                source=_MANCHESTER, applies=CARS),
        "bogie_spacing": Param(19.0, "float", "m", "vehicle: distance between the bogie centres",
                               "pos", source=_MANCHESTER, applies=CARS),
        "wheelbase": Param(2.56, "float", "m", "vehicle: axle distance within a bogie", "pos",
                           source=_MANCHESTER, applies=CARS),
        "car_length": Param(26.4, "float", "m",
                            "vehicle: length over couplers (distance of successive cars)", "pos",
                            source="UIC-Z coach length over couplers (not in the benchmark)",
                            applies=CARS),
        "coupler_stiffness": Param(0.0, "float", "N/m",
                                   "vehicle: vertical stiffness coupling successive car ends",
                                   "nonneg", applies=CARS),
    },
    "train2": {
        "enabled": Param(True, "bool", "-",
                         "with track.count = 2: a second train runs on track 2 (false: the "
                         "track is there, unloaded)", applies=SECOND_TRACK),
        "direction": Param("opposite", "str", "-",
                           "the second train's direction: 'same' as [vehicle] (+x) or "
                           "'opposite' (-x, from the far end of the rigid exit rail)",
                           choices=("same", "opposite"), applies=SECOND_TRAIN),
        "t_start": Param(0.0, "float", "s",
                         "delay of the second train: it is where [vehicle]'s train would be "
                         "at t = 0 (mirrored for 'opposite') t_start later", "nonneg",
                         applies=SECOND_TRAIN),
        "speed": Param(0.0, "float", "m/s", "the second train's speed (0: vehicle.speed)",
                       "nonneg", applies=SECOND_TRAIN),
        "n_cars": Param(0, "int", "-",
                        "vehicle.type = 'vehicle': the second train's cars (0: vehicle.n_cars)",
                        "nonneg", applies=SECOND_TRAIN_CARS),
    },
    "irregularity": {
        "type": Param("none", "str", "-",
                      "vertical rail irregularity: none, a profile file, or a seeded random "
                      "profile from the FRA or ISO 8608 spectrum",
                      choices=("none", "file", "fra", "iso8608"), applies=WHEELS),
        "file": Param("", "str", "-",
                      "profile file: columns x z, or x z_rail0 z_rail1 [m] (relative to the case "
                      "file)", applies=PROFILE_FILE),
        "track_class": Param("6", "str", "-",
                             "FRA class 1..6 or ISO 8608 class A..H",
                             choices=("1", "2", "3", "4", "5", "6",
                                      "A", "B", "C", "D", "E", "F", "G", "H"),
                                      applies=RANDOM_PROFILE),
        "seed": Param(1, "int", "-", "random seed of the profile", "nonneg",
                      applies=RANDOM_PROFILE),
        "wavelength_min": Param(1.524, "float", "m",
                                "shortest wavelength of the random profile (the FRA spectra are "
                                "fitted to 1.524-304.8 m, i.e. 5-1000 ft)", "pos",
                                source="FRA spectra fitted to 5-1000 ft (Hamid et al., "
                                       "FRA/ORD-80/28, 1980; 1.524 m = 5 ft)",
                                applies=RANDOM_PROFILE),
        "wavelength_max": Param(30.0, "float", "m", "longest wavelength of the random profile",
                                "pos", applies=RANDOM_PROFILE),
        "flat_depth": Param(0.0, "float", "m", "wheel flat depth (0: no flat)", "nonneg",
                            applies=WHEELS),
        "flat_length": Param(0.05, "float", "m", "wheel flat length", "pos", applies=WHEEL_FLATS),
        "flat_wheels": Param([0.0], "floats", "-", "indices of the wheels with a flat",
                             applies=WHEEL_FLATS),
    },
    "mbs": {
        "n_modes": Param(0, "int", "-", "modes used (0: all modes in modes.h5)", "nonneg"),
        "dt": Param(0.0, "float", "s",
                    "time step (0: automatic from the highest mode and the contact stiffness)",
                    "nonneg"),
        "points_per_period": Param(20, "int", "-",
                                   "automatic time step: steps per period of the fastest "
                                   "oscillation", "pos"),
        "store_every": Param(1, "int", "-", "store every n-th time step in mbs.h5", "pos"),
        "damping_modes": Param([], "floats", "-",
                               "modes (1-based) whose damping ratio is overridden"),
        "damping_ratios": Param([], "floats", "-",
                                "damping ratios of damping_modes (one per entry)"),
        "static_correction": Param(False, "bool", "-",
                                   "add the residual static flexibility of the modes not "
                                   "kept as residual modes with their mass and damping "
                                   "(modal truncation augmentation; needs static.h5 from the "
                                   "modal stage)"),
    },
    "load": {
        "force": Param(0.0, "float", "N",
                       "with track.count = 0: downward force of each point load moving over "
                       "the bare soil surface (0: no surface load; STEM's 'moving load on "
                       "soil', the verification against the steady state of a load moving "
                       "over an elastic half-space, railvib_hpc.fem.halfspace)", "nonneg",
                       source="issue 28 item 5: a verification load, no default model",
                       applies=BARE_SOIL),
        "speed": Param(30.0, "float", "m/s",
                       "the surface load's speed along +x (at or above the ground's Rayleigh "
                       "speed only with vehicle.supercritical = true)", "pos",
                       source="vehicle.speed's default", applies=BARE_SOIL),
        "y": Param(0.0, "float", "m",
                   "lateral position of the load's path on the ground (the line y = load.y, "
                   "z = geometry.z1); it must cross the soil", applies=BARE_SOIL),
        "x_start": Param(0.0, "float", "m",
                         "position of the leading load at t = 0 (a load off the soil's ground "
                         "is off)", applies=BARE_SOIL),
        "x_end": Param(0.0, "float", "m",
                       "the run ends when the last load reaches this position (0: the soil's "
                       "end along x, geometry.x4 + domain.extra_length)", "nonneg",
                       applies=BARE_SOIL),
        "t_after": Param(0.0, "float", "s",
                         "extra time simulated after the last load reaches load.x_end",
                         "nonneg", applies=BARE_SOIL),
        "offsets": Param([0.0], "floats", "m",
                         "positions of the loads along x relative to the leading one "
                         "(<= 0; one load of load.force each)", applies=BARE_SOIL),
        "start": Param("ramp", "str", "-",
                       "how the loads start at t = 0: 'ramp' (the soil at rest, the forces "
                       "switched on over load.ramp_time while the loads move at load.speed; "
                       "0: a step, which radiates a pulse) or 'static' (the soil at rest in "
                       "static equilibrium under the full forces at their start positions, "
                       "K u0 = f0, velocities zero; the loads then run up to load.speed "
                       "over load.ramp_time, 0: at once, which radiates the moving field's "
                       "difference from the static one as a pulse; needs the box held "
                       "statically: a fixed, roller, caughey or pml face, or absorbing "
                       "faces with boundary.virtual_thickness > 0)",
                       choices=("ramp", "static"),
                       source="'ramp': the surface load's start before 'static' existed "
                              "(the results of earlier cases unchanged)", applies=BARE_SOIL),
        "ramp_time": Param(0.0, "float", "s",
                           "load.start = 'ramp': the forces grow as sin^2(pi t / (2 "
                           "ramp_time)) over this time, then stay (0: a step at t = 0, which "
                           "radiates a pulse); load.start = 'static': the loads' speed grows "
                           "so from 0 to load.speed (they cover load.speed x ramp_time / 2 in "
                           "it)", "nonneg", applies=BARE_SOIL),
        "half_width": Param(0.0, "float", "m",
                            "half-width a of each load's spreading along x, (1 + cos(pi s / "
                            "a)) / (2 a) over |s| <= a (0: a point load, the consistent load "
                            "of the element under it; a >= 2 element sizes keeps a point "
                            "load's grid pulses at speed / element size small)", "nonneg",
                            applies=BARE_SOIL),
        "frequency": Param(0.0, "float", "Hz",
                           "each load varies as cos(2 pi frequency t) after its switch-on (0: "
                           "constant): the moving harmonic load, which radiates Rayleigh "
                           "waves of wavelength (c_R -/+ speed) / frequency ahead of and "
                           "behind it (its plane-strain reference: "
                           "railvib_hpc.fem.halfspace_line); at most transient.f_max",
                           "nonneg", source="issue 28 item 7: a verification load",
                           applies=BARE_SOIL),
    },
    "transient": {
        "dt": Param(0.0, "float", "s",
                    "time step of the full-order time integration (0: automatic, the largest "
                    "step that divides output.dt and resolves transient.f_max with "
                    "transient.steps_per_period steps and, with a vehicle, crosses a rail "
                    "element in transient.steps_per_element steps)", "nonneg"),
        "f_max": Param(80.0, "float", "Hz",
                       "highest frequency of the analysis band (80 Hz: the top one-third-octave "
                       "band of the assessment); a coarser time step is warned about", "pos"),
        "steps_per_period": Param(20, "int", "-",
                                  "automatic time step: steps per period of transient.f_max "
                                  "(20: period error 0.8 % with the trapezoidal rule)", "pos"),
        "steps_per_element": Param(8, "int", "-",
                                   "automatic time step: steps while a wheel crosses one rail "
                                   "element (8: peak contact force within 0.3 % of half the "
                                   "step on the coarse thesis model)", "pos"),
        "rho_inf": Param(1.0, "float", "-",
                         "generalized-alpha (Chung-Hulbert) spectral radius at infinite "
                         "frequency: 1 = Newmark average acceleration (trapezoidal rule, no "
                         "numerical damping, energy conserving), < 1 damps the highest "
                         "frequencies (0.8: period error 0.86 % instead of 0.82 % at 20 steps "
                         "per period)",
                         "unit", applies=DIRECT_ENGINE),
        "engine": Param("direct", "str", "-",
                        "time integration of the full-order model: 'direct' (generalized-"
                        "alpha, one MUMPS factor of K_eff: unconditionally stable, memory "
                        "~n^(4/3)) or 'explicit' (central differences with the lumped mass: "
                        "memory and work per step linear in the DOFs, the step limited by the "
                        "largest natural frequency; needs modal.lumped_mass = true) or "
                        "'imex' (implicit-explicit, Hughes & Liu 1978: the elements of "
                        "transient.implicit_parts by the trapezoidal rule with one small "
                        "MUMPS factor, the rest (the soil) explicit with the lumped mass: the "
                        "step limited by the soil's elements only; needs modal.lumped_mass = "
                        "true)",
                        choices=TRANSIENT_ENGINES,
                        source="issue 28: an engine whose memory and cost grow linearly"),
        "implicit_elements": Param("parts", "str", "-",
                                   "transient.engine = 'imex': 'parts' integrates the parts "
                                   "of transient.implicit_parts implicitly; 'auto' also every "
                                   "solid element whose own stable step (its largest "
                                   "frequency with the lumped mass and its Rayleigh damping) is "
                                   "below the target step (transient.dt, or the band's step), "
                                   "at most the 5 % with the smallest steps: thin slices and "
                                   "heavily damped elements of the soil no longer set the "
                                   "step of the whole model",
                                   choices=("parts", "auto"),
                                   source="issue 28: element-wise stable steps",
                                   applies=IMEX_ENGINE),
        "implicit_parts": Param(["track", "building"], "strs", "-",
                                "transient.engine = 'imex': the parts integrated implicitly "
                                "(part names, or the groups 'track' = rails, sleepers, pads, "
                                "under-sleeper pads, ballast mats and 'building' = the "
                                "building's parts and its base isolation); every other "
                                "element is explicit and sets the stable step",
                                source="issue 28: the stiff, small track and building "
                                       "implicit, the soil explicit", applies=IMEX_ENGINE),
        "checkpoint_interval": Param(120.0, "float", "s",
                                     "wall-clock time between checkpoints of the state (an "
                                     "interrupted run resumes from the last one; 0: none)",
                                     "nonneg"),
    },
    "output": {
        "dt": Param(0.001, "float", "s",
                    "time step of the reconstructed fields (a multiple of the MBS step; 0: every "
                    "step stored in mbs.h5)", "nonneg"),
        "window": Param([], "floats", "s",
                        "time window [t0, t1] of the reconstructed fields (empty: all)"),
        "float32": Param(False, "bool", "-", "store reconstructed fields in single precision"),
        "stress_times": Param([0.54, 0.61], "floats", "s",
                              "times of the element stress/strain fields (thesis: 0.54, 0.61 s)",
                              source="thesis Figs. 21-26: t = 0.54 s and 0.61 s"),
        "probes": Param([], "floats", "m",
                        "extra probe points as a flat list x1, y1, z1, x2, y2, z2, ..."),
        "probe_roles": Param([], "strs", "-",
                             "role of each extra probe point, in the order of output.probes "
                             "(empty: every point is 'ground'); 'floor' points are assessed "
                             "with the DIN 4150-3 floor limit, the others as foundations",
                             choices=PROBE_ROLES),
        "static_correction_rates": Param(False, "bool", "-",
                                         "with mbs.static_correction: add the correction also "
                                         "to velocities and accelerations (R g', R g''); off: "
                                         "the classical mode-acceleration method, displacements "
                                         "and stresses corrected, velocities and accelerations "
                                         "from the modes (R g'' carries the node-to-node "
                                         "stepping of the moving load far above the modal band)",
                                         applies=STATIC_CORRECTION),
    },
    "probes": {
        "line": Param([], "probe_lines", "-",
                      "free-field probe lines as [[probes.line]] tables with name, distances, "
                      "side and x (docs/sites.md): each distance is a probe <name>_<d>m of role "
                      "free_field on the ground, assessed by PPV, the largest 1 s running RMS "
                      "and the one-third-octave velocity spectrum; [] = none"),
    },
    "assessment": {
        "standards": Param(list(STANDARDS), "strs", "-",
                           "vibration criteria to evaluate: " + "; ".join(
                               f"{s.name} = {s.title}" for s in STANDARDS.values()),
                           choices=tuple(STANDARDS)),
        "building_use": Param("residential", "str", "-",
                              "use of the building: ISO multiplier, FTA category, VC curve, "
                              "DIN 4150-3 line", choices=tuple(BUILDING_USES)),
        "period": Param("day", "str", "-", "assessment period (ISO 10137, DIN 4150-2)",
                        choices=PERIODS),
        "fta_events": Param("frequent", "str", "-", "FTA event frequency", choices=FTA_EVENTS,
                            applies=FTA),
        "din4150_2_events": Param(0, "int", "-",
                                  "train passages per assessment period for DIN 4150-2 KB_FTr "
                                  "(0: not given; the middle band stays undetermined)",
                                  "nonneg", applies=DIN4150_2),
        "wave_threshold": Param(0.1, "float", "-",
                                "wave arrival: first time the acceleration magnitude exceeds "
                                "this fraction of its peak", "fraction"),
    },
    # Uncertain inputs (issue 30, docs/uncertainty.md): `railvib study uncertainty CASE`
    # samples them; `railvib run` uses the nominal values (and field realisation 0: none).
    "uncertainty": {
        "parameter": Param([], "uncertain_parameters", "-",
                           "[[uncertainty.parameter]] tables: key (a numeric case key, or "
                           "soil.layers[k].<name>), distribution (normal, lognormal, uniform, "
                           "truncated_normal), mean (default: the case's value), std or cov, "
                           "low, high, name (label)"),
        "correlation": Param([], "matrix", "-",
                             "correlation matrix of the parameters' normal scores (Gaussian "
                             "copula), one row per [[uncertainty.parameter]] in their order; "
                             "[] = independent; symmetric, unit diagonal, positive definite"),
        "method": Param("lhs", "str", "-",
                        "sampling: lhs (Latin hypercube), mc (Monte Carlo) or sobol (Saltelli "
                        "design for Sobol' indices: samples * (parameters + 2) runs)",
                        choices=SAMPLING_METHODS),
        "samples": Param(32, "int", "-", "number of samples (sobol: base points, a power "
                         "of 2)", "pos"),
        "seed": Param(2026, "int", "-", "seed of the design and the random fields (every "
                      "sample is reproducible; the bootstrap has a fixed seed of its own)",
                      "nonneg"),
        "field": Param([], "random_fields", "-",
                       "[[uncertainty.field]] tables: layer (1-based soil layer), quantity "
                       "(E or rho), model (gaussian, exponential, matern), cov, len_h, len_v "
                       "[m], nu (Matern smoothness, default 1.5)"),
        "realisation": Param(0, "int", "-", "realisation of the random fields the model "
                             "uses: 0 none (the nominal layers), k >= 1 the k-th (seeded by "
                             "uncertainty.seed and k; the study sets it per sample)", "nonneg",
                             applies=RANDOM_FIELDS),
        "model": Param("full", "str", "-",
                       "how each sample is solved: full (its own mesh and eigensolve) or "
                       "reduced (the parametric reduced model on the nominal mesh, with "
                       "residual checks, fallback to full solves and reference samples; "
                       "docs/uncertainty.md)", choices=UQ_MODELS),
        "reduced_tol": Param(REDUCED_TOL, "float", "-",
                             "largest relative residual ||K phi - lambda M phi|| / ||K phi|| "
                             "of a reduced mode; a sample above it gets the full eigensolve "
                             "(on the nominal mesh)", "pos",
                             source="docs/uncertainty.md, 'The reduced model' (measured on "
                                    "the coarse thesis model)", applies=REDUCED_MODEL),
        "reduced_checks": Param(2, "int", "-",
                                "reference samples of the reduced model: drawn at random "
                                "(uncertainty.seed), each also solved in full and compared",
                                "nonneg", applies=REDUCED_MODEL),
        "basis": Param("", "str", "-",
                       "the reduced basis a sample's modes come from (set by railvib study "
                       "uncertainty with model = 'reduced'; empty: a plain model)",
                       applies=REDUCED_MODEL),
        "reference": Param(False, "bool", "-",
                           "with uncertainty.basis: solve in full too and record the reduced "
                           "model's error (set by the study on its reference samples)",
                           applies=REDUCED_BASIS),
    },
    # Settings of `railvib study KIND`: one table per study (``[study.convergence]``, ...);
    # ``--study-set key=value`` sets ``study.KIND.key``. Defaults chosen for the thesis model.
    "study": {
        "convergence": {
            "levels": Param([0.5, 0.75, 1.0, 1.25], "floats", "-",
                            "mesh.refinement of each level (at least 2, coarse to fine)",
                            "refinement", unique=True),
            "tolerance": Param(5.0, "float", "%", "verdict: converged when the estimated "
                               "error of the finest level is at most this many percent", "pos"),
            "n_frequencies": Param(5, "int", "-", "lowest natural frequencies compared", "pos"),
            "formal_order": Param(2.0, "float", "-", "order assumed with two levels or when "
                                  "the observed order is unreliable (trilinear hexahedra: 2)",
                                  "pos"),
            "solver": _study_solver("no natural frequencies are then compared"),
            "probes": _study_probes(),
        },
        "modes": {
            "n_modes": Param([50, 100, 200, 300], "ints", "-",
                             "numbers of modes used by the MBS (mbs.n_modes), from one modal "
                             "solve with the largest", "pos", unique=True),
            "static_correction": Param([False, True], "bools", "-",
                                       "run every mode count without and/or with the static "
                                       "correction", unique=True),
            "tolerance": Param(5.0, "float", "%", "accuracy asked for: modes needed to stay "
                               "within this many percent of the reference (most modes, "
                               "corrected if run)", "pos"),
            "probes": _study_probes(),
        },
        "reflection": {
            "domains": Param([[-1.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 2.0, 6.0],
                              [4.0, 4.0, 12.0]], "triples", "m",
                             "[depth, length, width] change of each domain: depth > 0 deepens "
                             "the subgrade (domain.extra_depth), < 0 raises the fixed base "
                             "(geometry.z0); length (each end) and width (beyond the building) "
                             ">= 0 (domain.extra_*); smallest first, the last is the reference. "
                             "Defaults: the thesis's Models 1-3 (3 m deep; the APDL's 4.8 m, "
                             "its '5 m'; + 2 m length, + 6 m width) and a larger reference",
                             unique=True),
            "names": Param(["model1", "model2", "model3", "larger"], "strs", "-",
                           "variant names, one per domain (default with other domains: "
                           "domain1, domain2, ...)", "name", unique=True),
            "threshold": Param(10.0, "float", "%", "verdict: reflections matter when a "
                               "building peak acceleration differs from the reference domain "
                               "by more than this many percent", "pos"),
            "band_hz": Param(0.0, "float", "Hz", "0: every domain uses modal.n_modes of the "
                             "case; > 0: every domain uses all its modes below this frequency "
                             "(the same band for all domains)", "nonneg"),
            "boundaries": Param(["case"], "strs", "-",
                                "boundary conditions of the truncation faces, each run on every "
                                "domain: case (the case file's [boundary]), thesis (rollers, "
                                "fixed base), absorbing (all five faces absorbing), pml (all "
                                "five faces perfectly matched layers of pml_thickness, added "
                                "outside each domain; solver = direct)",
                                choices=("case", "thesis", "absorbing", "pml"), unique=True),
            "pml_thickness": Param(4.0, "float", "m",
                                   "boundaries = pml: thickness of the layers (about 5 "
                                   "element layers of the coarse mesh's soil near the "
                                   "building, Collino & Tsogka 2001's smallest good layer)",
                                   "pos"),
            "solver": Param("modal", "str", "-",
                            "modal (modes + mbs, the thesis's method) or direct (railvib "
                            "transient: the full model in the time domain, causal; band_hz "
                            "does not apply)", choices=("modal", "direct")),
            "probes": _study_probes(),
        },
        "speed": {
            "speeds": Param([10.0, 20.0, 30.0, 40.0, 50.0, 60.0], "floats", "m/s",
                            "vehicle speeds (one MBS run each on the same modes); without a track "
                            "(track.count = 0, solver = direct): the moving load's, load.speed",
                            "pos",
                            unique=True),
            "solver": _study_solver("every speed is then a full-order run, no shared modes"),
            "probes": _study_probes(),
        },
        "mitigation": {
            "measures": Param([
                "soft_pads: pads.kz=1.2e8",
                "open_trench: trench.type=open; trench.distance=6.0; trench.width=0.6; "
                "trench.depth=3.0",
                "filled_trench: trench.type=filled; trench.distance=6.0; trench.width=0.6; "
                "trench.depth=3.0",
                "wib: wib.type=block; wib.width=6.0; wib.depth=1.0; wib.thickness=1.0"],
                "strs", "-",
                "the measures, each 'name: key=value; key=value' (case overrides, TOML "
                "values). Defaults: soft rail pads (120 kN/mm instead of the thesis's "
                "7,000), an open and an EPS-filled trench 0.6 m wide and 3 m deep 6 m from "
                "the track, and a 6 m wide, 1 m thick wave-impeding block 1 m under the "
                "track", unique=True),
            "same_mesh": Param(True, "bool", "-",
                               "compare a measure that changes the soil geometry (trench.*, "
                               "wib.*) with a reference on its own mesh (the same lines, no "
                               "measure) instead of the baseline: the insertion loss is then "
                               "the measure's, not the mesh's"),
            "solver": _study_solver("every variant, the references included"),
            "probes": _study_probes(),
        },
        "uncertainty": {
            "confidence": Param(0.95, "float", "-", "confidence level of the intervals "
                                "(percentile bootstrap, Wilson, Sobol' bootstrap)", "fraction"),
            "solver": _study_solver("every sample is then a full-order run"),
            "probes": _study_probes(),
        },
        "thesis": {
            "n_modes": Param(300, "int", "-", "the thesis's mode count (mbs.n_modes of the "
                             "count variants; the band must hold at least this many)", "pos"),
            "band_hz": Param(57.87, "float", "Hz", "the thesis's band: the shared model has "
                             "every mode below it (modal.f_max), the band variants use them "
                             "all", "pos"),
            "drop_heights": Param([0.0, 1e-5, 1e-4], "floats", "m",
                                  "wheelset drop heights (vehicle.drop_height; 0: start at "
                                  "rest): the thesis's unspecified start", "nonneg",
                                  unique=True),
            "contact_damping": Param([0.0], "floats", "N s/m^2",
                                     "Hertz contact damping C of the drops "
                                     "(vehicle.contact_damping; the thesis gives none)",
                                     "nonneg", unique=True),
            "probes": Param([*BUILDING_PROBES, "basement_wall_far"], "strs", "-",
                            "mesh probes whose responses are compared (the building probes "
                            "and the thesis's wave-arrival point)", "name", unique=True),
        },
    },
}

#: [vehicle] keys the second train shares with the first: how the run goes (its own
#: speed, cars and delay are ``train2.speed``, ``n_cars``, ``t_start``), and the wheel-rail
#: contact law, which the integrators apply to every wheel alike (one Hertz constant,
#: contact damping and conicity; :class:`railvib_hpc.mbs.train.Traffic`). The model type
#: is shared for the same reason: a wheelset's contact normals lean with its conicity, a
#: car's (no lateral dynamics) do not.
TRAIN2_SHARED_VEHICLE_KEYS = ("type", "speed", "x_start", "x_end", "t_after", "drop_height",
                              "n_cars", "wheel_radius", "k_hertz", "contact_damping",
                              "conicity", "supercritical")
SCHEMA["train2"]["vehicle"] = Param(
    {}, "vehicle", "-",
    "the second train's own vehicle, of [vehicle]'s type: a [train2.vehicle] table of the "
    "[vehicle] keys that differ (masses, inertias, suspension, spacings, axle_offsets, "
    "force); {} = [vehicle]'s vehicle",
    choices=tuple(k for k in SCHEMA["vehicle"] if k not in TRAIN2_SHARED_VEHICLE_KEYS),
    applies=SECOND_TRAIN)


class PresetValue(NamedTuple):
    """A preset's value of one key and where it comes from."""

    value: Any
    source: str


#: Values of the thesis's Table I where it differs from the APDL script
#: (../shared/reference/benchmarks.md section 3), each with its source. Layer depths are the
#: same in both presets: Table I's "ballast 4.8 m" contradicts the APDL z-levels and
#: the thesis's own wave speeds. Table I gives neither torsion constants nor the
#: sleeper's lateral second moment: those keep the APDL section's values.
_PRESET_VALUES: dict[str, dict[str, PresetValue]] = {
    "apdl": {},
    "table1": {
        "materials.ballast.nu": PresetValue(0.3, f"{_T1}: Poisson's ratio of the ballast 0.3"),
        "materials.ballast.rho": PresetValue(1300.0, f"{_T1}: density of the ballast 1300"),
        "materials.subballast.nu": PresetValue(
            0.35, f"{_T1}: Poisson's ratio of the subballast 0.35"),
        "materials.subgrade.nu": PresetValue(0.35, f"{_T1}: Poisson's ratio of the subgrade 0.35"),
        "materials.sleeper.rho": PresetValue(2750.0, f"{_T1}: density of a sleeper 2750"),
        **{f"pads.k{d}": PresetValue(26.5e7, f"{_T1}: stiffness coefficient of a pad 26.5e7")
           for d in "xyz"},
        **{f"pads.c{d}": PresetValue(4.6e4, f"{_T1}: damping coefficient of a pad 4.6e4")
           for d in "xyz"},
        "sections.rail.area": PresetValue(
            64.5e-4, f"{_T1}: cross-sectional area of the rail 64.5e-4"),
        "sections.rail.iyy": PresetValue(2010e-8, f"{_T1}: second moment of the rail Iyy 2010e-8"),
        "sections.rail.izz": PresetValue(326e-8, f"{_T1}: second moment of the rail Izz 326e-8"),
        "sections.rail.shear_coefficient_y": PresetValue(
            0.34, f"{_T1}: Timoshenko shear coefficient 0.34"),
        "sections.rail.shear_coefficient_z": PresetValue(
            0.34, f"{_T1}: Timoshenko shear coefficient 0.34 (one value given, used for both "
            "planes)"),
        "sections.sleeper.area": PresetValue(
            513.8e-4, f"{_T1}: cross-sectional area of a sleeper 513.8e-4"),
        "sections.sleeper.iyy": PresetValue(
            18907e-8, f"{_T1}: second moment of a sleeper 18907e-8"),
        "sections.sleeper.shear_coefficient_y": PresetValue(
            0.83, f"{_T1}: Timoshenko shear coefficient 0.83"),
        "sections.sleeper.shear_coefficient_z": PresetValue(
            0.83, f"{_T1}: Timoshenko shear coefficient 0.83 (one value given, used for both "
            "planes)"),
    },
}
#: The keys each preset sets and their values: ``PRESETS[preset][key]`` (``apdl``: none, the
#: schema defaults).
PRESETS: dict[str, dict[str, Any]] = {
    name: {key: entry.value for key, entry in values.items()}
    for name, values in _PRESET_VALUES.items()}
#: Where each preset value comes from: ``PRESET_SOURCES[preset][key]``; the defaults' own
#: sources are :attr:`Param.source`.
PRESET_SOURCES: dict[str, dict[str, str]] = {
    name: {key: entry.source for key, entry in values.items()}
    for name, values in _PRESET_VALUES.items()}


def source(key: str, preset: str = "apdl") -> str:
    """Where the value of ``key`` comes from in ``preset`` ('' for program settings).

    A key the preset does not set takes the source of its default (:attr:`Param.source`).
    """
    own = PRESET_SOURCES.get(preset, {}).get(key)
    if own:
        return own
    node: Any = SCHEMA
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return ""
        node = node[part]
    return node.source if isinstance(node, Param) else ""


def iter_params(tree: dict[str, Any] | None = None, prefix: str = ""):
    """Yield ``(dotted_key, Param)`` for every key of the schema, in order."""
    tree = SCHEMA if tree is None else tree
    for name, node in tree.items():
        key = f"{prefix}{name}"
        if isinstance(node, Param):
            yield key, node
        else:
            yield from iter_params(node, key + ".")
