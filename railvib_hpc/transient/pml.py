"""The perfectly matched layers of ``pml`` faces for the time-domain engines (docs/transient.md).

A face ``boundary.<face> = "pml"`` is fixed, and the hexahedra with a Gauss point within
``boundary.layer_thickness`` of it form its layer (:func:`pml_geometry`): their coordinate
normal to the face is stretched by ``1 + d(xi) / (i omega)`` (:mod:`railvib_hpc.fem.pml`:
formulation, profile, kernel), with ``xi`` the depth into the layer. Edges and corners,
where two or three layers overlap, stretch two or three coordinates; the soil's layers and
parts continue through it (each element keeps its material). The layer's strength ``d_max`` follows
from the largest P-wave speed in it and ``boundary.pml_reflection``,
``boundary.pml_power``.

What may lie in a layer: soil, the track bed and the mitigation measures (continua,
stretched like the soil). The building may not (it is the model, not its truncation:
refused). The track's beams and springs that run into an ``x`` layer are not stretched
(1-D elements; the rail's own truncation is ``track.ends``), so they reflect what they
carry, as at any fixed face.

The layer's elements enter K with the plain full-integration stiffness, whatever
``modal.hex_formulation`` says (the stage passes :func:`pml_geometry`'s mask to the
assembly): the memory terms use the plain gradients, and with B-bar on one side only the
layer's energy grew ~17 decades per 0.5 s on the plane-strain test slab.

Each rank computes the layer's elements that touch its nodes (as the assembly does, so
no force is summed across ranks), with the displacements of their nodes gathered from
their owners (:class:`~.petsc.GhostGather`). Cost per layer element: ~4.4 kB and ~6
kflop per step (the gradients and forces at 8 Gauss points); the rest of the model is
untouched.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..boundary_registry import boundary_kind
from ..errors import UserError
from ..fem.material import lame_parameters
from ..fem.pml import (
    MIN_ELEMENTS,
    PmlElements,
    lumped_mass_coefficients,
    profile,
    profile_strength,
)
from ..fem.reference import GAUSS_VALUES
from ..mesh.model import Mesh
from ..model.boundary import FACE_AXIS, face_node_sets, face_types
from ..problem import Problem
from ..schema import BUILDING_PARTS, PART_ID, SOLID_MATERIAL

#: Relative round-off allowed in a layer's element count (thickness / median size) before
#: it counts as fewer than :data:`~railvib_hpc.fem.pml.MIN_ELEMENTS`.
ACROSS_TOL = 1e-6
#: Layer elements per block of :meth:`PmlLayer.instant_matrix` (4096 x 24 x 24 doubles:
#: 19 MB per block of element matrices).
INSTANT_CHUNK = 4096


class PmlError(UserError):
    """A perfectly matched layer the mesh cannot carry."""


@dataclass(frozen=True)
class PmlFace:
    """One ``pml`` face: its coordinate axis, the plane's coordinate, the layer's
    strength ``d_max`` [1/s], the largest P-wave speed in it [m/s], its elements and the
    element layers across it."""

    face: str
    axis: int
    plane: float
    d_max: float
    c_p: float
    elements: int
    across: float


def pml_faces(problem: Problem) -> list[str]:
    """The faces whose kind has a perfectly matched layer (``pml``,
    :attr:`~railvib_hpc.model.boundary_kind.BoundaryKind.matched_layer`)."""
    return [face for face, kind in face_types(problem).items()
            if boundary_kind(kind).matched_layer]


def _element_materials(mesh: Mesh, problem: Problem, sel: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lame parameters and densities of the hexahedra ``sel`` (their random fields'
    factors applied at the centroids, as the assembly does)."""
    from ..model.elements import element_factors

    lam, mu, rho = np.zeros(len(sel)), np.zeros(len(sel)), np.zeros(len(sel))
    parts = mesh.hex_part[sel]
    centres = mesh.points[mesh.hexes[sel]].mean(axis=1)
    for part, name in SOLID_MATERIAL.items():
        here = parts == PART_ID[part]
        if not here.any():
            continue
        mat = problem.material(name)
        E, density = np.full(here.sum(), mat.E), np.full(here.sum(), mat.rho)
        if any(f.part == name for f in problem.fields):
            E = E * element_factors(problem.fields, name, "E", centres[here])
            density = density * element_factors(problem.fields, name, "rho", centres[here])
        lam[here], mu[here] = lame_parameters(E, mat.nu)
        rho[here] = density
    return lam, mu, rho


def _gauss_coordinates(mesh: Mesh, axis: int) -> np.ndarray:
    """Coordinate ``axis`` of every hexahedron's 2x2x2 Gauss points, (n_hexes, 8)."""
    return mesh.points[mesh.hexes][:, :, axis] @ GAUSS_VALUES.T


def pml_geometry(mesh: Mesh, problem: Problem) -> tuple[list[PmlFace], np.ndarray]:
    """The ``pml`` faces and the mask of the hexahedra in their layers (checked).

    A face's layer holds every hexahedron with a Gauss point less than
    ``boundary.layer_thickness`` from the face (by more than :data:`ACROSS_TOL` of it):
    the elements where its stretching ``d > 0`` acts. So the stretching is a function of
    the coordinate normal to the face alone, as the continuous layer's (an element that
    straddles the layer's inner plane is in it, whatever its size; by the centroids, a
    coarse element whose centroid lay at the thickness was in or out by round-off: 10 of
    the 496 8-m elements of a 4-m layer on the coarse thesis model).

    Raises
    ------
    PmlError
        A face without nodes, a layer that holds no element, or a building element in a
        layer.
    """
    thickness = problem.boundary.layer_thickness
    sets = face_node_sets(mesh)
    centres = mesh.points[mesh.hexes].mean(axis=1)
    inside = np.zeros(len(mesh.hexes), dtype=bool)
    faces = []
    building = np.isin(mesh.hex_part, [PART_ID[p] for p in BUILDING_PARTS])
    for face in pml_faces(problem):
        nodes = sets[face]
        if nodes.size == 0:
            raise PmlError(f"boundary.{face} = 'pml': the mesh has no nodes on that face")
        axis = FACE_AXIS[face]
        plane = float(mesh.points[nodes, axis].mean())
        distance = np.abs(_gauss_coordinates(mesh, axis) - plane).min(axis=1)
        layer = distance < thickness * (1.0 - ACROSS_TOL)
        if not layer.any():
            k = int(np.argmin(distance))
            ext = mesh.points[mesh.hexes[k], axis]
            size = float(ext.max() - ext.min())
            raise PmlError(
                f"boundary.layer_thickness = {thickness:g}: the pml layer of boundary.{face} "
                f"holds no element (the nearest Gauss point lies {distance[k]:.4g} m from "
                f"the face); allowed: more than {distance[k]:.4g} m, better {MIN_ELEMENTS} "
                f"element layers (about {MIN_ELEMENTS * size:.3g} m on this mesh)")
        if (layer & building).any():
            k = int(np.flatnonzero(layer & building)[0])
            raise PmlError(
                f"boundary.layer_thickness = {thickness:g}: the pml layer of boundary.{face} "
                f"reaches the building (element {k} at {np.round(centres[k], 3).tolist()} "
                "m); a layer stands in for the ground beyond the model: make it thinner or "
                "the domain larger (domain.extra_depth, domain.extra_length, "
                "domain.extra_width)")
        lam, mu, rho = _element_materials(mesh, problem, np.flatnonzero(layer))
        c_p = float(np.sqrt((lam + 2.0 * mu) / rho).max())
        d_max = profile_strength(c_p, thickness, problem.boundary.pml_power,
                                 problem.boundary.pml_reflection)
        ext = mesh.points[mesh.hexes[layer]][:, :, axis]
        h = float(np.median(ext.max(axis=1) - ext.min(axis=1)))
        faces.append(PmlFace(face, axis, plane, d_max, c_p, int(layer.sum()), thickness / h))
        inside |= layer
    return faces, inside


def pml_warnings(faces: list[PmlFace], problem: Problem) -> list[str]:
    """Lines on layers with fewer than :data:`~railvib_hpc.fem.pml.MIN_ELEMENTS` element
    layers across: the discrete layer's reflection grows with ``d_max h / c_P = (p + 1)
    ln(1 / R) / (2 n)`` far above the target ``R`` (Collino & Tsogka 2001)."""
    b = problem.boundary
    out = []
    for f in faces:
        if f.across >= MIN_ELEMENTS * (1.0 - ACROSS_TOL):
            continue
        h = b.layer_thickness / f.across
        out.append(f"warning: boundary.layer_thickness = {b.layer_thickness:g} m gives the pml "
                   f"layer of boundary.{f.face} {f.across:.3g} element layers of {h:.3g} m; "
                   f"below {MIN_ELEMENTS} its discrete reflection lies far above "
                   f"boundary.pml_reflection = {b.pml_reflection:g}: make it at least "
                   f"{MIN_ELEMENTS * h:.3g} m")
    return out


def pml_memory_warning(problem: Problem, duration: float) -> str | None:
    """A line for the classical layer (``boundary.pml_alpha = 0``), else None: its memory
    integrates a quasi-static stress without decay, and with energy trapped between roller
    sides its energy was measured to grow from 7.4 s on (docs/transient.md); with
    ``alpha > 0`` every memory variable decays at the rate ``alpha`` and stays bounded
    (measured: no growth in 10 s / 20,000-step runs). ``duration`` [s]: the simulated
    time, named in the line."""
    if problem.boundary.pml_alpha > 0.0:
        return None
    return ("warning: boundary.pml_alpha = 0: the classical layer's memory never decays, so "
            "a quasi-static stress in the layers accumulates, and its energy can grow on long "
            f"runs (measured from 7.4 s on; this run lasts {duration:.4g} s); a frequency "
            "shift alpha > 0 bounds it (default pi 1/s)")


def damping_at(points: np.ndarray, faces: list[PmlFace], problem: Problem) -> np.ndarray:
    """``d_0, d_1, d_2`` [1/s] at ``points`` (..., 3): each face's profile over the depth
    into its layer, along its axis (the largest where two faces share an axis)."""
    thickness, power = problem.boundary.layer_thickness, problem.boundary.pml_power
    d = np.zeros(points.shape)
    for f in faces:
        depth = thickness - np.abs(points[..., f.axis] - f.plane)
        d[..., f.axis] = np.maximum(d[..., f.axis], profile(depth, thickness, f.d_max, power))
    return d


def pml_line(faces: list[PmlFace], problem: Problem) -> str:
    """One line on the layers for the run's log."""
    b = problem.boundary
    return (f"perfectly matched layers ({b.layer_thickness:g} m, R = {b.pml_reflection:g}, "
            f"p = {b.pml_power:g}): " + ", ".join(
                f"{f.face} {f.elements} elements, {f.across:.3g} across, d_max "
                f"{f.d_max:.4g} 1/s" for f in faces))


class PmlLayer:
    """This rank's share of the layers: the memory kernel of their elements touching its
    nodes and the mass-side diagonals of its rows (collective construction).

    The equations of its rows gain (module :mod:`railvib_hpc.fem.pml`)::

        M_e1 u' + M_e2 u + M_e3 int u + f_memory(u history)

    :attr:`damping_diagonal` (``M_e1``) is taken at the full-step velocity by the engine,
    like the face dashpots; :meth:`force` returns the rest at ``u_{n+1}``. The direct
    engine takes the layer implicitly: :meth:`instant_matrix` is the part of
    :meth:`force` that ``u_{n+1}`` makes, :meth:`peek` the history's part.

    Parameters
    ----------
    mesh, problem, dofmap
        The model.
    rank, r0, r1
        This rank and its DOF rows ``[r0, r1)``.
    gather
        ``gather(dofs) -> callable``: a collective factory of a function that returns, from
        this rank's rows of a vector, its values at the global ``dofs``
        (:class:`~.petsc.GhostGather`).
    geometry
        :func:`pml_geometry` of the model, when the caller has it already (computed here
        otherwise).
    """

    def __init__(self, mesh: Mesh, problem: Problem, dofmap, rank: int, r0: int, r1: int,
                 gather: Callable, geometry: tuple | None = None):
        self.faces, inside = pml_geometry(mesh, problem) if geometry is None else geometry
        own = np.zeros(mesh.n_nodes, dtype=bool)
        own[dofmap.owned_nodes(rank)] = True
        sel = np.flatnonzero(inside & own[mesh.hexes].any(axis=1))
        #: The global numbers of this rank's layer elements (increasing): the key of
        #: their memory in a checkpoint (:meth:`memory`).
        self.elements = sel
        conn = mesh.hexes[sel]
        x = mesh.points[conn]
        lam, mu, rho = _element_materials(mesh, problem, sel)
        gauss = np.einsum("qa,eak->eqk", GAUSS_VALUES, x)
        alpha = self.alpha = problem.boundary.pml_alpha
        damping = damping_at(gauss, self.faces, problem)
        self.kernel = PmlElements(x, lam, mu, damping, alpha)
        self.dofs = dofmap.index[conn][:, :, :3]                    # (nel, 8, 3), -1 fixed
        flat = self.dofs.ravel()
        needed = np.unique(flat[flat >= 0])
        # element slots with a free DOF and where their value sits in the gathered vector
        self._free = np.flatnonzero(flat >= 0)
        self._slots = np.searchsorted(needed, flat[self._free])
        self._gather = gather(needed)
        self.r0, self.n_local = r0, r1 - r0
        self._n_global = dofmap.n_dofs
        # element slots of this rank's rows, and those rows
        self._owned = np.flatnonzero((flat >= r0) & (flat < r1))
        self._rows = flat[self._owned] - r0
        # the layer elements' lumped masses weighted by e1, e2, e3 at the Gauss points,
        # where the memory terms take d (at the nodes the layer grew, fem.pml)
        m1, m2, m3 = (self._to_rows(np.repeat(c[:, :, None], 3, axis=2))
                      for c in lumped_mass_coefficients(x, rho, damping))
        # rho s^2 J u with J = 1 + e1 r + e2 r^2 + e3 r^3, r = 1 / (s + alpha):
        # M_e1 u' + (M_e2 - alpha M_e1) u + c_k chi_k, chi_k = r^k u (fem.pml)
        self.damping_diagonal = m1
        self.stiffness_diagonal = m2 - alpha * m1
        #: ``M_e2`` (>= 0), which the conditionally stable engines take at the Newmark
        #: average displacement, so that it never limits their step (the explicit
        #: engine's ``m + dt^2 / 4 M_e2``, the imex engine's K_eff; it is in
        #: :attr:`stiffness_diagonal` and :meth:`force` as the direct engine takes it)
        self.average_diagonal = m2
        self._chi_coef = (alpha * alpha * m1 - 2.0 * alpha * m2 + m3,
                          alpha * alpha * m2 - 2.0 * alpha * m3, alpha * alpha * m3)
        self.n_elements = len(sel)
        self._u = np.zeros(self.n_local)
        self._chi = [np.zeros(self.n_local) for _ in range(3)]
        #: Whether :meth:`start` has set the rest state (else it is u = 0).
        self.started = False
        #: The rest state of :meth:`start` (None: u = 0, nothing to subtract per step).
        self._offset = None

    @property
    def nbytes(self) -> int:
        """Memory of this rank's layer [bytes] (kernel, maps, diagonals)."""
        return self.kernel.nbytes + self.dofs.nbytes + sum(
            a.nbytes for a in (self._free, self._slots, self._owned, self._rows)) + \
            9 * 8 * self.n_local

    def destroy(self) -> None:
        """Free the gather's PETSc objects (if it has any)."""
        release = getattr(self._gather, "destroy", None)
        if release is not None:
            release()

    def _to_rows(self, values: np.ndarray) -> np.ndarray:
        """Sum element values (nel, 8, 3) into this rank's rows (float64 also on a rank
        without layer elements, where ``bincount`` of nothing would give integers)."""
        return np.bincount(self._rows, values.reshape(-1)[self._owned],
                           self.n_local).astype(float, copy=False)

    def _element_values(self, u: np.ndarray) -> np.ndarray:
        """The layer elements' displacements (nel, 8, 3) from this rank's rows ``u``
        (collective)."""
        values = self._gather(u)
        out = np.zeros(self.dofs.shape)
        out.reshape(-1)[self._free] = values[self._slots]
        return out

    def start(self, u: np.ndarray) -> np.ndarray:
        """Take the initial displacements ``u`` (this rank's rows) as the layer's rest
        state, its memory at rest: from here on the layer acts on ``u - u_0`` only, so a
        static deflection at the start (a wheel resting on the flexible rail) is no load
        on it. Returns the layer's force at the start: zero.

        (The layer's terms are dynamic: its stretched static problem is not the soil's,
        and ``M_e2 u_0``, ~10 x the soil's stiffness per unit displacement at
        ``d ~ 1e3 1/s``, would act on the whole static field in the layer as a load at
        t = 0: measured on the coarse thesis model with layers and a wheel starting on
        the flexible rail, the building's peak accelerations were 1.5-3 x those with
        dashpots before, within 1-12 % of them after; docs/transient.md.)"""
        self._offset = np.array(u, dtype=float, copy=True) if np.any(u) else None
        self.kernel.start(np.zeros(self.dofs.shape))
        self._u = np.zeros(self.n_local)
        self._chi = [np.zeros(self.n_local) for _ in range(3)]
        self.started = True
        return np.zeros(self.n_local)

    #: The element memory of :meth:`~railvib_hpc.fem.pml.PmlElements.memory`, by name.
    MEMORY = ("psi", "g", "sigma", "s1", "s2")

    def memory(self) -> dict[str, tuple[str, np.ndarray]]:
        """The layer's whole state after a step, for a checkpoint (copies): ``name:
        (kind, array)``, kind ``"rows"`` for this rank's rows of a vector over the global
        DOFs (the displacement of the last step from the rest state, the chains
        ``chi_k``, the rest state itself) and ``"elements"`` for one row per element of
        :attr:`elements` (the kernel's memory, :meth:`~railvib_hpc.fem.pml.PmlElements.
        memory`; an element several ranks hold has the same memory on each, computed
        from the same gathered displacements), with the element numbers under
        ``"pml_elements"`` (kind ``"ids"``). :meth:`restore` takes it back on any number
        of ranks."""
        out = {"pml_elements": ("ids", self.elements.astype(np.int64))}
        for name, a in zip(self.MEMORY, self.kernel.memory()):
            out[f"pml_{name}"] = ("elements", a)
        out["pml_u"] = ("rows", self._u.copy())
        for k, chi in enumerate(self._chi):
            out[f"pml_chi{k}"] = ("rows", chi.copy())
        offset = np.zeros(self.n_local) if self._offset is None else self._offset.copy()
        out["pml_offset"] = ("rows", offset)
        return out

    def restore(self, saved: dict[str, np.ndarray]) -> None:
        """Set the state of :meth:`memory` back: ``saved`` holds this rank's rows and
        the rows of its :attr:`elements` (by the same names); the layer is started."""
        self.kernel.restore(tuple(np.array(saved[f"pml_{name}"], dtype=float)
                                  for name in self.MEMORY))
        self._u = np.array(saved["pml_u"], dtype=float)
        self._chi = [np.array(saved[f"pml_chi{k}"], dtype=float) for k in range(3)]
        offset = np.array(saved["pml_offset"], dtype=float)
        self._offset = offset if np.any(offset) else None
        self.started = True

    def instant_diagonal(self, dt: float) -> np.ndarray:
        """``d f / d u_{n+1}`` of the mass-side terms of :meth:`force` on this rank's rows:
        ``M_e2 - alpha M_e1 + sum_k c_k w^k``, ``w = (dt / 2) / (1 + alpha dt / 2)`` (the
        trapezoidal chains)."""
        w = 0.5 * dt / (1.0 + 0.5 * dt * self.alpha)
        out = self.stiffness_diagonal.copy()
        for k, c in enumerate(self._chi_coef, start=1):
            out += c * w ** k
        return out

    def instant_matrix(self, dt: float, chunk: int = INSTANT_CHUNK):
        """``d f / d u_{n+1}`` of :meth:`force` on this rank's rows, a scipy CSR matrix
        (n_local, n_global; global columns): what an implicit step (the direct engine)
        puts into its effective matrix, so that ``force(u) = A (u - u_0) + force at u_0``
        (symmetric to round-off, :meth:`~railvib_hpc.fem.pml.PmlElements.
        instant_matrices`; the pattern of the layer elements, a subset of K's). Built
        ``chunk`` elements at a time (~4.6 kB per element of the chunk)."""
        import scipy.sparse as sp

        n_global = self._n_global
        out = sp.diags(self.instant_diagonal(dt), offsets=self.r0,
                       shape=(self.n_local, n_global), format="csr")
        nel = self.n_elements
        for c0 in range(0, nel, chunk):
            sl = slice(c0, min(c0 + chunk, nel))
            mats = self.kernel.subset(sl).instant_matrices(dt)           # (n, 24, 24)
            dofs = self.dofs[sl].reshape(-1, 24)
            rows = np.broadcast_to(dofs[:, :, None], mats.shape).ravel()
            cols = np.broadcast_to(dofs[:, None, :], mats.shape).ravel()
            keep = (rows >= self.r0) & (rows < self.r0 + self.n_local) & (cols >= 0)
            out = out + sp.csr_matrix((mats.ravel()[keep], (rows[keep] - self.r0, cols[keep])),
                                      shape=(self.n_local, n_global))
        out.sum_duplicates()
        return out

    def peek(self, u: np.ndarray, dt: float) -> np.ndarray:
        """What :meth:`force` would return at ``u``, the layer left as it was (collective):
        with ``u = 0``, the part of the next step's force that the history makes,
        ``force(0) = force(u) - A u`` (:meth:`instant_matrix`)."""
        # (force rebinds _u and updates _chi and the kernel's memory in place)
        saved = (self.kernel.memory(), self._u, [c.copy() for c in self._chi])
        try:
            return self.force(u, dt)
        finally:
            memory, self._u, self._chi = saved
            self.kernel.restore(memory)

    def force(self, u: np.ndarray, dt: float) -> np.ndarray:
        """Advance to the next step's displacements ``u`` and return the layer's force on
        this rank's rows there, ``f_memory + (M_e2 - alpha M_e1) u + sum_k c_k chi_k``
        (``u`` from the rest state of :meth:`start`)
        (the chains ``chi_k' + alpha chi_k = chi_{k-1}``, ``chi_0 = u``, by the trapezoidal
        rule; collective; once per step)."""
        if self._offset is not None:
            u = u - self._offset
        a = 0.5 * dt * self.alpha
        before, after = self._u, u
        for chi in self._chi:
            old = chi.copy()
            chi *= 1.0 - a
            chi += (0.5 * dt) * (before + after)
            chi /= 1.0 + a
            before, after = old, chi
        self._u = u.copy()
        extra = self._to_rows(self.kernel.advance(self._element_values(u), dt))
        extra += self.stiffness_diagonal * u
        for c, chi in zip(self._chi_coef, self._chi):
            extra += c * chi
        return extra


__all__ = ["PmlError", "PmlFace", "PmlLayer", "damping_at", "pml_faces", "pml_geometry",
           "pml_line", "pml_memory_warning", "pml_warnings"]
