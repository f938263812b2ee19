"""``roller``: the normal displacement of the face zero (the thesis's x and y faces)."""

from __future__ import annotations

from ..boundary import FACE_AXIS
from ..boundary_kind import BoundaryKind
from ..dofmap import COMPONENTS


class Roller(BoundaryKind):
    """The displacement normal to the face fixed, the face slides in its plane."""

    name = "roller"

    def constrained(self, face: str) -> tuple[str, ...]:
        return (COMPONENTS[FACE_AXIS[face]],)


KIND = Roller()
