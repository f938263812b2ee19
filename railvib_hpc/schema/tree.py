"""The schema's tree: :data:`SCHEMA` (section -> key -> :class:`Param`, in the order of the
case reference and the baseline case), assembled from the section modules, and
:func:`iter_params`.
"""

from __future__ import annotations

from typing import Any

from .boundary import BOUNDARY_SECTIONS
from .mesh import MESH_SECTIONS
from .param import Param
from .site import SITE_SECTIONS
from .solvers import SOLVERS_SECTIONS
from .structures import STRUCTURES_SECTIONS
from .studies import STUDIES_SECTIONS
from .vehicle import VEHICLE_SECTIONS

#: The sections in the schema's order (the case reference's and the baseline case's).
SCHEMA: dict[str, dict[str, Any]] = {
    "case": SITE_SECTIONS["case"],
    "site": SITE_SECTIONS["site"],
    "geometry": SITE_SECTIONS["geometry"],
    "track": STRUCTURES_SECTIONS["track"],
    "building": STRUCTURES_SECTIONS["building"],
    "materials": STRUCTURES_SECTIONS["materials"],
    "sections": STRUCTURES_SECTIONS["sections"],
    "pads": STRUCTURES_SECTIONS["pads"],
    "mesh": MESH_SECTIONS["mesh"],
    "soil": MESH_SECTIONS["soil"],
    "trench": MESH_SECTIONS["trench"],
    "wib": MESH_SECTIONS["wib"],
    "usp": MESH_SECTIONS["usp"],
    "ballast_mat": MESH_SECTIONS["ballast_mat"],
    "isolation": MESH_SECTIONS["isolation"],
    "domain": BOUNDARY_SECTIONS["domain"],
    "boundary": BOUNDARY_SECTIONS["boundary"],
    "damping": BOUNDARY_SECTIONS["damping"],
    "modal": SOLVERS_SECTIONS["modal"],
    "vehicle": VEHICLE_SECTIONS["vehicle"],
    "train2": VEHICLE_SECTIONS["train2"],
    "irregularity": VEHICLE_SECTIONS["irregularity"],
    "mbs": SOLVERS_SECTIONS["mbs"],
    "load": VEHICLE_SECTIONS["load"],
    "transient": SOLVERS_SECTIONS["transient"],
    "output": SOLVERS_SECTIONS["output"],
    "probes": SOLVERS_SECTIONS["probes"],
    "assessment": STUDIES_SECTIONS["assessment"],
    "uncertainty": STUDIES_SECTIONS["uncertainty"],
    "study": STUDIES_SECTIONS["study"],
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
