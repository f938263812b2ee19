"""The track and the building: the ``[track]``, ``[building]``, ``[materials]``,
``[sections]`` and ``[pads]`` sections.
"""

from __future__ import annotations

from typing import Any

from ..sections import APDL_RAIL, APDL_SLEEPER, SectionProperties
from .conditions import (
    BUILDING,
    EMBANKMENT,
    FILLED_TRENCH,
    ON_TRACK,
    OWN_HEIGHTS_NOT_GIVEN,
    SECOND_TRACK,
    STOREY_2,
    SUPPORTED_ENDS,
    WIB_BLOCK,
    in_building,
)
from .param import _APDL, _OTHER_DAMPING, _RAIL_SEC, _SLP_SEC, _T1, Param, _mat, _mp
from .parts import FOUNDATION_TYPES, MAX_ROTATION_DEG, MAX_STOREYS


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


#: The sections of this module, in the schema's order.
STRUCTURES_SECTIONS: dict[str, dict[str, Any]] = {
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
}
