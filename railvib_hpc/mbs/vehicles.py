"""Vehicle models for the reduced multibody simulation and their static equilibrium.

:class:`SuspendedWheelset` is the thesis's suspended wheelset (SAMS, Table II):
a rigid wheelset with bounce ``z`` (up positive, measured from the position of
zero penetration on the undeformed rail), roll ``theta`` (positive raises the
wheel at ``+contact_span/2``) and lateral displacement ``y`` (global +y).
Wheel 0 runs on rail 0 (the rail at negative global y) at lateral position
``+contact_span/2`` of the roll arm, wheel 1 on rail 1. A primary suspension
(spring + damper per side, at ``+-suspension_span/2``, plus a lateral spring
and damper) connects it to a frame that moves at constant height, lateral
position and speed; the frame may push down with a static ``preload`` per side
(the share of car body weight; 0 in the thesis, whose wheel load 7.69 kN is
half the wheelset weight 1568 kg * 9.80665 m/s^2, standard gravity).

Lateral motion couples through the coned treads (linearised contact
geometry, conicity ``lambda``): the contact normal of each wheel leans towards
the track centre, ``n = (0, +-lambda, 1)``. A lateral shift ``y`` of the wheelset
towards rail 1 lowers the contact point of the wheel on rail 1 by ``lambda y``
(larger rolling radius) and raises the other, so the wheel heights are
``B^T y`` with the lateral row ``(+lambda, -lambda)``; the normal forces push the
wheelset laterally with ``lambda (F_0 - F_1)`` and push the rails outwards
(:func:`railvib_hpc.mbs.coupling.contact_normal_rail` mixes the rails' lateral
modal rows into the contact rows accordingly). Lateral creep forces and flange
contact are not modelled.

Reading of the partly garbled Table II (documented choice): mass 1568 kg,
roll inertia Ixx = 656 kg m^2, suspension stiffness 25,000 N/m and damping
1,000 N s/m per side. Iyy = 168 and Izz = 13,500 kg m^2 belong to pitch and yaw,
which do not couple to the normal contact forces here. The table gives no
lateral suspension: the defaults use the vertical values (25 kN/m, 1 kN s/m)
and the UIC tread inclination 1:40 (conicity 0.025).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..constants import STANDARD_GRAVITY
from .contact import hertz_force, hertz_penetration, jenkins_hertz_constant


@runtime_checkable
class Vehicle(Protocol):
    """What the integrators (:mod:`.integrate`) need from a vehicle: the plug-in point for
    new vehicle models.

    A vehicle is linear between its wheels: constant mass, damping and stiffness matrices
    in its ``n_dof`` generalised coordinates, and a contact matrix ``B`` that maps the
    ``n_wheels`` normal contact forces to generalised forces. :class:`SuspendedWheelset`,
    :class:`~railvib_hpc.mbs.train.RailVehicle` and :class:`~railvib_hpc.mbs.train.Train`
    implement it; ``isinstance(obj, Vehicle)`` checks the members' presence.

    Attributes
    ----------
    n_dof, n_wheels
        Numbers of generalised coordinates and of wheels.
    dof_names
        (n_dof,) names of the coordinates (stored in ``mbs.h5``).
    wheel_rail
        (n_wheels,) rail of each wheel: 0 at negative global y, 1 at positive.
    wheel_offsets
        (n_wheels,) x of each wheel relative to the leading wheel [m] (<= 0).
    conicity
        Equivalent conicity of the treads: the contact normals lean by it towards the
        track centre (0 for vertical-only models).
    contact_damping
        Hertz contact damping [N s/m^2].
    hertz_constant
        Hertz constant K_H [N/m^1.5] (the same for every wheel).
    """

    n_dof: int
    n_wheels: int
    dof_names: tuple[str, ...]
    wheel_rail: Sequence[int] | np.ndarray
    wheel_offsets: Sequence[float] | np.ndarray
    conicity: float
    contact_damping: float

    @property
    def hertz_constant(self) -> float: ...

    def mass_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) mass matrix."""

    def stiffness_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) suspension stiffness matrix."""

    def damping_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) suspension damping matrix."""

    def contact_matrix(self) -> np.ndarray:
        """(n_dof, n_wheels) matrix B: generalised force ``B @ F`` of the wheel forces F."""

    def external_force(self) -> np.ndarray:
        """(n_dof,) constant generalised force (gravity, preload)."""

    def static_wheel_loads(self) -> np.ndarray:
        """(n_wheels,) wheel loads on a rigid, level rail [N]."""

    def energy(self, y: np.ndarray, y_dot: np.ndarray) -> np.ndarray:
        """Kinetic + suspension + potential energy [J] of states (..., n_dof)."""


def missing_members(obj: object) -> list[str]:
    """The members of the :class:`Vehicle` protocol that ``obj`` lacks (sorted)."""
    members = set(Vehicle.__annotations__) | {
        n for n, v in vars(Vehicle).items() if not n.startswith("_")
        and (callable(v) or isinstance(v, property))}
    return sorted(m for m in members if not hasattr(obj, m))


class LinearVehicle:
    """Shared methods of vehicles with constant mass, damping and stiffness matrices."""

    def energy(self, y: np.ndarray, y_dot: np.ndarray) -> np.ndarray:
        """Kinetic + suspension + gravity/preload potential energy.

        Parameters
        ----------
        y, y_dot
            (..., n_dof) displacements and velocities.

        Returns
        -------
        numpy.ndarray
            (...) energy [J] (zero at ``y = 0``, ``y_dot = 0``).
        """
        m, k = self.mass_matrix(), self.stiffness_matrix()
        return (0.5 * np.einsum("...i,ij,...j->...", y_dot, m, y_dot)
                + 0.5 * np.einsum("...i,ij,...j->...", y, k, y) - y @ self.external_force())


@dataclass(frozen=True)
class SuspendedWheelset(LinearVehicle):
    """Rigid wheelset with bounce and roll on a primary suspension.

    Parameters
    ----------
    mass
        Wheelset mass [kg].
    roll_inertia
        Moment of inertia about the track axis [kg m^2].
    wheel_radius
        Rolling radius [m] (Jenkins' Hertz constant unless ``k_hertz`` is given).
    contact_span
        Lateral distance between the two wheel-rail contact points [m].
    suspension_span
        Lateral distance between the two primary suspensions [m].
    k_suspension, c_suspension
        Primary suspension stiffness [N/m] and damping [N s/m] per side.
    preload
        Static downward force of the frame on each side [N].
    contact_damping
        Hertz contact damping ``C`` [N s/m^2] (see :mod:`.contact`).
    gravity
        Gravitational acceleration [m/s^2] (standard gravity by default).
    k_hertz
        Hertz constant [N/m^1.5]; None for Jenkins' formula.
    k_lateral, c_lateral
        Lateral suspension stiffness [N/m] and damping [N s/m] (total).
    conicity
        Equivalent conicity ``lambda`` of the treads (0: no lateral coupling).
    """

    mass: float = 1568.0
    roll_inertia: float = 656.0
    wheel_radius: float = 0.46
    contact_span: float = 1.5
    suspension_span: float = 2.0
    k_suspension: float = 25_000.0
    c_suspension: float = 1_000.0
    preload: float = 0.0
    contact_damping: float = 0.0
    gravity: float = STANDARD_GRAVITY
    k_hertz: float | None = None
    k_lateral: float = 25_000.0
    c_lateral: float = 1_000.0
    conicity: float = 0.025

    n_dof = 3
    n_wheels = 2
    dof_names = ("z", "roll", "y")
    wheel_rail = (0, 1)
    wheel_offsets = (0.0, 0.0)

    @property
    def hertz_constant(self) -> float:
        """Hertz constant ``K_H`` used at both wheels [N/m^1.5]."""
        return self.k_hertz if self.k_hertz is not None else jenkins_hertz_constant(
            self.wheel_radius)

    def mass_matrix(self) -> np.ndarray:
        """(3, 3) mass matrix of ``(z, theta, y)``."""
        return np.diag([self.mass, self.roll_inertia, self.mass])

    def _suspension_matrix(self, k: float, k_lat: float) -> np.ndarray:
        s = 0.5 * self.suspension_span
        return np.diag([2.0 * k, 2.0 * k * s * s, k_lat])

    def stiffness_matrix(self) -> np.ndarray:
        """(3, 3) suspension stiffness matrix."""
        return self._suspension_matrix(self.k_suspension, self.k_lateral)

    def damping_matrix(self) -> np.ndarray:
        """(3, 3) suspension damping matrix."""
        return self._suspension_matrix(self.c_suspension, self.c_lateral)

    def contact_matrix(self) -> np.ndarray:
        """(3, n_wheels) matrix B: generalised force ``B @ F`` of the wheels' normal forces F.

        Its transpose maps ``(z, theta, y)`` to the wheel heights ``B.T @ y``.
        """
        b, lam = 0.5 * self.contact_span, self.conicity
        return np.array([[1.0, 1.0], [b, -b], [lam, -lam]])

    def external_force(self) -> np.ndarray:
        """(3,) constant generalised force: gravity and suspension preload."""
        return np.array([-self.mass * self.gravity - 2.0 * self.preload, 0.0, 0.0])

    def static_wheel_loads(self) -> np.ndarray:
        """(2,) wheel loads on a rigid, level rail [N]."""
        return np.full(2, 0.5 * (self.mass * self.gravity + 2.0 * self.preload))


def static_equilibrium(
    vehicle: Vehicle, flexibility: np.ndarray, rail_height: np.ndarray,
    tol: float = 1e-12, max_iter: int = 50,
) -> tuple[np.ndarray, np.ndarray]:
    """Static equilibrium of the vehicle on a (flexible) rail.

    Solves ``K_v y = f_ext + B F`` with ``F = K_H delta^1.5``,
    ``delta = rail_height - C F - B^T y`` by Newton's method.

    Parameters
    ----------
    vehicle
        The vehicle.
    flexibility
        (n_wheels, n_wheels) static rail flexibility ``C`` at the contact points:
        ``C_jk = sum_m psi_j psi_k / omega^2`` (zeros on a rigid rail).
    rail_height
        (n_wheels,) undeformed rail top heights (irregularity) under the wheels [m].
    tol
        Relative tolerance on the wheel forces.
    max_iter
        Maximum Newton iterations.

    Returns
    -------
    y
        (n_dof,) vehicle displacements.
    forces
        (n_wheels,) contact forces (upward on the wheels) [N].
    """
    kh = vehicle.hertz_constant
    kv, b, f0 = vehicle.stiffness_matrix(), vehicle.contact_matrix(), vehicle.external_force()
    cf = np.asarray(flexibility, dtype=float)
    r = np.asarray(rail_height, dtype=float)
    nd, nw = b.shape
    forces = np.linalg.lstsq(b, -f0, rcond=None)[0]
    delta = hertz_penetration(forces, kh)
    y = np.linalg.lstsq(b.T, r - cf @ forces - delta, rcond=None)[0]
    scale = float(np.max(np.abs(forces))) or 1.0
    for _ in range(max_iter):
        delta = r - cf @ forces - b.T @ y
        dh = 1.5 * kh * np.sqrt(np.maximum(delta, 0.0))
        res = np.concatenate([kv @ y - f0 - b @ forces, forces - hertz_force(delta, kh)])
        jac = np.block([[kv, -b], [dh[:, None] * b.T, np.eye(nw) + dh[:, None] * cf]])
        step = np.linalg.solve(jac, -res)
        y, forces = y + step[:nd], forces + step[nd:]
        y_scale = float(np.max(np.abs(y))) or 1.0
        if (np.max(np.abs(step[nd:])) <= tol * scale
                and np.max(np.abs(step[:nd])) <= tol * y_scale):
            return y, forces
    raise RuntimeError("static equilibrium of the vehicle did not converge")
