"""The spectral soil of the explicit engine: spectral hexahedra of order N on MPI ranks,
matrix-free, with a diagonal mass (docs/spectral.md; no case, no PETSc).

The soil's hexahedra are all promoted to order ``N`` (:func:`~railvib_hpc.fem.spectral_mesh.
spectral_mesh`: ``(N + 1)^3`` Gauss-Lobatto-Legendre nodes each, shared with the neighbours)
and integrated on their GLL nodes, so the mass is diagonal (Komatitsch & Tromp 1999). Per
step (the central-difference scheme of :mod:`.explicit`, Newmark beta = 0, gamma = 1/2)::

    u_{n+1}   = u_n + dt v_n + dt^2 / 2 a_n
    v*        = v_n + dt / 2 a_n
    r         = f_{n+1} - K (u_{n+1} + beta v*) - k_s u_{n+1}
    a_{n+1}   = (r - c v*) / (m + dt / 2 c)
    v_{n+1}   = v* + dt / 2 a_{n+1}

``K`` the sum-factorised elastic operator (:mod:`railvib_hpc.fem.spectral_kernel`, compiled),
``beta K`` the stiffness-proportional part of Rayleigh damping applied by the same kernel
call, ``m`` the GLL mass, ``c = alpha m + c_d`` the mass-proportional part and the
Lysmer-Kuhlemeyer dashpots ``c_d`` of the absorbing faces (``rho c_P`` normal, ``rho c_S``
tangential, per node its GLL face weight ``w_i w_j |dx/dxi x dx/deta|``; the diagonal of the
node's block, exact on the axis-aligned faces of a box), ``k_s`` the faces' springs
(``(lambda + 2 mu) / t``, ``mu / t``). The diagonal damping is taken at ``v_{n+1}``
(trapezoidal): it costs nothing and does not limit the step; ``beta K`` is taken at ``v*``
and does: ``dt <= 2 / omega (sqrt(1 + xi^2) - xi)``, ``xi = beta omega / 2``, at the largest
``omega`` of ``M^-1 (K + K_s)`` found by Lanczos (:meth:`SpectralSoil.largest_omega`).
Undamped, the scheme conserves the discrete energy ``1/2 v.Mv + 1/2 u.Ku`` to
``O(dt^2)`` (exactly its modified energy).

**MPI.** Every rank builds the same node set; the elements are split into slabs along
``x`` (contiguous in their centroids' ``x``), and each rank holds the nodes of its own
elements only (its local numbering). The nodes that two or more ranks hold (the slabs'
interfaces) are summed by one ``Allreduce`` of their forces per step, on an interface set
every rank lists in the same order: afterwards every rank has the whole force at each of
its nodes and updates them all (the interface nodes identically on both sides). Cost: one
``Allreduce`` of ``3 n_interface`` doubles per step (a plane of ``(N n_y + 1)(N n_z + 1)``
nodes per cut), no ghost elements. Each node is *owned* by the lowest rank that holds it
(dot products, energies and the outputs count it once).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..fem.gll import derivative_matrix, gll_points, hex_interpolation, lexicographic_index
from ..fem.spectral_kernel import spectral_elasticity, stiffness_diagonal
from ..fem.spectral_mesh import spectral_mesh

__all__ = ["STEP_SAFETY", "FacePlane", "SpectralSoil", "SpectralState"]

#: Fraction of the critical step taken (the explicit engine's, :data:`.explicit.STEP_SAFETY`).
STEP_SAFETY = 0.9
#: Lanczos steps and relative tolerance of the largest frequency's bound.
POWER_ITERATIONS, POWER_TOLERANCE = 200, 1e-6
#: Relative residual and iteration limit of the static start's Jacobi-preconditioned CG.
STATIC_RTOL, STATIC_MAX_IT = 1e-10, 20_000
#: Relative tolerance of "on a face plane" (of the model's extent).
PLANE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class FacePlane:
    """A truncation face of the box: its name, the axis of its normal, its coordinate, the
    components held there (0, 1, 2) and whether it carries dashpots (and springs)."""

    name: str
    axis: int
    plane: float
    held: tuple[int, ...] = ()
    absorbing: bool = False


@dataclass
class SpectralState:
    """The state at step ``step`` on this rank's local nodes ((n_local, 3) each)."""

    step: int
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray


def _slabs(centroid_x: np.ndarray, size: int) -> np.ndarray:
    """Rank of every element: contiguous slabs in the order of the centroids' ``x``."""
    order = np.argsort(centroid_x, kind="stable")
    rank = np.empty(len(order), dtype=np.int64)
    for r, part in enumerate(np.array_split(order, size)):
        rank[part] = r
    return rank


class SpectralSoil:
    """The spectral soil on this rank (collective constructor and methods).

    Parameters
    ----------
    order
        ``N`` (2..8; 1 works too: the GLL element of order 1, nodal quadrature).
    points, hexes
        The hex8 mesh (the mesh stage's nodes and hexahedra), every one promoted.
    lam, mu, rho
        Per hexahedron [Pa, Pa, kg/m^3].
    faces
        The truncation faces (:class:`FacePlane`) with their holds and dashpots.
    virtual_thickness
        ``t`` of the absorbing faces' springs [m] (0: none).
    alpha, beta
        Rayleigh damping ``alpha M + beta K``.
    comm
        MPI communicator.
    """

    def __init__(self, order: int, points: np.ndarray, hexes: np.ndarray, lam: np.ndarray,
                 mu: np.ndarray, rho: np.ndarray, faces: list[FacePlane],
                 virtual_thickness: float, alpha: float, beta: float, comm):
        t0 = time.perf_counter()
        self.comm, self.order = comm, int(order)
        self.alpha, self.beta = float(alpha), float(beta)
        hexes = np.asarray(hexes)
        self.mesh = spectral_mesh(points, hexes, np.ones(len(hexes), bool), self.order)
        sm = self.mesh
        rank_of = _slabs(np.asarray(points)[hexes].mean(axis=1)[:, 0], comm.size)
        self.elements_global = np.flatnonzero(rank_of == comm.rank)
        held_by = [np.unique(sm.elements[rank_of == r]) for r in range(comm.size)]
        self.nodes = held_by[comm.rank]                           # local -> global
        touch = np.zeros(sm.n_nodes, dtype=np.int64)
        owner = np.full(sm.n_nodes, comm.size, dtype=np.int64)
        for r, nodes in enumerate(held_by):
            touch[nodes] += 1
            owner[nodes] = np.minimum(owner[nodes], r)
        g2l = np.full(sm.n_nodes, -1, dtype=np.int64)
        g2l[self.nodes] = np.arange(len(self.nodes))
        self.g2l = g2l
        interface = np.flatnonzero(touch > 1)
        here = g2l[interface]
        self._if_slot = np.flatnonzero(here >= 0)
        self._if_local = here[self._if_slot]
        self._if_buffer = np.zeros((len(interface), 3))
        self.n_interface = len(interface)
        self.owned = owner[self.nodes] == comm.rank
        # the global owned numbering (the guard's rows and the outputs' node order)
        owned_global = [nodes[owner[nodes] == r] for r, nodes in enumerate(held_by)]
        self.owned_offsets = np.cumsum([0] + [len(o) for o in owned_global])
        self.owned_points = sm.points[np.concatenate(owned_global)]
        local_elements = g2l[sm.elements[self.elements_global]]
        ids = self.elements_global
        self.op = spectral_elasticity(self.order, sm.points[self.nodes], local_elements,
                                      np.asarray(lam)[ids], np.asarray(mu)[ids],
                                      np.asarray(rho)[ids], n_nodes=len(self.nodes))
        self.local_elements = local_elements
        n = len(self.nodes)
        self.m = self.assemble(np.repeat(self.op.mass[:, None], 3, axis=1).copy())[:, 0].copy()
        self.held = np.zeros((n, 3), bool)
        extent = float(np.ptp(sm.points, axis=0).max()) or 1.0
        local_points = sm.points[self.nodes]
        for face in faces:
            on = np.abs(local_points[:, face.axis] - face.plane) <= PLANE_TOLERANCE * extent
            for c in face.held:
                self.held[on, c] = True
        dash, spring = self._face_terms(faces, lam, mu, rho, virtual_thickness, extent)
        self.dashpot = self.assemble(dash)
        self.spring = self.assemble(spring)
        self.c = self.alpha * self.m[:, None] + self.dashpot
        self.free = ~self.held
        self.setup_time = time.perf_counter() - t0
        self.time_products = 0.0
        self.dt = 0.0

    # ------------------------------------------------------------------ geometry
    def _face_terms(self, faces, lam, mu, rho, thickness, extent):
        """Per local node and component: the dashpots and springs of the absorbing faces
        (this rank's elements' GLL face nodes; summed over the ranks by the caller)."""
        n = self.order
        _, w = gll_points(n)
        d = derivative_matrix(n)
        ijk = lexicographic_index(n)
        sm = self.mesh
        lam, mu, rho = (np.asarray(v, float)[self.elements_global] for v in (lam, mu, rho))
        cp, cs = np.sqrt((lam + 2.0 * mu) / rho), np.sqrt(mu / rho)
        dash = np.zeros((len(self.nodes), 3))
        spring = np.zeros_like(dash)
        conn = self.local_elements
        xyz = sm.points[self.nodes]
        for face in faces:
            if not face.absorbing:
                continue
            for side in (0, n):
                local = np.flatnonzero(ijk[:, face.axis] == side)
                a, b = [k for k in range(3) if k != face.axis]
                # face nodes ordered (i_a, i_b): local index sorted by (b, a) in lexicographic
                order = np.lexsort((ijk[local, a], ijk[local, b]))
                local = local[order]
                nodes = conn[:, local]                                 # (ne, (n+1)^2)
                coord = xyz[nodes][..., face.axis]
                on = np.all(np.abs(coord - face.plane) <= PLANE_TOLERANCE * extent, axis=1)
                if not on.any():
                    continue
                x = xyz[nodes[on]].reshape(-1, n + 1, n + 1, 3)        # (e, i_b, i_a, 3)
                ta = np.einsum("pq,ebqc->ebpc", d, x)
                tb = np.einsum("pq,eqac->epac", d, x)
                cross = np.cross(ta, tb)
                area = np.linalg.norm(cross, axis=-1)                  # (e, i_b, i_a)
                normal = cross / np.where(area > 0, area, 1.0)[..., None]
                area = area * w[None, :, None] * w[None, None, :]
                for c in range(3):
                    share = normal[..., c] ** 2
                    coef_d = (rho[on] * cs[on])[:, None, None] * (1.0 - share) + \
                        (rho[on] * cp[on])[:, None, None] * share
                    np.add.at(dash[:, c], nodes[on].ravel(), (coef_d * area).ravel())
                    if thickness > 0:
                        coef_s = (mu[on] / thickness)[:, None, None] * (1.0 - share) + \
                            ((lam[on] + 2.0 * mu[on]) / thickness)[:, None, None] * share
                        np.add.at(spring[:, c], nodes[on].ravel(), (coef_s * area).ravel())
        return dash, spring

    # ------------------------------------------------------------------ operators
    def assemble(self, f: np.ndarray) -> np.ndarray:
        """Sum the interface nodes' values over the ranks, in place (collective); returns
        ``f``."""
        if self.comm.size == 1:
            return f
        from mpi4py import MPI

        buf = self._if_buffer
        buf[:] = 0.0
        buf[self._if_slot] = f[self._if_local]
        self.comm.Allreduce(MPI.IN_PLACE, buf, op=MPI.SUM)
        f[self._if_local] = buf[self._if_slot]
        return f

    def stiffness_times(self, u: np.ndarray) -> np.ndarray:
        """``(K + K_s) u`` on the local nodes, assembled (collective)."""
        f = np.zeros_like(u)
        self.op.add_forces(np.ascontiguousarray(u), f)
        self.assemble(f)
        return f + self.spring * u

    def dot(self, x: np.ndarray, y: np.ndarray) -> float:
        """``x . y`` over the owned nodes, summed over the ranks (collective)."""
        local = float(np.vdot(x[self.owned], y[self.owned]))
        return self.comm.allreduce(local) if self.comm.size > 1 else local

    def global_random(self, seed: int) -> np.ndarray:
        """A random field by global node (the same on any number of ranks)."""
        x = np.random.default_rng(seed).standard_normal((self.mesh.n_nodes, 3))
        return x[self.nodes]

    def largest_omega(self) -> float:
        """An upper estimate of the largest ``omega`` of ``M^-1 (K + K_s)`` on the free
        components (collective): Lanczos on ``M^-1/2 (K + K_s) M^-1/2`` (no
        reorthogonalisation; the extreme Ritz value converges first), its largest Ritz
        value plus its residual bound ``beta_k |s_k|`` (a rigorous bound on the distance
        to an eigenvalue; power iteration, which stalls below the top of a dense spectrum,
        gave steps past the limit on 2 M DOFs), to :data:`POWER_TOLERANCE` or
        :data:`POWER_ITERATIONS` steps."""
        scale = np.where(self.free, 1.0 / np.sqrt(self.m[:, None]), 0.0)
        q = self.global_random(0) * self.free
        q /= math.sqrt(self.dot(q, q))
        q_old = np.zeros_like(q)
        alphas, betas = [], []
        beta = 0.0
        bound = previous = 0.0
        for k in range(POWER_ITERATIONS):
            w = scale * self.stiffness_times(scale * q) - beta * q_old
            alpha = self.dot(w, q)
            w -= alpha * q
            beta = math.sqrt(max(self.dot(w, w), 0.0))
            alphas.append(alpha)
            betas.append(beta)
            if k >= 4 or beta == 0.0:
                t = np.diag(alphas) + np.diag(betas[:-1], 1) + np.diag(betas[:-1], -1)
                theta, vectors = np.linalg.eigh(t)
                bound = float(theta[-1] + beta * abs(vectors[-1, -1]))
                if beta == 0.0 or abs(bound - previous) <= POWER_TOLERANCE * bound:
                    break
                previous = bound
            q_old, q = q, w / beta
        return math.sqrt(bound)

    def stable_step(self) -> tuple[float, float]:
        """``(dt_critical, omega_max)``: the central-difference limit with the
        stiffness-proportional damping at the largest frequency."""
        omega = self.largest_omega()
        xi = 0.5 * self.beta * omega
        return 2.0 / omega * (math.sqrt(1.0 + xi * xi) - xi), omega

    # ------------------------------------------------------------------ loads
    def element_load(self, elements: np.ndarray, xi: np.ndarray, force: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """``(local nodes, values)``: the consistent nodal loads of point forces ``force``
        (p, 3) at reference points ``xi`` (p, 3) of global hexahedra ``elements`` (p,)
        that this rank holds (the others are left out: their rank adds them)."""
        mine = self.g2l_element(elements)
        keep = mine >= 0
        if not keep.any():
            return np.zeros(0, np.int64), np.zeros((0, 3))
        phi = hex_interpolation(self.order, np.clip(xi[keep], -1.0, 1.0))  # (p, q)
        nodes = self.local_elements[mine[keep]]                             # (p, q)
        values = phi[..., None] * force[keep][:, None, :]
        return nodes.ravel(), values.reshape(-1, 3)

    def g2l_element(self, elements: np.ndarray) -> np.ndarray:
        """Local index of global hexahedra (-1: another rank's)."""
        if not hasattr(self, "_e2l"):
            self._e2l = np.full(len(self.mesh.elements), -1, dtype=np.int64)
            self._e2l[self.elements_global] = np.arange(len(self.elements_global))
        return self._e2l[np.asarray(elements, dtype=np.int64)]

    # ------------------------------------------------------------------ time stepping
    def static_solve(self, f: np.ndarray) -> tuple[np.ndarray, int]:
        """``(K + K_s) u = f`` on the free components by CG with the diagonal of ``K + K_s``
        as preconditioner (collective); ``f`` assembled. Returns ``u`` and the iterations.

        Raises
        ------
        RuntimeError
            No convergence to :data:`STATIC_RTOL` within :data:`STATIC_MAX_IT` iterations
            (a box not held statically: absorbing faces without springs).
        """
        diag = self.assemble(stiffness_diagonal(self.op)) + self.spring
        inv = np.where(self.free, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
        f = np.where(self.free, f, 0.0)
        u = np.zeros_like(f)
        r = f.copy()
        z = inv * r
        p = z.copy()
        rz = self.dot(r, z)
        norm0 = math.sqrt(max(self.dot(f, f), 0.0))
        if norm0 == 0.0:
            return u, 0
        for it in range(1, STATIC_MAX_IT + 1):
            q = np.where(self.free, self.stiffness_times(p), 0.0)
            step = rz / self.dot(p, q)
            u += step * p
            r -= step * q
            if math.sqrt(max(self.dot(r, r), 0.0)) <= STATIC_RTOL * norm0:
                return u, it
            z = inv * r
            rz, previous = self.dot(r, z), rz
            p = z + (rz / previous) * p
        residual = math.sqrt(max(self.dot(r, r), 0.0)) / norm0
        raise RuntimeError(f"the static start did not converge in {STATIC_MAX_IT} CG "
                           f"iterations (relative residual {residual:.2g})")

    def acceleration(self, u: np.ndarray, v_star: np.ndarray, f_ext: np.ndarray,
                     dt: float) -> np.ndarray:
        """``a`` of the module notes from ``u``, ``v*`` and the unassembled external
        load (collective)."""
        t0 = time.perf_counter()
        w = u + self.beta * v_star if self.beta else u
        f = np.zeros_like(u)
        self.op.add_forces(np.ascontiguousarray(w), f)
        r = f_ext - f
        self.assemble(r)
        r -= self.spring * u + self.c * v_star
        a = np.where(self.free, r / (self.m[:, None] + 0.5 * dt * self.c), 0.0)
        self.time_products += time.perf_counter() - t0
        return a

    def step(self, st: SpectralState, f_ext: np.ndarray, dt: float) -> None:
        """One step ``n -> n + 1`` in place (``f_ext``: the unassembled load at ``n + 1``)."""
        st.u += dt * st.v + 0.5 * dt * dt * st.a
        v_star = st.v + 0.5 * dt * st.a
        st.a = self.acceleration(st.u, v_star, f_ext, dt)
        st.v = v_star + 0.5 * dt * st.a
        st.step += 1

    def energy(self, st: SpectralState, dt: float = 0.0) -> float:
        """The scheme's energy ``1/2 v.Mv + 1/2 u.(K - dt^2 / 4 K M^-1 K) u`` (``K`` with
        the springs; collective): undamped and unloaded, the central-difference step
        conserves it to round-off (``dt = 0``: the physical energy, to ``O(dt^2)``)."""
        ku = self.stiffness_times(st.u)
        out = 0.5 * self.dot(st.v, self.m[:, None] * st.v) + 0.5 * self.dot(st.u, ku)
        if dt:
            free_ku = np.where(self.free, ku, 0.0)
            out -= dt * dt / 8.0 * self.dot(free_ku, free_ku / self.m[:, None])
        return out

    @property
    def n_dofs(self) -> int:
        """Free DOFs of the whole soil."""
        local = int(np.count_nonzero(self.free[self.owned]))
        return self.comm.allreduce(local) if self.comm.size > 1 else local

    @property
    def nbytes(self) -> int:
        """Memory held by this rank's soil [B]: the operator, ``u, v, a``, the mass, the
        damping, springs and holds (the whole node set's coordinates and the global
        element map, built on every rank, are counted in :attr:`mesh_nbytes`)."""
        n = len(self.nodes)
        return int(self.op.nbytes + 3 * 24 * n + 8 * n + 3 * 24 * n + 3 * n + 8 * n)

    @property
    def mesh_nbytes(self) -> int:
        """Memory of the whole spectral node set every rank builds [B]."""
        return int(self.mesh.nbytes)


def _max():
    from mpi4py import MPI

    return MPI.MAX
