"""The features the case keys belong to (:attr:`Param.applies`, :mod:`railvib_hpc.applies`):
where one is off, its keys keep their defaults
(:func:`railvib_hpc.validation.feature_key_problems`).
"""

from __future__ import annotations

from dataclasses import replace

from ..applies import above, all_of, any_of, includes, is_, is_not, not_empty
from .param import Param

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


