"""``free``: nothing on the face (a traction-free surface)."""

from __future__ import annotations

from ..boundary_kind import BoundaryKind


class Free(BoundaryKind):
    """No constraint, no block, no layer: the base class's defaults."""

    name = "free"


KIND = Free()
