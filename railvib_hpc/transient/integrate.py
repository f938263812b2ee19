"""The time-stepping loop of the full-order model, with prescribed loads or a vehicle.

Every step ``t_n -> t_{n+1}`` (:class:`DirectSolver`):

1. right-hand side: the history products of :class:`~.petsc.TransientSystem` plus the loads
   ``alpha_f f_n + (1 - alpha_f) f_{n+1}`` of the prescribed forces (sparse);
2. one solve with the stored factor: ``u_hat = K_eff^-1 rhs``, the response with zero
   contact force at ``t_{n+1}``;
3. with a vehicle, the contact is solved exactly: the rail displacement under wheel ``j`` is
   ``w_j = c_j . u[D_j]`` (Hermite weights ``c_j`` on its DOFs ``D_j``,
   :class:`~.rail.WheelCoupling`), and the end-of-step contact forces ``F`` (downwards on the
   rail) enter through the columns ``X = K_eff^-1 E_D`` of the rail DOFs (computed once per
   DOF, :class:`RailColumns`)::

       u_{n+1} = u_hat - (1 - alpha_f) X (c F),
       delta = delta_hat - A F,   A = (1 - alpha_f) c^T X_DD c + A_vehicle,

   with ``delta_hat = c . u_hat[D] + r(x) - B^T y_pred`` and the vehicle's own flexibility
   ``A_vehicle`` (:class:`~railvib_hpc.mbs.integrate.VehicleNewmark`, Newmark average
   acceleration, the same as the modal multibody stage). The Hertz law is solved on this
   small system by :func:`~railvib_hpc.mbs.integrate.solve_contact` (Newton, loss of contact
   exact) — one solve of the full model per step plus a few-unknown nonlinear solve;
4. velocities and accelerations from the Newmark relations.

The state (``u, v, a`` rows of this rank, vehicle, contact) is a :class:`State`; the loop
is deterministic, so a run resumed from a stored state gives the same answer.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..resources import release_memory
from .guard import sparse_dot
from .petsc import TransientSystem
from .rail import RailDofs, WheelCoupling

#: Sparse load: (global DOF numbers, values); DOFs < 0 are ignored.
SparseLoad = tuple[np.ndarray, np.ndarray]


@dataclass
class State:
    """Everything the step ``n -> n + 1`` needs (this rank's rows of u, v, a).

    ``y, y_dot, y_ddot`` (vehicle DOFs), ``penetration`` and ``force`` (contact, downwards on
    the rail) are the same on every rank; empty without a vehicle.
    """

    step: int
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    y: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y_dot: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y_ddot: np.ndarray = field(default_factory=lambda: np.zeros(0))
    penetration: np.ndarray = field(default_factory=lambda: np.zeros(0))
    force: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class StepInfo:
    """What one step produced besides the new state (for recording)."""

    wheel_dofs: np.ndarray | None = None      # (nw, 8)
    wheel_coef: np.ndarray | None = None      # (nw, 8)
    rail_displacement: np.ndarray | None = None   # (nw,) under the wheels, along the normal
    irregularity: np.ndarray | None = None    # (nw,)
    wheel_height: np.ndarray | None = None    # (nw,) B^T y


def add_sparse(target: np.ndarray, r0: int, dofs: np.ndarray, values: np.ndarray,
               weight: float = 1.0) -> None:
    """``target[d - r0] += weight * v`` for the DOFs owned here (``r0 <= d < r0 + len``)."""
    d = np.asarray(dofs).ravel()
    v = np.asarray(values, dtype=float).ravel()
    own = (d >= r0) & (d < r0 + target.size)
    if own.any():
        np.add.at(target, d[own] - r0, weight * v[own])


def gather_values(comm, local: np.ndarray, r0: int, dofs: np.ndarray) -> np.ndarray:
    """Global values at ``dofs`` (0 for -1) on every rank (one Allreduce)."""
    from mpi4py import MPI

    d = np.asarray(dofs).ravel()
    out = np.zeros(d.size)
    own = (d >= r0) & (d < r0 + local.size)
    out[own] = local[d[own] - r0]
    if comm.size > 1:
        comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    return out.reshape(np.shape(dofs))


#: Rail nodes per block of rail columns (:class:`RailColumns`): 16 nodes x 4 DOFs = 64
#: right-hand sides, one MUMPS solve of :meth:`~.petsc.TransientSystem.solve_block`.
COLUMN_BLOCK_NODES = 16


#: A block of rail columns is kept on all rows (no row index) when its support holds more
#: than this share of them: a row index and a value take 16 bytes against 8.
DENSE_SUPPORT = 0.5


class RailColumns:
    """Columns ``X[:, d] = K_eff^-1 e_d`` of the rail DOFs near the wheels (this rank's rows).

    Computed in fixed blocks: the DOFs of rail nodes ``[b B, (b + 1) B)`` of one rail
    (``B =`` :data:`COLUMN_BLOCK_NODES`), always together, in the same order, in one
    MUMPS solve. A MUMPS solve with several right-hand sides rounds each column
    differently depending on the others in the block (measured: 1e-17 relative), and the
    exact contact solve carries that round-off on into the response (5e-9 relative in the
    building's accelerations after a few steps); with fixed blocks a column is the same
    bits whenever it is computed, so a run resumed from a checkpoint (empty cache) gives
    the uninterrupted run's numbers exactly. The blocks that meet the next ``lookahead``
    rail nodes ahead of every wheel are kept while a wheel is within that window and
    freed once every wheel has passed: a few hundred columns at a time, whatever the
    length of the track.

    Each block keeps only the rows where one of its columns is nonzero (:attr:`rows`; the
    values there in :attr:`cache`): 8 bytes per row of that support and column. For the
    direct engine that is every row (``8 n_local`` bytes per column); for the IMEX engine
    only the implicit rows the rail reaches (the explicit rows of ``K_eff`` are diagonal
    and uncoupled, so their entries are exact zeros): on ``jobs/real_site.toml`` 240,789 of
    1,491,156 rows at most, where the full columns took ~2 MB per step and rank while the
    car entered (5.3 GB per rank at step 2,474, measured 2026-12-06). The values are the
    same bits: adding the zeros changed nothing.
    """

    def __init__(self, system: TransientSystem, rails: RailDofs, lookahead: int = 12,
                 block_nodes: int = COLUMN_BLOCK_NODES):
        self.system = system
        self.rails = rails
        self.lookahead = int(lookahead)
        self.block_nodes = max(1, int(block_nodes))
        #: DOF -> its column's values on its block's :attr:`rows`
        self.cache: dict[int, np.ndarray] = {}
        #: DOF -> the local rows its column's values stand on (``slice(None)``: all)
        self.rows: dict[int, np.ndarray | slice] = {}
        self.blocks: dict[tuple[int, int], np.ndarray] = {}   # (rail, block) -> its DOFs
        self.n_computed = 0
        self.time = 0.0
        self._block_of = {int(d): (r, n // self.block_nodes)
                          for r in range(rails.dofs.shape[0])
                          for n in range(rails.n_nodes) for d in rails.dofs[r, n] if d >= 0}
        self._block_key: tuple | None = None
        self._block: np.ndarray | None = None

    def _block_dofs(self, key: tuple[int, int]) -> np.ndarray:
        r, b = key
        d = self.rails.dofs[r, b * self.block_nodes:(b + 1) * self.block_nodes].ravel()
        return d[d >= 0].astype(np.int64)

    def _window(self, wheel_rail: np.ndarray, elem: np.ndarray) -> set[tuple[int, int]]:
        """The blocks that meet the look-ahead window of every wheel on the flexible rail."""
        k, bn = self.rails.n_nodes, self.block_nodes
        out: set[tuple[int, int]] = set()
        for r, e in zip(wheel_rail, elem):
            if e < 0:
                continue
            lo, hi = max(int(e) - 1, 0), min(int(e) + self.lookahead + 1, k)
            out.update((int(r), b) for b in range(lo // bn, (hi - 1) // bn + 1))
        return out

    def require(self, dofs: np.ndarray, wheel_rail: np.ndarray, elem: np.ndarray) -> None:
        """Make sure the columns of ``dofs`` exist (collective; same arguments on all ranks)."""
        need = np.unique(dofs[dofs >= 0])
        if all(int(d) in self.cache for d in need):
            return
        t0 = time.perf_counter()
        keep = self._window(wheel_rail, elem) | {self._block_of[int(d)] for d in need}
        for key in [key for key in self.blocks if key not in keep]:
            for d in self.blocks.pop(key):
                del self.cache[int(d)]
                del self.rows[int(d)]
        sys_ = self.system
        for key in sorted(keep - set(self.blocks)):
            todo = self._block_dofs(key)
            rhs = np.zeros((sys_.n_local, todo.size))
            own = (todo >= sys_.r0) & (todo < sys_.r1)
            rhs[todo[own] - sys_.r0, np.flatnonzero(own)] = 1.0
            cols = sys_.solve_block(rhs) if todo.size else rhs
            del rhs
            support = np.flatnonzero((cols != 0.0).any(axis=1))
            rows: np.ndarray | slice = support
            if support.size > DENSE_SUPPORT * sys_.n_local:      # (index + value: 16 bytes)
                rows, values = slice(None), np.ascontiguousarray(cols.T)
            else:
                values = np.ascontiguousarray(cols[support].T)
            del cols
            for j, d in enumerate(todo):
                self.cache[int(d)] = values[j]
                self.rows[int(d)] = rows
            self.blocks[key] = todo
            self.n_computed += todo.size
        # the block solve's temporaries (n_local x 64 right-hand sides and MUMPS's
        # workspace) stay in glibc's heap otherwise: measured +0.74 GB resident on a
        # 588,912-DOF jobs/real_site.toml mesh after the first block, 0 after the trim
        release_memory()
        self.time += time.perf_counter() - t0

    def apply(self, dofs: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """This rank's rows of ``sum_k X[:, dofs_k] weights_k``."""
        out = np.zeros(self.system.n_local)
        for d, w in zip(np.ravel(dofs), np.ravel(weights)):
            if d >= 0 and w != 0.0:
                out[self.rows[int(d)]] += w * self.cache[int(d)]
        return out

    def values(self, dof: int, rows: np.ndarray) -> np.ndarray:
        """``X[r0 + rows, dof]``: the column of ``dof`` at the local ``rows`` (zero off its
        support)."""
        col, support = self.cache[int(dof)], self.rows[int(dof)]
        if isinstance(support, slice):
            return col[rows]
        if not support.size:
            return np.zeros(len(rows))
        at = np.minimum(np.searchsorted(support, rows), support.size - 1)
        return np.where(support[at] == rows, col[at], 0.0)

    def block(self, dofs: np.ndarray) -> np.ndarray:
        """``X[dofs, dofs]`` (flattened ``dofs``; zero rows/columns for -1), on every rank."""
        key = tuple(np.ravel(dofs).tolist())
        if key == self._block_key:
            return self._block
        from mpi4py import MPI

        d = np.ravel(dofs)
        sys_ = self.system
        own = (d >= sys_.r0) & (d < sys_.r1)
        part = np.zeros((d.size, d.size))
        for j, dj in enumerate(d):
            if dj >= 0:
                part[own, j] = self.values(int(dj), d[own] - sys_.r0)
        comm = sys_.comm
        if comm.size > 1:
            comm.Allreduce(MPI.IN_PLACE, part, op=MPI.SUM)
        self._block_key, self._block = key, 0.5 * (part + part.T)
        return self._block


class VehicleDriver:
    """A vehicle rolling at constant speed over the full-order model's rails.

    Parameters
    ----------
    vehicle
        A :mod:`railvib_hpc.mbs` vehicle (wheelset, car, train).
    coupling
        The wheels on the rails (:class:`~.rail.WheelCoupling`).
    x
        (n_steps + 1, n_wheels) wheel positions at every step.
    irregularity
        Rail-top heights under the wheels, a function of the (n_wheels,) positions, or None.
    dt
        Time step.
    newton_tol
        Contact Newton tolerance, relative to the static Hertz penetration.
    """

    def __init__(self, vehicle, coupling: WheelCoupling, x: np.ndarray,
                 irregularity: Callable[[np.ndarray], np.ndarray] | None, dt: float,
                 newton_tol: float = 1e-10, max_iter: int = 50):
        from ..mbs.integrate import VehicleNewmark, contact_tolerance

        self.vehicle = vehicle
        self.coupling = coupling
        self.x = x
        nw = vehicle.n_wheels
        self.irregularity = irregularity or (lambda xs: np.zeros(nw))
        self.newmark = VehicleNewmark(vehicle, dt)
        self.tol = contact_tolerance(vehicle, newton_tol)
        self.max_iter = max_iter

    def heights(self, n: int) -> np.ndarray:
        return np.asarray(self.irregularity(self.x[n]), dtype=float)


class DirectSolver:
    """Step the full-order model (see the module notes).

    Parameters
    ----------
    system
        Matrices and the factored effective matrix.
    prescribed
        ``prescribed(n) -> (dofs, values)``: the prescribed load at step ``n`` (or None).
    driver
        A vehicle (or None).
    columns
        Rail columns (needed with a vehicle).
    """

    def __init__(self, system: TransientSystem,
                 prescribed: Callable[[int], SparseLoad] | None = None,
                 driver: VehicleDriver | None = None, columns: RailColumns | None = None):
        self.system = system
        self.scheme = system.scheme
        self.prescribed = prescribed
        self.driver = driver
        self.columns = columns
        if driver is not None and columns is None:
            raise ValueError("a vehicle needs the rail columns")
        self._u, self._v, self._a = (np.zeros(system.n_local) for _ in range(3))
        self._vecs = [system.vector(arr) for arr in (self._u, self._v, self._a)]
        self._rhs_arr, self._uhat_arr = np.zeros(system.n_local), np.zeros(system.n_local)
        self._rhs, self._uhat = system.vector(self._rhs_arr), system.vector(self._uhat_arr)
        self._contact_load: SparseLoad | None = None
        self.time_contact = 0.0
        #: The loads' work on this rank's rows so far, in the scheme's energy balance
        #: (:mod:`.guard`): ``f_{n+1-alpha_f}^T (u_{n+1} - u_n)`` per step, or ``dt
        #: f_{n+1}^T v_{n+1}`` for a leapfrog system (``system.LOAD_WORK = "velocity"``,
        #: the IMEX engine's)
        self.work = 0.0
        self._work_velocity = system.LOAD_WORK == "velocity"

    # ---------------------------------------------------------------- helpers
    def _prescribed(self, n: int) -> SparseLoad | None:
        return None if self.prescribed is None else self.prescribed(n)

    def contact_load(self, n: int, force: np.ndarray) -> SparseLoad:
        """Load of the contact forces ``force`` at the wheel positions of step ``n``."""
        dofs, coef, _ = self.driver.coupling.at(self.driver.x[n])
        return dofs, -coef * force[:, None]

    def start(self, state: State) -> None:
        """Set the contact load of the starting step (call before stepping)."""
        if self.driver is not None:
            self._contact_load = self.contact_load(state.step, state.force)

    # ---------------------------------------------------------------- one step
    def step(self, st: State) -> StepInfo:
        """Advance ``st`` from ``t_n`` to ``t_{n+1}`` in place; collective."""
        sys_ = self.system
        r0 = sys_.r0
        n1 = st.step + 1
        wf0, wf1 = self.scheme.load_weights()
        self._u[:], self._v[:], self._a[:] = st.u, st.v, st.a
        sys_.history_rhs(*self._vecs, self._rhs)
        rhs = self._rhs_arr
        loads = ((self._prescribed(st.step), wf0), (self._prescribed(n1), wf1),
                 (self._contact_load, wf0))
        for load, w in loads:
            if load is not None:
                add_sparse(rhs, r0, load[0], load[1], w)
        sys_.solve(self._rhs, self._uhat)
        u_new = self._uhat_arr.copy()
        info = StepInfo()
        if self.driver is not None:
            u_new = self._contact(st, n1, u_new, info)
        sys_.end_step(u_new)             # the layers' memory (petsc.TransientSystem)
        v_new, a_new = self.scheme.update(u_new, st.u, st.v, st.a)
        if self.driver is not None:                  # the contact force at t_{n+1}
            loads = (*loads, (self._contact_load, wf1))
        moved = self.scheme.dt * v_new if self._work_velocity else u_new - st.u
        self.work += sum(w * sparse_dot(load, r0, moved) for load, w in loads if w != 0.0)
        st.u[:], st.v[:], st.a[:] = u_new, v_new, a_new
        st.step = n1
        return info

    def _contact(self, st: State, n1: int, u_hat: np.ndarray, info: StepInfo) -> np.ndarray:
        from ..mbs.integrate import solve_contact

        t0 = time.perf_counter()
        drv, cols, sys_ = self.driver, self.columns, self.system
        wf1 = self.scheme.load_weights()[1]
        dofs, coef, elem = drv.coupling.at(drv.x[n1])
        cols.require(dofs, drv.coupling.wheel_rail, elem)
        xdd = cols.block(dofs)                                   # (8 nw, 8 nw)
        nw = coef.shape[0]
        flat = coef.ravel()
        g = np.zeros((nw, flat.size))                            # wheel j -> its 8 entries
        for j in range(nw):
            g[j, 8 * j:8 * j + 8] = coef[j]
        a_rail = wf1 * g @ xdd @ g.T
        u_d = gather_values(sys_.comm, u_hat, sys_.r0, dofs).ravel()
        w_hat = g @ u_d
        r = drv.heights(n1)
        veh = drv.newmark
        kh, cc = drv.vehicle.hertz_constant, drv.vehicle.contact_damping
        pred = veh.predict(st.y, st.y_dot, st.y_ddot)
        delta_hat = w_hat + r - pred.heights
        delta, force = solve_contact(delta_hat, a_rail + veh.a_veh, st.penetration, kh, cc,
                                     sys_.scheme.dt, drv.tol, drv.max_iter)
        u_new = u_hat - wf1 * cols.apply(dofs, coef * force[:, None])
        st.y, st.y_dot, st.y_ddot = veh.correct(pred, force)
        st.penetration, st.force = delta, force
        self._contact_load = (dofs, -coef * force[:, None])
        info.wheel_dofs, info.wheel_coef = dofs, coef
        info.rail_displacement = w_hat - a_rail @ force
        info.irregularity = r
        info.wheel_height = veh.b.T @ st.y
        self.time_contact += time.perf_counter() - t0
        return u_new

    def destroy(self) -> None:
        for vec in (*self._vecs, self._rhs, self._uhat):
            vec.destroy()


def initial_acceleration(system: TransientSystem, state: State,
                         loads: Sequence[SparseLoad]) -> None:
    """Set ``a_0 = M^-1 (f_0 - C v_0 - K u_0)`` (skipped when the residual is zero)."""
    sys_ = system
    res = np.zeros(sys_.n_local)
    for dofs, values in loads:
        add_sparse(res, sys_.r0, dofs, values)
    tmp = [sys_.vector(np.ascontiguousarray(x)) for x in (state.u, state.v)]
    out = sys_.vector()
    for A, x in ((sys_.K, tmp[0]), (sys_.C, tmp[1])):
        if A is not None:
            A.mult(x, out)
            res -= sys_.local(out)
    norm = sys_.comm.allreduce(float(np.abs(res).max()) if res.size else 0.0, op=_max())
    if norm > 0.0:
        state.a[:] = sys_.solve_matrix(sys_.M, res[:, None])[:, 0]
    for v in (*tmp, out):
        v.destroy()


def _max():
    from mpi4py import MPI

    return MPI.MAX


__all__ = ["DirectSolver", "RailColumns", "State", "StepInfo", "VehicleDriver",
           "add_sparse", "gather_values", "initial_acceleration"]
