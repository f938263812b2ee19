"""Generalized-alpha time integration of ``M u'' + C u' + K u = f`` (pure numpy coefficients).

Chung & Hulbert (1993), parametrised by the spectral radius at infinite frequency
``rho_inf`` in [0, 1] (the parametrisation of PETSc's ``TSALPHA2``)::

    alpha_m = (2 rho_inf - 1) / (rho_inf + 1),   alpha_f = rho_inf / (rho_inf + 1),
    gamma = 1/2 - alpha_m + alpha_f,              beta = (1 - alpha_m + alpha_f)^2 / 4,

with the Newmark updates

    u_{n+1} = u_n + dt v_n + dt^2 ((1/2 - beta) a_n + beta a_{n+1}),
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})

and equilibrium at the intermediate times, ``x_{n+1-alpha} = (1 - alpha) x_{n+1} + alpha x_n``:

    M a_{n+1-alpha_m} + C v_{n+1-alpha_f} + K u_{n+1-alpha_f} = f_{n+1-alpha_f}.

``rho_inf = 1`` (``alpha_m = alpha_f = 1/2``, ``gamma = 1/2``, ``beta = 1/4``) is the
Newmark average-acceleration (trapezoidal) rule: unconditionally stable, second order,
no numerical damping, and it conserves the discrete energy
``1/2 v^T M v + 1/2 u^T K u`` exactly (less the dashpot work ``dt vbar^T C vbar``).
``rho_inf < 1`` damps the highest frequencies while staying second order.

Solving for ``u_{n+1}`` gives the effective matrix ``K_eff = c_m M + c_c C + c_k K``
(constant for a constant step: factored once) and a right-hand side that is linear in
``(u_n, v_n, a_n)`` (:meth:`GeneralizedAlpha.history`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GeneralizedAlpha:
    """Coefficients of the generalized-alpha scheme for one time step.

    Attributes
    ----------
    dt
        Time step [s].
    rho_inf
        Spectral radius at infinite frequency.
    alpha_m, alpha_f, gamma, beta
        Scheme parameters (see the module notes).
    """

    dt: float
    rho_inf: float
    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float

    @classmethod
    def from_radius(cls, dt: float, rho_inf: float = 1.0) -> GeneralizedAlpha:
        """The second-order scheme with spectral radius ``rho_inf`` at infinite frequency.

        >>> s = GeneralizedAlpha.from_radius(1e-3, 1.0)
        >>> (s.alpha_m, s.alpha_f, s.gamma, s.beta)
        (0.5, 0.5, 0.5, 0.25)
        """
        if not dt > 0.0:
            raise ValueError(f"dt must be positive, got {dt}")
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"rho_inf must lie in [0, 1], got {rho_inf}")
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        gamma = 0.5 - am + af
        beta = 0.25 * (1.0 - am + af) ** 2
        return cls(float(dt), float(rho_inf), am, af, gamma, beta)

    @classmethod
    def newmark(cls, dt: float) -> GeneralizedAlpha:
        """The Newmark average-acceleration (trapezoidal) rule itself, ``alpha_m = alpha_f =
        0``, ``gamma = 1/2``, ``beta = 1/4``: equilibrium at ``t_{n+1}`` (the implicit part
        of the IMEX engine, :mod:`.imex`; second order, no numerical damping).

        >>> s = GeneralizedAlpha.newmark(1e-3)
        >>> (s.alpha_m, s.alpha_f, s.gamma, s.beta, s.load_weights())
        (0.0, 0.0, 0.5, 0.25, (0.0, 1.0))
        """
        if not dt > 0.0:
            raise ValueError(f"dt must be positive, got {dt}")
        return cls(float(dt), 1.0, 0.0, 0.0, 0.5, 0.25)

    # ---------------------------------------------------------------- effective matrix
    @property
    def c_mass(self) -> float:
        """Coefficient of M in ``K_eff``: ``(1 - alpha_m) / (beta dt^2)``."""
        return (1.0 - self.alpha_m) / (self.beta * self.dt**2)

    @property
    def c_damping(self) -> float:
        """Coefficient of C in ``K_eff``: ``(1 - alpha_f) gamma / (beta dt)``."""
        return (1.0 - self.alpha_f) * self.gamma / (self.beta * self.dt)

    @property
    def c_stiffness(self) -> float:
        """Coefficient of K in ``K_eff``: ``1 - alpha_f``."""
        return 1.0 - self.alpha_f

    # ---------------------------------------------------------------- right-hand side
    def history(self) -> dict[str, tuple[float, float, float]]:
        """Coefficients of ``(u_n, v_n, a_n)`` in the right-hand side, per matrix.

        ``K_eff u_{n+1} = f_{n+1-alpha_f} + M (m_u u + m_v v + m_a a)
        + C (c_u u + c_v v + c_a a) - alpha_f K u``; returns
        ``{"M": (m_u, m_v, m_a), "C": (c_u, c_v, c_a), "K": (-alpha_f, 0, 0)}``.
        """
        am, af, g, b, dt = self.alpha_m, self.alpha_f, self.gamma, self.beta, self.dt
        m = (self.c_mass, (1.0 - am) / (b * dt), (1.0 - am) * (0.5 / b - 1.0) - am)
        c = (self.c_damping, (1.0 - af) * (g / b - 1.0) - af, (1.0 - af) * dt * (0.5 * g / b - 1.0))
        return {"M": m, "C": c, "K": (-af, 0.0, 0.0)}

    def update(self, u_new: np.ndarray, u: np.ndarray, v: np.ndarray, a: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """``(v_{n+1}, a_{n+1})`` from the new displacement (Newmark relations)."""
        dt, b, g = self.dt, self.beta, self.gamma
        a_new = (u_new - u - dt * v) / (b * dt * dt) - (0.5 / b - 1.0) * a
        v_new = v + dt * ((1.0 - g) * a + g * a_new)
        return v_new, a_new

    def load_weights(self) -> tuple[float, float]:
        """Weights of ``(f_n, f_{n+1})`` in ``f_{n+1-alpha_f}``."""
        return self.alpha_f, 1.0 - self.alpha_f

    # ---------------------------------------------------------------- accuracy
    def amplification(self, omega: float, zeta: float = 0.0) -> np.ndarray:
        """3 x 3 amplification matrix of ``(u, dt v, dt^2 a)`` for one oscillator.

        One step of ``u'' + 2 zeta omega u' + omega^2 u = 0`` with this scheme.
        """
        dt = self.dt
        h = self.history()
        k_eff = self.c_mass + self.c_damping * 2.0 * zeta * omega + self.c_stiffness * omega**2
        out = np.empty((3, 3))
        for j in range(3):
            state = np.zeros(3)
            state[j] = 1.0
            u, v, a = state[0], state[1] / dt, state[2] / dt**2
            rhs = (h["M"][0] * u + h["M"][1] * v + h["M"][2] * a
                   + 2.0 * zeta * omega * (h["C"][0] * u + h["C"][1] * v + h["C"][2] * a)
                   + h["K"][0] * omega**2 * u)
            u1 = rhs / k_eff
            v1, a1 = self.update(np.float64(u1), np.float64(u), np.float64(v), np.float64(a))
            out[:, j] = (u1, dt * v1, dt * dt * a1)
        return out

    def accuracy(self, frequency_hz: float) -> tuple[float, float]:
        """Relative period error and algorithmic damping ratio at ``frequency_hz``.

        From the principal eigenvalues ``exp(dt omega_h (-xi +- i))`` of the undamped
        amplification matrix: period error ``omega / omega_h - 1`` (positive: the
        numerical oscillation is slower), damping ratio ``xi``.

        >>> s = GeneralizedAlpha.from_radius(1.0 / (20 * 80.0), 1.0)
        >>> pe, xi = s.accuracy(80.0)
        >>> round(100 * pe, 2), abs(round(xi, 12))
        (0.82, 0.0)
        """
        omega = 2.0 * math.pi * frequency_hz
        lam = np.linalg.eigvals(self.amplification(omega))
        lam = lam[np.argmax(np.abs(lam.imag))]
        phase = abs(math.atan2(lam.imag, lam.real))
        if phase == 0.0:
            return math.inf, math.inf
        omega_h = phase / self.dt
        xi = -math.log(abs(lam)) / phase
        return omega / omega_h - 1.0, xi


def steps_for_band(frequency_hz: float, steps_per_period: int) -> float:
    """Largest step with ``steps_per_period`` steps per period of ``frequency_hz``."""
    return 1.0 / (steps_per_period * frequency_hz)


def choose_time_step(f_max: float, steps_per_period: int, output_dt: float = 0.0,
                     element_time: float = 0.0, steps_per_element: int = 1) -> float:
    """Automatic time step: the band, the element passage, and a divisor of ``output_dt``.

    Parameters
    ----------
    f_max
        Highest frequency of the analysis band [Hz].
    steps_per_period
        Steps per period of ``f_max``.
    output_dt
        Output interval [s]; the step divides it into whole steps (0: no constraint).
    element_time
        Time a wheel needs to cross the shortest rail element [s] (0: no vehicle).
    steps_per_element
        Steps per element crossing.

    Returns
    -------
    float
        The time step [s].

    >>> choose_time_step(80.0, 20, 1e-3, 0.12 / 30.0, 10)
    0.0003333333333333333
    >>> choose_time_step(80.0, 20, 1e-3, 0.11999999999 / 30.0, 8)   # round-off: 5e-4
    0.0005
    """
    dt = steps_for_band(f_max, steps_per_period)
    if element_time > 0.0:
        dt = min(dt, element_time / steps_per_element)
    if output_dt > 0.0:
        # tolerant to round-off in the node coordinates (0.11999999999 m elements)
        dt = output_dt / math.ceil(output_dt / dt * (1.0 - 1e-6))
    return dt


def coarse_step_warning(dt: float, f_max: float, steps_per_period: int, rho_inf: float
                        ) -> str | None:
    """A warning with the numbers when ``dt`` is too coarse for ``f_max`` (else None)."""
    limit = steps_for_band(f_max, steps_per_period)
    if dt <= limit * (1.0 + 1e-9):
        return None
    pe, xi = GeneralizedAlpha.from_radius(dt, rho_inf).accuracy(f_max)
    pe_ok, _ = GeneralizedAlpha.from_radius(limit, rho_inf).accuracy(f_max)
    per = 1.0 / (dt * f_max)
    damping = f", algorithmic damping {100 * xi:.2f} %" if rho_inf < 1.0 else ""
    return (f"warning: transient.dt = {dt:.4g} s resolves transient.f_max = {f_max:g} Hz with "
            f"{per:.1f} steps per period (period error {100 * pe:.2f} %{damping}); "
            f"{steps_per_period} steps per period need dt <= {limit:.4g} s (period error "
            f"{100 * pe_ok:.2f} %)")


__all__ = ["GeneralizedAlpha", "choose_time_step", "coarse_step_warning", "steps_for_band"]
