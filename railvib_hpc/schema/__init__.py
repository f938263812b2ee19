"""The case-file schema: every key, its default, type, unit and meaning.

Defaults reproduce the model the thesis actually solved (the ANSYS APDL script
of its Appendix A). Where the thesis's Table I disagrees, Table I's values are
available as the preset ``table1`` (see :data:`PRESETS`).

The schema is one package, a module per group of sections: :mod:`.param` (the
:class:`Param` of one key and the sources it cites), :mod:`.parts` (the model's parts and
limits), :mod:`.conditions` (the features keys apply under), :mod:`.boundary` (the faces,
their conditions, the time-domain engines; ``[domain]``, ``[boundary]``, ``[damping]``),
:mod:`.site`, :mod:`.structures`, :mod:`.mesh`, :mod:`.solvers`, :mod:`.vehicle` and
:mod:`.studies` (the sections), :mod:`.tree` (:data:`SCHEMA` in its order) and
:mod:`.presets`. Every name is importable from ``railvib_hpc.schema``.

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

from .boundary import (
    ABSORBING_FACES,
    BOUNDARY_FACES,
    BOUNDARY_TYPES,
    CAUGHEY_FACES,
    LAYER_FACES,
    PML_ALPHA,
    PML_ENGINES,
    PML_FACES,
    TRANSIENT_ENGINES,
)
from .case_view import CaseView
from .conditions import (
    BALLAST_MAT,
    BAND_SLICED,
    BARE_SOIL,
    BLOCK_LANCZOS,
    BUILDING,
    CARS,
    DIN4150_2,
    DIRECT_ENGINE,
    EMBANKMENT,
    FILLED_TRENCH,
    FTA,
    IMEX_ENGINE,
    ISOLATION,
    MOVING_FORCES,
    ON_TRACK,
    OWN_HEIGHTS_NOT_GIVEN,
    PROFILE_FILE,
    RANDOM_FIELDS,
    RANDOM_PROFILE,
    REDUCED_BASIS,
    REDUCED_MODEL,
    REFINED_LAYOUT,
    REFINED_TRACK_BED,
    SECOND_TRACK,
    SECOND_TRAIN,
    SECOND_TRAIN_CARS,
    STATIC_CORRECTION,
    STOREY_2,
    SUPPORTED_ENDS,
    TRENCH,
    USP,
    WHEEL_FLATS,
    WHEELS,
    WHEELSET,
    WHEELSET_MASS,
    WIB,
    WIB_BLOCK,
    in_building,
)
from .param import (
    Param,
)
from .parts import (
    BEAM_PARTS,
    BUILDING_PARTS,
    DEFAULT_PROBE_ROLE,
    FOUNDATION_TYPES,
    IMPLICIT_GROUPS,
    INTERFACE_PARTS,
    MAX_ROTATION_DEG,
    MAX_SOIL_LAYERS,
    MAX_STOREYS,
    MEASURE_PARTS,
    MIN_SOIL_LAYER_THICKNESS,
    PAD_PARTS,
    PART_ID,
    PARTS,
    PROBE_LINE_KEYS,
    PROBE_LINE_SIDES,
    PROBE_ROLES,
    SOIL_LAYER_KEYS,
    SOIL_LAYER_PARTS,
    SOIL_PARTS,
    SOLID_MATERIAL,
    SOLID_PARTS,
)
from .presets import (
    PRESET_SOURCES,
    PRESETS,
    PresetValue,
    source,
)
from .studies import (
    BUILDING_PROBES,
)
from .tree import (
    SCHEMA,
    iter_params,
)
from .vehicle import (
    TRAIN2_SHARED_VEHICLE_KEYS,
)

__all__ = [
    "ABSORBING_FACES",
    "BALLAST_MAT",
    "BAND_SLICED",
    "BARE_SOIL",
    "BEAM_PARTS",
    "BLOCK_LANCZOS",
    "BOUNDARY_FACES",
    "BOUNDARY_TYPES",
    "BUILDING",
    "BUILDING_PARTS",
    "BUILDING_PROBES",
    "CARS",
    "CAUGHEY_FACES",
    "DEFAULT_PROBE_ROLE",
    "DIN4150_2",
    "DIRECT_ENGINE",
    "EMBANKMENT",
    "FILLED_TRENCH",
    "FOUNDATION_TYPES",
    "FTA",
    "IMEX_ENGINE",
    "IMPLICIT_GROUPS",
    "INTERFACE_PARTS",
    "ISOLATION",
    "LAYER_FACES",
    "MAX_ROTATION_DEG",
    "MAX_SOIL_LAYERS",
    "MAX_STOREYS",
    "MEASURE_PARTS",
    "MIN_SOIL_LAYER_THICKNESS",
    "MOVING_FORCES",
    "ON_TRACK",
    "OWN_HEIGHTS_NOT_GIVEN",
    "PAD_PARTS",
    "PARTS",
    "PART_ID",
    "PML_ALPHA",
    "PML_ENGINES",
    "PML_FACES",
    "PRESETS",
    "PRESET_SOURCES",
    "PROBE_LINE_KEYS",
    "PROBE_LINE_SIDES",
    "PROBE_ROLES",
    "PROFILE_FILE",
    "RANDOM_FIELDS",
    "RANDOM_PROFILE",
    "REDUCED_BASIS",
    "REDUCED_MODEL",
    "REFINED_LAYOUT",
    "REFINED_TRACK_BED",
    "SCHEMA",
    "SECOND_TRACK",
    "SECOND_TRAIN",
    "SECOND_TRAIN_CARS",
    "SOIL_LAYER_KEYS",
    "SOIL_LAYER_PARTS",
    "SOIL_PARTS",
    "SOLID_MATERIAL",
    "SOLID_PARTS",
    "STATIC_CORRECTION",
    "STOREY_2",
    "SUPPORTED_ENDS",
    "TRAIN2_SHARED_VEHICLE_KEYS",
    "TRANSIENT_ENGINES",
    "TRENCH",
    "USP",
    "WHEELS",
    "WHEELSET",
    "WHEELSET_MASS",
    "WHEEL_FLATS",
    "WIB",
    "WIB_BLOCK",
    "CaseView",
    "Param",
    "PresetValue",
    "in_building",
    "iter_params",
    "source",
]
