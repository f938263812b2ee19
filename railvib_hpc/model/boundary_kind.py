"""What a boundary kind of a truncation face declares: the base class of every kind.

A kind (``boundary.<face> = "<name>"``) is one module of :mod:`railvib_hpc.model.boundary_kinds`
(or anywhere importable) holding ``KIND``, an instance of a :class:`BoundaryKind` subclass,
registered by one line in :data:`railvib_hpc.boundary_registry.BOUNDARY_KINDS`. The kind says

* the DOFs it constrains (:meth:`~BoundaryKind.constrained`, for the DOF map) and the
  displacement components with which it holds the soil box (:meth:`~BoundaryKind.restrained`,
  :meth:`~BoundaryKind.statically_held`);
* the lumped 3 x 3 node blocks it adds to the damping or stiffness matrix
  (:meth:`~BoundaryKind.node_blocks`; the dashpot diagonal of the explicit engine follows
  from them, :func:`railvib_hpc.model.boundary.dashpot_diagonal`);
* its layer inside the mesh (:attr:`~BoundaryKind.graded_damping`: Rayleigh damping in C;
  :attr:`~BoundaryKind.matched_layer`: a perfectly matched layer of the time domain);
* which paths and engines take it (:attr:`~BoundaryKind.modal`,
  :attr:`~BoundaryKind.engines`) and the reflection study's variant of it;
* its checks: of the ``[boundary]`` values (:meth:`~BoundaryKind.section_problems`, run by
  the case validation) and of the mesh (:meth:`~BoundaryKind.check`, before anything is
  computed).

After the boundary-parameter classes of STEM (``stem/boundary.py``,
``BoundaryParametersABC``), one class per condition.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from ..schema import TRANSIENT_ENGINES
from .dofmap import COMPONENTS

if TYPE_CHECKING:
    import numpy as np

    from ..mesh.model import Mesh
    from ..problem import Problem
    from .boundary import FaceElements

#: A refusal: ``(key, value, allowed)``, as the case validation and the stages' refusals.
Refusal = tuple[str, Any, str]


class BoundaryKind:
    """A condition of a truncation face; the defaults are those of a free face.

    Attributes
    ----------
    name
        The value of ``boundary.<face>``.
    modal
        Whether the modal path (``modal``, ``mbs``, ``run`` and the modal studies) takes it;
        False for a kind with no modes, refused there (:meth:`modal_refusal`).
    engines
        The ``transient.engine`` values that take it; None: every engine.
    graded_damping
        A graded Caughey layer inside the mesh (``boundary.layer_*``), Rayleigh damping of
        the ground elements near the face (:func:`railvib_hpc.model.boundary.layer_weights`).
    matched_layer
        A perfectly matched layer inside the mesh (``boundary.pml_*``,
        :mod:`railvib_hpc.transient.pml`).
    reflection_variant
        The reflection study offers it on all five faces (``study.reflection.boundaries``).
    reflection_overrides
        Further case overrides of that variant.
    reflection_layer_outside
        The variant's layer is added outside each domain (``study.reflection.pml_thickness``).
    no_modes
        Why the modal path has no modes of it (with ``modal = False``).
    time_domain_note
        The same in a few words, for the studies that must run it in the time domain.
    """

    name: str = ""
    modal: bool = True
    engines: tuple[str, ...] | None = None
    graded_damping: bool = False
    matched_layer: bool = False
    reflection_variant: bool = False
    reflection_overrides: tuple[str, ...] = ()
    reflection_layer_outside: bool = False
    no_modes: str = ""
    time_domain_note: str = ""

    @property
    def has_layer(self) -> bool:
        """Whether the kind has a layer of ``boundary.layer_thickness`` inside the mesh."""
        return self.graded_damping or self.matched_layer

    def constrained(self, face: str) -> tuple[str, ...]:
        """The DOF components (:data:`~railvib_hpc.model.dofmap.COMPONENTS`) fixed on
        ``face``'s nodes (the constraint rule of :func:`~railvib_hpc.model.dofmap.build_dofmap`;
        none: the face adds no rule)."""
        return ()

    def restrained(self, face: str) -> tuple[int, ...]:
        """Displacement components (0, 1, 2 = x, y, z) with which ``face`` holds the soil box
        against rigid-body motion (:func:`railvib_hpc.model.boundary.unsupported_motions`);
        by default those it constrains."""
        fixed = self.constrained(face)
        return tuple(i for i, c in enumerate(COMPONENTS[:3]) if c in fixed)

    def statically_held(self, face: str, boundary: Mapping[str, Any]) -> tuple[int, ...]:
        """The components ``face`` holds against a static load (``load.start = 'static'``),
        from the case's ``[boundary]`` values; by default :meth:`restrained`."""
        return self.restrained(face)

    def node_blocks(self, mesh: Mesh, problem: Problem, faces: Sequence[str], which: str
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Lumped 3 x 3 blocks on ``(ux, uy, uz)`` of the kind's ``faces``, per distinct node
        (ascending), for the damping (``which = "dashpot"``) or the stiffness matrix
        (``"spring"``); None: it adds none."""
        return None

    def check(self, mesh: Mesh, problem: Problem, faces: Sequence[str]) -> None:
        """Raise a :class:`~railvib_hpc.model.boundary.BoundaryError` when the mesh cannot
        carry the kind on ``faces`` (run before anything is computed or written)."""

    def summary(self, problem: Problem, elements: FaceElements) -> dict:
        """The kind's entries of the boundary summary of a face with element faces."""
        return {}

    def section_problems(self, boundary: Mapping[str, Any], faces: Sequence[str]
                         ) -> list[Refusal]:
        """The problems of the case's ``[boundary]`` values with this kind on ``faces``
        (checked with the case): a layer needs a thickness."""
        thickness = boundary["layer_thickness"]
        if self.has_layer and not thickness > 0:
            return [("boundary.layer_thickness", thickness,
                     f"must be > 0 m for the {self.name} face(s) {', '.join(faces)}")]
        return []

    def modal_refusal(self, allowed: Sequence[str]) -> str:
        """Why the modal path refuses the kind (``modal = False``), naming the engines that
        take it and the ``allowed`` kinds."""
        engines = self.engines or TRANSIENT_ENGINES
        names = ", ".join(f"'{e}'" for e in engines[:-1]) + f" or '{engines[-1]}'"
        return (f"{self.no_modes}, so the modal path (modal, mbs, run and the modal studies) "
                f"has no modes of it; it is for railvib transient with transient.engine = "
                f"{names}; allowed here: {', '.join(allowed)}")
