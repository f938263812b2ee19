"""The ``[case]``, ``[site]`` and ``[geometry]`` sections: what the case is, the site as an
engineer gives it and the APDL script's coordinates.
"""

from __future__ import annotations

from typing import Any

from .conditions import BUILDING
from .param import _APDL, Param, _apdl_coordinate

#: The sections of this module, in the schema's order.
SITE_SECTIONS: dict[str, dict[str, Any]] = {
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
}
