"""Result container of the reduced multibody simulation and its step-wise storage."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .coupling import RailCoupling, shape_functions


@dataclass
class PassageHistory:
    """Histories of a reduced multibody simulation (stored every ``store_every`` steps).

    Attributes
    ----------
    t
        (nt,) times [s].
    x
        (nt, n_wheels) wheel/load positions along the track [m].
    contact_force
        (nt, n_wheels) force of each wheel/load on its rail, positive downwards [N].
    penetration
        (nt, n_wheels) Hertz penetrations [m] (zeros for moving forces).
    rail_displacement
        (nt, n_wheels) rail vertical displacement under each wheel/load [m].
    q, q_dot, q_ddot
        (nt, m) modal displacements, velocities and accelerations.
    y, y_dot, y_ddot
        (nt, n_dof) vehicle DOF histories (n_dof = 0 for moving forces).
    dof_names
        Names of the vehicle DOFs.
    dt
        Integration time step [s].
    n_steps
        Number of integration steps.
    n_loss_of_contact
        Number of steps (of all ``n_steps``) at whose end at least one wheel has no contact.
    loss_of_contact_per_wheel
        (n_wheels,) the same count for each wheel.
    rail_loads
        (nt, n_r) loads on the rail DOFs (static correction only, else (nt, 0)), see
        :mod:`.static_correction`.
    """

    t: np.ndarray
    x: np.ndarray
    contact_force: np.ndarray
    penetration: np.ndarray
    rail_displacement: np.ndarray
    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray
    y: np.ndarray
    y_dot: np.ndarray
    y_ddot: np.ndarray
    dof_names: tuple[str, ...]
    dt: float
    n_steps: int
    n_loss_of_contact: int = 0
    loss_of_contact_per_wheel: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    rail_loads: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def rails_tuple(rails: RailCoupling | Sequence[RailCoupling], n: int) -> tuple:
    """One rail per wheel/load: a single rail is shared by all ``n``.

    Parameters
    ----------
    rails
        A :class:`RailCoupling` or a sequence of ``n`` of them.
    n
        Number of wheels/loads.

    Returns
    -------
    tuple
        ``n`` rails.
    """
    if isinstance(rails, RailCoupling):
        return (rails,) * n
    rails = tuple(rails)
    if len(rails) != n:
        raise ValueError(f"need one RailCoupling per wheel/load ({n}), got {len(rails)}")
    return rails


class RowEvaluator:
    """Modal rows of all wheels at all steps from precomputed shape functions (fast gathers).

    Wheels running on the same rail are evaluated together (one gather per rail
    and step, vectorised over the wheels).
    """

    def __init__(self, rails: tuple, x: np.ndarray):
        """Precompute elements and weights for positions ``x`` (n_steps + 1, n_wheels)."""
        self.rails = rails
        self.n_wheels = x.shape[1]
        groups: dict[int, list[int]] = {}
        uniq: dict[int, RailCoupling] = {}
        for j, r in enumerate(rails):
            groups.setdefault(id(r), []).append(j)
            uniq[id(r)] = r
        self.groups = []
        for key, cols in groups.items():
            rail = uniq[key]
            elem, wts, _ = shape_functions(rail.x_nodes, x[:, cols].ravel(), rail.hermite)
            shape = (x.shape[0], len(cols))
            self.groups.append((rail, np.array(cols), elem.reshape(shape),
                                wts.reshape(shape + (wts.shape[1],))))

    def rows(self, n: int) -> np.ndarray:
        """(m, n_wheels) modal rows ``psi`` of every wheel at step ``n``."""
        out = None
        for rail, cols, elem, wts in self.groups:
            e, w = elem[n], wts[n]
            if rail.hermite:
                block = (rail.phi_w[:, e] * w[:, 0] - rail.phi_r[:, e] * w[:, 1]
                         + rail.phi_w[:, e + 1] * w[:, 2] - rail.phi_r[:, e + 1] * w[:, 3])
            else:
                block = rail.phi_w[:, e] * w[:, 0] + rail.phi_w[:, e + 1] * w[:, 1]
            if len(self.groups) == 1:
                return block
            if out is None:
                out = np.empty((block.shape[0], self.n_wheels))
            out[:, cols] = block
        return out


def n_steps(t_end: float, dt: float) -> int:
    """Number of steps covering ``t_end`` (rounded up, tolerant to round-off)."""
    n = int(np.ceil(t_end / dt - 1e-9))
    if n < 1:
        raise ValueError("t_end must be positive")
    return n


def kept_steps(nt: int, store_every: int) -> np.ndarray:
    """Indices of the stored steps: every ``store_every``-th and always the last."""
    keep = np.arange(0, nt + 1, max(int(store_every), 1))
    return keep if keep[-1] == nt else np.append(keep, nt)


class Storage:
    """Preallocated histories of the kept steps (see :class:`PassageHistory`)."""

    def __init__(self, keep: np.ndarray, m: int, nw: int, nd: int, nr: int = 0):
        """Allocate for kept steps ``keep``, m modes, nw wheels, nd vehicle DOFs, nr rail DOFs."""
        self.keep = keep
        self.slot = {int(n): i for i, n in enumerate(keep)}
        nk = keep.size
        self.q, self.v, self.a = (np.empty((nk, m)) for _ in range(3))
        self.f, self.d, self.w = (np.empty((nk, nw)) for _ in range(3))
        self.y, self.yd, self.ydd = (np.zeros((nk, nd)) for _ in range(3))
        self.loads = np.zeros((nk, nr))

    def wants(self, n: int) -> bool:
        """True if step ``n`` is stored."""
        return n in self.slot

    def put(self, n, q, v, a, f, d, w, y=None, yd=None, ydd=None) -> None:
        """Store the state of step ``n`` (modal, wheel and optional vehicle quantities)."""
        i = self.slot[n]
        self.q[i], self.v[i], self.a[i] = q, v, a
        self.f[i], self.d[i], self.w[i] = f, d, w
        if y is not None:
            self.y[i], self.yd[i], self.ydd[i] = y, yd, ydd

    def put_loads(self, n: int, loads: np.ndarray) -> None:
        """Store the rail-DOF loads of step ``n`` (static correction)."""
        self.loads[self.slot[n]] = loads

    def result(self, t, x, names, dt, nt, lost) -> PassageHistory:
        """Build the result; ``lost`` is ``[any wheel, wheel 0, wheel 1, ...]`` step counts."""
        k = self.keep
        return PassageHistory(t=t[k], x=x[k], contact_force=self.f, penetration=self.d,
                         rail_displacement=self.w, q=self.q, q_dot=self.v, q_ddot=self.a,
                         y=self.y, y_dot=self.yd, y_ddot=self.ydd, dof_names=tuple(names),
                         dt=dt, n_steps=nt, n_loss_of_contact=int(lost[0]),
                         loss_of_contact_per_wheel=lost[1:].copy(), rail_loads=self.loads)
