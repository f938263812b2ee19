"""``fixed``: every displacement (and rotation, if any) of the face zero (the thesis's base)."""

from __future__ import annotations

from ..boundary_kind import BoundaryKind
from ..dofmap import COMPONENTS


class Fixed(BoundaryKind):
    """All components of the face's nodes fixed (the thesis's ``bottom`` rule)."""

    name = "fixed"

    def constrained(self, face: str) -> tuple[str, ...]:
        return COMPONENTS


KIND = Fixed()
