"""The mesh and the soil: the ``[mesh]``, ``[soil]`` sections and the mitigation measures
and elastic interfaces (``[trench]``, ``[wib]``, ``[usp]``, ``[ballast_mat]``,
``[isolation]``).
"""

from __future__ import annotations

from typing import Any

from .conditions import (
    BALLAST_MAT,
    BUILDING,
    ISOLATION,
    ON_TRACK,
    REFINED_LAYOUT,
    REFINED_TRACK_BED,
    TRENCH,
    USP,
    WIB,
)
from .param import _APDL, _SLP_SEC, Param

#: The sections of this module, in the schema's order.
MESH_SECTIONS: dict[str, dict[str, Any]] = {
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
                                             "1.6 % at 10); trilinear only: with mesh.order > 1 "
                                             "the warning comes below 4 GLL points per "
                                             "wavelength, the fewest the spectral grid "
                                             "resolves, and its dispersion is predicted",
                                             "pos"),
        "order": Param(1, "int", "-",
                       "order N of the soil's hexahedra: 1 the trilinear element (today's "
                       "model and results); 2..8 spectral elements with (N+1)^3 "
                       "Gauss-Lobatto-Legendre nodes and a diagonal mass (railvib transient, "
                       "explicit engine, bare soil without track or building; "
                       "docs/spectral.md)", "pos", maximum=8,
                       source="Komatitsch & Tromp 1999 (Geophys. J. Int. 139): the spectral "
                              "element of order N on GLL points; docs/spectral.md"),
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
                                      source="numerical dispersion of the hexahedral grid "
                                             "(Mullen & Belytschko 1982; "
                                             "docs/transient.md): accuracy that holds over "
                                             "distance"),
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
}
