"""The parts of the model and their program limits: soil layers, interfaces, solid,
building, beam and pad parts, their ids and materials, probe roles and the keys of the
``[[soil.layers]]`` and ``[[probes.line]]`` entries.
"""

from __future__ import annotations

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
#: 300, 107 s at 1000, out of memory at 1e8), and 100 storeys (380 m at the
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


