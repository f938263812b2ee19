"""Time integration of a load or vehicle rolling over a rail described by modes.

Track: modal coordinates ``q`` (m,) with ``q'' + 2 zeta omega q' + omega^2 q = Q``
where ``Q = sum_j Q_j`` and each wheel/load j adds ``-F_j psi_j(x_j)`` (forces
F are positive *downwards on the rail*, i.e. upward on the wheel).

Method (per step ``t_n -> t_{n+1}``):

* modes: exact propagation with the modal force linear inside the step
  (:mod:`.propagator`), unconditionally stable and exact for any ``omega dt``;
* vehicle: Newmark average acceleration (trapezoidal rule, energy
  conserving for the linear suspension);
* contact: both are linear in the end-of-step forces ``F_{n+1}``, so the
  penetrations are ``delta = delta_hat - A F`` with a small (n_wheels x
  n_wheels) flexibility ``A`` (rail: ``psi^T diag(b_q1) psi``; vehicle:
  ``dt^2/4 B^T S^-1 B``). The Hertz law ``F = h(delta)`` is then solved by
  Newton's method on ``delta`` from the upper bound ``delta_hat``, which
  converges monotonically for a single contact (``h`` is convex). Loss of
  contact is exact (``F = 0`` whenever ``delta_hat <= 0``). The contact
  damping uses ``delta_dot = (delta_{n+1} - delta_n) / dt`` (first order;
  zero damping by default).

The whole scheme is second order in ``dt``. Cost per step is O(m * n_wheels)
numpy work, no loop over modes.

Automatic time step (:func:`auto_time_step`): ``points_per_period`` (20)
steps per period of the fastest of (a) the highest mode and (b) the
linearised Hertz contact resonance of a wheel against the rail,
``omega_c^2 = k_lin (1/m_wheel + max_node sum_m phi_w^2)`` with ``k_lin`` the
Hertz tangent stiffness at twice the static wheel load and ``m_wheel`` the
wheel's effective vehicle mass (``1/m = (B^T M^-1 B)_jj``). Using all modes in
the rail receptance is conservative (modes stiffer than the step respond
quasi-statically in the exact propagator). For a moving vehicle the step is
also limited to ``2 * points_per_period`` steps per passage of the shortest rail
element (the contact flexibility varies along each element and, with the
static correction, sharply near the pads: on the thesis track this rule sets
dt = 1e-4 s and keeps the peak contact force within 0.6 % of the dt/2 result).
Pass ``dt`` to override.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from ..errors import ContactNewtonError, DivergenceError
from .contact import hertz_energy, hertz_linear_stiffness
from .coupling import RailCoupling
from .propagator import CoupledPropagator, ModalPropagator, make_propagator
from .results import PassageHistory, RowEvaluator, Storage, kept_steps, n_steps, rails_tuple
from .static_correction import ContactResidual
from .vehicles import Vehicle, missing_members, static_equilibrium

Irregularity = Callable[[np.ndarray], np.ndarray]


def auto_time_step(
    omega: np.ndarray, rails: Sequence[RailCoupling] = (),
    vehicle: Vehicle | None = None, points_per_period: int = 20,
    speed: float = 0.0,
) -> float:
    """Automatic time step (see the module notes).

    Parameters
    ----------
    omega
        (m,) natural circular frequencies [rad/s].
    rails
        Rails in contact with the vehicle (for the rail receptance).
    vehicle
        The vehicle, or None for moving forces (modal criterion only).
    points_per_period
        Steps per period of the fastest relevant oscillation.
    speed
        Vehicle speed [m/s] (0: no element-passage limit).

    Returns
    -------
    float
        Time step [s].
    """
    w_max = float(np.max(omega)) if np.size(omega) else 0.0
    if vehicle is not None:
        k_lin = hertz_linear_stiffness(2.0 * float(np.max(vehicle.static_wheel_loads())),
                                       vehicle.hertz_constant)
        b = vehicle.contact_matrix()
        inv_m = float(np.max(np.diag(b.T @ np.linalg.solve(vehicle.mass_matrix(), b))))
        inv_rail = max((float(np.max(np.sum(r.phi_w**2, axis=0))) for r in rails), default=0.0)
        w_max = max(w_max, np.sqrt(k_lin * (inv_m + inv_rail)))
    if w_max <= 0.0:
        raise ValueError("cannot choose a time step: no frequency scale; pass dt")
    dt = 2.0 * np.pi / w_max / points_per_period
    if vehicle is not None and speed > 0.0 and rails:
        h_min = min(float(np.min(np.diff(r.x_nodes))) for r in rails)
        dt = min(dt, h_min / speed / (2 * points_per_period))
    return dt


def simulate_moving_force(
    omega: np.ndarray, zeta: float | np.ndarray, rails: RailCoupling | Sequence[RailCoupling],
    loads: float | np.ndarray, x0: float | np.ndarray, speed: float, t_end: float,
    dt: float | None = None, store_every: int = 1, residual: np.ndarray | None = None,
    load_rail: Sequence[int] | None = None,
) -> PassageHistory:
    """Constant vertical forces moving at constant speed over the rail(s), track at rest at t=0.

    Parameters
    ----------
    omega
        (m,) natural circular frequencies [rad/s].
    zeta
        Modal damping ratio(s).
    rails
        One :class:`RailCoupling` for all loads, or one per load.
    loads
        Scalar or (n,) forces, positive downwards [N].
    x0
        Scalar or (n,) positions at t = 0 [m].
    speed
        Speed [m/s], or (n,) velocities along x (negative towards -x).
    t_end
        Simulated time [s] (rounded up to whole steps).
    dt
        Time step; default :func:`auto_time_step` (20 steps per period of the highest mode).
    store_every
        Keep every ``store_every``-th step (the last step is always kept).
    residual
        (n_r, n_r) residual flexibility for the static correction (rails indexed by
        ``load_rail``; ``rails`` must then be the sequence of distinct rails).
    load_rail
        (n,) rail index of each load (static correction only; default all on rail 0).

    Returns
    -------
    PassageHistory
        Histories; ``contact_force`` holds the constant loads.
    """
    p = np.atleast_1d(np.asarray(loads, dtype=float))
    x0a = np.broadcast_to(np.asarray(x0, dtype=float), p.shape)
    rl = rails_tuple(rails, p.size) if residual is None else None
    dt = float(dt) if dt is not None else auto_time_step(omega)
    prop = make_propagator(omega, zeta, dt)
    nt = n_steps(t_end, dt)
    t = np.arange(nt + 1) * dt
    x = x0a[None, :] + np.broadcast_to(np.asarray(speed, dtype=float), p.shape)[None, :] \
        * t[:, None]
    res = None
    if residual is not None:
        lr = np.zeros(p.size, int) if load_rail is None else np.asarray(load_rail, int)
        distinct = (rails,) if isinstance(rails, RailCoupling) else tuple(rails)
        res = ContactResidual(residual, distinct, lr, x)
        rl = tuple(distinct[i] for i in lr)
    rows = RowEvaluator(rl, x)
    m = prop.omega.size
    keep = kept_steps(nt, store_every)
    out = Storage(keep, m, p.size, 0, res.n_dofs if res is not None else 0)
    q, v = np.zeros(m), np.zeros(m)

    def put(n):
        w = psi.T @ q
        if res is not None:
            w = w - res.matrix(n) @ p
            out.put_loads(n, res.loads(n, p))
        out.put(n, q, v, prop.acceleration(q, v, Q), p, np.zeros(p.size), w)

    psi = rows.rows(0)
    Q = -psi @ p
    put(0)
    for n in range(1, nt + 1):
        psi = rows.rows(n)
        Q1 = -psi @ p
        q, v = prop.step(q, v, Q, Q1)
        Q = Q1
        if out.wants(n):
            put(n)
    return out.result(t, x, (), dt, nt, np.zeros(p.size + 1, int))


def hertz_force_and_slope(d: float, d_old: float, kh: float, c: float, dt: float
                          ) -> tuple[float, float]:
    """Hertz force and its derivative w.r.t. the penetration (contact damping included)."""
    if d <= 0.0:
        return 0.0, 0.0
    s = math.sqrt(d)
    f = kh * d * s + c * d * (d - d_old) / dt
    if f <= 0.0:
        return 0.0, 0.0
    return f, 1.5 * kh * s + c * (2.0 * d - d_old) / dt


#: Relative floor of the contact Newton's convergence test: the correction of a
#: penetration ``d`` cannot fall below the round-off of ``d`` itself (a few eps of it; 16
#: eps leaves room for the residual's sums). It matters only far above the absolute
#: tolerance (``1e-10`` of the static penetration, :func:`contact_tolerance`), at a
#: penetration ~3e4 times the static one; there the iteration stalled at 1.9e-14 m against
#: 2e-15 m.
NEWTON_ROUNDOFF = 16 * np.finfo(float).eps


def solve_contact(
    delta_hat: np.ndarray, a: np.ndarray, delta_old: np.ndarray, kh: float, c: float,
    dt: float, tol: float, max_iter: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``delta = delta_hat - A h(delta)`` for the Hertz law h; return (delta, F).

    ``delta_hat`` (n_wheels,) are the penetrations at zero contact force and ``A``
    (n_wheels, n_wheels) the flexibility of the penetrations to the end-of-step
    forces (rail plus vehicle); the modal MBS and the full-order solver
    (:mod:`railvib_hpc.transient`) both reduce their implicit step to this. Newton's
    method on ``delta`` from ``delta_hat``. One or two wheels: plain Python floats
    (faster than numpy calls for 2x2); more wheels: vectorised.

    Raises
    ------
    ContactNewtonError
        When the correction is still above ``tol`` after ``max_iter`` iterations (a run
        that is not a result: exit code 3).
    """
    if delta_hat.size > 2:
        return _solve_contact_many(delta_hat, a, delta_old, kh, c, dt, tol, max_iter)
    dhat = delta_hat.tolist()
    if max(dhat) <= 0.0:
        return delta_hat.copy(), np.zeros_like(delta_hat)
    nw = len(dhat)
    am = a.tolist()
    dold = delta_old.tolist()
    d = list(dhat)
    for _ in range(max_iter):
        fd = [hertz_force_and_slope(d[i], dold[i], kh, c, dt) for i in range(nw)]
        g = [d[i] + sum(am[i][k] * fd[k][0] for k in range(nw)) - dhat[i] for i in range(nw)]
        jac = [[(i == k) + am[i][k] * fd[k][1] for k in range(nw)] for i in range(nw)]
        if nw == 1:
            step = [g[0] / jac[0][0]]
        else:
            det = jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0]
            step = [(jac[1][1] * g[0] - jac[0][1] * g[1]) / det,
                    (jac[0][0] * g[1] - jac[1][0] * g[0]) / det]
        d = [d[i] - step[i] for i in range(nw)]
        largest = max(abs(x) for x in step)
        if largest <= tol or largest <= tol + NEWTON_ROUNDOFF * max(abs(x) for x in d):
            f = [hertz_force_and_slope(d[i], dold[i], kh, c, dt)[0] for i in range(nw)]
            return np.array(d), np.array(f)
    raise ContactNewtonError(max_iter, largest, tol)


def _hertz_vector(d: np.ndarray, d_old: np.ndarray, kh: float, c: float, dt: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`hertz_force_and_slope`."""
    dp = np.maximum(d, 0.0)
    s = np.sqrt(dp)
    f = kh * dp * s + c * dp * (d - d_old) / dt
    df = 1.5 * kh * s + c * np.where(d > 0.0, 2.0 * d - d_old, 0.0) / dt
    on = (d > 0.0) & (f > 0.0)
    return np.where(on, f, 0.0), np.where(on, df, 0.0)


def _solve_contact_many(delta_hat, a, delta_old, kh, c, dt, tol, max_iter):
    """Vectorised Newton for many wheels (wheels with ``delta_hat <= 0`` stay free)."""
    if delta_hat.max() <= 0.0:
        return delta_hat.copy(), np.zeros_like(delta_hat)
    d = delta_hat.copy()
    eye = np.eye(d.size)
    for _ in range(max_iter):
        f, df = _hertz_vector(d, delta_old, kh, c, dt)
        step = np.linalg.solve(eye + a * df[None, :], d + a @ f - delta_hat)
        d -= step
        largest = float(np.abs(step).max())
        if largest <= tol or largest <= tol + NEWTON_ROUNDOFF * np.abs(d).max():
            return d, _hertz_vector(d, delta_old, kh, c, dt)[0]
    raise ContactNewtonError(max_iter, largest, tol)


class VehiclePrediction(NamedTuple):
    """Predictor of one vehicle step (Newmark average acceleration)."""

    y: np.ndarray
    y_dot: np.ndarray
    a0: np.ndarray
    heights: np.ndarray


class VehicleNewmark:
    """Newmark average-acceleration step of a linear vehicle loaded by contact forces.

    ``M y'' + C y' + K y = f_0 + B F`` is linear in the end-of-step contact forces
    ``F``: :meth:`predict` gives everything at ``F = 0`` (and the wheel heights
    ``B^T y``), ``a_veh`` is the flexibility ``dt^2/4 B^T S^-1 B`` of the heights to ``F``
    (``S = M + dt/2 C + dt^2/4 K``), and :meth:`correct` completes the step once ``F``
    is known. Shared by the modal MBS and the full-order solver.
    """

    def __init__(self, vehicle, dt: float):
        self.dt = float(dt)
        self.mv, self.cv = vehicle.mass_matrix(), vehicle.damping_matrix()
        self.kv = vehicle.stiffness_matrix()
        self.b, self.f0 = vehicle.contact_matrix(), vehicle.external_force()
        self.s_inv = np.linalg.inv(self.mv + 0.5 * dt * self.cv + 0.25 * dt * dt * self.kv)
        self.a_veh = 0.25 * dt * dt * self.b.T @ self.s_inv @ self.b

    def predict(self, y: np.ndarray, yd: np.ndarray, ydd: np.ndarray) -> VehiclePrediction:
        """State at the step end for zero contact force, and its wheel heights."""
        dt = self.dt
        y_p = y + dt * yd + 0.25 * dt * dt * ydd
        yd_p = yd + 0.5 * dt * ydd
        a0 = self.s_inv @ (self.f0 - self.cv @ yd_p - self.kv @ y_p)
        return VehiclePrediction(y_p, yd_p, a0, self.b.T @ (y_p + 0.25 * dt * dt * a0))

    def correct(self, pred: VehiclePrediction, f: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(y, y_dot, y_ddot)`` at the step end with contact forces ``f``."""
        dt = self.dt
        ydd = pred.a0 + self.s_inv @ (self.b @ f)
        return pred.y + 0.25 * dt * dt * ydd, pred.y_dot + 0.5 * dt * ydd, ydd

    def acceleration(self, y: np.ndarray, yd: np.ndarray, f: np.ndarray) -> np.ndarray:
        """``y''`` from the equations of motion with contact forces ``f``."""
        return np.linalg.solve(self.mv, self.f0 + self.b @ f - self.cv @ yd - self.kv @ y)


def contact_tolerance(vehicle, newton_tol: float = 1e-10) -> float:
    """Absolute Newton tolerance: ``newton_tol`` times the largest static Hertz penetration."""
    kh = vehicle.hertz_constant
    return newton_tol * float(np.max((vehicle.static_wheel_loads() / kh) ** (2.0 / 3.0)))


def wheel_rails(rails: RailCoupling | Sequence[RailCoupling], vehicle) -> tuple:
    """One rail per wheel: a shared rail, one per wheel, or one per ``vehicle.wheel_rail`` index.

    Parameters
    ----------
    rails
        A :class:`RailCoupling`, ``n_wheels`` of them, or the rails indexed by
        ``vehicle.wheel_rail``.
    vehicle
        The vehicle (``n_wheels``; optional ``wheel_rail``).

    Returns
    -------
    tuple
        ``n_wheels`` rails.
    """
    nw = vehicle.n_wheels
    if isinstance(rails, RailCoupling):
        return (rails,) * nw
    rails = tuple(rails)
    wr = vehicle.wheel_rail
    if len(rails) != nw and len(rails) > int(np.max(wr)):
        return tuple(rails[int(r)] for r in wr)
    return rails_tuple(rails, nw)


def simulate_vehicle(
    omega: np.ndarray, zeta: float | np.ndarray, rails: RailCoupling | Sequence[RailCoupling],
    vehicle: Vehicle, x0: float, speed: float, t_end: float,
    dt: float | None = None, irregularity: Irregularity | None = None,
    initial_state: tuple[np.ndarray, ...] | None = None, store_every: int = 1,
    points_per_period: int = 20, newton_tol: float = 1e-10, max_iter: int = 50,
    residual: np.ndarray | None = None, progress: Callable[[int, int], None] | None = None,
    drop_height: float = 0.0,
) -> PassageHistory:
    """A vehicle (wheelset, car, train) rolling at constant speed over the modal rail(s).

    Parameters
    ----------
    omega
        (m,) natural circular frequencies [rad/s].
    zeta
        Modal damping ratio(s): scalar or (m,).
    rails
        One :class:`RailCoupling` shared by all wheels, one per wheel, or the
        rails indexed by ``vehicle.wheel_rail`` (wheel 0 of a wheelset at
        ``+contact_span/2`` on rail 0).
    vehicle
        Any :class:`~railvib_hpc.mbs.vehicles.Vehicle` (wheelset, car, train):
        mass/damping/stiffness/contact matrices, external force, Hertz data,
        ``wheel_offsets`` (n_wheels,) along x relative to ``x0`` and ``wheel_rail``
        (n_wheels,) rail indices.
    x0
        Position of the reference (leading) wheel at t = 0 [m] (e.g. on the rigid
        rail before the flexible part).
    speed
        Speed [m/s] (0 for a standing vehicle), or (n_wheels,) velocities along x (trains
        on two tracks, :class:`~railvib_hpc.mbs.train.Traffic`: negative towards -x).
    t_end
        Simulated time [s] (rounded up to whole steps).
    dt
        Time step; default :func:`auto_time_step`.
    irregularity
        Function of the (n_wheels,) wheel positions returning the (n_wheels,)
        heights of the undeformed rail tops [m] (positive up; wheel flats
        included); None for smooth rails.
    initial_state
        ``(q, q_dot, y, y_dot)``; default: static equilibrium at ``x0``
        (vehicle at rest on the statically deflected rail, no drop impact), or the
        drop of ``drop_height``.
    store_every
        Keep every ``store_every``-th step (the last step is always kept).
    points_per_period
        Resolution of the automatic time step.
    newton_tol
        Contact Newton tolerance, relative to the static Hertz penetration.
    max_iter
        Maximum Newton iterations per step.
    residual
        (n_r, n_r) residual flexibility of the rail DOFs for the static
        correction (:mod:`.static_correction`), rails indexed like
        ``vehicle.wheel_rail``; None for a pure modal rail.
    progress
        Called as ``progress(step, n_steps)`` about every 2 % of the run.
    drop_height
        > 0 (and no ``initial_state``): the vehicle is dropped. At t = 0 the track is
        at rest and undeformed and the vehicle at rest in the position of
        :func:`drop_state`: its static equilibrium on a rigid rail lifted rigidly so that
        every wheel is at least ``drop_height`` above the rail top [m].

    Returns
    -------
    PassageHistory
        Histories (``rail_loads`` holds the rail-DOF loads when ``residual`` is given).
    """
    if drop_height < 0.0:
        raise ValueError(f"drop_height must be >= 0, got {drop_height!r}")
    if not isinstance(vehicle, Vehicle):
        raise TypeError(f"{type(vehicle).__name__} is not a railvib_hpc.mbs.Vehicle: it lacks "
                        + ", ".join(missing_members(vehicle)))
    run = _prepare_run(omega, zeta, rails, vehicle, x0, speed, t_end, dt, irregularity,
                       points_per_period, newton_tol, residual)
    start = _initial_state(run, vehicle, initial_state, drop_height)
    out = Storage(kept_steps(run.nt, store_every), run.omega.size, vehicle.n_wheels,
                  vehicle.n_dof, run.res.n_dofs if run.res is not None else 0)
    lost = _march(run, vehicle, start, out, max_iter, progress)
    return out.result(run.t, run.x, vehicle.dof_names, run.dt, run.nt, lost)


class _VehicleRun(NamedTuple):
    """The fixed data of one :func:`simulate_vehicle` run."""

    omega: np.ndarray                 # (m,) circular frequencies [rad/s]
    dt: float                         # time step [s]
    nt: int                           # number of steps
    t: np.ndarray                     # (nt + 1,) times [s]
    x: np.ndarray                     # (nt + 1, n_wheels) wheel positions [m]
    prop: ModalPropagator | CoupledPropagator
    rows: RowEvaluator                # the wheels' modal rows at every step
    res: ContactResidual | None       # the static correction (None: pure modal rail)
    irr: Irregularity                 # rail-top heights under the wheels
    veh: VehicleNewmark               # the vehicle's Newmark step
    tol: float                        # absolute contact Newton tolerance [m]


class _VehicleState(NamedTuple):
    """Track, vehicle and contact state at one step (and the rows it was computed with)."""

    q: np.ndarray                     # (m,) modal coordinates
    v: np.ndarray                     # (m,) their velocities
    y: np.ndarray                     # (n_dof,) vehicle displacements
    yd: np.ndarray                    # (n_dof,) and velocities
    ydd: np.ndarray                   # (n_dof,) and accelerations
    f: np.ndarray                     # (n_wheels,) contact forces [N]
    delta: np.ndarray                 # (n_wheels,) penetrations [m]
    Q: np.ndarray                     # (m,) modal loads
    psi: np.ndarray                   # (m, n_wheels) modal rows under the wheels
    c_res: np.ndarray | float         # residual flexibility at the wheels (0.0 without)


def _prepare_run(omega, zeta, rails, vehicle, x0, speed, t_end, dt, irregularity,
                 points_per_period, newton_tol, residual) -> _VehicleRun:
    """Rails per wheel, time step and grid, wheel positions, modal propagator, static
    correction and Newmark step of a :func:`simulate_vehicle` run (same arguments)."""
    rl = wheel_rails(rails, vehicle)
    om = np.asarray(omega, dtype=float)
    wheel_speed = np.broadcast_to(np.asarray(speed, dtype=float), (vehicle.n_wheels,))
    if dt is None:
        dt = auto_time_step(om, rl, vehicle, points_per_period, float(np.max(abs(wheel_speed))))
    dt = float(dt)
    prop = make_propagator(om, zeta, dt)
    nt = n_steps(t_end, dt)
    t = np.arange(nt + 1) * dt
    nw = vehicle.n_wheels
    offsets = np.asarray(vehicle.wheel_offsets, dtype=float)
    x = float(x0) + offsets[None, :] + wheel_speed[None, :] * t[:, None]
    rows = RowEvaluator(rl, x)
    res = None
    if residual is not None:
        wr = np.asarray(vehicle.wheel_rail)
        uniq = tuple(rails) if not isinstance(rails, RailCoupling) else (rails,)
        res = ContactResidual(residual, uniq if len(uniq) > 1 else rl, wr, x)
    irr = (lambda xs: np.zeros(nw)) if irregularity is None else irregularity
    veh = VehicleNewmark(vehicle, dt)
    return _VehicleRun(om, dt, nt, t, x, prop, rows, res, irr, veh,
                       contact_tolerance(vehicle, newton_tol))


def _initial_state(run: _VehicleRun, vehicle: Vehicle,
                   initial_state: tuple[np.ndarray, ...] | None,
                   drop_height: float) -> _VehicleState:
    """The state at t = 0: ``initial_state``, the drop of ``drop_height``
    (:func:`drop_state`) or the static equilibrium on the modal rail, with the contact
    forces, penetrations and modal loads that go with it."""
    om, res, veh = run.omega, run.res, run.veh
    kh = vehicle.hertz_constant
    psi = run.rows.rows(0)
    c_res = res.matrix(0) if res is not None else 0.0
    r = np.asarray(run.irr(run.x[0]), dtype=float)
    if initial_state is None and drop_height > 0.0:
        initial_state = (np.zeros(om.size), np.zeros(om.size),
                         drop_state(vehicle, drop_height, r), np.zeros(vehicle.n_dof))
    if initial_state is None:
        if np.any(om <= 0.0):
            raise ValueError("static initial state needs omega > 0; pass initial_state")
        flex = psi.T @ (psi / om[:, None] ** 2) + c_res
        y, f = static_equilibrium(vehicle, flex, r)
        q, v = -(psi @ f) / om**2, np.zeros(om.size)
        yd = np.zeros(vehicle.n_dof)
    else:
        q, v, y, yd = (np.array(s, dtype=float) for s in initial_state)
        f = None
    delta = psi.T @ q + r - veh.b.T @ y
    if f is None:
        f = np.maximum(kh * np.maximum(delta, 0.0) ** 1.5, 0.0)
    if res is not None:
        delta = delta - c_res @ f
    ydd = veh.acceleration(y, yd, f)
    return _VehicleState(q, v, y, yd, ydd, f, delta, -psi @ f, psi, c_res)


def _store(out: Storage, run: _VehicleRun, n: int, s: _VehicleState) -> None:
    """Step ``n``'s state into ``out`` (the rail under the wheels, the rail-DOF loads)."""
    w = s.psi.T @ s.q
    if run.res is not None:
        w = w - s.c_res @ s.f
    out.put(n, s.q, s.v, run.prop.acceleration(s.q, s.v, s.Q), s.f, s.delta, w, s.y, s.yd,
            s.ydd)
    if run.res is not None:
        out.put_loads(n, run.res.loads(n, s.f))


def _march(run: _VehicleRun, vehicle: Vehicle, start: _VehicleState, out: Storage,
           max_iter: int, progress: Callable[[int, int], None] | None) -> np.ndarray:
    """Steps 1 .. nt from ``start``, the kept ones stored in ``out`` (with step 0).

    Returns
    -------
    numpy.ndarray
        (n_wheels + 1,) steps without contact: at any wheel, then per wheel.
    """
    prop, rows, res, irr, veh = run.prop, run.rows, run.res, run.irr, run.veh
    dt, nt, x, tol = run.dt, run.nt, run.x, run.tol
    kh, cc = vehicle.hertz_constant, vehicle.contact_damping
    q, v, y, yd, ydd, f, delta, Q, psi, c_res = start
    _store(out, run, 0, start)
    lost = np.zeros(vehicle.n_wheels + 1, int)
    every = max(nt // 50, 1)
    for n in range(1, nt + 1):
        qf, vf = prop.free(q, v, Q)
        psi = rows.rows(n)
        bpsi = prop.q1(psi)
        r = np.asarray(irr(x[n]), dtype=float)
        pred = veh.predict(y, yd, ydd)
        delta_hat = psi.T @ qf + r - pred.heights
        a_mat = psi.T @ bpsi + veh.a_veh
        if res is not None:
            c_res = res.matrix(n)
            a_mat = a_mat + c_res
        try:
            delta, f = solve_contact(delta_hat, a_mat, delta, kh, cc, dt, tol, max_iter)
        except ContactNewtonError as exc:
            raise DivergenceError(
                f"the modal passage failed at t = {n * dt:.4f} s (leading wheel at x = "
                f"{float(np.max(x[n])):.2f} m): {exc}; "
                "likely cause: a step too large for the Hertz contact's stiffness; change: "
                "more mbs.points_per_period or a smaller mbs.dt; nothing was written as a "
                "result") from exc
        Q = -psi @ f
        q = qf + prop.q1(Q)
        v = vf + prop.v1(Q)
        y, yd, ydd = veh.correct(pred, f)
        no_contact = f <= 0.0
        lost[0] += bool(no_contact.any())
        lost[1:] += no_contact
        if out.wants(n):
            _store(out, run, n, _VehicleState(q, v, y, yd, ydd, f, delta, Q, psi, c_res))
        if progress is not None and (n % every == 0 or n == nt):
            progress(n, nt)
    return lost


def rigid_lift(vehicle) -> np.ndarray:
    """(n_dof,) displacement that translates every body of ``vehicle`` 1 m upwards.

    The vertical DOFs are those named ``z`` or ``*.z`` (:attr:`dof_names`); the wheel
    heights ``B^T u`` of the result are all 1 (checked).
    """
    names = vehicle.dof_names
    u = np.array([1.0 if (n == "z" or n.endswith(".z")) else 0.0 for n in names])
    heights = vehicle.contact_matrix().T @ u
    if not np.allclose(heights, 1.0, rtol=0.0, atol=1e-12):
        raise ValueError("the vehicle's vertical DOFs do not translate all its wheels")
    return u


def drop_state(vehicle, drop_height: float, rail_height: np.ndarray | None = None
               ) -> np.ndarray:
    """Vehicle position of a drop from ``drop_height`` [m] (at rest, track undeformed).

    The static equilibrium on a rigid rail (``rail_height`` under the wheels, zeros by
    default) lifted rigidly by ``drop_height`` plus the largest static Hertz
    penetration: the suspension keeps its static deflection, the most loaded wheel
    hangs ``drop_height`` above the rail and no wheel touches it. The vehicle then
    falls freely until the first contact (the thesis's "dropped from a small distance").

    Returns
    -------
    numpy.ndarray
        (n_dof,) displacements.
    """
    nw = vehicle.n_wheels
    r = np.zeros(nw) if rail_height is None else np.asarray(rail_height, dtype=float)
    y, _ = static_equilibrium(vehicle, np.zeros((nw, nw)), r)
    gap = vehicle.contact_matrix().T @ y - r                   # -penetration (<= 0)
    return y + (drop_height - float(np.min(gap))) * rigid_lift(vehicle)


def simulate_wheelset(
    omega: np.ndarray, zeta: float | np.ndarray, rails: RailCoupling | Sequence[RailCoupling],
    vehicle: Vehicle, x0: float, speed: float, t_end: float, **kwargs,
) -> PassageHistory:
    """The suspended wheelset rolling over the rails: :func:`simulate_vehicle` (same arguments)."""
    return simulate_vehicle(omega, zeta, rails, vehicle, x0, speed, t_end, **kwargs)


def coupled_energy(
    result: PassageHistory, omega: np.ndarray, vehicle: Vehicle
) -> np.ndarray:
    """Total mechanical energy of track + vehicle + Hertz springs at every stored step.

    Conserved by the continuous system only without damping and at zero speed
    (a moving frame does work). Zero at rest on the undeformed rail.

    Parameters
    ----------
    result
        Output of :func:`simulate_wheelset`.
    omega
        (m,) natural circular frequencies [rad/s].
    vehicle
        The vehicle used.

    Returns
    -------
    numpy.ndarray
        (nt,) energy [J].
    """
    om = np.asarray(omega, dtype=float)
    track = 0.5 * np.sum(result.q_dot**2 + (om * result.q) ** 2, axis=1)
    contact = np.sum(hertz_energy(result.penetration, vehicle.hertz_constant), axis=1)
    return track + vehicle.energy(result.y, result.y_dot) + contact


__all__ = [
    "PassageHistory",
    "VehicleNewmark",
    "auto_time_step",
    "contact_tolerance",
    "coupled_energy",
    "drop_state",
    "rigid_lift",
    "simulate_moving_force",
    "simulate_vehicle",
    "simulate_wheelset",
    "solve_contact",
    "wheel_rails",
]
