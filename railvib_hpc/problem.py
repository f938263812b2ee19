"""The problem object: what the numerical kernels take from a case, read once (pure).

The boundary between the case and the kernels
---------------------------------------------
*Translators* read the :class:`~railvib_hpc.config.Case`: the case itself and its checks
(``config``, ``validation``, ``schema``, ``site``), this module, the mesh builders that
turn case keys into geometry (``mesh.layout``, ``mesh.building``, ``mesh.turn``,
``mesh.interfaces``, ``mesh.dispersion_check``), the vehicle and damping-model
translations of the MBS (``mbs.case_vehicle``, ``mbs.damping_model``), every
``*/stage.py``, the thesis comparison (``assess.thesis``: it describes the case's mesh,
vehicle and geometry next to the thesis's tables), the stage-file layer (``io``: digests
and provenance of the case), the studies, the API and the CLI. The stages build this
object from the case once per computation, with :meth:`Problem.from_case`.

*Numerical kernels* take arrays (the mesh, the DOF map, matrices, modes) and a
:class:`Problem`, never the case: every other module of :mod:`railvib_hpc.fem`,
:mod:`railvib_hpc.mesh`, :mod:`railvib_hpc.modal`, :mod:`railvib_hpc.mbs`,
:mod:`railvib_hpc.transient`, :mod:`railvib_hpc.reconstruct` and :mod:`railvib_hpc.assess`
(the element kernels and the assembly, the DOF map, the boundaries and damping, the
eigensolvers, the time integrators, the field, stress and probe reconstruction, the
criteria). ``make lint`` (``tools/code_rules.py``) and ``tests/test_code_rules.py`` fail
on a kernel module that imports from ``railvib_hpc.config`` or takes a parameter named
``case``; the translators are listed there (``TRANSLATORS``) with the reason each reads
the case.

What the problem holds, and what it does not
--------------------------------------------
The physics of the model as the kernels need it: each material (E, nu, rho, damping
ratio; the soil layers' resolved from ``c_s`` where given), the beam sections, the rail
pads' springs and dashpots, the elastic interfaces, each truncation face's condition and
the boundary parameters, the damping model, and the element switches (lumped mass, hex
formulation, the constrained rotations). Not the mesh nor the DOF map (arrays, passed
next to it), and not the solver settings (tolerances, shifts, block sizes, PETSc
prefixes): those belong to the solver objects
(:class:`~railvib_hpc.model.factor.ShiftInvertFactor`, the eigensolver's and the time
integrators' settings).

Examples
--------
>>> from railvib_hpc.config import Case
>>> problem = Problem.from_case(Case.defaults())
>>> problem.material("subgrade").E, problem.boundary.faces["base"], problem.damping.model
(200000000.0, 'fixed', 'rayleigh')
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from .schema import (
    BOUNDARY_FACES,
    INTERFACE_PARTS,
    MIN_SOIL_LAYER_THICKNESS,
    PML_ALPHA,
    SOIL_LAYER_PARTS,
)
from .uncertainty.fields import RandomField

if TYPE_CHECKING:
    from .config import Case

@dataclass(frozen=True)
class Material:
    """An isotropic elastic material: ``materials.<name>`` or a soil layer."""

    E: float
    nu: float
    rho: float
    damping_ratio: float


@dataclass(frozen=True)
class Section:
    """A beam cross-section (``sections.<name>``)."""

    area: float
    iyy: float
    izz: float
    j: float
    shear_coefficient_y: float
    shear_coefficient_z: float


@dataclass(frozen=True)
class Pads:
    """The rail pads' springs ``kx, ky, kz`` [N/m] and dashpots ``cx, cy, cz`` [N s/m]."""

    kx: float
    ky: float
    kz: float
    cx: float
    cy: float
    cz: float


@dataclass(frozen=True)
class Interface:
    """An elastic interface (``[usp]``, ``[ballast_mat]``, ``[isolation]``): bedding
    modulus, shear ratio, loss factor and the bearing width of its tributary areas
    (``usp.width``; 0 for the others)."""

    modulus: float
    shear_ratio: float
    loss_factor: float
    width: float = 0.0


@dataclass(frozen=True)
class Boundary:
    """``[boundary]``: each truncation face's condition (in :data:`BOUNDARY_FACES` order)
    and the absorbing faces' and Caughey layers' parameters."""

    faces: Mapping[str, str]
    virtual_thickness: float
    layer_thickness: float
    layer_damping: float
    pml_reflection: float = 1e-4
    pml_power: float = 2.0
    pml_alpha: float = PML_ALPHA


@dataclass(frozen=True)
class Damping:
    """``[damping]`` and the global ratio ``modal.damping_ratio`` (the Rayleigh model's,
    the rail pads' group)."""

    model: str
    f1: float
    f2: float
    pads: bool
    ratio: float


@dataclass(frozen=True)
class TrackEnds:
    """``track.ends`` and its supported sections (:mod:`railvib_hpc.model.track_ends`).

    ``kind`` is ``"rigid"`` or ``"supported"``; the supported rail lies on ``[box_start -
    length, box_start]`` and ``[box_end, box_end + length]`` with a support at every
    ``spacing`` from the box's ends; ``stiffness`` is the vertical spring per rail and
    support (0: not fitted yet), ``damping`` the far ends' ratio of critical damping.
    """

    kind: str = "rigid"
    box_start: float = 0.0
    box_end: float = 0.0
    length: float = 0.0
    spacing: float = 1.0
    stiffness: float = 0.0
    damping: float = 0.0

    @property
    def supported(self) -> bool:
        return self.kind == "supported"


@dataclass(frozen=True)
class Problem:
    """The physics of the model the kernels need, read from a case once.

    Attributes
    ----------
    materials
        ``{name: Material}``: every ``materials.<name>`` and the case's soil layers
        (``soil_layer_<k>``).
    sections
        ``{name: Section}`` (``rail``, ``sleeper``).
    pads
        The rail pads.
    interfaces
        ``{kind: Interface}`` of the elastic interfaces.
    boundary, damping
        :class:`Boundary`, :class:`Damping`.
    lumped_mass, hex_formulation, fix_sleeper_rotations, fix_rail_rotations_at_pads
        The ``modal.*`` switches of the elements and the constraints.
    fields
        The random fields of the soil layers' E and rho (``[[uncertainty.field]]`` at
        ``uncertainty.realisation`` >= 1; empty otherwise): the element kernels scale each
        hexahedron's matrices by the factors at its centre
        (:class:`~railvib_hpc.uncertainty.fields.RandomField`).
    track_ends
        ``track.ends``: the rail beyond the soil box (:class:`TrackEnds`).
    """

    materials: Mapping[str, Material]
    sections: Mapping[str, Section]
    pads: Pads
    interfaces: Mapping[str, Interface]
    boundary: Boundary
    damping: Damping
    lumped_mass: bool
    hex_formulation: str
    fix_sleeper_rotations: bool
    fix_rail_rotations_at_pads: bool
    fields: tuple[RandomField, ...] = ()
    track_ends: TrackEnds = TrackEnds()

    def material(self, name: str) -> Material:
        """The material ``name`` (a ``materials.<name>`` or a soil layer ``soil_layer_<k>``).

        Raises
        ------
        KeyError
            A soil layer the case does not give, or an unknown material.
        """
        try:
            return self.materials[name]
        except KeyError:
            if name in SOIL_LAYER_PARTS:
                n = sum(1 for k in self.materials if k in SOIL_LAYER_PARTS)
                raise KeyError(f"{name}: the case gives {n} soil layer(s)") from None
            raise KeyError(f"materials.{name}: no such material") from None

    @classmethod
    def from_case(cls, case: Case) -> Problem:
        """The problem of a validated case (read with ``case[key]`` only: duck-typed)."""
        from .site import soil_layers

        materials: dict[str, Material] = {
            name: _material(values) for name, values in case["materials"].items()}
        for part, layer in zip(SOIL_LAYER_PARTS, soil_layers(case)):
            materials[part] = _material(layer)
        sections = {name: Section(**{k: sec[k] for k in Section.__dataclass_fields__})
                    for name, sec in case["sections"].items()}
        pads = case["pads"]
        interfaces = {kind: Interface(case[f"{kind}.modulus"], case[f"{kind}.shear_ratio"],
                                      case[f"{kind}.loss_factor"],
                                      case["usp.width"] if kind == "usp" else 0.0)
                      for kind in INTERFACE_PARTS}
        boundary = Boundary(MappingProxyType({f: case[f"boundary.{f}"] for f in BOUNDARY_FACES}),
                            case["boundary.virtual_thickness"], case["boundary.layer_thickness"],
                            case["boundary.layer_damping"], case["boundary.pml_reflection"],
                            case["boundary.pml_power"], case["boundary.pml_alpha"])
        damping = Damping(case["damping.model"], case["damping.f1"], case["damping.f2"],
                          case["damping.pads"], case["modal.damping_ratio"])
        return cls(MappingProxyType(materials), MappingProxyType(sections),
                   Pads(**{k: pads[k] for k in Pads.__dataclass_fields__}),
                   MappingProxyType(interfaces), boundary, damping,
                   case["modal.lumped_mass"], case["modal.hex_formulation"],
                   case["modal.fix_sleeper_rotations"], case["modal.fix_rail_rotations_at_pads"],
                   _fields(case), _track_ends(case))

    @classmethod
    def from_modes(cls, f) -> Problem:
        """The problem of the materials and sections an open ``modes.h5`` was computed with
        (:func:`case_from_modes`; its other fields are the defaults')."""
        return cls.from_case(case_from_modes(f))


#: Seeds of the fields of one realisation: ``uncertainty.seed + realisation * this + k``
#: for its k-th field (distinct for up to this many fields).
FIELD_SEED_STRIDE = 1000
#: The case keys the random fields are made of (:func:`_fields`), as a selection of the
#: product table (:data:`railvib_hpc.io.products.Selection`): every product computed from
#: the element matrices (the modes, the full-order solution) depends on them; at their
#: defaults (realisation 0: no field) they enter no digest.
RANDOM_FIELD_KEYS = (("uncertainty.field", ()), ("uncertainty.realisation", ()),
                     ("uncertainty.seed", ()))


def _fields(case: Case) -> tuple[RandomField, ...]:
    """The random fields of realisation ``uncertainty.realisation`` (none at 0)."""
    from .uncertain_inputs import DEFAULT_MATERN_NU

    real = case["uncertainty.realisation"]
    if real <= 0:
        return ()
    base = case["uncertainty.seed"] + real * FIELD_SEED_STRIDE
    return tuple(RandomField(SOIL_LAYER_PARTS[f["layer"] - 1], f["quantity"], f["model"],
                             float(f["cov"]), float(f["len_h"]), float(f["len_v"]),
                             float(f.get("nu", DEFAULT_MATERN_NU)), base + k)
                 for k, f in enumerate(case["uncertainty.field"]))
def _track_ends(case: Case) -> TrackEnds:
    """The :class:`TrackEnds` of ``track.*`` (duck-typed like :meth:`Problem.from_case`)."""
    return TrackEnds(case["track.ends"], case["geometry.x1"], case["geometry.x4"],
                     case["track.rigid_length"],
                     case["track.sleeper_spacing"], case["track.end_stiffness"],
                     case["track.end_damping"])


def _material(values: Mapping[str, Any]) -> Material:
    """A :class:`Material` from a mapping with (at least) ``E``, ``nu``, ``rho``,
    ``damping_ratio``."""
    return Material(values["E"], values["nu"], values["rho"], values["damping_ratio"])


def case_from_modes(f) -> Case:
    """The materials and sections the modes of an open ``modes.h5`` were computed with.

    Only ``[materials]`` and ``[sections]`` of the stored case (attribute
    ``case_toml``, fully resolved) are used, on top of the defaults, so that a
    file written by an older version with since-renamed keys elsewhere still reads;
    with soil layers also ``[soil]`` and the levels they are checked against
    (``[geometry]``, ``[domain]``, ``mesh.file``).
    """
    import tomllib

    from .config import build_case

    text = f.attrs["case_toml"]
    raw = tomllib.loads(text.decode() if isinstance(text, bytes) else text)
    keep = {k: raw[k] for k in ("materials", "sections") if k in raw}
    layers = raw.get("soil", {}).get("layers")
    if layers:
        keep.update({k: raw[k] for k in ("soil", "geometry", "domain") if k in raw})
        if raw.get("mesh", {}).get("file"):
            # a user's mesh holds its own layer levels; only the layers' materials are
            # needed here, so the levels are set to ones that pass the checks
            n = len(layers)
            keep["soil"] = {"layers": [{**x, "thickness": 0.0 if k == n - 1 else
                                        MIN_SOIL_LAYER_THICKNESS}
                                       for k, x in enumerate(layers)]}
            # a base below every layer but the last, with room for the last one
            keep["domain"] = {**keep.get("domain", {}),
                              "extra_depth": n * MIN_SOIL_LAYER_THICKNESS}
    return build_case(keep)
