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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

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


__all__ = ["ContactResidual", "rail_dof_rows", "residual_flexibility"]
