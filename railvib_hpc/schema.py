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

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Param:
    """One case-file key.

    Parameters
    ----------
    default
        Default value (the thesis's APDL value where one exists).
    kind
        ``"float"``, ``"int"``, ``"str"``, ``"bool"``, ``"floats"`` (list of
        numbers) or ``"strs"`` (list of strings).
    unit
        SI unit, ``"-"`` for dimensionless.
    doc
        One-line meaning (shown in the README reference and in errors).
    check
        ``"pos"`` (> 0), ``"nonneg"`` (>= 0), ``"poisson"`` (0 <= nu < 0.5),
        ``"fraction"`` (0 <= x < 1), ``"unit"`` (0 <= x <= 1) or ``None``.
    choices
        Allowed values for strings (or list items).
    """

    default: Any
    kind: str
    unit: str
    doc: str
    check: str | None = None
    choices: tuple[str, ...] = field(default_factory=tuple)


def _mat(e: float, nu: float, rho: float, what: str) -> dict[str, Param]:
    return {
        "E": Param(e, "float", "Pa", f"Young's modulus of the {what}", "pos"),
        "nu": Param(nu, "float", "-", f"Poisson's ratio of the {what}", "poisson"),
        "rho": Param(rho, "float", "kg/m^3", f"density of the {what}", "pos"),
        "damping_ratio": Param(0.03, "float", "-",
                               f"damping ratio of the {what}, used when modal.damping = "
                               "'strain_energy'", "fraction"),
    }


#: Parts of the model, in the order of their part ids (id = index + 1).
PARTS: tuple[str, ...] = (
    "rail", "rigid_rail", "sleeper", "pad_x", "pad_y", "pad_z",
    "ballast", "subballast", "subgrade", "footing", "column", "beam", "slab", "wall",
)
SOLID_PARTS = ("ballast", "subballast", "subgrade", "footing", "column", "beam", "slab", "wall")
BEAM_PARTS = ("rail", "rigid_rail", "sleeper")
PAD_PARTS = ("pad_x", "pad_y", "pad_z")
BUILDING_PARTS = ("footing", "column", "beam", "slab", "wall")
PART_ID = {name: i + 1 for i, name in enumerate(PARTS)}
#: Conditions of a truncation face of the soil box (``[boundary]``).
BOUNDARY_TYPES = ("fixed", "roller", "free", "absorbing", "caughey")
#: The truncation faces of the soil box: x = min/max, y = min/max, z = min.
BOUNDARY_FACES = ("x_min", "x_max", "y_min", "y_max", "base")


def _face(default: str, where: str) -> Param:
    return Param(default, "str", "-",
                 f"{where}: fixed (all displacements 0), roller (normal displacement 0), free, "
                 "absorbing (Lysmer-Kuhlemeyer dashpots rho c_P normal, rho c_S tangential "
                 "per unit area, from the soil behind the face) or caughey (fixed, with a "
                 "graded Caughey absorbing layer inside the mesh, boundary.layer_*)",
                 choices=BOUNDARY_TYPES)

SCHEMA: dict[str, dict[str, Any]] = {
    "case": {
        "name": Param("thesis_baseline", "str", "-", "name of the case (used in reports)"),
        "description": Param("", "str", "-", "free text"),
        "preset": Param("apdl", "str", "-",
                        "parameter set for values not given in the file: 'apdl' (what the thesis "
                        "solved, Appendix A) or 'table1' (the thesis's Table I)",
                        choices=("apdl", "table1")),
    },
    "geometry": {
        "x0": Param(0.0, "float", "m", "X0: start of the first rigid rail"),
        "x1": Param(3.0, "float", "m", "X1: start of the flexible rail and of the soil"),
        "x2": Param(12.6, "float", "m", "X2: building (and its excavation) starts"),
        "x3": Param(19.8, "float", "m", "X3: building ends"),
        "x4": Param(24.6, "float", "m", "X4: end of the flexible rail and of the soil"),
        "ys0": Param(8.25, "float", "m", "YS0: soil edge on the side away from the building"),
        "ys1": Param(-4.25, "float", "m",
                     "YS1: toe of the embankment (subballast base half-width is |YS1|)"),
        "ys2": Param(-9.9, "float", "m", "YS2: building face nearest the track"),
        "ys3": Param(-17.1, "float", "m", "YS3: building face farthest from the track"),
        "ys4": Param(-29.1, "float", "m", "YS4: soil edge beyond the building"),
        "z0": Param(0.0, "float", "m", "Z0: bottom of the subgrade (fixed base)"),
        "z1": Param(4.8, "float", "m", "Z1: top of the subgrade = ground level"),
        "z2": Param(5.3, "float", "m", "Z2: top of the subballast"),
        "z3": Param(5.8, "float", "m", "Z3: top of the ballast = sleeper axis"),
        "z4": Param(6.00424, "float", "m", "Z4: rail axis height"),
        "xbb": Param(16.2, "float", "m", "XBB: x of the building base point (centre of its plan)"),
        "ybb": Param(-13.5, "float", "m", "YBB: y of the building base point (centre of its plan)"),
        "zbb": Param(2.4, "float", "m", "ZBB: z of the building base (underside of footings)"),
        "ballast_top_half_width": Param(3.25, "float", "m",
                                        "half-width of the ballast crest (top of the shoulder)",
                                        "pos"),
        "ballast_bottom_half_width": Param(3.75, "float", "m",
                                           "half-width of the ballast at the subballast top",
                                           "pos"),
    },
    "track": {
        "rigid_length": Param(3.0, "float", "m", "length of each rigid rail section", "pos"),
        "rail_length": Param(21.6, "float", "m", "length of the flexible rail", "pos"),
        "gauge": Param(1.5113, "float", "m", "distance between the rail axes (2 x 0.75565)", "pos"),
        "sleeper_spacing": Param(0.6, "float", "m", "distance between sleepers", "pos"),
        "n_sleepers": Param(37, "int", "-", "number of sleepers (first at X1, last at X4)", "pos"),
        "sleeper_length": Param(2.5, "float", "m", "sleeper length across the track", "pos"),
    },
    "building": {
        "footing_size": Param(1.2, "float", "m", "plan size of the square corner footings", "pos"),
        "footing_height": Param(0.6, "float", "m", "HSF: footing height", "pos"),
        "column_size": Param(0.6, "float", "m", "square column side", "pos"),
        "beam_width": Param(0.6, "float", "m", "BEAM_WIDTH: width of beams and grade beams", "pos"),
        "beam_depth": Param(0.6, "float", "m", "depth of beams and grade beams", "pos"),
        "slab_thickness": Param(0.2, "float", "m", "thickness of both slabs", "pos"),
        "wall_thickness": Param(0.3, "float", "m", "WALL_WIDTH: basement wall thickness", "pos"),
        "z_slab1_base": Param(4.2, "float", "m", "Z_SLAB1_BASE: underside of slab 1 above ZBB",
                              "pos"),
        "z_slab2_base": Param(8.0, "float", "m", "Z_SLAB2_BASE: underside of slab 2 above ZBB",
                              "pos"),
    },
    "materials": {
        "rail": _mat(210e9, 0.30, 7700.0, "flexible rail"),
        "rigid_rail": _mat(210e10, 0.30, 7700.0, "rigid rail (its DOFs are fixed)"),
        "sleeper": _mat(64e9, 0.25, 2570.0, "sleepers"),
        "ballast": _mat(260e6, 0.25, 1800.0, "ballast"),
        "subballast": _mat(200e6, 0.20, 1850.0, "subballast"),
        "subgrade": _mat(200e6, 0.20, 1850.0, "subgrade"),
        "concrete": _mat(31e9, 0.25, 2500.0, "concrete building"),
    },
    "sections": {
        "rail": {
            "area": Param(64.5e-4, "float", "m^2", "rail cross-section area", "pos"),
            "iyy": Param(2010e-8, "float", "m^4", "rail second moment, vertical bending", "pos"),
            "izz": Param(326e-8, "float", "m^4", "rail second moment, lateral bending", "pos"),
            "j": Param(2.59e-6, "float", "m^4",
                       "rail torsion constant (thin-walled estimate of the APDL I-section)", "pos"),
            "shear_coefficient_y": Param(0.34, "float", "-",
                                         "Timoshenko shear coefficient, vertical bending", "pos"),
            "shear_coefficient_z": Param(0.34, "float", "-",
                                         "Timoshenko shear coefficient, lateral bending", "pos"),
        },
        "sleeper": {
            "area": Param(513.8e-4, "float", "m^2", "sleeper cross-section area", "pos"),
            "iyy": Param(18907e-8, "float", "m^4", "sleeper second moment, vertical bending",
                         "pos"),
            "izz": Param(2.17e-4, "float", "m^4",
                         "sleeper second moment, horizontal bending (APDL trapezoid section)",
                         "pos"),
            "j": Param(3.38e-4, "float", "m^4", "sleeper torsion constant (APDL section)", "pos"),
            "shear_coefficient_y": Param(0.83, "float", "-",
                                         "Timoshenko shear coefficient, vertical bending", "pos"),
            "shear_coefficient_z": Param(0.83, "float", "-",
                                         "Timoshenko shear coefficient, horizontal bending",
                                         "pos"),
        },
    },
    "pads": {
        "kx": Param(70e8, "float", "N/m", "rail pad stiffness along the track", "pos"),
        "ky": Param(70e8, "float", "N/m", "rail pad stiffness across the track", "pos"),
        "kz": Param(70e8, "float", "N/m", "rail pad stiffness, vertical", "pos"),
        "cx": Param(5e5, "float", "N s/m", "rail pad damping along the track", "nonneg"),
        "cy": Param(5e5, "float", "N s/m", "rail pad damping across the track", "nonneg"),
        "cz": Param(5e5, "float", "N s/m", "rail pad damping, vertical", "nonneg"),
    },
    "mesh": {
        "refinement": Param(1.0, "float", "-",
                            "multiplies every element count (1: thesis size, ~56k nodes; "
                            "2: ~8x the nodes)", "pos"),
        "file": Param("", "str", "-",
                      "use this gmsh .msh (same physical-group names) instead of generating; "
                      "relative to the case file"),
        "rail_elements_per_bay": Param(5, "int", "-", "rail beam elements between sleepers",
                                       "pos"),
        "soil_elements_per_bay": Param(2, "int", "-",
                                       "soil elements along x per sleeper bay, away from building",
                                       "pos"),
        "soil_elements_per_bay_building": Param(4, "int", "-",
                                                "soil elements along x per bay in line with the "
                                                "building", "pos"),
        "sleeper_outer_elements": Param(2, "int", "-",
                                        "sleeper elements between its end and the rail", "pos"),
        "sleeper_middle_elements": Param(4, "int", "-", "sleeper elements between the rails",
                                         "pos"),
        "shoulder_elements": Param(3, "int", "-", "elements across each ballast shoulder", "pos"),
        "size_far": Param(0.6, "float", "m",
                          "element size across the track in the far field and vertically in the "
                          "upper soil", "pos"),
        "size_deep": Param(0.8, "float", "m", "vertical element size below the building base",
                           "pos"),
        "size_building_y": Param(0.3, "float", "m",
                                 "building and soil element size across the track in line with "
                                 "the building", "pos"),
        "size_building_z": Param(0.6, "float", "m", "building element size vertically", "pos"),
        "layer_elements": Param(1, "int", "-",
                                "elements through each of the ballast and subballast layers",
                                "pos"),
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
                                   "a static load)", "nonneg"),
        "layer_thickness": Param(0.0, "float", "m",
                                 "caughey faces: thickness of the absorbing layer, measured "
                                 "into the mesh from the face (part of the model: enlarge the "
                                 "domain by it, [domain])", "nonneg"),
        "layer_damping": Param(0.3, "float", "-",
                               "caughey faces: Rayleigh damping ratio at the face (at "
                               "damping.f1 and f2), decreasing quadratically to 0 at the inner "
                               "edge of the layer", "fraction"),
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
                      "modal damping does not use them)"),
    },
    "modal": {
        "n_modes": Param(300, "int", "-", "number of modes to extract", "pos"),
        "f_max": Param(0.0, "float", "Hz",
                       "if > 0: extract all modes below this frequency instead of n_modes",
                       "nonneg"),
        "damping_ratio": Param(0.03, "float", "-",
                               "modal damping ratio for all modes (modal.damping = 'uniform'; "
                               "with 'strain_energy': the rail pads' share)", "fraction"),
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
                                 "integration", choices=("bbar", "incompatible", "full")),
        "method": Param("block_lanczos", "str", "-",
                        "eigensolver: block shift-invert Lanczos (fast, many right-hand sides "
                        "per MUMPS solve) or SLEPc Krylov-Schur; f_max always uses SLEPc "
                        "spectrum slicing", choices=("block_lanczos", "krylovschur")),
        "block_size": Param(32, "int", "-", "block Lanczos: right-hand sides per solve", "pos"),
        "out_of_core": Param("auto", "str", "-",
                             "MUMPS factor on disk (ICNTL(22)): auto = only when the in-core "
                             "factor would not fit in the available memory but the out-of-core "
                             "one does (block Lanczos); always; never (then a model too large "
                             "stops with a clear message)", choices=("auto", "always", "never")),
        "max_basis": Param(0, "int", "-",
                           "block Lanczos: basis size before a thick restart (0: 3 n_modes, "
                           "capped at 4 GB of basis vectors)", "nonneg"),
        "shift_hz": Param(0.0, "float", "Hz",
                          "shift of the spectral transformation (modes nearest to it)",
                          "nonneg"),
        "tol": Param(1e-8, "float", "-", "relative residual tolerance of the eigenpairs", "pos"),
        "max_restarts": Param(100, "int", "-", "maximum restarts of the eigensolver", "pos"),
        "fix_sleeper_rotations": Param(True, "bool", "-",
                                       "fix all rotations of sleeper nodes (thesis, App. A)"),
        "fix_rail_rotations_at_pads": Param(True, "bool", "-",
                                            "fix all rotations of rail nodes above the pads "
                                            "(thesis, App. A)"),
    },
    "vehicle": {
        "type": Param("wheelset", "str", "-",
                      "load model: constant moving forces, the thesis's suspended wheelset "
                      "(Table II), or cars with 2 bogies and 4 wheelsets each",
                      choices=("moving_force", "wheelset", "vehicle")),
        "speed": Param(30.0, "float", "m/s", "running speed", "pos"),
        "x_start": Param(0.0, "float", "m",
                         "position of the leading wheel at t = 0 (on the rigid entry rail; 0: "
                         "its start, the thesis's time origin)"),
        "x_end": Param(0.0, "float", "m",
                       "the run ends when the last wheel reaches this position (0: the end of "
                       "the rigid exit rail)", "nonneg"),
        "t_after": Param(0.0, "float", "s",
                         "extra time simulated after the last wheel reaches x_end", "nonneg"),
        "force": Param(0.0, "float", "N",
                       "moving_force: force per wheel (0: the wheelset's static wheel load, "
                       "mass * g / 2)", "nonneg"),
        "axle_offsets": Param([0.0], "floats", "m",
                              "moving_force: axle positions relative to the leading axle "
                              "(<= 0, one force per rail and axle)"),
        "wheelset_mass": Param(1568.0, "float", "kg", "wheelset mass (thesis Table II)", "pos"),
        "wheelset_roll_inertia": Param(656.0, "float", "kg m^2",
                                       "wheelset roll inertia Ixx (thesis Table II)", "pos"),
        "wheel_radius": Param(0.46, "float", "m", "wheel rolling radius (Hertz constant)", "pos"),
        "contact_span": Param(1.5, "float", "m",
                              "lateral distance of the two wheel-rail contact points", "pos"),
        "suspension_span": Param(2.0, "float", "m",
                                 "wheelset: lateral distance of the two suspension springs",
                                 "pos"),
        "k_suspension": Param(25_000.0, "float", "N/m",
                              "wheelset: suspension stiffness per side (thesis Table II)",
                              "nonneg"),
        "c_suspension": Param(1_000.0, "float", "N s/m",
                              "wheelset: suspension damping per side (thesis Table II)",
                              "nonneg"),
        "preload": Param(0.0, "float", "N",
                         "wheelset: static downward force of the frame per side (share of a "
                         "car body; 0 in the thesis)", "nonneg"),
        "k_lateral": Param(25_000.0, "float", "N/m",
                           "wheelset: lateral suspension stiffness (not in Table II: the vertical "
                           "value)", "nonneg"),
        "c_lateral": Param(1_000.0, "float", "N s/m", "wheelset: lateral suspension damping",
                           "nonneg"),
        "conicity": Param(0.025, "float", "-",
                          "wheelset: equivalent tread conicity (UIC 1:40); the contact normals "
                          "lean inwards and couple lateral motion and the rails' lateral modes",
                          "nonneg"),
        "k_hertz": Param(0.0, "float", "N/m^1.5",
                         "Hertz constant K_H (0: Jenkins' formula from wheel_radius)", "nonneg"),
        "contact_damping": Param(0.0, "float", "N s/m^2",
                                 "Hertz contact damping C in F = K_H d^1.5 - C d' |d|",
                                 "nonneg"),
        "n_cars": Param(1, "int", "-", "vehicle: number of coupled cars in the train", "pos"),
        "car_mass": Param(32_000.0, "float", "kg", "vehicle: car body mass (defaults: Manchester "
                          "Benchmark passenger coach, Iwnicki 1998)", "pos"),
        "car_pitch_inertia": Param(1.97e6, "float", "kg m^2", "vehicle: car body pitch inertia",
                                   "pos"),
        "car_roll_inertia": Param(5.68e4, "float", "kg m^2", "vehicle: car body roll inertia",
                                  "pos"),
        "bogie_mass": Param(2_615.0, "float", "kg", "vehicle: bogie frame mass", "pos"),
        "bogie_pitch_inertia": Param(1_476.0, "float", "kg m^2", "vehicle: bogie pitch inertia",
                                     "pos"),
        "bogie_roll_inertia": Param(1_722.0, "float", "kg m^2", "vehicle: bogie roll inertia",
                                    "pos"),
        "car_wheelset_mass": Param(1_813.0, "float", "kg", "vehicle: wheelset mass", "pos"),
        "car_wheelset_roll_inertia": Param(1_120.0, "float", "kg m^2",
                                           "vehicle: wheelset roll inertia", "pos"),
        "k_primary": Param(1.22e6, "float", "N/m",
                           "vehicle: primary suspension stiffness per axle box", "nonneg"),
        "c_primary": Param(4.0e3, "float", "N s/m",
                           "vehicle: primary suspension damping per axle box", "nonneg"),
        "k_secondary": Param(4.3e5, "float", "N/m",
                             "vehicle: secondary suspension stiffness per side", "nonneg"),
        "c_secondary": Param(2.0e4, "float", "N s/m",
                             "vehicle: secondary suspension damping per side", "nonneg"),
        "primary_span": Param(2.0, "float", "m",
                              "vehicle: lateral distance of the primary springs", "pos"),
        "secondary_span": Param(2.0, "float", "m",
                                "vehicle: lateral distance of the secondary springs", "pos"),
        "bogie_spacing": Param(19.0, "float", "m", "vehicle: distance between the bogie centres",
                               "pos"),
        "wheelbase": Param(2.56, "float", "m", "vehicle: axle distance within a bogie", "pos"),
        "car_length": Param(26.4, "float", "m",
                            "vehicle: length over couplers (distance of successive cars)", "pos"),
        "coupler_stiffness": Param(0.0, "float", "N/m",
                                   "vehicle: vertical stiffness coupling successive car ends",
                                   "nonneg"),
    },
    "irregularity": {
        "type": Param("none", "str", "-",
                      "vertical rail irregularity: none, a profile file, or a seeded random "
                      "profile from the FRA or ISO 8608 spectrum",
                      choices=("none", "file", "fra", "iso8608")),
        "file": Param("", "str", "-",
                      "profile file: columns x z, or x z_rail0 z_rail1 [m] (relative to the case "
                      "file)"),
        "track_class": Param("6", "str", "-",
                             "FRA class 1..6 or ISO 8608 class A..H",
                             choices=("1", "2", "3", "4", "5", "6",
                                      "A", "B", "C", "D", "E", "F", "G", "H")),
        "seed": Param(1, "int", "-", "random seed of the profile", "nonneg"),
        "wavelength_min": Param(1.0, "float", "m",
                                "shortest wavelength of the random profile (the FRA spectra are "
                                "fitted to wavelengths above ~1.5 m)",
                                "pos"),
        "wavelength_max": Param(30.0, "float", "m", "longest wavelength of the random profile",
                                "pos"),
        "flat_depth": Param(0.0, "float", "m", "wheel flat depth (0: no flat)", "nonneg"),
        "flat_length": Param(0.05, "float", "m", "wheel flat length", "pos"),
        "flat_wheels": Param([0.0], "floats", "-", "indices of the wheels with a flat"),
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
                                   "kept (mode-acceleration method; needs static.h5 from the "
                                   "modal stage)"),
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
                         "unit"),
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
                              "times of the element stress/strain fields (thesis: 0.54, 0.61 s)"),
        "probes": Param([], "floats", "m",
                        "extra probe points as a flat list x1, y1, z1, x2, y2, z2, ..."),
        "static_correction_rates": Param(False, "bool", "-",
                                         "with mbs.static_correction: add the correction also "
                                         "to velocities and accelerations (R g', R g''); off: "
                                         "the classical mode-acceleration method, displacements "
                                         "and stresses corrected, velocities and accelerations "
                                         "from the modes (R g'' carries the node-to-node "
                                         "stepping of the moving load far above the modal band)"),
    },
    "assessment": {
        "standards": Param(["iso2631", "din4150-2", "din4150-3", "fta", "vc", "thesis"],
                           "strs", "-", "vibration criteria to evaluate",
                           choices=("iso2631", "din4150-2", "din4150-3", "fta", "vc", "thesis")),
        "building_use": Param("residential", "str", "-",
                              "use of the building: ISO multiplier, FTA category, VC curve, "
                              "DIN 4150-3 line",
                              choices=("critical", "residential", "office", "workshop")),
        "period": Param("day", "str", "-", "assessment period (ISO 10137, DIN 4150-2)",
                        choices=("day", "night")),
        "fta_events": Param("frequent", "str", "-", "FTA event frequency",
                            choices=("frequent", "occasional", "infrequent")),
        "din4150_2_events": Param(0, "int", "-",
                                  "train passages per assessment period for DIN 4150-2 KB_FTr "
                                  "(0: not given; the middle band stays undetermined)",
                                  "nonneg"),
        "wave_threshold": Param(0.1, "float", "-",
                                "wave arrival: first time the acceleration magnitude exceeds "
                                "this fraction of its peak", "fraction"),
    },
}

#: Values of the thesis's Table I where it differs from the APDL script
#: (../shared/reference/benchmarks.md section 3). Layer depths are the same in
#: both presets: Table I's "ballast 4.8 m" contradicts the APDL z-levels and
#: the thesis's own wave speeds.
PRESETS: dict[str, dict[str, Any]] = {
    "apdl": {},
    "table1": {
        "materials.ballast.nu": 0.3,
        "materials.ballast.rho": 1300.0,
        "materials.subballast.nu": 0.35,
        "materials.subgrade.nu": 0.35,
        "materials.sleeper.rho": 2750.0,
        "pads.kx": 26.5e7, "pads.ky": 26.5e7, "pads.kz": 26.5e7,
        "pads.cx": 4.6e4, "pads.cy": 4.6e4, "pads.cz": 4.6e4,
    },
}


def iter_params(tree: dict[str, Any] | None = None, prefix: str = ""):
    """Yield ``(dotted_key, Param)`` for every key of the schema, in order."""
    tree = SCHEMA if tree is None else tree
    for name, node in tree.items():
        key = f"{prefix}{name}"
        if isinstance(node, Param):
            yield key, node
        else:
            yield from iter_params(node, key + ".")
