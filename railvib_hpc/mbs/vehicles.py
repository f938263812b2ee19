"""Vehicle models for the reduced multibody simulation and their static equilibrium.

:class:`SuspendedWheelset` is the thesis's suspended wheelset (SAMS, Table II)
reduced to its vertical plane motions: a rigid wheelset with bounce ``z`` (up
positive, measured from the position of zero penetration on the undeformed
rail) and roll ``theta`` (positive raises the wheel at ``+contact_span/2``).
Wheel 0 runs on rail 0 at lateral position ``+contact_span/2``, wheel 1 on rail
1 at ``-contact_span/2``. A primary suspension (spring + damper per side, at
``+-suspension_span/2``) connects it to a frame that moves at constant height
and speed; the frame may push down with a static ``preload`` per side (the
share of car body weight; 0 in the thesis, whose wheel load 7.69 kN is half
the wheelset weight 1568 kg * 9.81 m/s^2).

Reading of the partly garbled Table II (documented choice): mass 1568 kg,
roll inertia Ixx = 656 kg m^2, suspension stiffness 25,000 N/m and damping
1,000 N s/m per side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .contact import hertz_force, hertz_penetration, jenkins_hertz_constant


@dataclass(frozen=True)
class SuspendedWheelset:
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
        Gravitational acceleration [m/s^2].
    k_hertz
        Hertz constant [N/m^1.5]; None for Jenkins' formula.
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
    gravity: float = 9.81
    k_hertz: float | None = None

    n_dof = 2
    n_wheels = 2
    dof_names = ("z", "roll")

    @property
    def hertz_constant(self) -> float:
        """Hertz constant ``K_H`` used at both wheels [N/m^1.5]."""
        return self.k_hertz if self.k_hertz is not None else jenkins_hertz_constant(
            self.wheel_radius)

    def mass_matrix(self) -> np.ndarray:
        """(2, 2) mass matrix of ``(z, theta)``."""
        return np.diag([self.mass, self.roll_inertia])

    def _suspension_matrix(self, k: float) -> np.ndarray:
        s = 0.5 * self.suspension_span
        return np.diag([2.0 * k, 2.0 * k * s * s])

    def stiffness_matrix(self) -> np.ndarray:
        """(2, 2) suspension stiffness matrix."""
        return self._suspension_matrix(self.k_suspension)

    def damping_matrix(self) -> np.ndarray:
        """(2, 2) suspension damping matrix."""
        return self._suspension_matrix(self.c_suspension)

    def contact_matrix(self) -> np.ndarray:
        """(2, n_wheels) matrix B: generalised force ``B @ F`` of upward wheel forces F.

        Its transpose maps ``(z, theta)`` to the wheel heights ``B.T @ y``.
        """
        b = 0.5 * self.contact_span
        return np.array([[1.0, 1.0], [b, -b]])

    def external_force(self) -> np.ndarray:
        """(2,) constant generalised force: gravity and suspension preload."""
        return np.array([-self.mass * self.gravity - 2.0 * self.preload, 0.0])

    def static_wheel_loads(self) -> np.ndarray:
        """(2,) wheel loads on a rigid, level rail [N]."""
        return np.full(2, 0.5 * (self.mass * self.gravity + 2.0 * self.preload))

    def energy(self, y: np.ndarray, y_dot: np.ndarray) -> np.ndarray:
        """Kinetic + suspension + gravity/preload potential energy.

        Parameters
        ----------
        y, y_dot
            (..., 2) displacements and velocities.

        Returns
        -------
        numpy.ndarray
            (...) energy [J] (zero at ``y = 0``, ``y_dot = 0``).
        """
        m, k = self.mass_matrix(), self.stiffness_matrix()
        return (0.5 * np.einsum("...i,ij,...j->...", y_dot, m, y_dot)
                + 0.5 * np.einsum("...i,ij,...j->...", y, k, y) - y @ self.external_force())


def static_equilibrium(
    vehicle: SuspendedWheelset, flexibility: np.ndarray, rail_height: np.ndarray,
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
        (2,) vehicle displacements.
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
