"""Static correction (mode-acceleration / residual flexibility) at the wheel contacts.

A truncated modal basis misses the quasi-static response of the modes left
out. With the exact static flexibility ``X_rr = K^-1`` restricted to the rail
DOFs (vertical displacement ``w`` and rotation ``ry`` of every rail node,
computed once with the factorization of K in the modal stage), the residual
flexibility of the kept modes is

    G = X_rr - Phi_r^T diag(1 / omega^2) Phi_r,

and the rail displacement under the wheels becomes ``w = psi^T q - C F`` with
the contact residual flexibility ``C_jk = N_j^T G N_k`` (``N_j``: the Hermite
shape functions of wheel j expressed on the ``(w, ry)`` DOFs, ``dw/dx = -ry``;
``F`` positive downwards on the rail). ``C`` is symmetric positive
semi-definite, instantaneous (no mass), and simply adds to the contact
flexibility of each time step. The same rail-DOF loads ``g(t) = -sum_j N_j F_j``
rebuild the correction in the whole model: ``u = Phi (q - Lambda^-1 Phi_r^T g) +
X g`` with the static fields ``X`` (see :func:`rail_dof_loads`).

DOF ordering of ``G`` and ``g``: ``((rail * k + node) * 2 + c)`` with ``c = 0``
for ``w`` and ``c = 1`` for ``ry``; ``k`` nodes per rail, sorted along x.

Residual vectors with mass and damping (what the multibody stage uses)
---------------------------------------------------------------------
A massless, undamped residual flexibility between wheel and modal rail makes the wheel
bounce on a spring the real track damps: on the thesis track (0.5 refinement, 300 modes)
the contact force of that scheme grew to 17.6 kN against 9.7 kN of the full-order solution
(``bench/transient_vs_modal.py``). :func:`residual_modes` instead adds the residual static
fields ``X' = X - Phi Lambda^-1 Phi_r^T`` to the basis (modal truncation augmentation;
Dickens, Nakagawa & Wittbrodt 1997). They are K- and M-orthogonal to the kept modes
(``Phi^T K X = Phi_r^T`` and ``Phi^T M X = Lambda^-1 Phi_r^T`` exactly), with

    X'^T K X' = G,    X'^T M X' = X^T M X - Phi_r^T Lambda^-2 Phi_r,

(``static.h5`` stores the mass of the static fields deflated by all of the file's modes,
formed on the full vectors, :func:`kept_residual_mass` adds the modes not kept) so a small
generalised eigenproblem turns them into ``k`` mass-normalised *residual
modes* ``X' V`` with frequencies above the kept band. They carry the rail's local mass
and the same damping model as the modes (Rayleigh, uniform, or the projected ``C`` of
``modal.damping = 'full'``, :func:`residual_damping_parts`), keep the static flexibility
exact, and reuse the reconstruction of the static correction with ``g = V p``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..tolerances import EPS
from .coupling import RailCoupling, shape_functions


def rail_dof_rows(rails: Sequence[RailCoupling]) -> np.ndarray:
    """Modal rows ``Phi_r`` (m, 2 * n_rails * k) on the rail DOFs in the module's ordering.

    Parameters
    ----------
    rails
        The rails (all with rotations and the same number of nodes).

    Returns
    -------
    numpy.ndarray
        ``Phi_r`` with columns ``(rail, node, [w, ry])``.
    """
    blocks = []
    for r in rails:
        if r.phi_r is None:
            raise ValueError("the static correction needs rail rotations (Hermite coupling)")
        blocks.append(np.stack([r.phi_w, r.phi_r], axis=2).reshape(r.n_modes, -1))
    return np.concatenate(blocks, axis=1)


def residual_flexibility(x_rr: np.ndarray, rails: Sequence[RailCoupling],
                         omega: np.ndarray) -> np.ndarray:
    """``G = X_rr - Phi_r^T Lambda^-1 Phi_r`` for the kept modes.

    Parameters
    ----------
    x_rr
        (n_r, n_r) static flexibility ``K^-1`` on the rail DOFs (zero rows/columns for
        constrained DOFs).
    rails
        The rails with the kept modes' rows.
    omega
        (m,) circular frequencies of the kept modes [rad/s].

    Returns
    -------
    numpy.ndarray
        (n_r, n_r) symmetric residual flexibility.
    """
    phi = rail_dof_rows(rails)
    if x_rr.shape != (phi.shape[1], phi.shape[1]):
        raise ValueError(f"static flexibility has shape {x_rr.shape}, the rails have "
                         f"{phi.shape[1]} DOFs")
    g = x_rr - (phi / np.asarray(omega, dtype=float)[:, None] ** 2).T @ phi
    return 0.5 * (g + g.T)


#: Relative size below which a direction of the residual flexibility is round-off:
#: sqrt(eps) (see :func:`residual_modes`).
RESIDUAL_RCOND = float(np.sqrt(EPS))


@dataclass(frozen=True)
class ResidualModes:
    """Residual modes ``X' V`` of the static correction (:func:`residual_modes`).

    Attributes
    ----------
    omega
        (k,) circular frequencies [rad/s], ascending.
    vectors
        (n_r, k) ``V``: residual-mode coordinates ``p`` give the rail-DOF loads ``g = V p``
        of the reconstruction (zero rows for constrained rail DOFs).
    rows
        (n_r, k) the residual modes on the rail DOFs, ``G V``, in the module's ordering.
    """

    omega: np.ndarray
    vectors: np.ndarray
    rows: np.ndarray

    def rails(self, rails: Sequence[RailCoupling]) -> tuple[RailCoupling, ...]:
        """The rails with the residual modes' rows appended to the modes' rows."""
        k = self.omega.size
        out = []
        for r, rail in enumerate(rails):
            n = rail.x_nodes.size
            block = self.rows[2 * r * n:2 * (r + 1) * n].reshape(n, 2, k)
            out.append(RailCoupling(rail.x_nodes, np.vstack([rail.phi_w, block[:, 0].T]),
                                    np.vstack([rail.phi_r, block[:, 1].T])))
        return tuple(out)


def residual_modes(x_rr: np.ndarray, x_mass: np.ndarray, rails: Sequence[RailCoupling],
                   omega: np.ndarray) -> ResidualModes:
    """Mass-normalised residual modes of the static correction (see the module notes).

    Directions of ``G`` below ``sqrt(eps) ||G||`` (:data:`RESIDUAL_RCOND`: round-off of the
    static solve and the modes) are left out, and so is any residual mode below the kept
    band (impossible in exact arithmetic: made of the errors of the static solve and of
    the modes, in directions the kept modes already hold). Residual masses below round-off
    become modes ``1 / sqrt(eps)`` times above the band (quasi-static in the exact
    propagator), so the static flexibility stays exact.

    Parameters
    ----------
    x_rr
        (n_r, n_r) static flexibility ``K^-1`` on the rail DOFs (zero rows/columns for
        constrained DOFs).
    x_mass
        (n_r, n_r) ``X'^T M X'`` of the static fields with the kept modes taken out
        (:func:`kept_residual_mass`).
    rails
        The rails with the kept modes' rows.
    omega
        (m,) circular frequencies of the kept modes [rad/s].

    Returns
    -------
    ResidualModes
        Their frequencies, ``V`` and rail rows.

    Examples
    --------
    A two-DOF chain whose first mode is kept: the one residual mode is the second mode.

    >>> import numpy as np
    >>> from railvib_hpc.mbs.coupling import RailCoupling
    >>> K = np.array([[2.0, -1.0], [-1.0, 1.0]])       # M = I; its DOFs are w of 2 rail nodes
    >>> lam, vec = np.linalg.eigh(K)
    >>> rail = RailCoupling(np.array([0.0, 1.0]), vec[:, :1].T, np.zeros((1, 2)))
    >>> x_rr = np.zeros((4, 4)); x_mass = np.zeros((4, 4)); w = [0, 2]
    >>> x_rr[np.ix_(w, w)] = np.linalg.inv(K)
    >>> xd = np.linalg.inv(K) - vec[:, :1] @ vec[:, :1].T / lam[0]   # X' = X - Phi L^-1 Phi^T
    >>> x_mass[np.ix_(w, w)] = xd @ xd
    >>> res = residual_modes(x_rr, x_mass, [rail], np.sqrt(lam[:1]))
    >>> bool(np.isclose(res.omega[0] ** 2, lam[1]))
    True
    """
    om = np.asarray(omega, dtype=float)
    g = residual_flexibility(x_rr, rails, om)
    mres = 0.5 * (x_mass + x_mass.T)
    free = np.flatnonzero(np.diag(x_rr) > 0.0)
    n_r = x_rr.shape[0]
    empty = ResidualModes(np.zeros(0), np.zeros((n_r, 0)), np.zeros((n_r, 0)))
    s, u = np.linalg.eigh(g[np.ix_(free, free)])
    # G = X_rr - Phi_r^T Lambda^-1 Phi_r carries the errors of the static solve and of the
    # modes, ~ eps cond(K) ||X_rr||, and cond(K) of a 3-D model exceeds 1 / sqrt(eps): a
    # direction below sqrt(eps) ||G|| is noise (or holds a flexibility below the accuracy
    # of the static solve), left out
    keep = s > RESIDUAL_RCOND * float(s.max(initial=0.0))
    s, u = s[keep], u[:, keep]
    if s.size == 0:
        return empty
    z = u / np.sqrt(s)                                  # p = z r: stiffness I
    b = z.T @ mres[np.ix_(free, free)] @ z
    beta, w = np.linalg.eigh(0.5 * (b + b.T))
    # X' lies in the span of the modes left out, so every residual mode lies above the kept
    # band; one below it is made of round-off (a direction of G the kept modes already hold,
    # left by the errors of the static solve and the modes, ~ eps cond(K) ||X_rr||)
    top = float(om.max()) if om.size else 0.0
    real = beta * top**2 <= 1.0
    beta, w = beta[real], w[:, real]
    # a residual mass below round-off: a mode 1 / sqrt(eps) times above the band instead
    # (quasi-static in the exact propagator), so that the static flexibility stays exact
    if top > 0.0:
        beta = np.maximum(beta, EPS / top**2)
    if beta.size == 0:
        return empty
    order = np.argsort(beta)[::-1]                      # ascending frequency
    beta, w = beta[order], w[:, order]
    vectors = np.zeros((n_r, beta.size))
    vectors[free] = z @ w / np.sqrt(beta)
    return ResidualModes(1.0 / np.sqrt(beta), vectors, g @ vectors)


def kept_residual_mass(residual_mass: np.ndarray, rest_rows: np.ndarray,
                       omega_rest: np.ndarray) -> np.ndarray:
    """``X'^T M X'`` for ``m`` kept modes from that of all the file's modes (``static.h5``).

    ``X'_m = X'_file + Phi_rest Lambda_rest^-1 Phi_r,rest^T`` and the modes are M-orthogonal
    to ``X'_file``, so the mass only gains ``Phi_r,rest^T Lambda_rest^-2 Phi_r,rest``: a sum of
    positive terms, without cancellation.

    Parameters
    ----------
    residual_mass
        (n_r, n_r) ``X'^T M X'`` with every mode of the file taken out.
    rest_rows
        (m_file - m, n_r) rail rows of the modes not kept (:func:`rail_dof_rows`).
    omega_rest
        (m_file - m,) their circular frequencies [rad/s].
    """
    rest = np.asarray(rest_rows, dtype=float)
    out = residual_mass + (rest / np.asarray(omega_rest, dtype=float)[:, None] ** 4).T @ rest
    return 0.5 * (out + out.T)


def residual_damping_parts(parts: dict[str, np.ndarray], res: ResidualModes,
                           rest_rows: np.ndarray, omega_rest: np.ndarray, m: int
                           ) -> dict[str, np.ndarray]:
    """The projected damping parts of ``modal_damping.h5`` on the basis ``[Phi_m, X'_m V]``.

    ``parts`` hold the projections on ``[Phi_file, X'_file]`` (the file's ``m_file`` modes,
    then the ``n_r`` deflated static fields of :func:`railvib_hpc.modal.static.deflate`); the
    result is (m + k, m + k) for the ``m`` kept modes (``X'_m = X'_file + Phi_rest
    Lambda_rest^-1 Phi_r,rest^T``, see :func:`kept_residual_mass`).
    """
    n_r, k = res.vectors.shape
    rest = np.asarray(rest_rows, dtype=float).reshape(-1, n_r)
    m_file = m + rest.shape[0]
    t = np.zeros((m_file + n_r, m + k))
    t[:m, :m] = np.eye(m)
    t[m:m_file, m:] = (rest / np.asarray(omega_rest, dtype=float)[:, None] ** 2) @ res.vectors
    t[m_file:, m:] = res.vectors
    out = {}
    for name, p in parts.items():
        if p.shape != (m_file + n_r, m_file + n_r):
            raise ValueError(f"damping part {name} has shape {p.shape}, expected "
                             f"({m_file + n_r}, {m_file + n_r}) (modes and static fields)")
        d = t.T @ p @ t
        out[name] = 0.5 * (d + d.T)
    return out


class ContactResidual:
    """Per-step contact residual flexibility and rail-DOF loads of moving wheels.

    Parameters
    ----------
    g
        (n_r, n_r) residual flexibility (:func:`residual_flexibility`).
    rails
        The rails, indexed like ``wheel_rail``.
    wheel_rail
        (n_wheels,) rail index of every wheel.
    x
        (n_steps + 1, n_wheels) wheel positions at every step.
    """

    def __init__(self, g: np.ndarray, rails: Sequence[RailCoupling],
                 wheel_rail: Sequence[int], x: np.ndarray):
        self.g = np.ascontiguousarray(g, dtype=float)
        self.n_dofs = self.g.shape[0]
        nt1, nw = x.shape
        self.idx = np.zeros((nt1, nw, 4), dtype=np.int64)
        self.coef = np.zeros((nt1, nw, 4))
        for j, r in enumerate(wheel_rail):
            rail = rails[int(r)]
            k = rail.x_nodes.size
            elem, w, _ = shape_functions(rail.x_nodes, x[:, j], True)
            base = (int(r) * k + elem) * 2
            self.idx[:, j] = np.stack([base, base + 1, base + 2, base + 3], axis=1)
            self.coef[:, j] = w * np.array([1.0, -1.0, 1.0, -1.0])

    def matrix(self, n: int) -> np.ndarray:
        """(n_wheels, n_wheels) contact residual flexibility ``C`` at step ``n``."""
        i, c = self.idx[n], self.coef[n]
        sub = self.g[i[:, :, None, None], i[None, None, :, :]]
        return np.einsum("ja,jakb,kb->jk", c, sub, c)

    def loads(self, n: int, forces: np.ndarray) -> np.ndarray:
        """(n_r,) rail-DOF loads ``g = -sum_j N_j F_j`` (F positive downwards on the rail)."""
        out = np.zeros(self.n_dofs)
        np.add.at(out, self.idx[n].ravel(), (-self.coef[n] * forces[:, None]).ravel())
        return out


__all__ = ["ContactResidual", "ResidualModes", "kept_residual_mass", "rail_dof_rows",
           "residual_damping_parts", "residual_flexibility", "residual_modes"]
