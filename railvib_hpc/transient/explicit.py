"""Explicit central-difference time integration with a lumped mass: O(N) memory and work per step.

The engine of ``transient.engine = "explicit"`` (docs/transient.md). With the diagonal (lumped) mass
``m`` of the model, every step ``t_n -> t_{n+1}`` is::

    u_{n+1}   = u_n + dt v_n + dt^2 / 2 a_n
    v_{n+1/2} = v_n + dt / 2 a_n
    a_{n+1}   = m^-1 (f_{n+1} - K u_{n+1} - C v_{n+1/2})
    v_{n+1}   = v_{n+1/2} + dt / 2 a_{n+1}

(Newmark beta = 0, gamma = 1/2: the central-difference method; the damping force takes the
half-step velocity, so no matrix is ever factored). A step costs two sparse products (K,
C; one with Rayleigh damping applied as an operator,
:class:`~railvib_hpc.model.petsc.RayleighOperator`) and a few vector operations, and the
memory is the matrices and a few vectors: both grow linearly with the DOFs, where the
direct path's factor grows as n^(4/3) (the fill of nested dissection on a 3-D mesh).
The scheme is second order, conserves the discrete energy of an undamped system and is
stable while ``m - dt / 2 C - dt^2 / 4 K`` is positive definite (:func:`stability_limit`):
``2 / omega_max`` undamped, with ``omega_max`` the largest natural frequency of ``K, m``;
less with damping. For one mode that is :func:`critical_step`; for damping that is not
proportional (the absorbing faces' dashpots, whose ratio ``c / m = 2 c_p / h`` at a face
node is far above that of the stiffest mode) the limit is found on the whole ``K, C, m``.

A vehicle is coupled explicitly too: its linear equations (mass, damping, stiffness
matrices of :class:`~railvib_hpc.mbs.integrate.VehicleNewmark`) take the same
central-difference step, and the Hertz contact force at ``t_{n+1}`` follows from the
penetration of the predicted rail and wheel positions (no Newton iteration: nothing at
``t_{n+1}`` depends on the force). The contact spring is part of the stability limit: its
frequency ``sqrt(k_H / m_rail)`` (linearised Hertz stiffness on the rail's nodal mass) is
checked with the model's.

Kernels work on this rank's rows as numpy arrays; PETSc does the sparse products
(:mod:`.petsc` style: the matrices are distributed AIJ).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .guard import sparse_dot
from .integrate import SparseLoad, State, StepInfo, VehicleDriver, add_sparse, gather_values

#: Options prefix of the largest-frequency eigensolve (``-railvib_cd_eps_...``).
PREFIX = "railvib_cd_"
#: Fraction of the critical step the automatic step uses, and the largest a given
#: ``transient.dt`` may reach: the largest frequency is computed to ``OMEGA_TOL`` and the
#: contact spring's is linearised, so a margin of 10 % (the usual safety factor of explicit
#: codes, e.g. LS-DYNA's TSSFAC = 0.9) covers both.
STEP_SAFETY = 0.9
#: Relative tolerance of the largest eigenvalue of ``m^-1/2 K m^-1/2`` (Krylov-Schur).
OMEGA_TOL = 1e-6
#: Iterations of the damped limit (:func:`damped_limit`) before it gives up: each solves
#: one largest eigenvalue; the thesis model and the absorbing boxes of the tests take 2-6.
DAMPED_MAX_IT = 30
#: Relative size of an off-diagonal mass entry that makes a mass matrix "not lumped".
LUMPED_TOL = 1e-12
#: Relative residual of the static start's CG solves (the direct path's factor solves to
#: ~1e-12; the static deflection enters the first contact force).
STATIC_RTOL = 1e-12
#: Iteration limit of those solves (measured with the rigid-body near null space: 75 on
#: the coarse thesis model, 108 on the refined one at 68,625 DOFs).
STATIC_MAX_IT = 2000
#: Largest model whose static start takes one MUMPS Cholesky factor of K (freed before the
#: first step; skipped as well when the memory check says it does not fit) instead of CG +
#: GAMG. Measured, one wheel's right-hand side on the refined thesis model (68,625 DOFs,
#: 1 rank): factor and solve 1.6 s; CG + GAMG with the rigid-body near null space 10.1 s
#: (108 iterations), without it 34.6 s (743); on the coarse one (18,063 DOFs) 1.1 s, 3.2 s
#: and 10.2 s. Above it the factor's memory (~n^(4/3)) and time (~n^2 in 3-D) outgrow the
#: O(N) engine's own, and CG's O(N) iterations win (a choice, not a measured crossover).
STATIC_FACTOR_MAX_DOFS = 500_000


class ExplicitEngineError(ValueError):
    """The model cannot be integrated explicitly as given (a mass that is not lumped)."""


def critical_step(omega: float, xi: float = 0.0) -> float:
    """Largest stable step of the scheme for a mode of frequency ``omega`` [rad/s] and
    damping ratio ``xi`` (the damping force at the half-step velocity).

    Bisection on the spectral radius of the one-step map of ``u'' + 2 xi omega u' + omega^2
    u = 0`` (``2 / omega`` for ``xi = 0``; damping lowers it).

    >>> round(critical_step(1000.0) * 1000.0, 6)
    2.0
    >>> critical_step(1000.0, 0.1) < critical_step(1000.0)
    True
    """
    if omega <= 0.0:
        return float("inf")

    def stable(h: float) -> bool:
        return spectral_radius(omega, xi, h) <= 1.0 + 1e-12

    lo, hi = 0.0, 2.0 / omega
    if stable(hi):
        return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def spectral_radius(omega: float, xi: float, h: float) -> float:
    """Spectral radius of the scheme's one-step map ``(u, v, a)_n -> (u, v, a)_{n+1}`` for
    one mode (see :func:`critical_step`)."""
    w2, c = omega * omega, 2.0 * xi * omega
    # u1 = u + h v + h^2/2 a; vh = v + h/2 a; a1 = -w2 u1 - c vh; v1 = vh + h/2 a1
    u1 = np.array([1.0, h, 0.5 * h * h])
    vh = np.array([0.0, 1.0, 0.5 * h])
    a1 = -w2 * u1 - c * vh
    v1 = vh + 0.5 * h * a1
    return float(np.abs(np.linalg.eigvals(np.array([u1, v1, a1]))).max())


def lumped_diagonal(M, comm) -> np.ndarray:
    """This rank's rows of the diagonal of ``M``, checked to be the whole matrix.

    The check costs two products and a few vectors (no copy of the matrix: at millions of
    DOFs a CSR copy was 1.5 GB per 0.5 M DOFs, 40 % of the explicit engine's setup peak):
    ``M x - diag(M) x`` for ``x`` = ones and a fixed pseudo-random sign vector, whose largest
    entry measures the off-diagonal mass of each row (a consistent mass, all of whose
    entries are positive, shows in the first; cancelling entries of other signs in the
    second).

    Raises
    ------
    ExplicitEngineError
        When ``M`` has off-diagonal entries above :data:`LUMPED_TOL` of its diagonal or a
        diagonal entry that is not positive.
    """
    from mpi4py import MPI

    d = M.createVecLeft()
    M.getDiagonal(d)
    diag = d.getArray().copy()
    x, y = M.createVecRight(), M.createVecLeft()
    r0 = M.getOwnershipRange()[0]
    # a sign vector that depends on the global row only (the same on any number of ranks):
    # the parity of a multiplicative hash (Knuth's 2654435761) of the row number
    rows = np.arange(r0, r0 + diag.size, dtype=np.uint64)
    signs = np.where(((rows * np.uint64(2654435761)) >> np.uint64(15)) & np.uint64(1),
                     -1.0, 1.0)
    worst = 0.0
    for probe in (np.ones(diag.size), signs):
        x.getArray()[:] = probe
        M.mult(x, y)
        off = np.abs(y.getArray() - diag * probe)
        worst = max(worst, float((off / np.maximum(np.abs(diag), 1e-300)).max(initial=0.0)))
    for vec in (d, x, y):
        vec.destroy()
    worst = comm.allreduce(worst, op=MPI.MAX)
    bad = comm.allreduce(int((diag <= 0.0).sum()), op=MPI.SUM)
    if worst > LUMPED_TOL or bad:
        raise ExplicitEngineError(
            "transient.engine = \"explicit\" needs a lumped (diagonal, positive) mass matrix: "
            f"off-diagonal mass up to {worst:.2g} x the diagonal, {bad} DOFs without mass; "
            "set modal.lumped_mass = true")
    return diag


@dataclass(frozen=True)
class StableStep:
    """The stability limit of a model (:func:`stability_limit`).

    Attributes
    ----------
    omega_max
        Largest natural frequency of ``K, m`` [rad/s].
    xi
        Damping ratio of that mode (``phi^T C phi / (2 omega phi^T m phi)``).
    dt_critical
        The critical step [s]: the largest ``dt`` with ``m - f dt / 2 C - dt^2 / 4 K``
        positive definite (``f``: the ``damping_factor`` of :func:`stability_limit`).
    limiting_dof
        Global DOF with the largest amplitude in the mode that sets ``dt_critical``
        (where the limit sits).
    iterations
        Krylov-Schur iterations the eigensolves took.
    dt_mode
        :func:`critical_step` of the largest mode alone (its own damping ratio): equal to
        ``dt_critical`` for damping proportional to that mode, larger where damping that is
        not (face dashpots, pads) lowers the limit.
    """

    omega_max: float
    xi: float
    dt_critical: float
    limiting_dof: int
    iterations: int
    dt_mode: float = float("nan")

    @property
    def dt_allowed(self) -> float:
        """The largest step allowed: :data:`STEP_SAFETY` of the critical one."""
        return STEP_SAFETY * self.dt_critical

    @property
    def damping_limited(self) -> bool:
        """Whether damping not proportional to the largest mode lowers the limit (by more
        than the eigensolves' tolerance)."""
        return bool(self.dt_critical < (1.0 - 10.0 * OMEGA_TOL) * self.dt_mode)


def stability_limit(K, m: np.ndarray, C, comm, minus: tuple | None = None,
                    damping_factor: float = 1.0) -> StableStep:
    """The critical step of ``K, C`` on the lumped mass ``m`` (collective).

    The largest frequency of ``K, m`` (SLEPc Krylov-Schur on ``m^-1/2 K m^-1/2``, to
    :data:`OMEGA_TOL`) converges in a few dozen products (it is the best separated end of
    the spectrum of a mesh); the mode localises on the elements that limit the step (the
    stiffest over the lightest: rail beams, thin slabs). With damping, the limit is the
    largest ``dt`` with ``m - f dt / 2 C - dt^2 / 4 K`` positive definite
    (:func:`damped_limit`, ``f = damping_factor``): the central differences with the
    damping at the half-step velocity are the centred scheme on the mass
    ``m - dt / 2 C``, whose energy ``1/2 w^T (m - dt / 2 C - dt^2 / 4 K) w + 1/2 ubar^T K
    ubar`` (``w = (u_{n+1} - u_n) / dt``, ``ubar`` their mean) is a norm exactly then. For
    one mode this is :func:`critical_step`; the damping ratio of the largest mode alone is
    not enough where damping is not proportional to it: on a box with absorbing faces the
    face nodes' dashpots made the step of that mode unstable from 0.55 of it.
    ``damping_factor = 2``: the damping at ``v_n + dt a_n`` (the IMEX engine's explicit
    part, :data:`~.imex.DAMPING_STABILITY_FACTOR`).

    ``minus = (K_p, C_p)``: the limit of ``K - K_p, C - C_p`` (the explicit part of the
    IMEX engine, :mod:`.imex`, whose implicit partition ``K_p, C_p`` is unconditionally
    stable; ``C_p`` may be None). ``K_p``'s pattern must be a subset of ``K``'s.
    """
    d = K.createVecLeft()
    d.getArray()[:] = 1.0 / np.sqrt(m)
    K_p, C_p = (None, None) if minus is None else minus
    # m^-1/2 (K - K_p) m^-1/2 as a shell: no copy of K (a third of the setup's peak)
    op = _ScaledCombination(d, [(K, 1.0), (K_p, -1.0)])
    lam, x, iterations = _largest_eigenpair(op, comm)
    phi = x.getArray() * d.getArray()        # the mode in displacements (x = m^1/2 phi)
    omega = float(np.sqrt(max(lam, 0.0)))
    xi, mode = 0.0, x
    dt_mode = dt_c = critical_step(omega)
    if C is not None and omega > 0.0:
        damping = _ScaledCombination(d, [(C, 1.0), (C_p, -1.0)])
        xi = max(damping.quadratic(x) / (2.0 * omega), 0.0)
        dt_mode = critical_step(omega, damping_factor * xi)
        dt_c, mode, more = damped_limit(op, damping, damping_factor, dt_mode, x, comm)
        iterations += more
        damping.release()
        phi = mode.getArray() * d.getArray()
    amp = np.abs(phi)
    r0 = K.getOwnershipRange()[0]
    local = (float(amp.max(initial=-1.0)), r0 + int(np.argmax(amp)) if amp.size else -1)
    _, dof = max(comm.allgather(local))
    op.release()
    for vec in {id(v): v for v in (d, x, mode)}.values():
        vec.destroy()
    return StableStep(omega, xi, min(dt_c, dt_mode), int(dof), int(iterations), dt_mode)


def damped_limit(stiffness, damping, factor: float, dt: float, start, comm) -> tuple:
    """The largest ``dt`` with ``I - factor dt / 2 C^ - dt^2 / 4 K^`` positive definite
    (``K^, C^``: the scaled shells of :func:`stability_limit`), from ``dt`` at or above it
    (the largest mode's :func:`critical_step`: its Rayleigh quotient reaches 1 there).

    Each iteration takes the eigenvector ``x`` of the largest eigenvalue of ``factor dt / 2
    C^ + dt^2 / 4 K^`` and moves ``dt`` to the root of its Rayleigh quotient ``factor dt /
    2 c + dt^2 / 4 k = 1``, ``c = x^T C^ x``, ``k = x^T K^ x``. That quotient is below the
    largest eigenvalue at every step (so each root is at or above the limit) and touches
    it at ``dt`` (so the step is at least Newton's, which the convexity of the largest
    eigenvalue in ``dt`` makes monotone): the steps fall to the limit from above, to
    :data:`OMEGA_TOL`. Returns ``(dt, x, iterations)``; the first eigenvalue at or below
    ``1 + OMEGA_TOL`` ends it at once (damping proportional to the largest mode).
    """
    x, iterations = start, 0
    for _ in range(DAMPED_MAX_IT):
        combined = _ScaledCombination(stiffness.d, [*((A, w * 0.25 * dt * dt)
                                                      for A, w in stiffness.terms),
                                                    *((A, w * 0.5 * factor * dt)
                                                      for A, w in damping.terms)])
        lam, y, its = _largest_eigenpair(combined, comm, start=x)
        combined.release()
        iterations += its
        if x is not start:
            x.destroy()
        x = y
        if lam <= 1.0 + OMEGA_TOL:
            return dt, x, iterations
        k, c = stiffness.quadratic(x), max(damping.quadratic(x), 0.0)
        dt = _quadratic_root(0.25 * k, 0.5 * factor * c)
    raise ExplicitEngineError(
        f"the damped stability limit did not settle in {DAMPED_MAX_IT} eigensolves "
        f"(last step {dt:.4g} s, largest eigenvalue {lam:.8g}); -{PREFIX}eps_* options tune "
        "them")


def _quadratic_root(a: float, b: float) -> float:
    """The positive root of ``a t^2 + b t = 1`` (``a, b >= 0``, not both zero), without
    cancellation.

    >>> _quadratic_root(0.25, 0.0), _quadratic_root(0.0, 0.5)
    (2.0, 2.0)
    """
    return 2.0 / (b + np.sqrt(b * b + 4.0 * a))


def _largest_eigenpair(op: _ScaledCombination, comm, start=None) -> tuple:
    """The largest eigenvalue of the symmetric shell ``op`` and its unit eigenvector (a new
    vector), with the Krylov-Schur iterations it took (options prefix :data:`PREFIX`)."""
    from petsc4py import PETSc
    from slepc4py import SLEPc

    S = PETSc.Mat().createPython(op.sizes, op, comm=comm)
    S.setUp()
    eps = SLEPc.EPS().create(comm)
    eps.setOptionsPrefix(PREFIX)
    eps.setOperators(S)
    eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.LARGEST_REAL)
    eps.setDimensions(1)
    eps.setTolerances(OMEGA_TOL, 10_000)
    if start is not None:
        eps.setInitialSpace([start])
    eps.setFromOptions()
    eps.solve()
    if eps.getConverged() < 1:
        raise ExplicitEngineError("the largest natural frequency of the model did not converge "
                                  f"in {eps.getIterationNumber()} iterations")
    x = S.createVecRight()
    lam = float(eps.getEigenpair(0, x).real)
    x.scale(1.0 / x.norm())
    iterations = eps.getIterationNumber()
    eps.destroy()
    S.destroy()
    return lam, x, iterations


class _ScaledCombination:
    """``y = d * (sum_i w_i A_i) (d * x)``: the symmetric shells of :func:`stability_limit`
    (terms whose matrix is None are left out; ``d = m^-1/2``). No matrix is copied."""

    def __init__(self, d, terms):
        self.d = d
        self.terms = [(A, float(w)) for A, w in terms if A is not None]
        A0 = self.terms[0][0]
        self.sizes = A0.getSizes()
        self.t, self.w = A0.createVecRight(), A0.createVecLeft()

    def mult(self, mat, x, y) -> None:
        self.t.pointwiseMult(x, self.d)
        y.zeroEntries()
        for A, weight in self.terms:
            A.mult(self.t, self.w)
            y.axpy(weight, self.w)
        y.pointwiseMult(y, self.d)

    def quadratic(self, x) -> float:
        """``x^T op x`` (collective)."""
        y = x.duplicate()
        self.mult(None, x, y)
        value = float(x.dot(y))
        y.destroy()
        return value

    def release(self) -> None:
        """Free the work vectors (called by :func:`stability_limit`; not the shell's
        ``destroy`` hook, which petsc4py may call during ``PetscFinalize``)."""
        self.t.destroy()
        self.w.destroy()


def contact_frequency(kh: float, static_load: float, rail_mass: float) -> float:
    """Frequency [rad/s] of the linearised Hertz spring (the tangent stiffness at the static
    wheel load, :func:`~railvib_hpc.mbs.contact.hertz_linear_stiffness`) on the rail's
    nodal mass ``rail_mass`` (the wheel, heavier, moves less: an upper bound)."""
    from ..mbs.contact import hertz_linear_stiffness

    if kh <= 0.0 or static_load <= 0.0 or rail_mass <= 0.0:
        return 0.0
    return float(np.sqrt(hertz_linear_stiffness(static_load, kh) / rail_mass))


def limiting_element(mesh, dof_index: np.ndarray, dof: int) -> str:
    """Where the stability limit sits: the part and position of the node of global ``dof``
    (``dof_index``: the DOF map's (n_nodes, n_components) table)."""
    from ..schema import PART_ID

    names = {v: k for k, v in PART_ID.items()}
    hit = np.argwhere(dof_index == dof)
    if not hit.size:
        return f"DOF {dof}"
    node = int(hit[0, 0])
    x, y, z = mesh.points[node]
    parts = [names.get(int(p), str(p)) for p in np.unique(mesh.line_part[
        (mesh.lines == node).any(axis=1)])] if len(mesh.lines) else []
    parts += [names.get(int(p), str(p)) for p in np.unique(mesh.hex_part[
        (mesh.hexes == node).any(axis=1)])]
    return (f"the {'/'.join(parts) or 'element'} elements at node {node} "
            f"(x = {x:.3f}, y = {y:.3f}, z = {z:.3f} m)")


class ExplicitSystem:
    """K, C and the lumped mass of the model for the explicit engine (collective setup).

    The counterpart of :class:`~.petsc.TransientSystem` without a factor: products with K
    and C, the mass diagonal, energies. Memory: the matrices and a few vectors, linear in
    the DOFs.

    ``dashpots``: this rank's rows of a diagonal damping taken at the full-step velocity
    ``v_{n+1}`` instead of the half step (the absorbing faces' dashpots,
    :func:`~railvib_hpc.model.boundary.dashpot_diagonal`; not in C then): the step solves
    ``(m + dt / 2 d) a_{n+1} = f - K u_{n+1} - C v_{n+1/2} - d v_{n+1/2}``, a diagonal, and
    the dashpots no longer limit it (trapezoidal on them: the leapfrog's damping force
    ``d v_n`` at the mean of the two half-step velocities dissipates at any step). Without
    it, face nodes with ``c / m = 2 c_p / h`` halve the stable step of a soil model
    (:func:`stability_limit`).

    ``pml``: the perfectly matched layers (:class:`~.pml.PmlLayer`, or None): their
    ``M_e1`` joins the full-step diagonal, and :meth:`ExplicitSolver.acceleration` adds
    their force. The energies here are those of K and m alone (a layer's energy is not
    conserved: it absorbs).
    """

    #: The loads' work in this scheme's energy balance is ``dt f_n^T v_n`` (:mod:`.guard`)
    LOAD_WORK = "velocity"
    #: The largest step the stability limit allows (set by the stage's setup; None before)
    allowed_step: float | None = None
    #: No factor: what the run statistics report of the direct path's
    time_factorization = 0.0
    factor_memory_gb = 0.0
    out_of_core = False

    def __init__(self, K, M, C, dt: float, comm, dashpots: np.ndarray | None = None,
                 pml=None):
        self.K, self.M, self.C, self.dt, self.comm = K, M, C, float(dt), comm
        self.n_global = K.getSize()[0]
        self.r0, self.r1 = K.getOwnershipRange()
        self.n_local = self.r1 - self.r0
        self.m = lumped_diagonal(M, comm)
        self.dashpots = None if dashpots is None else np.asarray(dashpots, dtype=float)
        self.pml = pml
        if pml is not None:           # the layers' M_e1 at the full step, like the dashpots
            base = np.zeros(self.n_local) if self.dashpots is None else self.dashpots
            self.dashpots = base + pml.damping_diagonal
        self._effective = None                # (dt, the divisor of accelerate)
        self._x, self._y = K.createVecRight(), K.createVecLeft()
        self._v, self._w = K.createVecRight(), K.createVecLeft()
        self.time_products = 0.0
        self.n_products = 0
        self.time_solves = 0.0
        self.n_solves = 0
        #: ``near_null() -> (n_local, k)``: the near null space of K for the static
        #: start's GAMG (the rigid-body motions,
        #: :func:`~railvib_hpc.model.dofmap.rigid_body_modes`), built only when CG runs,
        #: not held through the run (48 bytes per DOF); None: none given
        self.near_null: Callable[[], np.ndarray] | None = None
        #: How the static start was solved, with its time (None before).
        self.static_method: str | None = None

    def solve_matrix(self, A, B: np.ndarray) -> np.ndarray:
        """``A^-1 B`` for a block B of this rank's rows: ``m^-1 B`` for the mass; for K
        (the static start of a wheel on the flexible rail) one MUMPS Cholesky factor up to
        :data:`STATIC_FACTOR_MAX_DOFS` where it fits (freed at once; options prefix
        ``railvib_cd_static_st_``), else conjugate gradients with an algebraic multigrid
        preconditioner (PETSc GAMG with :attr:`near_null`, relative residual
        :data:`STATIC_RTOL`; options prefix ``railvib_cd_static_``): memory linear in the
        DOFs. :attr:`static_method` says which, with its time."""
        B = np.ascontiguousarray(B, dtype=float)
        if A is self.M:
            return B / self.m[:, None]
        t0 = time.perf_counter()
        out = self._factor_solve(A, B) if self.n_global <= STATIC_FACTOR_MAX_DOFS else None
        how = "MUMPS Cholesky of K"
        if out is None:
            out, iterations = self._cg_solve(A, B)
            how = (f"CG + GAMG, {iterations} iterations over {B.shape[1]} right-hand "
                   f"side(s)")
        elapsed = time.perf_counter() - t0
        self.static_method = f"{how}, {elapsed:.2f} s"
        self.time_solves += elapsed
        self.n_solves += B.shape[1]
        return out

    def _factor_solve(self, A, B: np.ndarray) -> np.ndarray | None:
        """``A^-1 B`` with a MUMPS Cholesky factor of A, None when it does not fit."""
        from ..model.factor import InsufficientMemory
        from .petsc import factor_solve

        try:
            return factor_solve(A, self.M, B, self.comm, PREFIX + "static_")
        except InsufficientMemory:
            return None

    def _near_null_space(self):
        """The orthonormalised :attr:`near_null` as a PETSc null space (None without)."""
        from petsc4py import PETSc

        if self.near_null is None:
            return None
        V = self.near_null()
        gram = self.comm.allreduce(V.T @ V)
        V = V @ np.linalg.inv(np.linalg.cholesky(gram)).T
        vectors = []
        for j in range(V.shape[1]):
            v = self.K.createVecLeft()
            v.getArray()[:] = V[:, j]
            vectors.append(v)
        space = PETSc.NullSpace().create(vectors=vectors, comm=self.comm)
        for v in vectors:
            v.destroy()
        return space

    def _cg_solve(self, A, B: np.ndarray) -> tuple[np.ndarray, int]:
        """``A^-1 B`` by CG + GAMG, column by column, and the iterations in all."""
        from petsc4py import PETSc

        space = self._near_null_space()
        if space is not None:
            A.setNearNullSpace(space)
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOptionsPrefix(PREFIX + "static_")
        ksp.setOperators(A)
        ksp.setType("cg")
        ksp.getPC().setType("gamg")
        ksp.setTolerances(rtol=STATIC_RTOL, max_it=STATIC_MAX_IT)
        ksp.setFromOptions()
        out = np.zeros_like(B)
        iterations = 0
        try:
            for j in range(B.shape[1]):
                self._x.getArray()[:] = B[:, j]
                ksp.solve(self._x, self._y)
                iterations += ksp.getIterationNumber()
                if ksp.getConvergedReason() <= 0:
                    raise ExplicitEngineError(
                        f"the static start did not converge: CG + GAMG stopped after "
                        f"{ksp.getIterationNumber()} iterations (reason "
                        f"{ksp.getConvergedReason()}); -{PREFIX}static_ksp_* options tune "
                        "it")
                out[:, j] = self._y.getArray()
        finally:
            ksp.destroy()
            if space is not None:
                space.destroy()              # (A keeps its own reference)
        return out, iterations

    def times(self, A, x: np.ndarray) -> np.ndarray:
        """``A x`` for this rank's rows ``x`` (a new array)."""
        t0 = time.perf_counter()
        self._x.getArray()[:] = x
        A.mult(self._x, self._y)
        out = self._y.getArray().copy()
        self.time_products += time.perf_counter() - t0
        self.n_products += 1
        return out

    def internal_force(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``K u + C v`` for this rank's rows (a new array): one product with K when C is
        Rayleigh damping applied as an operator
        (:func:`~railvib_hpc.model.petsc.stiffness_and_damping`)."""
        from ..model.petsc import stiffness_and_damping

        t0 = time.perf_counter()
        self._x.getArray()[:] = u
        self._v.getArray()[:] = v
        stiffness_and_damping(self.K, self.C, self._x, self._v, self._y, self._w)
        out = self._y.getArray().copy()
        self.time_products += time.perf_counter() - t0
        self.n_products += 1
        return out

    def accelerate(self, rhs: np.ndarray, v_half: np.ndarray) -> np.ndarray:
        """``a_{n+1}`` from ``rhs = f_{n+1} - K u_{n+1} - C v_{n+1/2}`` (changed in place):
        ``rhs / m``, or with the diagonal dashpots at ``v_{n+1} = v_{n+1/2} + dt / 2
        a_{n+1}``, ``(rhs - d v_{n+1/2}) / (m + dt / 2 d)``; with layers ``+ dt^2 / 4
        M_e2`` in the divisor (:meth:`effective_mass`)."""
        d = self.dashpots
        if d is not None:
            rhs -= d * v_half
        return rhs / self.effective_mass()

    def effective_mass(self) -> np.ndarray:
        """The diagonal that :meth:`accelerate` divides by: ``m + dt / 2 d + dt^2 / 4
        M_e2`` (the dashpots ``d`` at the full-step velocity; the layers' ``M_e2``,
        :attr:`~.pml.PmlLayer.average_diagonal`, at the average displacement ``(u_{n+1}
        + 2 u_n + u_{n-1}) / 4 = u_n + dt^2 / 4 a_n``, Newmark's beta = 1/4 on a diagonal:
        the step ``(m + dt^2 / 4 e) a_n + (K + e) u_n = f_n`` is stable while ``m +
        dt^2 / 4 e - dt^2 / 4 (K + e) = m - dt^2 / 4 K`` is positive, the elastic limit,
        so ``M_e2`` no longer shortens the step; with it explicit, the limit of ``K +
        M_e2`` was 1.65 x shorter on a box with five layers). Formed once per step size."""
        if self._effective is None or self._effective[0] != self.dt:
            out = self.m.copy()
            if self.dashpots is not None:
                out += (0.5 * self.dt) * self.dashpots
            if self.pml is not None:
                out += (0.25 * self.dt * self.dt) * self.pml.average_diagonal
            self._effective = (self.dt, out)
        return self._effective[1]

    def energy(self, u: np.ndarray, v: np.ndarray) -> float:
        """Kinetic plus strain energy ``1/2 v^T m v + 1/2 u^T K u`` (collective)."""
        local = 0.5 * float(v @ (self.m * v)) + 0.5 * float(u @ self.times(self.K, u))
        return self.comm.allreduce(local)

    def scheme_energy(self, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> float:
        """The discrete energy that the central differences conserve, from the state at
        ``t_n`` (this rank's rows; collective)::

            E_{n+1/2} = 1/2 v_{n+1/2}^T m v_{n+1/2} + 1/2 u_n^T K u_{n+1},
            v_{n+1/2} = v_n + dt / 2 a_n,   u_{n+1} = u_n + dt v_{n+1/2}.

        The scheme is the leapfrog ``m (v_{n+1/2} - v_{n-1/2}) = dt (f_n - K u_n - D_n)``,
        ``u_{n+1} - u_n = dt v_{n+1/2}``, with the damping force ``D_n = C v_{n-1/2}``, so
        ``E_{n+1/2} - E_{n-1/2} = dt (f_n - D_n)^T v_n`` exactly (``v_n`` is the mean of
        the two half-step velocities): without damping and loads it is constant to
        round-off, and the damping takes :meth:`step_dissipation`. It is positive below
        the critical step (``u_n^T K u_{n+1} = ubar^T K ubar - dt^2 / 4 v^T K v``). The
        diagonal dashpots' force is ``d v_n`` in this leapfrog.
        """
        dt = self.dt
        w = v + (0.5 * dt) * a
        u1 = u + dt * w
        local = 0.5 * float(w @ (self.m * w)) + 0.5 * float(u @ self.times(self.K, u1))
        return self.comm.allreduce(local)

    def step_dissipation(self, previous: tuple[np.ndarray, np.ndarray],
                         current: tuple[np.ndarray, np.ndarray]) -> float:
        """The energy the damping forces took in the step that led to ``current``
        (``(v_n, a_n)``; ``previous``: ``(v_{n-1}, a_{n-1})``, unused here): ``dt v_n^T C
        v_{n-1/2}`` with the half-step velocity ``v_{n-1/2} = v_n - dt / 2 a_n`` the
        damping took, so that ``E_{n+1/2} = E_{n-1/2} - step_dissipation`` without loads
        (:meth:`scheme_energy`; collective). The diagonal dashpots add ``dt v_n^T d v_n``.
        """
        v, a = current
        work = 0.0 if self.C is None else self._damping_work(v, v - (0.5 * self.dt) * a)
        if self.dashpots is not None:
            work += self.comm.allreduce(self.dt * float(v @ (self.dashpots * v)))
        return work

    def _damping_work(self, v: np.ndarray, v_damping: np.ndarray) -> float:
        """``dt v^T C v_damping`` (collective)."""
        return self.comm.allreduce(self.dt * float(v @ self.times(self.C, v_damping)))

    def destroy(self) -> None:
        for vec in (self._x, self._y, self._v, self._w):
            vec.destroy()
        if self.pml is not None:
            self.pml.destroy()


def initial_acceleration(system: ExplicitSystem, state: State,
                         loads: list[SparseLoad]) -> None:
    """``a_0 = m^-1 (f_0 - C v_0 - d v_0 - K u_0)`` (the counterpart of
    :func:`~.integrate.initial_acceleration`; the mass is diagonal, ``d`` the system's
    diagonal dashpots; with layers ``m + dt^2 / 4 M_e2``, their ``M_e2`` at the average
    displacement as in every step, :meth:`ExplicitSystem.effective_mass`)."""
    res = -system.internal_force(state.u, state.v)
    mass = system.m
    if system.pml is not None:
        res -= system.pml.start(state.u)
        mass = mass + (0.25 * system.dt * system.dt) * system.pml.average_diagonal
    if system.dashpots is not None:
        res -= system.dashpots * state.v
    for dofs, values in loads:
        add_sparse(res, system.r0, dofs, values)
    state.a[:] = res / mass


class ExplicitSolver:
    """Step the full-order model explicitly (see the module notes); the interface of
    :class:`~.integrate.DirectSolver` (``start``, ``step``, ``destroy``).

    Parameters
    ----------
    system
        The matrices and the lumped mass.
    prescribed
        ``prescribed(n) -> (dofs, values)``: the prescribed load at step ``n`` (or None).
    driver
        A vehicle (or None).
    """

    def __init__(self, system: ExplicitSystem,
                 prescribed: Callable[[int], SparseLoad] | None = None,
                 driver: VehicleDriver | None = None):
        self.system = system
        self.prescribed = prescribed
        self.driver = driver
        self.time_contact = 0.0
        self.time_pml = 0.0
        #: The loads' work on this rank's rows so far, ``sum dt f_n^T v_n``: the exact change
        #: of the discrete energy (:meth:`ExplicitSystem.scheme_energy`; :mod:`.guard`)
        self.work = 0.0
        self._loads: list[SparseLoad] = []
        if driver is not None:
            nm = driver.newmark
            self._mv_inv = np.linalg.inv(nm.mv)

    def start(self, state: State) -> None:
        """Nothing to prepare: the contact force of step ``n`` is in ``state.force``."""

    def acceleration(self, n: int, u: np.ndarray, v_half: np.ndarray,
                     contact: SparseLoad | None) -> np.ndarray:
        """``m^-1 (f_n - K u - C v_half)`` with the prescribed and contact loads of step n
        (and the diagonal dashpots at the full step, :meth:`ExplicitSystem.accelerate`)."""
        sys_ = self.system
        rhs = -sys_.internal_force(u, v_half)
        if sys_.pml is not None:
            t0 = time.perf_counter()
            rhs -= sys_.pml.force(u, sys_.dt)
            self.time_pml += time.perf_counter() - t0
        loads = ((None if self.prescribed is None else self.prescribed(n)), contact)
        self._loads = [load for load in loads if load is not None]
        for load in self._loads:
            add_sparse(rhs, sys_.r0, load[0], load[1])
        return sys_.accelerate(rhs, v_half)

    def step(self, st: State) -> StepInfo:
        """Advance ``st`` from ``t_n`` to ``t_{n+1}`` in place; collective."""
        dt = self.system.dt
        n1 = st.step + 1
        u1 = st.u + dt * st.v + (0.5 * dt * dt) * st.a
        v_half = st.v + (0.5 * dt) * st.a
        info = StepInfo()
        contact = None
        if self.driver is not None:
            contact = self._contact(st, n1, u1, info)
        a1 = self.acceleration(n1, u1, v_half, contact)
        st.u[:], st.v[:], st.a[:] = u1, v_half + (0.5 * dt) * a1, a1
        self.work += dt * sum(sparse_dot(load, self.system.r0, st.v) for load in self._loads)
        st.step = n1
        return info

    def _contact(self, st: State, n1: int, u1: np.ndarray, info: StepInfo) -> SparseLoad:
        """Predict the vehicle, evaluate the Hertz force at t_{n+1}, finish the vehicle's
        step; returns the contact load on the rail."""
        from ..mbs.integrate import hertz_force_and_slope

        t0 = time.perf_counter()
        drv, sys_, dt = self.driver, self.system, self.system.dt
        nm = drv.newmark
        y1 = st.y + dt * st.y_dot + (0.5 * dt * dt) * st.y_ddot
        yd_half = st.y_dot + (0.5 * dt) * st.y_ddot
        dofs, coef, _ = drv.coupling.at(drv.x[n1])
        w = np.einsum("ij,ij->i", coef, gather_values(sys_.comm, u1, sys_.r0, dofs))
        r = drv.heights(n1)
        heights = nm.b.T @ y1
        delta = w + r - heights
        kh, cc = drv.vehicle.hertz_constant, drv.vehicle.contact_damping
        force = np.array([hertz_force_and_slope(float(d), float(d0), kh, cc, dt)[0]
                          for d, d0 in zip(delta, st.penetration)])
        ydd = self._mv_inv @ (nm.f0 + nm.b @ force - nm.cv @ yd_half - nm.kv @ y1)
        st.y, st.y_dot, st.y_ddot = y1, yd_half + (0.5 * dt) * ydd, ydd
        st.penetration, st.force = delta, force
        info.wheel_dofs, info.wheel_coef = dofs, coef
        info.rail_displacement = w
        info.irregularity = r
        info.wheel_height = heights
        self.time_contact += time.perf_counter() - t0
        return dofs, -coef * force[:, None]

    def destroy(self) -> None:
        """Nothing to free (the system owns the matrices)."""


__all__ = ["ExplicitEngineError", "ExplicitSolver", "ExplicitSystem", "StableStep",
           "contact_frequency", "critical_step", "damped_limit", "initial_acceleration",
           "limiting_element", "lumped_diagonal", "spectral_radius", "stability_limit"]
