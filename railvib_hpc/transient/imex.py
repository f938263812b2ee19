"""Implicit-explicit time integration: the track and building implicit, the soil explicit.

The engine of ``transient.engine = "imex"`` (docs/transient.md). The explicit engine's step
(:mod:`.explicit`) is set by the stiffest, lightest elements of the model: the rail's
beams (~2e-5 s), thin concrete slabs (~5e-5 s, less with their Rayleigh damping), the
pads' springs. The soil, almost all of the DOFs of a real site, would allow 2-4e-4 s at
80 Hz resolution. Hughes & Liu's element partition (T. J. R. Hughes, W. K. Liu,
"Implicit-explicit finite elements in transient analysis", J. Appl. Mech. 45, 1978)
integrates the elements of ``transient.implicit_parts`` (``K_I, C_I``) implicitly and
the rest (``K_E = K - K_I, C_E = C - C_I``) explicitly, in one Newmark step
(``beta = 1/4, gamma = 1/2``) with the lumped mass ``m``::

    u~ = u_n + dt v_n + dt^2 (1/2 - beta) a_n,      v~ = v_n + dt (1 - gamma) a_n
    (m + gamma dt C_I + beta dt^2 K_I) a_{n+1} = f_{n+1} - K u~ - C v~
    u_{n+1} = u~ + beta dt^2 a_{n+1},               v_{n+1} = v~ + gamma dt a_{n+1}

The explicit elements see the predictors only (their forces are known before the solve);
the implicit ones take the trapezoidal rule. The matrix ``m + gamma dt C_I + beta dt^2
K_I`` is diagonal on every DOF that no implicit element touches, so its MUMPS factor
covers only the track and the building (a small fraction of a site's DOFs): memory and
work per step stay linear in the soil's DOFs. The step is stable up to the critical step
of the explicit part alone, ``K_E, C_E`` on ``m`` (Hughes & Liu's theorem for gamma =
1/2; :func:`~.explicit.stability_limit` with ``minus``); the implicit elements do not
limit it.

In displacement form (what :class:`~.integrate.DirectSolver` steps) the effective matrix
is ``K_eff = (m + gamma dt C_I + beta dt^2 K_I) / (beta dt^2)`` and the right-hand side
``m u~ / (beta dt^2) - K u~ - C v~ + (K_I + gamma / (beta dt) C_I) u~ + f``: the direct
path's solver, its exact wheel-rail contact (the rail is implicit: the rail columns of
:class:`~.integrate.RailColumns` come from the small factor) and its checkpoints work
unchanged. A step costs the products with K and C (as the explicit engine), one with the
small ``K_I + gamma / (beta dt) C_I``, and one solve with the small factor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..schema import IMPLICIT_GROUPS
from .explicit import ExplicitSystem
from .petsc import csr_matrix
from .scheme import GeneralizedAlpha

if TYPE_CHECKING:
    from ..problem import Problem

#: Options prefix of the factor of the implicit partition (``-railvib_imex_st_mat_mumps_...``).
PREFIX = "railvib_imex_"


def implicit_part_names(names: list[str], present: list[str]) -> tuple[str, ...]:
    """The parts of ``transient.implicit_parts`` (groups expanded) that the mesh has.

    >>> implicit_part_names(["track"], ["rail", "sleeper", "pad_z", "subgrade", "slab"])
    ('pad_z', 'rail', 'sleeper')
    >>> implicit_part_names(["building", "ballast"], ["rail", "ballast", "slab", "wall"])
    ('ballast', 'slab', 'wall')
    """
    wanted = {p for name in names for p in IMPLICIT_GROUPS.get(name, (name,))}
    return tuple(sorted(wanted & set(present)))


def damped_critical_steps(omega: np.ndarray, alpha: np.ndarray | float,
                          beta: np.ndarray | float) -> np.ndarray:
    """Critical steps [s] of modes ``omega`` [rad/s] under Rayleigh damping ``alpha, beta``
    for the explicit part of this engine: the central differences' closed form
    ``(2 / omega) (sqrt(1 + x^2) - x)`` at ``x`` = :data:`DAMPING_STABILITY_FACTOR` times
    the damping ratio ``alpha / (2 omega) + beta omega / 2``.

    >>> float(damped_critical_steps(np.array([1000.0]), 0.0, 0.0)[0])
    0.002
    """
    omega = np.asarray(omega, dtype=float)
    w = np.where(omega > 0, omega, 1.0)
    x = DAMPING_STABILITY_FACTOR * (np.asarray(alpha) / (2.0 * w) + np.asarray(beta) * w / 2.0)
    return np.where(omega > 0, 2.0 / w * (np.sqrt(1.0 + x * x) - x), np.inf)


#: Largest share of the hexahedra the element-wise partition makes implicit: the factor
#: must stay small against the model (a partition of most of the soil would be the direct
#: path's factor again). Measured on jobs/real_site.toml: 626,720 of 679,504 elements
#: allow less than the band's 5e-4 s; the 5 % with the smallest steps are the thin slices
#: under the building's grid lines and the most damped elements.
AUTO_IMPLICIT_SHARE = 0.05


def element_allowed_steps(mesh, problem: Problem, safety: float) -> np.ndarray:
    """Every hexahedron's own allowed step: ``safety`` x its critical step alone
    (:func:`damped_critical_steps` of :func:`~railvib_hpc.model.elements.hex_max_frequencies`
    with its Rayleigh coefficients). By Irons' theorem the explicit part's critical step is
    at least the smallest of these over its elements (a bound, not the limit itself)."""
    from ..model.damping import material_rayleigh, rayleigh_coefficients
    from ..model.elements import hex_max_frequencies, material_groups
    from ..schema import PART_ID

    omega = hex_max_frequencies(mesh, problem)
    alpha = np.zeros(len(omega))
    beta = np.zeros(len(omega))
    model = problem.damping.model
    if model == "rayleigh":
        a, b = rayleigh_coefficients(problem.damping.ratio, problem.damping.f1,
                                     problem.damping.f2)
        alpha[:], beta[:] = a, b
    elif model == "per_material":
        groups = material_groups(mesh)
        coeffs = material_rayleigh(problem, list(groups))
        for group, parts in groups.items():
            on = np.isin(mesh.hex_part, [PART_ID[p] for p in parts])
            alpha[on], beta[on] = coeffs[group]
    return safety * damped_critical_steps(omega, alpha, beta)


def auto_implicit_hexes(mesh, problem: Problem, target_dt: float, safety: float,
                        candidates: np.ndarray | None = None,
                        share: float = AUTO_IMPLICIT_SHARE) -> np.ndarray:
    """Mask of the hexahedra whose own allowed step (:func:`element_allowed_steps`) is
    below ``target_dt`` and among the ``share`` of the ``candidates`` (default: all; the
    elements not implicit already) with the smallest steps: the IMEX engine's element-wise
    partition (``transient.implicit_elements = 'auto'``)."""
    steps = element_allowed_steps(mesh, problem, safety)
    pool = np.ones(len(steps), bool) if candidates is None else np.asarray(candidates, bool)
    if not pool.any():
        return np.zeros(len(steps), dtype=bool)
    return pool & (steps < min(target_dt, float(np.quantile(steps[pool], share))))


def damping_velocity(v: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
    """The velocity the explicit elements' damping forces take: ``v* = v_n + dt a_n``.

    A second-order estimate of ``v_{n+1}`` (its error is ``dt^2 / 2`` times the jerk),
    where the Newmark predictor ``v~ = v_n + dt / 2 a_n`` (or the central differences'
    half-step velocity) is only first order: with it the damped response converges as
    ``dt`` (measured on the thesis model: 1.07 / 0.55 / 0.30 % peak acceleration error
    at 1e-4 / 5e-5 / 2.5e-5 s), with ``v*`` as ``dt^2``. The price: the explicit part's
    critical step is that of twice the damping ratio (:data:`DAMPING_STABILITY_FACTOR`).

    >>> damping_velocity(np.array([1.0]), np.array([2.0]), 0.5)
    array([2.])
    """
    return v + dt * a


#: The explicit part's critical step with the damping at :func:`damping_velocity` is
#: :func:`~.explicit.critical_step` at this many times the mode's damping ratio (the
#: one-step map's spectral radius, tests/transient/test_imex.py).
DAMPING_STABILITY_FACTOR = 2.0


def implicit_rows(K_I) -> np.ndarray:
    """This rank's rows of ``K_I`` with a nonzero entry (boolean mask): the rows an implicit
    element touches (a pattern may hold structural zeros)."""
    ip, _, values = K_I.getValuesCSR()
    stiff = np.zeros(len(ip) - 1)
    filled = np.diff(ip) > 0
    if values.size:
        stiff[filled] = np.add.reduceat(np.abs(values), ip[:-1][filled])
    return stiff > 0.0


def with_diagonal(A, diagonal: np.ndarray, comm):
    """A new AIJ matrix ``A + diag(diagonal)`` whose pattern is ``A``'s plus the whole
    diagonal (``A``'s rows may be empty; ``diagonal``: this rank's rows)."""
    import scipy.sparse as sp
    from petsc4py import PETSc

    r0, r1 = A.getOwnershipRange()
    n_local, n_global = r1 - r0, A.getSize()[0]
    ip, ix, v = A.getValuesCSR()
    local = sp.csr_matrix((v, ix, ip), shape=(n_local, n_global))
    local = local + sp.csr_matrix((diagonal, (np.arange(n_local), r0 + np.arange(n_local))),
                                  shape=(n_local, n_global))
    B = csr_matrix(comm, local)
    B.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    B.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    return B


class ImexSystem(ExplicitSystem):
    """The IMEX engine's system: the explicit engine's products and lumped mass plus the
    implicit partition's small factor (see the module notes); the interface of
    :class:`~.petsc.TransientSystem` that :class:`~.integrate.DirectSolver` and
    :class:`~.integrate.RailColumns` use (``scheme``, ``history_rhs``, ``solve``,
    ``solve_block``, ``vector``, ``local``).

    Parameters
    ----------
    K, M, C
        The whole model's matrices (M lumped; C may be None).
    K_I, C_I
        Stiffness and damping of the implicit partition
        (:func:`~railvib_hpc.model.petsc.assemble_partition`; C_I may be None). The system
        owns them from here on.
    dt
        Time step (at most the explicit part's stable step).
    comm
        MPI communicator.
    extra_gb
        Memory the caller needs besides the factor (the rail columns) [GB], or a function
        of the implicit rows (all ranks) that gives it: the rail columns stand on those
        rows only (:class:`~.integrate.RailColumns`).
    pml
        The perfectly matched layers (:class:`~.pml.PmlLayer`, or None; the system owns
        it): see :meth:`history_rhs`.
    """

    def __init__(self, K, M, C, K_I, C_I, dt: float, comm,
                 extra_gb: float | Callable[[int], float] = 0.0, pml=None):
        from petsc4py import PETSc

        from ..model.factor import ShiftInvertFactor

        super().__init__(K, M, C, dt, comm)
        # (not through ExplicitSystem's dashpots: here M_e1 is implicit, in K_eff)
        self.pml = pml
        self.K_I, self.C_I = K_I, C_I
        self.scheme = scheme = GeneralizedAlpha.newmark(dt)
        b, g = scheme.beta, scheme.gamma
        t0 = time.perf_counter()
        self.h_implicit = K_I.duplicate(copy=True)
        if C_I is not None:
            self.h_implicit.axpy(g / (b * dt), C_I,
                                 structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        self._c_mass = 1.0 / (b * dt * dt)
        #: This rank's rows that an implicit element touches; K_eff is diagonal elsewhere
        #: (``c_mass m``) and couples them to nothing, so only they are factored.
        self.implicit = implicit_rows(self.h_implicit)
        self.implicit_rows = comm.allreduce(int(self.implicit.sum()))
        self._diagonal = self._c_mass * self.m
        if pml is not None:
            # the layers' M_e1, trapezoidal like C_I, and M_e2, implicit like K_I (so
            # it does not shorten the step): in K_eff
            self._diagonal = self._diagonal + (g / (b * dt)) * pml.damping_diagonal \
                + pml.average_diagonal
        self.op = self.k_implicit = None
        if self.implicit_rows:
            full = with_diagonal(self.h_implicit, self._diagonal, comm)
            rows = PETSc.IS().createGeneral(
                (self.r0 + np.flatnonzero(self.implicit)).astype(PETSc.IntType), comm=comm)
            self.k_implicit = full.createSubMatrix(rows, rows)
            self.k_implicit.setOption(PETSc.Mat.Option.SYMMETRIC, True)
            full.destroy()
            rows.destroy()
        self.time_setup = time.perf_counter() - t0
        self.time_pml = 0.0
        if self.k_implicit is not None:
            if callable(extra_gb):
                extra_gb = extra_gb(self.implicit_rows)
            self.op = ShiftInvertFactor(self.k_implicit, self.k_implicit, 0.0, comm, PREFIX,
                                        extra_gb=extra_gb)
            self.time_factorization = self.op.time_factorization
            self.factor_memory_gb = self.op.factor_memory_gb
            self.out_of_core = self.op.out_of_core

    # ---------------------------------------------------------------- vectors
    def vector(self, array: np.ndarray | None = None):
        """A distributed PETSc vector on ``array`` (this rank's rows; zeros if None)."""
        from petsc4py import PETSc

        if array is None:
            array = np.zeros(self.n_local)
        return PETSc.Vec().createWithArray(array, size=(self.n_local, self.n_global),
                                           comm=self.comm)

    @staticmethod
    def local(vec) -> np.ndarray:
        """The numpy view of a vector created by :meth:`vector`."""
        return vec.getArray(readonly=False)

    # ---------------------------------------------------------------- one step
    def history_rhs(self, u, v, a, out) -> None:
        """``out = m u~ / (beta dt^2) - K u~ - C v* + (K_I + gamma / (beta dt) C_I) u~
        + C_I (v* - v~)`` from the state ``u, v, a`` (PETSc vectors; see the module
        notes); once per step.

        With perfectly matched layers also ``+ (gamma / (beta dt) d + e) u~ - d v~ -
        f_pml(u~)``: their ``M_e1`` (diagonal ``d``) is implicit like ``C_I`` (in K_eff's
        diagonal: ``d v_{n+1}``), their ``M_e2`` (diagonal ``e``,
        :attr:`~.pml.PmlLayer.average_diagonal`) implicit like ``K_I`` (``e u_{n+1}``:
        it does not limit the step), the rest of their force (memory, ``-alpha M_e1``,
        the chains) explicit, at the predictor ``u~``, the displacement the explicit
        elements see (with gamma = 1/2 the predictors step as the central differences,
        :meth:`scheme_energy`: the layer advances along them as in the explicit engine).
        The memory starts at rest with the first predictor.
        """
        dt, b, g = self.dt, self.scheme.beta, self.scheme.gamma
        u_, v_, a_ = (self.local(x) for x in (u, v, a))
        u_pred = u_ + dt * v_ + (dt * dt * (0.5 - b)) * a_
        res = self._diagonal * u_pred         # (c_mass m [+ g/(b dt) d + e], formed once)
        res -= self.internal_force(u_pred, damping_velocity(v_, a_, dt))
        res += self.times(self.h_implicit, u_pred)
        if self.C_I is not None:
            # the implicit elements' damping at v~ (trapezoidal), not at v*
            res += self.times(self.C_I, (dt * g) * a_)
        if self.pml is not None:
            t0 = time.perf_counter()
            if not self.pml.started:
                self.pml.start(u_ - (b * dt * dt) * a_)
            res -= self.pml.damping_diagonal * (v_ + (dt * (1.0 - g)) * a_)
            res -= self.pml.force(u_pred, dt)
            self.time_pml += time.perf_counter() - t0
        self.local(out)[:] = res

    def end_step(self, u_new: np.ndarray) -> None:
        """Nothing to finish: the layers' memory advanced with the predictor
        (:meth:`history_rhs`)."""

    def solve(self, rhs, out) -> None:
        """``out = K_eff^-1 rhs``: the implicit rows with the factor, the rest diagonal
        (timed and counted by :meth:`solve_block`: before, both counted, and the run's
        line showed twice the solves' time)."""
        self.local(out)[:] = self.solve_block(self.local(rhs)[:, None])[:, 0]

    def solve_block(self, B: np.ndarray) -> np.ndarray:
        """``K_eff^-1 B`` for this rank's rows of a block (n_local, k)."""
        t0 = time.perf_counter()
        out = B / self._diagonal[:, None]
        if self.op is not None:
            out[self.implicit] = self.op.solve(np.ascontiguousarray(B[self.implicit]))
        self.time_solves += time.perf_counter() - t0
        self.n_solves += B.shape[1]
        return out

    # ---------------------------------------------------------------- energy
    def scheme_energy(self, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> float:
        """The discrete energy that the step conserves, from the state at ``t_n`` (this
        rank's rows; collective).

        With ``gamma = 1/2`` the predictors ``p_n = u_n - beta dt^2 a_n`` obey the central
        differences ``p_{n+1} - 2 p_n + p_{n-1} = dt^2 a_n`` (from the Newmark updates
        alone), and the step's equation is ``(m + beta dt^2 K_I) a_n + K p_n + D_n = f_n``
        with the damping force ``D_n = C_I v_n + C_E v*_n`` (:func:`damping_velocity`). So
        the step is a leapfrog with the mass ``m + beta dt^2 K_I``, and::

            E_{n+1/2} = 1/2 w^T (m + beta dt^2 K_I) w + 1/2 p_n^T K p_{n+1},
            w = (p_{n+1} - p_n) / dt = v_n + dt / 2 a_n,

        changes by ``dt (f_n - D_n)^T v_n`` in a step (``v_n`` is the mean of the two
        ``w``): constant without damping and loads, less :meth:`step_dissipation`.
        """
        dt, b = self.dt, self.scheme.beta
        w = v + (0.5 * dt) * a
        p = u - (b * dt * dt) * a
        p1 = p + dt * w
        local = 0.5 * float(w @ (self.m * w + (b * dt * dt) * self.times(self.K_I, w)))
        local += 0.5 * float(p @ self.times(self.K, p1))
        return self.comm.allreduce(local)

    def step_dissipation(self, previous: tuple[np.ndarray, np.ndarray],
                         current: tuple[np.ndarray, np.ndarray]) -> float:
        """The energy the damping forces took in the step from ``previous = (v_{n-1},
        a_{n-1})`` to ``current = (v_n, a_n)``: ``dt v_n^T (C v* + C_I (v_n - v*))``, the
        explicit elements' damping at ``v* = v_{n-1} + dt a_{n-1}`` and the implicit ones'
        at ``v_n`` (:meth:`scheme_energy`; collective)."""
        if self.C is None:
            return 0.0
        v, _ = current
        v_star = damping_velocity(previous[0], previous[1], self.dt)
        work = self._damping_work(v, v_star)
        if self.C_I is not None:
            work += self.comm.allreduce(self.dt * float(v @ self.times(self.C_I, v - v_star)))
        return work

    def destroy(self) -> None:
        if self.op is not None:
            self.op.destroy()
        for A in (self.k_implicit, self.h_implicit, self.K_I, self.C_I):
            if A is not None:
                A.destroy()
        super().destroy()


__all__ = ["AUTO_IMPLICIT_SHARE", "DAMPING_STABILITY_FACTOR", "ImexSystem", "auto_implicit_hexes",
           "damped_critical_steps", "damping_velocity", "element_allowed_steps",
           "implicit_part_names", "implicit_rows", "with_diagonal"]
