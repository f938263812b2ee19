"""The mesh check's pure functions: the parts a mesh has, its longest edges per soil part
and the warnings of the quality report (aspect ratio, tiny elements, the shear wavelength).

Shared by the ``mesh`` stage (:mod:`.stage`, which builds the quality report) and the
stages that read a mesh (the static correction needs the rails, the transient stage checks
its own band, ``transient.f_max``), so none of them imports the mesh stage's module.
"""

from __future__ import annotations

import numpy as np

from ..config import Case
from ..errors import MeshError
from ..schema import PART_ID, PARTS, SOIL_PARTS, SOLID_MATERIAL
from .model import Mesh

#: Aspect ratio (longest / shortest edge of a hexahedron) above which the mesh check warns:
#: the default shape-check warning limit of ANSYS Mechanical APDL for solids (SHPP,
#: "Aspect ratio", warning 20; error 1e6). Flat elements bend poorly (B-bar locks less but
#: is too soft) and stiffen the eigenproblem as (aspect ratio)^2.
ASPECT_RATIO_WARNING = 20.0

#: Relative round-off of the lowest eigenvalue that a tiny element may cause, as a multiple
#: of modal.tol. An element of size h in a model of size L (wave speed c) raises the largest
#: eigenvalue to ~12 c^2 / h^2 against ~(c / L)^2 for the lowest, so the lowest eigenpairs
#: carry a relative round-off ~ u 12 (L / h)^2 (railvib_hpc.tolerances, item 1): the check
#: warns when that exceeds modal.tol, i.e. when h < L sqrt(12 u / tol) (2.6 cm for a 50 m
#: model at tol = 1e-8).
TINY_ELEMENT_FACTOR = 12.0


def quality_warnings(quality: dict, tol: float) -> list[str]:
    """Warnings of the mesh check: extreme aspect ratios and tiny elements (see
    :data:`ASPECT_RATIO_WARNING`, :data:`TINY_ELEMENT_FACTOR`); ``tol`` is modal.tol."""
    from ..tolerances import EPS

    out = []
    ar = quality.get("max_aspect_ratio", 1.0)
    if ar > ASPECT_RATIO_WARNING:
        out.append(f"max aspect ratio {ar:.3g} > {ASPECT_RATIO_WARNING:g} (ANSYS's shape-check "
                   "warning limit): flat elements bend poorly and make the eigenproblem "
                   "ill-conditioned; refine across the thin direction or coarsen along it")
    h, size = quality.get("min_edge"), quality.get("model_size")
    if h is not None and size and h > 0:
        roundoff = EPS * TINY_ELEMENT_FACTOR * (size / h) ** 2
        if roundoff > tol:
            out.append(f"tiny elements: shortest edge {h:.3g} m in a {size:.3g} m model; the "
                       f"lowest eigenpairs carry a relative round-off of ~{roundoff:.1e} > "
                       f"modal.tol = {tol:.1e} (edges below "
                       f"{size * (TINY_ELEMENT_FACTOR * EPS / tol) ** 0.5:.3g} m); merge or "
                       "remove slivers")
    return out


def wavelength_warnings(quality: dict, case: Case, band: tuple[float, str] | None = None
                        ) -> list[str]:
    """One warning per soil part whose longest element edge resolves the shear wavelength at
    :func:`~railvib_hpc.mesh.layout.resolved_frequency` (or ``band = (frequency, key)``,
    the transient stage's ``transient.f_max``) with fewer than
    ``mesh.min_elements_per_wavelength`` elements; for a spectral soil (``mesh.order = N``)
    with fewer GLL points (``N`` per element) than the grid resolves,
    :data:`~railvib_hpc.fem.dispersion_gll_rayleigh.MIN_POINTS_PER_WAVELENGTH` (its
    dispersion is the mesh check's, :mod:`.dispersion_check`); none when no frequency is
    set."""
    from ..site import solid_material
    from .layout import resolved_frequency, shear_wave_speed

    f = resolved_frequency(case) if band is None else band[0]
    need = case["mesh.min_elements_per_wavelength"]
    if f <= 0:
        return []
    key = ("mesh.wavelength_hz" if case["mesh.wavelength_hz"] else "modal.f_max") \
        if band is None else band[1]
    order = case["mesh.order"]
    if order > 1:             # the GLL grid's own limit (the trilinear rule does not apply)
        from ..fem.dispersion_gll_rayleigh import MIN_POINTS_PER_WAVELENGTH

        need = MIN_POINTS_PER_WAVELENGTH
    out = []
    for part, h in quality.get("max_edge_per_soil_part", {}).items():
        try:
            c_s = shear_wave_speed(solid_material(case, SOLID_MATERIAL[part]))
        except KeyError:          # a layer part in a user's mesh that the case does not give
            continue
        per = c_s / f / h
        if order * per < need:
            count = (f"{per:.2g} per wavelength" if order == 1 else
                     f"{per:.2g} per wavelength, {order * per:.2g} GLL points at order {order}")
            limit = (f"mesh.min_elements_per_wavelength = {need:g}" if order == 1 else
                     f"{need:g}, the fewest the GLL grid resolves")
            out.append(f"{key} = {f:g} Hz is under-resolved in {part}: c_S {c_s:.4g} m/s, "
                       f"wavelength {c_s / f:.3g} m, elements up to {h:.3g} m = {count} < "
                       f"{limit}; refine "
                       "(mesh.elements_per_wavelength, mesh.refinement) or lower the band")
    return out


def max_edge_per_soil_part(mesh: Mesh, longest: np.ndarray | None = None
                           ) -> dict[str, float]:
    """Longest hexahedron edge of every soil part present (m); ``longest``: each hex's
    longest edge when already computed (:meth:`~.model.Mesh.element_measures`)."""
    if longest is None:
        longest = mesh.element_measures()[2]
    out = {}
    for part in SOIL_PARTS:
        sel = mesh.hex_part == PART_ID[part]
        if sel.any():
            out[part] = float(longest[sel].max())
    return out


def present_parts(mesh: Mesh) -> list[str]:
    """The parts (physical groups) that have elements in ``mesh``, in schema order."""
    ids = set(np.unique(mesh.hex_part).tolist()) | set(np.unique(mesh.line_part).tolist())
    return [p for p in PARTS if PART_ID[p] in ids]


def require_parts(mesh: Mesh, parts: tuple[str, ...], what: str) -> None:
    """One clear line when a stage needs parts the (user) mesh does not have."""
    have = present_parts(mesh)
    missing = [p for p in parts if p not in have]
    if missing:
        raise MeshError(f"{what} needs the part(s) {', '.join(missing)}, which the mesh does "
                        f"not have (it has: {', '.join(have) or 'nothing'}); use a mesh with "
                        "them or switch that feature off")
