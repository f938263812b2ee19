"""Exact one-step propagation of damped modal oscillators under piecewise-linear forcing.

Each mode obeys ``q'' + 2 zeta omega q' + omega^2 q = Q(t)``. Over a step of
length ``dt`` with ``Q`` varying linearly from ``Q_n`` to ``Q_{n+1}``
(first-order hold) the solution is exact:

    q_{n+1} = a_qq q_n + a_qv v_n + b_q0 Q_n + b_q1 Q_{n+1}
    v_{n+1} = a_vq q_n + a_vv v_n + b_v0 Q_n + b_v1 Q_{n+1}

The coefficients come from the matrix exponential of the augmented 4x4
system ``[q, v, Q, dQ/dt]`` (batched over modes, computed once per ``dt``).
The scheme is unconditionally stable and exact for any ``omega dt`` (stiff
modes respond quasi-statically, ``q -> Q / omega^2``); its only error is the
linear interpolation of the force inside a step, O(dt^2).

Non-proportional damping (absorbing boundaries, per-material Rayleigh damping,
``modal.damping = 'full'``) couples the modes through the full modal damping
matrix ``D = Phi^T C Phi``: ``q'' + D q' + Lambda q = Q``.
:class:`CoupledPropagator` propagates it exactly in the same way, with the matrix
exponential of the (4m x 4m) augmented system: the step coefficients are (m, m)
matrices, unconditionally stable (exact) for any ``dt`` whenever ``D`` is positive
semi-definite. :func:`make_propagator` picks the diagonal or the coupled one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm


@dataclass(frozen=True)
class ModalPropagator:
    """Per-mode step coefficients (each an (m,) array) for a fixed time step.

    Attributes
    ----------
    dt
        Time step [s].
    omega, two_zeta_omega
        Natural circular frequencies and ``2 zeta omega`` (for accelerations).
    a_qq, a_qv, a_vq, a_vv
        Free-response coefficients.
    b_q0, b_q1, b_v0, b_v1
        Responses of ``q`` and ``v`` to ``Q_n`` and ``Q_{n+1}``.
    """

    dt: float
    omega: np.ndarray
    two_zeta_omega: np.ndarray
    a_qq: np.ndarray
    a_qv: np.ndarray
    a_vq: np.ndarray
    a_vv: np.ndarray
    b_q0: np.ndarray
    b_q1: np.ndarray
    b_v0: np.ndarray
    b_v1: np.ndarray

    def free(self, q: np.ndarray, v: np.ndarray, Q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Part of ``(q_{n+1}, v_{n+1})`` that does not depend on ``Q_{n+1}``."""
        return (self.a_qq * q + self.a_qv * v + self.b_q0 * Q0,
                self.a_vq * q + self.a_vv * v + self.b_v0 * Q0)

    def step(
        self, q: np.ndarray, v: np.ndarray, Q0: np.ndarray, Q1: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Propagate ``(q, v)`` over one step with modal force ramping from ``Q0`` to ``Q1``."""
        qf, vf = self.free(q, v, Q0)
        return qf + self.b_q1 * Q1, vf + self.b_v1 * Q1

    def acceleration(self, q: np.ndarray, v: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Modal acceleration ``Q - 2 zeta omega v - omega^2 q`` (exact at a step end)."""
        return Q - self.two_zeta_omega * v - self.omega**2 * q

    def q1(self, x: np.ndarray) -> np.ndarray:
        """Response of ``q_{n+1}`` to ``Q_{n+1} = x`` ((m,) or columns (m, k))."""
        return self.b_q1[:, None] * x if np.ndim(x) == 2 else self.b_q1 * x

    def v1(self, x: np.ndarray) -> np.ndarray:
        """Response of ``v_{n+1}`` to ``Q_{n+1} = x`` ((m,) or columns (m, k))."""
        return self.b_v1[:, None] * x if np.ndim(x) == 2 else self.b_v1 * x


def modal_propagator(omega: np.ndarray, zeta: float | np.ndarray, dt: float) -> ModalPropagator:
    """Build the exact first-order-hold propagator for all modes at once.

    Parameters
    ----------
    omega
        (m,) natural circular frequencies [rad/s], >= 0.
    zeta
        Modal damping ratio(s), scalar or (m,).
    dt
        Time step [s].

    Returns
    -------
    ModalPropagator
        Step coefficients.
    """
    om = np.asarray(omega, dtype=float)
    if om.ndim != 1 or np.any(om < 0.0):
        raise ValueError("omega must be a 1-D array of non-negative frequencies")
    if dt <= 0.0:
        raise ValueError("dt must be positive")
    tzo = 2.0 * np.broadcast_to(np.asarray(zeta, dtype=float), om.shape) * om
    a = np.zeros((om.size, 4, 4))
    a[:, 0, 1] = 1.0
    a[:, 1, 0] = -(om**2)
    a[:, 1, 1] = -tzo
    a[:, 1, 2] = 1.0
    a[:, 2, 3] = 1.0
    e = expm(a * dt)
    # Q(t) = Q0 + (Q1 - Q0) t / dt: state (Q, dQ/dt) = (Q0, (Q1 - Q0) / dt)
    return ModalPropagator(
        dt=float(dt), omega=om, two_zeta_omega=tzo,
        a_qq=e[:, 0, 0].copy(), a_qv=e[:, 0, 1].copy(),
        a_vq=e[:, 1, 0].copy(), a_vv=e[:, 1, 1].copy(),
        b_q0=e[:, 0, 2] - e[:, 0, 3] / dt, b_q1=e[:, 0, 3] / dt,
        b_v0=e[:, 1, 2] - e[:, 1, 3] / dt, b_v1=e[:, 1, 3] / dt,
    )


@dataclass(frozen=True)
class CoupledPropagator:
    """Exact first-order-hold step of ``q'' + D q' + diag(omega^2) q = Q`` with full ``D``.

    Same interface as :class:`ModalPropagator`; every coefficient is an (m, m) matrix.

    Attributes
    ----------
    dt
        Time step [s].
    omega
        (m,) natural circular frequencies.
    damping
        (m, m) modal damping matrix ``D = Phi^T C Phi``.
    a_qq, a_qv, a_vq, a_vv, b_q0, b_q1, b_v0, b_v1
        (m, m) step matrices.
    """

    dt: float
    omega: np.ndarray
    damping: np.ndarray
    a_qq: np.ndarray
    a_qv: np.ndarray
    a_vq: np.ndarray
    a_vv: np.ndarray
    b_q0: np.ndarray
    b_q1: np.ndarray
    b_v0: np.ndarray
    b_v1: np.ndarray

    def free(self, q: np.ndarray, v: np.ndarray, Q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Part of ``(q_{n+1}, v_{n+1})`` that does not depend on ``Q_{n+1}``."""
        return (self.a_qq @ q + self.a_qv @ v + self.b_q0 @ Q0,
                self.a_vq @ q + self.a_vv @ v + self.b_v0 @ Q0)

    def step(
        self, q: np.ndarray, v: np.ndarray, Q0: np.ndarray, Q1: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Propagate ``(q, v)`` over one step with modal force ramping from ``Q0`` to ``Q1``."""
        qf, vf = self.free(q, v, Q0)
        return qf + self.b_q1 @ Q1, vf + self.b_v1 @ Q1

    def acceleration(self, q: np.ndarray, v: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Modal acceleration ``Q - D v - omega^2 q``."""
        return Q - self.damping @ v - self.omega**2 * q

    def q1(self, x: np.ndarray) -> np.ndarray:
        """Response of ``q_{n+1}`` to ``Q_{n+1} = x`` ((m,) or columns (m, k))."""
        return self.b_q1 @ x

    def v1(self, x: np.ndarray) -> np.ndarray:
        """Response of ``v_{n+1}`` to ``Q_{n+1} = x`` ((m,) or columns (m, k))."""
        return self.b_v1 @ x


def coupled_propagator(omega: np.ndarray, damping: np.ndarray, dt: float) -> CoupledPropagator:
    """Build the exact propagator of the modal equations with a full damping matrix.

    Parameters
    ----------
    omega
        (m,) natural circular frequencies [rad/s], >= 0.
    damping
        (m, m) symmetric positive semi-definite modal damping matrix ``Phi^T C Phi``
        [1/s] (its diagonal is ``2 zeta_i omega_i``).
    dt
        Time step [s].

    Returns
    -------
    CoupledPropagator
        Step matrices from ``expm`` of the (4m x 4m) augmented system
        ``[q, v, Q, dQ/dt]``.
    """
    om = np.asarray(omega, dtype=float)
    d = np.asarray(damping, dtype=float)
    m = om.size
    if om.ndim != 1 or np.any(om < 0.0):
        raise ValueError("omega must be a 1-D array of non-negative frequencies")
    if d.shape != (m, m):
        raise ValueError(f"damping matrix must be ({m}, {m}), got {d.shape}")
    if dt <= 0.0:
        raise ValueError("dt must be positive")
    eye = np.eye(m)
    a = np.zeros((4 * m, 4 * m))
    a[:m, m:2 * m] = eye
    a[m:2 * m, :m] = -np.diag(om**2)
    a[m:2 * m, m:2 * m] = -d
    a[m:2 * m, 2 * m:3 * m] = eye
    a[2 * m:3 * m, 3 * m:] = eye
    e = expm(a * dt)
    blk = [slice(k * m, (k + 1) * m) for k in range(4)]

    def part(i: int, j: int) -> np.ndarray:
        return np.ascontiguousarray(e[blk[i], blk[j]])

    return CoupledPropagator(
        dt=float(dt), omega=om, damping=d,
        a_qq=part(0, 0), a_qv=part(0, 1), a_vq=part(1, 0), a_vv=part(1, 1),
        b_q0=part(0, 2) - part(0, 3) / dt, b_q1=part(0, 3) / dt,
        b_v0=part(1, 2) - part(1, 3) / dt, b_v1=part(1, 3) / dt,
    )


def make_propagator(omega: np.ndarray, damping: float | np.ndarray, dt: float
                    ) -> ModalPropagator | CoupledPropagator:
    """The propagator for modal damping ratios (scalar or (m,): uncoupled, exact per mode)
    or for a full (m, m) modal damping matrix ``Phi^T C Phi`` (coupled)."""
    if np.ndim(damping) == 2:
        return coupled_propagator(omega, damping, dt)
    return modal_propagator(omega, damping, dt)
